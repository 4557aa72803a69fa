"""Accuracy of the reduced-model LFT against the physically perturbed full model.

The reduced LFT (eqs. 51-52) moves the kept eigenvalues with A_r + B_w,r Theta C_z,r, where
B_w,r = T_L B_w_f and C_z,r = C_z_f T_R use the *nominal* modal basis. That is exact only to
first order in theta: the perturbed full model also mixes in the modes that were left out.
:func:`reduced_eigenvalue_error` measures how far apart the two are.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment

from bayes_amb.errors import ParameterError
from bayes_amb.reduction import reduce_pseudo_modal
from bayes_amb.rig import Rig
from bayes_amb.rotor import assemble, full_model, state_matrices
from bayes_amb.uncertainty.lft import lft_reduced
from bayes_amb.uncertainty.parameters import get_spec, physical_change


@dataclass(frozen=True)
class ReducedAccuracy:
    """Relative eigenvalue error of the reduced LFT for one parameter.

    thetas (n,) dimensionless; max_rel_error (n,) is, per theta, the largest
    |lambda_r - lambda_f| / |lambda_f| over the matched kept eigenvalues (dimensionless);
    n_states the reduced order; speed_rpm the rotor speed.
    """

    param: str
    thetas: NDArray
    max_rel_error: NDArray
    n_states: int
    speed_rpm: float

    def worst(self) -> float:
        """Largest relative error over all thetas."""
        return float(np.max(self.max_rel_error))


def matched_relative_error(approx: NDArray, exact: NDArray) -> NDArray:
    """|approx_i - exact_j| / |exact_j| for the optimal one-to-one matching (i, j).

    Both arrays have the same length; the matching minimises the summed relative error
    (Hungarian algorithm, scipy.optimize.linear_sum_assignment).
    """
    approx = np.asarray(approx, dtype=complex)
    exact = np.asarray(exact, dtype=complex)
    if approx.shape != exact.shape:
        raise ValueError(f"eigenvalue sets differ in size: {approx.size} against {exact.size}")
    cost = np.abs(approx[:, None] - exact[None, :]) / np.abs(exact)[None, :]
    rows, cols = linear_sum_assignment(cost)
    return cost[rows, cols]


def reduced_eigenvalue_error(rig: Rig, param: str, thetas: ArrayLike,
                             speed_rpm: float | None = None, n_bending: int = 0
                             ) -> ReducedAccuracy:
    """Compare the reduced LFT with the full model rebuilt from the perturbed rig.

    For each theta, the eigenvalues of A_r + B_w,r theta C_z,r (eqs. 47, 51-52) are matched
    against the n smallest-modulus eigenvalues of the full A_f built by
    :func:`bayes_amb.rotor.state_matrices` with the physical change
    :func:`~bayes_amb.uncertainty.parameters.physical_change` (n = 8 + 4 n_bending).

    Parameters
    ----------
    rig : Rig
    param : str
        One parameter name, e.g. "k_By".
    thetas : array_like, shape (n_theta,)
        Values of theta, dimensionless.
    speed_rpm : float, optional
        Rotor speed; default the rig's nominal speed.
    n_bending : int
        Bending-mode pairs kept in the reduction (0: the paper's 8 states).

    Examples
    --------
    >>> from bayes_amb.rig import load_rig
    >>> acc = reduced_eigenvalue_error(load_rig(), "k_By", [0.0, 0.5])
    >>> bool(acc.max_rel_error[0] < 1e-8), bool(acc.worst() < 0.02)
    (True, True)
    """
    spec = get_spec(param)
    th = np.atleast_1d(np.asarray(thetas, dtype=float))
    if th.ndim != 1 or not np.all(np.isfinite(th)):
        raise ParameterError(f"thetas must be a finite 1-D array, got shape {th.shape}")
    speed = rig.nominal_speed_rpm if speed_rpm is None else float(speed_rpm)
    mats = assemble(rig)
    reduced = reduce_pseudo_modal(full_model(rig, speed, mats), n_bending=n_bending)
    plant = lft_reduced(reduced, rig, param)
    n = reduced.n_states
    errors = np.empty(th.size)
    for i, t in enumerate(th):
        dK, dC = physical_change(spec, rig, float(t), mats.n_q)
        A_full = state_matrices(mats, speed, dK, dC)[0]
        lam_f = np.linalg.eigvals(A_full)
        lam_f = lam_f[np.argsort(np.abs(lam_f), kind="stable")][:n]
        lam_r = np.linalg.eigvals(plant.A_theta([t]))
        errors[i] = float(np.max(matched_relative_error(lam_r, lam_f)))
    return ReducedAccuracy(param=param, thetas=th, max_rel_error=errors, n_states=n,
                           speed_rpm=speed)
