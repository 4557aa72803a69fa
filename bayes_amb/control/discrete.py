"""Exact zero-order-hold discretisation and fast frequency responses of state-space data."""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray

from bayes_amb.control.schur_response import schur_freqresp


def zoh(A: NDArray, B: NDArray, dt: float) -> tuple[NDArray, NDArray]:
    """Exact ZOH discretisation: (Ad, Bd) = (e^{A dt}, int_0^dt e^{A s} ds B).

    Uses the block exponential expm([[A, B], [0, 0]] dt) (Van Loan).

    Examples
    --------
    >>> Ad, Bd = zoh(np.array([[-1.0]]), np.array([[1.0]]), 0.1)
    >>> bool(np.isclose(Ad[0, 0], np.exp(-0.1)) and np.isclose(Bd[0, 0], 1 - np.exp(-0.1)))
    True
    """
    n, m = B.shape
    E = np.zeros((n + m, n + m))
    E[:n, :n] = A
    E[:n, n:] = B
    Ed = sla.expm(E * dt)
    return Ed[:n, :n], Ed[:n, n:]


def ss_response(A: NDArray, B: NDArray, C: NDArray, D: NDArray | None, u: NDArray
                ) -> NDArray:
    """Output (N, p) of x+ = A x + B u, y = C x + D u from rest, for inputs u (N, m)."""
    drive = u @ B.T
    out = np.zeros((u.shape[0], C.shape[0])) if D is None else u @ np.asarray(D).T
    xs = np.zeros(A.shape[0])
    for k in range(u.shape[0]):
        out[k] += C @ xs
        xs = A @ xs + drive[k]
    return out


def ss_freqresp(A: NDArray, B: NDArray, C: NDArray, D: NDArray | None, z: NDArray) -> NDArray:
    """C (zI - A)^-1 B + D at each complex point z; shape (n_z, n_out, n_in)."""
    n = A.shape[0]
    z = np.asarray(z)
    if n == 0:
        out = np.zeros((z.size, C.shape[0], B.shape[1]), dtype=complex)
    else:
        # batched solve: (n_z, n, n) systems
        Z = z[:, None, None] * np.eye(n)[None] - A[None]
        out = C[None] @ np.linalg.solve(Z, np.broadcast_to(B, (z.size, *B.shape)))
    if D is not None:
        out = out + D[None]
    return out


def ss_freqresp_modal(A: NDArray, B: NDArray, C: NDArray, D: NDArray | None, z: NDArray,
                      max_cond: float = 1e6) -> NDArray:
    """:func:`ss_freqresp` through the eigen-decomposition A = V diag(lam) V^-1,

        C (zI - A)^-1 B + D = (C V) diag(1 / (z - lam)) (V^-1 B) + D,

    O(n) per point instead of an n x n solve (the noise filters of the whole-band
    likelihood, 10^4 points). Its rounding grows with the condition number of V: above
    max_cond (a nearly defective A: a controller's repeated poles) it falls back to the
    complex Schur form (schur_response.py), O(n^2) per point and backward stable.

    Examples
    --------
    >>> A = np.array([[0.5, 0.1], [0.0, -0.3]]); B = np.eye(2); C = np.ones((1, 2))
    >>> z = np.exp(1j * np.linspace(0.1, 3.0, 5))
    >>> bool(np.allclose(ss_freqresp_modal(A, B, C, None, z), ss_freqresp(A, B, C, None, z)))
    True
    """
    n = A.shape[0]
    z = np.asarray(z)
    if n == 0:
        return ss_freqresp(A, B, C, D, z)
    lam, V = np.linalg.eig(A)
    if not np.all(np.isfinite(lam)) or np.linalg.cond(V) > max_cond:
        return schur_freqresp(A, B, C, D, z)
    Bm = np.linalg.solve(V, B.astype(complex))                      # (n, m)
    Cm = C @ V                                                       # (p, n)
    inv = 1.0 / (z[:, None] - lam[None, :])                          # (n_z, n)
    out = (Cm[None] * inv[:, None, :]) @ Bm
    if D is not None:
        out = out + D[None]
    return out


def spectral_radius(A: NDArray) -> float:
    """Largest |eigenvalue| (discrete-time stability: < 1)."""
    return float(np.max(np.abs(np.linalg.eigvals(A)))) if A.size else 0.0
