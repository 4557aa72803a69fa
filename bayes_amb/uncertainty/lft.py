"""LFT uncertainty on the full and the reduced model (eqs. 46-52).

A_f(theta) = A_f + B_w_f Theta C_z_f, with Theta = blockdiag(theta_p I_{r_p}) and G_zw = 0.
Reduced (eqs. 51-52): B_w = T_L B_w_f and C_z = C_z_f T_R.

Notation (METHOD.md section 1): in code, ``B_w``/``C_z`` are the *matrices* the paper calls
G_yw_f / G_zu_f (eqs. 49-50). The *transfer matrices* G_yw = C (sI-A)^-1 B_w etc. of eq. 13
are built by :func:`lft_transfer_blocks`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bayes_amb.errors import LFTError, ParameterError
from bayes_amb.reduction.pseudo_modal import ReducedModel
from bayes_amb.rig import Rig
from bayes_amb.rotor import FullModel
from bayes_amb.uncertainty.parameters import get_spec, lft_columns, parse_param_list


@dataclass(frozen=True)
class UncertainPlant:
    """A plant with LFT parameter uncertainty, continuous time.

    A (n, n), B (n, 4), C (4, n), B_w (n, r), C_z (r, n); ``names`` the parameters and
    ``blocks`` how many LFT channels each uses (1 for k/c, 2 for kxy), sum(blocks) = r.
    """

    A: NDArray
    B: NDArray
    C: NDArray
    B_w: NDArray
    C_z: NDArray
    names: tuple[str, ...]
    blocks: tuple[int, ...]

    @property
    def n_states(self) -> int:
        return self.A.shape[0]

    def theta_diag(self, theta: NDArray | list[float]) -> NDArray:
        """Diagonal of Theta (length r) from one theta per parameter."""
        th = np.asarray(theta, dtype=float).reshape(-1)
        if th.size != len(self.names):
            raise ParameterError(f"theta has {th.size} values; expected {len(self.names)} "
                                 f"for parameters {list(self.names)}")
        return np.repeat(th, self.blocks)

    def A_theta(self, theta: NDArray | list[float]) -> NDArray:
        """A + B_w Theta C_z (eq. 47 on the state matrix)."""
        return self.A + (self.B_w * self.theta_diag(theta)) @ self.C_z


def lft_full(model: FullModel, rig: Rig, params: str | tuple[str, ...] | list[str]
             ) -> UncertainPlant:
    """Full-model LFT (eqs. 48-50) for one or several named parameters."""
    names = parse_param_list(params)
    cols, rows, blocks = [], [], []
    for n in names:
        bw, cz = lft_columns(get_spec(n), rig, model.matrices)
        cols.append(bw)
        rows.append(cz)
        blocks.append(bw.shape[1])
    return UncertainPlant(A=model.A, B=model.B, C=model.C, B_w=np.hstack(cols),
                          C_z=np.vstack(rows), names=names, blocks=tuple(blocks))


def lft_reduced(reduced: ReducedModel, rig: Rig, params: str | tuple[str, ...] | list[str]
                ) -> UncertainPlant:
    """Reduced-model LFT (eqs. 51-52): B_w = T_L B_w_f, C_z = C_z_f T_R.

    Examples
    --------
    >>> from bayes_amb.rig import load_rig
    >>> from bayes_amb.reduction import reduce_pseudo_modal
    >>> rig = load_rig()
    >>> up = lft_reduced(reduce_pseudo_modal(rig), rig, "k_By,c_By,kxy_A")
    >>> up.B_w.shape, up.C_z.shape, up.blocks
    ((8, 4), (4, 8), (1, 1, 2))
    """
    full = lft_full(reduced.full, rig, params)
    return UncertainPlant(A=reduced.A, B=reduced.B, C=reduced.C, B_w=reduced.T_L @ full.B_w,
                          C_z=full.C_z @ reduced.T_R, names=full.names, blocks=full.blocks)


def lower_lft(P11: NDArray, P12: NDArray, P21: NDArray, P22: NDArray, Delta: NDArray,
              ) -> NDArray:
    """Lower LFT of constant matrices, eq. 46: P11 + P12 Delta (I - P22 Delta)^-1 P21.

    Checks dimensions and well-posedness (I - P22 Delta invertible).

    Examples
    --------
    >>> lower_lft(np.eye(1), np.eye(1), np.eye(1), np.zeros((1, 1)), 0.5 * np.eye(1))
    array([[1.5]])
    """
    P11, P12, P21, P22, Delta = (np.atleast_2d(np.asarray(m, dtype=complex if np.iscomplexobj(m)
                                                          else float))
                                 for m in (P11, P12, P21, P22, Delta))
    if P12.shape[0] != P11.shape[0]:
        raise LFTError(f"P12 has the wrong number of rows; expected {P11.shape[0]} instead of "
                       f"{P12.shape[0]}")
    if P21.shape[1] != P11.shape[1]:
        raise LFTError(f"P21 has the wrong number of columns; expected {P11.shape[1]} instead "
                       f"of {P21.shape[1]}")
    if P22.shape != (P21.shape[0], P12.shape[1]):
        raise LFTError(f"P22 has the wrong shape; expected {(P21.shape[0], P12.shape[1])} "
                       f"instead of {P22.shape}")
    if Delta.shape != (P12.shape[1], P21.shape[0]):
        raise LFTError(f"Delta has the wrong shape; expected {(P12.shape[1], P21.shape[0])} "
                       f"instead of {Delta.shape}")
    E = np.eye(P22.shape[0]) - P22 @ Delta
    if np.linalg.cond(E) > 1e12:
        raise LFTError("LFT is ill-posed: I - P22*Delta is singular "
                       f"(condition number {np.linalg.cond(E):.3g})")
    return P11 + P12 @ Delta @ np.linalg.solve(E, P21)
