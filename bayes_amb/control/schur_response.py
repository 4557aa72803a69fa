"""Frequency responses through the complex Schur form, for state matrices whose
eigenvectors are ill-conditioned (discrete.ss_freqresp_modal's fallback).

With A = Q T Q^H (T upper triangular, Q unitary; scipy.linalg.schur, complex),

    C (zI - A)^-1 B = (C Q) (zI - T)^-1 (Q^H B),

and the row vectors y = (C Q)_r (zI - T)^-1 follow by one forward substitution,

    y_j = ((C Q)_rj + sum_{i<j} y_i T_ij) / (z - T_jj),

O(p n^2 + p n m) per point where the dense solve of ss_freqresp is O(n^3 + n^2 m). The
Schur form is backward stable whatever the eigenvectors' condition, so a controller's
integrator, repeated poles or Jordan blocks (ROSS's test-rig controllers: a 40-state loop
whose eigenvectors have condition numbers above 1e6) cost nothing in accuracy (Golub and
Van Loan, Matrix Computations, 4th ed., sec. 7.1 and 7.6; Laub, "Efficient multivariable
frequency response computations", IEEE TAC 26 (1981), which uses the Hessenberg form).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
from numba import njit
from numpy.typing import NDArray


@njit(cache=True, nogil=True)
def _triangular_response(T, Bq, Cq, z, out):  # pragma: no cover - compiled
    # out[k] = Cq (z_k I - T)^-1 Bq for upper triangular T, by forward substitution of the
    # rows of Cq (module docstring).
    n = T.shape[0]
    p = Cq.shape[0]
    m = Bq.shape[1]
    y = np.empty((p, n), dtype=np.complex128)
    for k in range(z.size):
        zk = z[k]
        for j in range(n):
            d = 1.0 / (zk - T[j, j])
            for r in range(p):
                s = Cq[r, j]
                for i in range(j):
                    s += y[r, i] * T[i, j]
                y[r, j] = s * d
        for r in range(p):
            for c in range(m):
                s = 0.0 + 0.0j
                for i in range(n):
                    s += y[r, i] * Bq[i, c]
                out[k, r, c] = s


def schur_freqresp(A: NDArray, B: NDArray, C: NDArray, D: NDArray | None, z: NDArray
                   ) -> NDArray:
    """C (zI - A)^-1 B + D at each complex point z through the complex Schur form of A
    (module docstring); shape (n_z, n_out, n_in), as discrete.ss_freqresp.

    Examples
    --------
    >>> from bayes_amb.control.discrete import ss_freqresp
    >>> A = np.array([[0.5, 1.0], [0.0, 0.5]]); B = np.eye(2); C = np.ones((1, 2))
    >>> z = np.exp(1j * np.linspace(0.1, 3.0, 5))
    >>> bool(np.allclose(schur_freqresp(A, B, C, None, z), ss_freqresp(A, B, C, None, z)))
    True
    """
    z = np.ascontiguousarray(np.asarray(z, dtype=complex).ravel())
    Ab, (s, perm) = sla.matrix_balance(np.asarray(A, dtype=float), separate=True)
    T, Q = sla.schur(Ab, output="complex")
    # A = P S Ab S^-1 P^T with the permutation P and scaling S of the balance
    Bb = (np.asarray(B, dtype=float)[perm] / s[:, None])
    Cb = (np.asarray(C, dtype=float)[:, perm] * s[None, :])
    Bq = np.ascontiguousarray(Q.conj().T @ Bb.astype(complex))
    Cq = np.ascontiguousarray(Cb.astype(complex) @ Q)
    out = np.empty((z.size, Cq.shape[0], Bq.shape[1]), dtype=complex)
    _triangular_response(np.ascontiguousarray(T), Bq, Cq, z, out)
    if D is not None:
        out = out + np.asarray(D)[None]
    return out
