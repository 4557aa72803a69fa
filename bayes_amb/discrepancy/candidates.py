"""Compatibility names: the candidate library now lives in bayes_amb.discrepancy.library
(one module per effect and the registry)."""

from bayes_amb.discrepancy.library import (
    BEARING_COEFFICIENTS,
    VOCABULARY,
    Actuator2nd,
    ActuatorGain,
    ActuatorLag,
    BearingCoefficient,
    Candidate,
    CrossCoupling,
    EffectParam,
    FlexibleMode,
    ModelContext,
    Runout,
    SensorDelay,
    SensorGain,
    SensorLag,
    SynchronousLine,
    TimeDelay,
    Unbalance,
    all_candidates,
    left_out_coefficients,
)

__all__ = ["BEARING_COEFFICIENTS", "VOCABULARY", "Actuator2nd", "ActuatorGain", "ActuatorLag",
           "BearingCoefficient", "Candidate", "CrossCoupling", "EffectParam", "FlexibleMode",
           "ModelContext", "Runout", "SensorDelay", "SensorGain", "SensorLag",
           "SynchronousLine", "TimeDelay", "Unbalance", "all_candidates",
           "left_out_coefficients"]
