"""A foreign recording generator, written independently of bayes_amb.simulate.

It plays a rotor on magnetic bearings with physics written again from the equations (see
README.md in this folder): its own state space from the FE matrices, its own modal
truncation, the controller read from its JSON file as a rig runs it, every effect a
continuous-time state augmentation or an exact piecewise integration, and the habits of
real records. It must not import bayes_amb.simulate, .discrepancy, .reduction,
.uncertainty, .inference or .control (a test checks the imports).
"""

from benchmarks.foreign.cases import (
    IN_FAMILY,
    KINDS,
    CaseSpec,
    Simulated,
    conceal,
    concealment,
    draw_case,
    simulate,
    write_case,
    write_suite,
)
from benchmarks.foreign.disturbances import Disturbance, draw_disturbance
from benchmarks.foreign.effects import EFFECT_PARAMS, HELD_OUT, Effect, build_plant
from benchmarks.foreign.habits import Habits, draw_habits
from benchmarks.foreign.loop import closed_loop, read_controller, run
from benchmarks.foreign.oracle import fisher_information, fisher_widths
from benchmarks.foreign.plant import bearing_changes, rotor

__all__ = ["EFFECT_PARAMS", "HELD_OUT", "IN_FAMILY", "KINDS", "CaseSpec", "Disturbance",
           "Effect", "Habits", "Simulated", "bearing_changes", "build_plant", "closed_loop",
           "conceal", "concealment", "draw_case", "draw_disturbance", "draw_habits",
           "fisher_information", "fisher_widths", "read_controller", "rotor", "run",
           "simulate", "write_case", "write_suite"]
