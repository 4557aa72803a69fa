"""Controller, coprime factors, Youla and dual-Youla parametrisations, S(theta) (eqs. 1-14)."""

from bayes_amb.control.compatible import (
    compatible_factors,
    excitation_signal_x,
    youla_parameter_of,
)
from bayes_amb.control.coprime import CoprimeFactors, bezout_residual, coprime_factors, freqresp
from bayes_amb.control.design import (
    DesignSettings,
    ObserverController,
    design_observer_controller,
)
from bayes_amb.control.pid import GenericController, PIDSettings, design_decentralised_pid
from bayes_amb.control.robustness import iso14839_zone, loop_spectral_radius, sensitivity
from bayes_amb.control.youla import (
    discrete_plant,
    g_of_s,
    g_of_s_left,
    k_of_q,
    s_theta,
    s_theta_exact,
    s_theta_lft,
    t_cl,
)

__all__ = [
    "CoprimeFactors",
    "DesignSettings",
    "GenericController",
    "ObserverController",
    "PIDSettings",
    "bezout_residual",
    "compatible_factors",
    "coprime_factors",
    "design_decentralised_pid",
    "design_observer_controller",
    "discrete_plant",
    "excitation_signal_x",
    "freqresp",
    "g_of_s",
    "g_of_s_left",
    "iso14839_zone",
    "k_of_q",
    "loop_spectral_radius",
    "s_theta",
    "s_theta_exact",
    "s_theta_lft",
    "sensitivity",
    "t_cl",
    "youla_parameter_of",
]
