"""Batched small-matrix kernels used by the fast likelihood (vectorised over walkers)."""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

_TAYLOR_DEGREE = 18


def expm_batched(X: NDArray) -> NDArray:
    """Matrix exponential of a stack (..., m, m) by scaling and squaring of a Taylor series.

    After scaling, ||X / 2^s||_inf <= 0.5, so the degree-18 remainder is below 1e-20.

    Examples
    --------
    >>> import scipy.linalg as sla
    >>> X = np.random.default_rng(0).normal(size=(3, 5, 5))
    >>> bool(np.allclose(expm_batched(X), np.stack([sla.expm(x) for x in X]), rtol=1e-12))
    True
    """
    X = np.asarray(X, dtype=float)
    norm = np.max(np.sum(np.abs(X), axis=-1))
    s = max(0, int(np.ceil(np.log2(norm / 0.5)))) if norm > 0.5 else 0
    Y = X / 2.0**s
    eye = np.broadcast_to(np.eye(X.shape[-1]), X.shape)
    term = eye.copy()
    out = eye.copy()
    for k in range(1, _TAYLOR_DEGREE + 1):
        term = term @ Y / k
        out = out + term
    for _ in range(s):
        out = out @ out
    return out


def zoh_batched(A: NDArray, B: NDArray, dt: float) -> tuple[NDArray, NDArray]:
    """Exact ZOH of a stack of continuous systems: A (nb, n, n), B (n, m) or (nb, n, m)."""
    nb, n, _ = A.shape
    B = np.broadcast_to(B, (nb, n, B.shape[-1]))
    m = B.shape[-1]
    E = np.zeros((nb, n + m, n + m))
    E[:, :n, :n] = A * dt
    E[:, :n, n:] = B * dt
    Ed = expm_batched(E)
    return Ed[:, :n, :n], Ed[:, :n, n:]


_ZOH_TOL = 1e-20
"""Truncation bound of the compiled ZOH's Taylor series, relative (below rounding)."""


@njit(cache=True, nogil=True, error_model="numpy")
def _zoh(A, B, dt, F, G):  # pragma: no cover - compiled
    # F = exp(A dt), G = int_0^dt exp(A t) dt B = Phi(A dt) B dt with Phi = sum (A dt)^k/(k+1)!
    nb, n, _ = A.shape
    m = B.shape[2]
    a = np.empty((n, n))
    bb = np.empty((n, m))
    P = np.empty((n, n))
    T = np.empty((n, n))
    Tg = np.empty((n, m))
    for b in range(nb):
        norm = 0.0                      # inf-norm of [A, B] dt, as expm_batched scales it
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += abs(A[b, i, j])
            for j in range(m):
                s += abs(B[b, i, j])
            norm = max(norm, s * dt)
        if not norm < np.inf:           # not finite: so is the result (flagged later)
            for i in range(n):
                for j in range(n):
                    F[b, i, j] = np.nan
                for j in range(m):
                    G[b, i, j] = np.nan
            continue
        sq = 0
        if norm > 0.5:
            sq = int(np.ceil(np.log2(norm / 0.5)))
        h = dt / 2.0**sq
        nrm = norm / 2.0**sq
        deg = 1                         # smallest degree with nrm^(d+1)/(d+1)! below _ZOH_TOL
        term = nrm
        while deg < 30:
            term *= nrm / (deg + 1)
            if term < _ZOH_TOL:
                break
            deg += 1
        for i in range(n):
            for j in range(n):
                a[i, j] = A[b, i, j] * h
                P[i, j] = 0.0
            P[i, i] = 1.0
            for j in range(m):
                bb[i, j] = B[b, i, j] * h
        for k in range(deg, 1, -1):     # Horner: P = I + a P / k, ends with Phi(a)
            for i in range(n):
                for j in range(n):
                    T[i, j] = 0.0
                for l in range(n):
                    f = a[i, l] / k
                    for j in range(n):
                        T[i, j] += f * P[l, j]
            for i in range(n):
                for j in range(n):
                    P[i, j] = T[i, j]
                P[i, i] += 1.0
        for i in range(n):              # F = I + a Phi, G = Phi b
            for j in range(n):
                F[b, i, j] = 0.0
            for j in range(m):
                G[b, i, j] = 0.0
            for l in range(n):
                f = a[i, l]
                for j in range(n):
                    F[b, i, j] += f * P[l, j]
                g = P[i, l]
                for j in range(m):
                    G[b, i, j] += g * bb[l, j]
            F[b, i, i] += 1.0
        for _ in range(sq):             # [F G; 0 I]^2 = [F F, F G + G; 0 I]
            for i in range(n):
                for j in range(n):
                    T[i, j] = 0.0
                for j in range(m):
                    Tg[i, j] = G[b, i, j]
                for l in range(n):
                    f = F[b, i, l]
                    for j in range(n):
                        T[i, j] += f * F[b, l, j]
                    for j in range(m):
                        Tg[i, j] += f * G[b, l, j]
            for i in range(n):
                for j in range(n):
                    F[b, i, j] = T[i, j]
                for j in range(m):
                    G[b, i, j] = Tg[i, j]


def zoh_compiled(A: NDArray, B: NDArray, dt: float) -> tuple[NDArray, NDArray]:
    """The exact ZOH of :func:`zoh_batched`, compiled, member by member: the Taylor series of
    [[A, B], [0, 0]] dt in its blocks (exp(A dt) and Phi(A dt) B dt, Horner's rule), scaled
    and squared so that ||[A, B] dt / 2^s||_inf <= 0.5 and truncated where the next term's
    bound falls below 1e-20 (degree 8 at the reference rig's dt = 1e-4 s).

    Examples
    --------
    >>> A = np.random.default_rng(0).normal(size=(3, 5, 5))
    >>> B = np.random.default_rng(1).normal(size=(5, 2))
    >>> F, G = zoh_compiled(A, B, 0.3)
    >>> F0, G0 = zoh_batched(A, B, 0.3)
    >>> bool(np.allclose(F, F0, rtol=1e-13, atol=1e-14) and np.allclose(G, G0, rtol=1e-13))
    True
    """
    A = np.require(A, np.float64, ("C", "W"))     # one compiled signature (eigen.modal_batch)
    nb, n, _ = A.shape
    B = np.require(np.broadcast_to(B, (nb, n, B.shape[-1])), np.float64, ("C", "W"))
    F = np.empty((nb, n, n))
    G = np.empty((nb, n, B.shape[2]))
    _zoh(A, B, float(dt), F, G)
    return F, G

