"""The library of candidate physics: one module per effect and the registry of them all.

    from bayes_amb.discrepancy.library import REGISTRY, all_candidates, library_table
    REGISTRY["sensor_lag"].physical        # what the effect reports, with units
    [c.key for c in all_candidates()]      # every candidate the diagnosis tries
"""

from bayes_amb.discrepancy.library.actuator_2nd import Actuator2nd
from bayes_amb.discrepancy.library.actuator_gain import ActuatorGain
from bayes_amb.discrepancy.library.actuator_lag import ActuatorLag
from bayes_amb.discrepancy.library.base import (
    Candidate,
    EffectEntry,
    EffectParam,
    Equivalence,
    ModelContext,
    Quantity,
    Sampled,
    SynchronousLine,
)
from bayes_amb.discrepancy.library.bearing_coefficient import (
    BEARING_COEFFICIENTS,
    BearingCoefficient,
    left_out_coefficients,
)
from bayes_amb.discrepancy.library.cross_coupling import CrossCoupling
from bayes_amb.discrepancy.library.flexible_mode import FlexibleMode
from bayes_amb.discrepancy.library.registry import (
    NOMINAL_FAMILY,
    REGISTRY,
    VOCABULARY,
    all_candidates,
    entry,
    equivalents_of,
    library_table,
    make_candidate,
    markdown_table,
    node_scan,
)
from bayes_amb.discrepancy.library.residual_flexibility import ResidualFlexibility
from bayes_amb.discrepancy.library.runout import Runout
from bayes_amb.discrepancy.library.sensor_delay import SensorDelay
from bayes_amb.discrepancy.library.sensor_gain import SensorGain
from bayes_amb.discrepancy.library.sensor_lag import SensorLag
from bayes_amb.discrepancy.library.time_delay import TimeDelay
from bayes_amb.discrepancy.library.unbalance import Unbalance

__all__ = ["BEARING_COEFFICIENTS", "NOMINAL_FAMILY", "REGISTRY", "VOCABULARY", "Actuator2nd",
           "ActuatorGain", "ActuatorLag", "BearingCoefficient", "Candidate", "CrossCoupling",
           "EffectEntry", "EffectParam", "Equivalence", "FlexibleMode", "ModelContext",
           "Quantity", "ResidualFlexibility", "Runout", "Sampled", "SensorDelay", "SensorGain",
           "SensorLag",
           "SynchronousLine", "TimeDelay", "Unbalance", "all_candidates", "entry",
           "equivalents_of", "left_out_coefficients", "library_table", "make_candidate",
           "markdown_table", "node_scan"]
