"""Pseudo-modal reduction of the full FE model (paper Section III.4-6, eqs. 18-45).

Selection rule
--------------
Eigenvalues of A_f are ordered by modulus |lambda| (the undamped natural frequency of a
lightly damped mode). The paper sorts by |Im lambda|; on an AMB rotor that is not robust:
the suspended rigid-body eigenvalues are real (+/-a, unstable) or nearly so, but so are the
overdamped high-order FE modes (C = beta*K makes them real at |lambda| ~ 1e7 rad/s), which
|Im| would rank first. By modulus, the 8 suspended rigid-body eigenvalues (2 bearings x 2
axes x a +/- pair) come first, then the bending modes as backward/forward whirl pairs, each a
complex-conjugate pair. ``n_bending=k`` keeps 8 + 4k eigenvalues. The cut must fall in a gap:
if |lambda_n| and |lambda_{n+1}| agree within ``gap_tol`` (relative), or the kept set is not
closed under conjugation, a ReductionError is raised rather than splitting a pair.

Real form (eqs. 28-42)
----------------------
For a real eigenvalue the real eigenvector is one state. For a complex pair (lambda,
conj lambda) with right eigenvector v and left eigenvector w (w^T A = lambda w^T, w^T v = 1),
the states are (Re z, Im z) with z = w^T x, and

    T_R = [2 Re v, -2 Im v],   T_L = [Re w^T; Im w^T],   A_block = [[a, -b], [b, a]].

This is the paper's complex separation (eqs. 28-34) followed by removal of the duplicate,
uncontrollable half (eqs. 35-42) in one step. T_L is finally re-biorthogonalised,
T_L <- (T_L T_R)^-1 T_L, so that T_L T_R = I also for repeated eigenvalues (at 0 rpm the x
and y planes decouple and every eigenvalue is double).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bayes_amb.errors import ReductionError
from bayes_amb.rig import Rig
from bayes_amb.rotor import FullModel, full_model

N_RIGID = 8
"""Number of suspended rigid-body eigenvalues of a rotor on two radial AMBs."""


@dataclass(frozen=True)
class ReducedModel:
    """Reduced model (eqs. 43-45): A = T_L A_f T_R, B = T_L B_f, C = C_f T_R.

    A (n, n) in 1/s, B (n, 4), C (4, n); T_L (n, N) and T_R (N, n) with N = 320 on the
    reference rig; ``poles`` are the kept eigenvalues of A_f in rad/s.
    """

    A: NDArray
    B: NDArray
    C: NDArray
    T_L: NDArray
    T_R: NDArray
    poles: NDArray
    n_bending: int
    speed_rpm: float
    full: FullModel

    @property
    def n_states(self) -> int:
        return self.A.shape[0]


def select_modes(lam: NDArray, n_keep: int, gap_tol: float = 1e-6) -> NDArray:
    """Indices of the first n_keep eigenvalues (already sorted by modulus), checked.

    Raises ReductionError if the cut splits a conjugate pair or falls where two moduli are
    equal within gap_tol (relative), i.e. where the modes cannot be separated.
    """
    if not 0 < n_keep < lam.size:
        raise ReductionError(f"cannot keep {n_keep} modes of a model with {lam.size} "
                             "eigenvalues")
    mod = np.abs(lam)
    if mod[n_keep] - mod[n_keep - 1] <= gap_tol * mod[n_keep]:
        raise ReductionError(
            f"modes cannot be separated: |lambda_{n_keep}| = {mod[n_keep - 1]:.6g} and "
            f"|lambda_{n_keep + 1}| = {mod[n_keep]:.6g} rad/s agree within {gap_tol:g}")
    kept = lam[:n_keep]
    scale = max(float(mod[n_keep - 1]), 1.0)
    for l in kept:
        if abs(l.imag) > 1e-9 * scale and np.min(np.abs(kept - np.conj(l))) > 1e-9 * scale:
            raise ReductionError(f"the cut at {n_keep} modes splits the conjugate pair of "
                                 f"lambda = {l:.6g} rad/s")
    return np.arange(n_keep)


def real_modal_basis(lam: NDArray, W: NDArray, V: NDArray,
                     tol: float = 1e-9) -> tuple[NDArray, NDArray, NDArray]:
    """Real (T_L, T_R) for a conjugate-closed set of eigenpairs; also the kept eigenvalues.

    lam (m,), W and V (N, m): left (w^T A = lambda w^T) and right eigenvectors.
    """
    cols_r: list[NDArray] = []
    rows_l: list[NDArray] = []
    kept: list[complex] = []
    scale = max(float(np.max(np.abs(lam))), 1.0)
    used = np.zeros(lam.size, dtype=bool)
    for i, l in enumerate(lam):
        if used[i]:
            continue
        v = V[:, i] / np.linalg.norm(V[:, i])
        w = W[:, i]
        if abs(l.imag) <= tol * scale:
            # real eigenvalue: rotate the vectors to be real
            v = np.real(v * np.exp(-1j * np.angle(v[np.argmax(np.abs(v))])))
            w = np.real(w * np.exp(-1j * np.angle(w[np.argmax(np.abs(w))])))
            w = w / (w @ v)
            cols_r.append(v)
            rows_l.append(w)
            kept.append(complex(l.real, 0.0))
            used[i] = True
        else:
            j = np.argmin(np.where(used, np.inf, np.abs(lam - np.conj(l))))
            used[i] = used[j] = True
            if l.imag < 0:      # use the member with positive imaginary part
                l, v, w = np.conj(l), np.conj(v), np.conj(w)
            w = w / (w @ v)
            cols_r += [2.0 * v.real, -2.0 * v.imag]
            rows_l += [w.real, w.imag]
            kept += [l, np.conj(l)]
    T_R = np.column_stack(cols_r)
    T_L = np.vstack(rows_l)
    T_L = np.linalg.solve(T_L @ T_R, T_L)       # enforce T_L T_R = I exactly
    return T_L, T_R, np.array(kept)


def reduce_pseudo_modal(model: FullModel | Rig, n_bending: int = 0,
                        speed_rpm: float | None = None) -> ReducedModel:
    """Pseudo-modal reduction (eqs. 18-45): keep the rigid-body modes and n_bending pairs.

    Parameters
    ----------
    model : FullModel or Rig
        The full model, or a rig (then built at ``speed_rpm``, default nominal).
    n_bending : int
        Number of bending-mode pairs (backward and forward whirl) to keep: 8 + 4k states.

    Examples
    --------
    >>> from bayes_amb.rig import load_rig
    >>> red = reduce_pseudo_modal(load_rig())
    >>> red.n_states, red.B.shape, red.C.shape
    (8, (8, 4), (4, 8))
    """
    if n_bending < 0:
        raise ReductionError(f"n_bending must be >= 0, got {n_bending}")
    fm = model if isinstance(model, FullModel) else full_model(model, speed_rpm)
    lam, W, V = fm.modes
    n_keep = N_RIGID + 4 * n_bending
    idx = select_modes(lam, n_keep)
    T_L, T_R, kept = real_modal_basis(lam[idx], W[:, idx], V[:, idx])
    A = T_L @ fm.A @ T_R
    B = T_L @ fm.B
    C = fm.C @ T_R
    return ReducedModel(A=A, B=B, C=C, T_L=T_L, T_R=T_R, poles=kept, n_bending=n_bending,
                        speed_rpm=fm.speed_rpm, full=fm)


def kept_states(pairs: tuple[int, ...]) -> NDArray:
    """Indices, in the modulus order of the eigenvalues, of the rigid-body modes and the
    bending pairs ``pairs`` (1-based, each its backward and forward whirl: four states)."""
    return np.concatenate([np.arange(N_RIGID)]
                          + [N_RIGID + 4 * (k - 1) + np.arange(4) for k in pairs]).astype(int)


def keep_bending_pairs(red: ReducedModel, pairs: tuple[int, ...]) -> ReducedModel:
    """The reduction keeping the rigid-body modes and only the bending pairs ``pairs``
    (1-based, each of them <= red.n_bending): its states are those of ``red`` for the kept
    modes. A is block diagonal in the real modal basis, so deleting a pair's four states
    (backward and forward whirl) is exactly the reduction that leaves that pair out.

    >>> from bayes_amb.rig import load_rig
    >>> keep_bending_pairs(reduce_pseudo_modal(load_rig(), n_bending=2), (2,)).n_states
    12
    """
    pairs = tuple(sorted(set(pairs)))
    if any(not 1 <= k <= red.n_bending for k in pairs):
        raise ReductionError(f"bending pairs {pairs} not all in 1..{red.n_bending}")
    if pairs == tuple(range(1, red.n_bending + 1)):
        return red
    idx = kept_states(pairs)
    return ReducedModel(A=red.A[np.ix_(idx, idx)], B=red.B[idx], C=red.C[:, idx],
                        T_L=red.T_L[idx], T_R=red.T_R[:, idx], poles=red.poles[idx],
                        n_bending=len(pairs), speed_rpm=red.speed_rpm, full=red.full)


def _left_out(fm: FullModel, pairs: tuple[int, ...], C: NDArray | None = None
              ) -> tuple[NDArray, NDArray, NDArray]:
    """The modes a reduction keeping ``pairs`` leaves out: their eigenvalues, C v (p, k)
    and w^T B_f (k, m) with w^T v = 1, so that mode i's residue is C v_i w_i^T B_f
    (C: default C_f, the probes)."""
    lam, _, V = fm.modes
    out = np.setdiff1d(np.arange(lam.size), kept_states(pairs))
    return lam[out], ((fm.C if C is None else C) @ V)[:, out], fm.mode_inputs[out]


def residual_corner(fm: FullModel, pairs: tuple[int, ...] = ()) -> tuple[NDArray, NDArray]:
    """(omega_e rad/s, zeta_e), one per input channel j: a lumped mode
    D_jj omega_e^2 / (s^2 + 2 zeta_e omega_e s + omega_e^2) for the modes a reduction
    keeping ``pairs`` leaves out, with D their static compliance (:func:`residual_static`).
    It matches the first two terms of their low-frequency expansion on the channel's own
    output, sum_i r_i / (s - lambda_i) = D_jj (1 + a_1 s + a_2 s^2 + ...):
    zeta_e / omega_e = -a_1 / 2 (the term that acts on the band like a damping: -beta of a
    Rayleigh damping) and 1 / omega_e^2 = a_1^2 - a_2 (the rise of their compliance below
    the lowest of them); above them it falls as they do. On ROSS's test rig: 454 Hz and
    0.14 at bearing A (pair 2 at 386/413 Hz holds most of it), 937 Hz and 0.29 at B.

    >>> from bayes_amb.rig import load_rig
    >>> from bayes_amb.rotor import full_model
    >>> w, z = residual_corner(full_model(load_rig()))
    >>> bool(np.all(w / (2 * np.pi) > 1000.0) and np.all((0.0 <= z) & (z < 1.0)))
    True
    """
    lo, CV, wB = _left_out(fm, pairs)
    d = np.einsum("ji,ij->ji", CV, wB)                          # residues (channel, mode)
    D = np.real(np.sum(-d / lo, axis=1))
    a1 = np.real(np.sum(-d / lo**2, axis=1)) / D
    a2 = np.real(np.sum(-d / lo**3, axis=1)) / D
    inv2 = a1**2 - a2
    # a channel whose left-out modes give no rise (inv2 <= 0): their lowest mode instead
    fallback = float(np.min(np.abs(lo)))
    omega = np.where(inv2 > 0.0, 1.0 / np.sqrt(np.abs(inv2)), fallback)
    zeta = np.clip(-0.5 * a1 * omega, 0.0, 0.99)
    return omega, zeta


def residual_static(fm: FullModel, pairs: tuple[int, ...] = (), C: NDArray | None = None
                    ) -> NDArray:
    """Static compliance (4, 4), C_f (-A_f^-1) B_f restricted to the modes that a reduction
    keeping the rigid-body modes and the bending pairs ``pairs`` (1-based) leaves out: the
    residual flexibility of the truncated modes (mode-acceleration method), in m per unit
    of the input of B_f. ``C`` (p, 2 n_q), default C_f: other outputs of the state (the
    LFT's z, uncertainty.lft.lft_reduced), giving (p, 4).

    Summed over the left-out modes, -C_f v w^T B_f / lambda with w^T v = 1. Written as
    (full static) - (kept static) it would be the difference of two numbers ~1e4 apart
    on the reference rig (the negative bearing stiffness makes the rigid-body part large),
    and a solve with A_f (condition ~7e14) loses ~2e-4 of it; this sum agrees with an
    80-bit reference of the difference to ~1e-8.

    >>> from bayes_amb.rig import load_rig
    >>> from bayes_amb.rotor import full_model
    >>> residual_static(full_model(load_rig())).shape
    (4, 4)
    """
    lo, CV, wB = _left_out(fm, pairs, C)
    return np.real(-CV @ (wB / lo[:, None]))
