"""Rig description: the reference turboexpander and user rig files (TOML)."""

from bayes_amb.rig.rig import (
    CHANNELS,
    Disc,
    Rig,
    Shaft,
    check_rig_matches,
    check_speed_rpm,
    load_rig,
    node_label,
    rig_difference,
    rig_from_dict,
)

__all__ = ["CHANNELS", "Disc", "Rig", "Shaft", "check_rig_matches", "check_speed_rpm",
           "load_rig", "node_label", "rig_difference", "rig_from_dict"]
