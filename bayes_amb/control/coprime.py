"""Doubly coprime factors of plant and controller (eqs. 1-3) and their Bezout check.

For the observer-based controller (METHOD.md section 2, D = 0):

    M  = [A+BF | B ; F | I]        U  = [A+BF | -L ; F | 0]
    N  = [A+BF | B ; C | 0]        V  = [A+BF | -L ; C | I]
    Mt = [A+LC | L ; C | I]        Ut = [A+LC | -L ; F | 0]
    Nt = [A+LC | B ; C | 0]        Vt = [A+LC | -B ; F | I]

G = N M^-1 = Mt^-1 Nt, K = U V^-1 = Vt^-1 Ut, and
[Vt -Ut; -Nt Mt] [M U; N V] = I (double Bezout identity, eq. 3).
"""

from __future__ import annotations

from dataclasses import dataclass

import control as ct
import numpy as np
from numpy.typing import NDArray

from bayes_amb.control.design import ObserverController
from bayes_amb.control.discrete import ss_freqresp


def ss(A: NDArray, B: NDArray, C: NDArray, D: NDArray, dt: float) -> ct.StateSpace:
    """A discrete python-control StateSpace without name bookkeeping overhead."""
    return ct.ss(A, B, C, D, dt)


def ss_inv(sys: ct.StateSpace) -> ct.StateSpace:
    """Inverse of a square system with invertible D: [A - B D^-1 C | B D^-1 ; -D^-1 C | D^-1]."""
    Di = np.linalg.inv(sys.D)
    return ss(sys.A - sys.B @ Di @ sys.C, sys.B @ Di, -Di @ sys.C, Di, sys.dt)


def freqresp(sys: ct.StateSpace, z: NDArray) -> NDArray:
    """Frequency response at complex points z (discrete: z = e^{j w dt}); (n_z, p, m)."""
    return ss_freqresp(np.asarray(sys.A), np.asarray(sys.B), np.asarray(sys.C),
                       np.asarray(sys.D), z)


@dataclass(frozen=True)
class CoprimeFactors:
    """The eight coprime factors of G and K as discrete python-control StateSpace systems."""

    M: ct.StateSpace
    N: ct.StateSpace
    U: ct.StateSpace
    V: ct.StateSpace
    Mt: ct.StateSpace
    Nt: ct.StateSpace
    Ut: ct.StateSpace
    Vt: ct.StateSpace
    dt: float


def coprime_factors(ctrl: ObserverController) -> CoprimeFactors:
    """Doubly coprime factors (eqs. 1-2) of the nominal plant and observer-based controller.

    Examples
    --------
    >>> from bayes_amb.rig import load_rig
    >>> from bayes_amb.reduction import reduce_pseudo_modal
    >>> from bayes_amb.control.design import design_observer_controller
    >>> f = coprime_factors(design_observer_controller(reduce_pseudo_modal(load_rig())))
    >>> bezout_residual(f) < 1e-9
    True
    """
    A, B, C, F, L, dt = ctrl.A, ctrl.B, ctrl.C, ctrl.F, ctrl.L, ctrl.dt
    m, p = B.shape[1], C.shape[0]
    AF, AL = A + B @ F, A + L @ C
    I_m, I_p = np.eye(m), np.eye(p)
    Z_mp, Z_pm = np.zeros((m, p)), np.zeros((p, m))
    return CoprimeFactors(
        M=ss(AF, B, F, I_m, dt), N=ss(AF, B, C, Z_pm, dt),
        U=ss(AF, -L, F, Z_mp, dt), V=ss(AF, -L, C, I_p, dt),
        Mt=ss(AL, L, C, I_p, dt), Nt=ss(AL, B, C, Z_pm, dt),
        Ut=ss(AL, -L, F, Z_mp, dt), Vt=ss(AL, -B, F, I_m, dt), dt=dt)


def unit_circle(dt: float, n: int = 400) -> NDArray:
    """Points z = e^{j w dt} from 0.1 Hz to the Nyquist frequency (log spaced)."""
    w = np.logspace(np.log10(2 * np.pi * 0.1), np.log10(np.pi / dt), n)
    return np.exp(1j * w * dt)


def bezout_matrices(f: CoprimeFactors, z: NDArray) -> tuple[NDArray, NDArray]:
    """Left and right products of eq. 3 at each z, each (n_z, m+p, m+p)."""
    M, N, U, V = (freqresp(s, z) for s in (f.M, f.N, f.U, f.V))
    Mt, Nt, Ut, Vt = (freqresp(s, z) for s in (f.Mt, f.Nt, f.Ut, f.Vt))
    left = np.concatenate([np.concatenate([Vt, -Ut], 2), np.concatenate([-Nt, Mt], 2)], 1)
    right = np.concatenate([np.concatenate([M, U], 2), np.concatenate([N, V], 2)], 1)
    return left, right


def _relative_block_residual(left: NDArray, right: NDArray, m: int) -> float:
    """Largest residual of each block of left @ right - I, relative to its two terms."""
    split = [slice(0, m), slice(m, left.shape[1])]
    worst = 0.0
    for i, ri in enumerate(split):
        for j, cj in enumerate(split):
            t1 = left[:, ri, split[0]] @ right[:, split[0], cj]
            t2 = left[:, ri, split[1]] @ right[:, split[1], cj]
            target = np.eye(t1.shape[1])[None] if i == j else 0.0
            scale = max(np.abs(t1).max(), np.abs(t2).max(), 1.0 if i == j else 0.0)
            worst = max(worst, float(np.abs(t1 + t2 - target).max() / scale))
    return worst


def bezout_residual(f: CoprimeFactors, z: NDArray | None = None) -> float:
    """Relative residual of the double Bezout identity (eq. 3) on a frequency grid.

    Both products [Vt -Ut; -Nt Mt][M U; N V] and [M U; N V][Vt -Ut; -Nt Mt] are formed at
    each z; each block's residual is taken relative to the larger of its two terms (the
    blocks carry units: U is in A/m, N in m/A), so the result is unit-independent.
    """
    z = unit_circle(f.dt) if z is None else z
    left, right = bezout_matrices(f, z)
    m = np.asarray(f.M.D).shape[0]
    return max(_relative_block_residual(left, right, m), _relative_block_residual(right, left, m))
