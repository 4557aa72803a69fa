"""Exact zero-order-hold discretisation and fast frequency responses of state-space data."""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray


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


def spectral_radius(A: NDArray) -> float:
    """Largest |eigenvalue| (discrete-time stability: < 1)."""
    return float(np.max(np.abs(np.linalg.eigvals(A)))) if A.size else 0.0
