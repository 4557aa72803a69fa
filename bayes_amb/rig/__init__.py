"""Rig description: the reference turboexpander and user rig files (TOML)."""

from bayes_amb.rig.rig import (
    CHANNELS,
    Disc,
    Magnet,
    Rig,
    check_rig_matches,
    check_speed_rpm,
    load_rig,
    magnet_constants,
    node_label,
    rig_difference,
    rig_from_dict,
)
from bayes_amb.rig.shaft import Material, Shaft, ShaftSection, SteppedShaft

__all__ = ["CHANNELS", "Disc", "Magnet", "Material", "Rig", "Shaft", "ShaftSection",
           "SteppedShaft", "check_rig_matches", "check_speed_rpm", "load_rig",
           "magnet_constants", "node_label", "rig_difference", "rig_from_dict"]
