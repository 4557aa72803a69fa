"""Answers in a rotordynamics engineer's terms, with their uncertainty.

Bearing stiffness and damping, closed-loop modes (frequency, damping ratio, log
decrement), API 617-style stability and separation margins, ISO 14839-3 peak sensitivity and
frequency responses, each propagated from the posterior draws of an identification.
"""

from bayes_amb.engineering.frf import (
    FrfEstimate,
    FrfResult,
    controller_response,
    frequency_responses,
    joint_io_frf,
)
from bayes_amb.engineering.intervals import CENTRAL_Z, CentralRegion, central_region, interval90
from bayes_amb.engineering.loop import (
    MODE_LABELS,
    LoopModes,
    closed_loop_modes,
    log_decrement,
    plant_matrices,
)
from bayes_amb.engineering.quantities import (
    API617_LOGDEC,
    Draws,
    EngineeringResult,
    Quantity,
    draws_from,
    physical_quantities,
    required_separation_margin,
)
from bayes_amb.engineering.snr import excitation_response, response_snr_db

__all__ = ["API617_LOGDEC", "CENTRAL_Z", "MODE_LABELS", "CentralRegion", "Draws",
           "EngineeringResult", "FrfEstimate", "FrfResult", "LoopModes", "Quantity",
           "central_region", "closed_loop_modes", "controller_response", "draws_from",
           "excitation_response", "frequency_responses", "interval90", "joint_io_frf",
           "log_decrement", "physical_quantities", "plant_matrices",
           "required_separation_margin", "response_snr_db"]
