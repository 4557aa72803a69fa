"""LFT uncertainty on the full and the reduced model (eqs. 46-52).

A_f(theta) = A_f + B_w_f Theta C_z_f, with Theta = blockdiag(theta_p I_{r_p}) and G_zw = 0.
Reduced (eqs. 51-52): B_w = T_L B_w_f and C_z = C_z_f T_R. A reduction that keeps bending
pairs may also hold the compliance of the modes it leaves out, on every path of the LFT
(:func:`lft_reduced`, ``keeps``).

Notation (METHOD.md section 1): in code, ``B_w``/``C_z`` are the *matrices* the paper calls
G_yw_f / G_zu_f (eqs. 49-50). The *transfer matrices* G_yw = C (sI-A)^-1 B_w etc. of eq. 13
are built by :func:`lft_transfer_blocks`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bayes_amb.errors import LFTError, ParameterError
from bayes_amb.reduction.pseudo_modal import ReducedModel, residual_corner, residual_static
from bayes_amb.rig import Rig
from bayes_amb.rotor import FullModel
from bayes_amb.uncertainty.parameters import get_spec, lft_columns, parse_param_list


@dataclass(frozen=True)
class UncertainPlant:
    """A plant with LFT parameter uncertainty, continuous time.

    A (n, n), B (n, 4), C (4, n), B_w (n, r), C_z (r, n); ``names`` the parameters and
    ``blocks`` how many LFT channels each uses (1 for k/c, 2 for kxy), sum(blocks) = r.
    ``n_left_out``: the last states hold the compliance of the modes a reduction left out
    (:func:`lft_reduced`), 0 if none.
    """

    A: NDArray
    B: NDArray
    C: NDArray
    B_w: NDArray
    C_z: NDArray
    names: tuple[str, ...]
    blocks: tuple[int, ...]
    n_left_out: int = 0

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


def lft_reduced(reduced: ReducedModel, rig: Rig, params: str | tuple[str, ...] | list[str],
                keeps: tuple[int, ...] | None = None) -> UncertainPlant:
    """Reduced-model LFT (eqs. 51-52): B_w = T_L B_w_f, C_z = C_z_f T_R.

    ``keeps``: the bending pairs (1-based) the reduction keeps. Given and not empty, the
    plant also holds the compliance of the modes it leaves out (:func:`with_left_out`).

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
    plant = UncertainPlant(A=reduced.A, B=reduced.B, C=reduced.C, B_w=reduced.T_L @ full.B_w,
                           C_z=full.C_z @ reduced.T_R, names=full.names, blocks=full.blocks)
    return with_left_out(plant, full, reduced.full, keeps) if keeps else plant


def with_left_out(plant: UncertainPlant, full_lft: UncertainPlant, full: FullModel,
                  keeps: tuple[int, ...]) -> UncertainPlant:
    """The reduced LFT ``plant`` plus the modes a reduction keeping the bending pairs
    ``keeps`` leaves out, on every path: from the currents u and from the LFT's w to the
    probes y and to its z.

    Their effect is carried by one lumped mode per actuator channel j,
    omega_j^2 / (s^2 + 2 zeta_j omega_j s + omega_j^2) (reduction.pseudo_modal.
    residual_corner), driven by that channel's force: u_j, plus the part of w that acts
    where u_j acts (B_w_f = B_f T; a w column that acts elsewhere gets no path). Its state
    q_j reaches each output through the left-out modes' static compliance from channel j
    (mode-acceleration method, residual_static): y += D_y q, and on z the displacement
    rows' compliance on q and the velocity rows' on dq/dt. So a bearing coefficient's
    force bends the left-out modes, and their deflection at the bearing feeds the
    coefficient, as in the full FE model: on ROSS's test rig a damping change alone moves
    the model's response by 0.6-1.6 % in band without these paths (studies/lft_residual.py).
    The 2 x 4 states are appended last, lumped mode j at states n + 2j (q_j) and
    n + 2j + 1 (dq_j/dt / omega_j)."""
    n_q = full.n_states // 2
    omega, zeta = residual_corner(full, keeps)
    m = omega.size
    A_L = np.zeros((2 * m, 2 * m))
    B_L = np.zeros((2 * m, m))
    c_q = np.zeros((m, 2 * m))
    c_v = np.zeros((m, 2 * m))
    for j, (w, z) in enumerate(zip(omega, zeta, strict=True)):
        # states (q_j, dq_j/dt / omega_j): entries of order omega, not omega^2 (a smaller
        # norm for the sampling's scaling and squaring)
        A_L[2 * j:2 * j + 2, 2 * j:2 * j + 2] = [[0.0, w], [-w, -2.0 * z * w]]
        B_L[2 * j + 1, j] = w
        c_q[j, 2 * j] = 1.0
        c_v[j, 2 * j + 1] = w
    # one sum over the left-out modes for the probes, z's displacement rows and z's
    # velocity rows read as displacements
    Cz = full_lft.C_z
    p, r = full.C.shape[0], Cz.shape[0]
    zero = np.zeros_like(Cz[:, :n_q])
    D = residual_static(full, keeps, np.vstack([full.C, np.hstack([Cz[:, :n_q], zero]),
                                                np.hstack([Cz[:, n_q:], zero])]))
    D_y, D_zq, D_zv = D[:p], D[p:p + r], D[p + r:]
    T, *_ = np.linalg.lstsq(full.B, full_lft.B_w, rcond=None)
    off = np.linalg.norm(full.B @ T - full_lft.B_w, axis=0) > 1e-9 * np.linalg.norm(
        full_lft.B_w, axis=0)
    T[:, off] = 0.0
    n = plant.n_states
    A = np.zeros((n + 2 * m, n + 2 * m))
    A[:n, :n] = plant.A
    A[n:, n:] = A_L
    return UncertainPlant(A=A, B=np.vstack([plant.B, B_L]),
                          C=np.hstack([plant.C, D_y @ c_q]),
                          B_w=np.vstack([plant.B_w, B_L @ T]),
                          C_z=np.hstack([plant.C_z, D_zq @ c_q + D_zv @ c_v]),
                          names=plant.names, blocks=plant.blocks, n_left_out=2 * m)


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
