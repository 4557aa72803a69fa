"""Rotor FE model: Euler-Bernoulli shaft elements, rigid discs, AMBs (eqs. 16-17)."""

from bayes_amb.rotor.assembly import (
    FullModel,
    RotorMatrices,
    assemble,
    channel_dofs,
    dof_index,
    full_model,
    rpm_to_rad_s,
    state_matrices,
)
from bayes_amb.rotor.elements import disc_matrices, shaft_element

__all__ = ["FullModel", "RotorMatrices", "assemble", "channel_dofs", "disc_matrices",
           "dof_index", "full_model", "rpm_to_rad_s", "shaft_element", "state_matrices"]
from bayes_amb.rotor.campbell import (
    CampbellData,
    bending_frequencies_hz,
    campbell_data,
    unstable_poles,
)

__all__ += ["CampbellData", "bending_frequencies_hz", "campbell_data", "unstable_poles"]
