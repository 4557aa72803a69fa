"""The band algebra of the Gauss-Newton linear model (gauss_newton.LinearModel.value_grad),
compiled.

Per band b of the linear model at delta (w = (1, delta)) and noise spectrum Psi_b:

    Q_ab = sum_c w_c M_b[a, c],   S_b = Psi_b + sum_a w_a Q_ab,   K_b = S_b^-1,

and the sums over the bands, weighted by wt_b, of log det S_b, of Re tr(K_b Q_ab) for
a >= 1 (the gradient along delta) and of Re tr(K_b Phi_sb) (along the noise intensities).
S_b is Hermitian positive definite (Psi_b is, and P_b = sum_k (G_k w)(G_k w)^H is a
Gram matrix), so one Cholesky factor per band gives the log determinant and the inverse.
The numpy path of value_grad (BAYES_AMB_KERNEL=numpy) forms the same sums with batched
slogdet, inv and einsum, whose many small calls held the diagnosis' searches: 7 280 calls
took 3.3 s of a 21 s diagnosis (the posterior benchmark's record, profiled).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

N = 4
"""Channels: the band matrices are 4 x 4."""


@njit(cache=True, nogil=True, error_model="numpy")
def _terms(MT, w, Psi, phi, wt, g_q, g_s):  # pragma: no cover - compiled
    # MT (A, nb * 16, A) complex: M_b[a, c]_ij at [a, b * 16 + 4 i + j, c]; w (A,);
    # Psi (nb, 4, 4); phi (nsrc, nb, 4, 4); wt (nb,). Writes g_q (A - 1,), g_s (nsrc,);
    # returns (positive definite everywhere, sum_b wt_b log det S_b).
    n_a = MT.shape[0]
    nb = Psi.shape[0]
    nsrc = phi.shape[0]
    Q = np.empty((n_a, N, N), dtype=np.complex128)
    S = np.empty((N, N), dtype=np.complex128)
    L = np.zeros((N, N), dtype=np.complex128)
    Li = np.zeros((N, N), dtype=np.complex128)
    K = np.empty((N, N), dtype=np.complex128)
    g_q[:] = 0.0
    g_s[:] = 0.0
    total = 0.0
    for b in range(nb):
        for a in range(n_a):
            for ij in range(N * N):
                acc = 0j
                row = b * N * N + ij
                for c in range(n_a):
                    acc += MT[a, row, c] * w[c]
                Q[a, ij // N, ij % N] = acc
        for i in range(N):
            for j in range(N):
                acc = Psi[b, i, j]
                for a in range(n_a):
                    acc += w[a] * Q[a, i, j]
                S[i, j] = acc
        logdet = 0.0
        for j in range(N):                       # Cholesky, S = L L^H
            d = S[j, j].real
            for k in range(j):
                d -= L[j, k].real ** 2 + L[j, k].imag ** 2
            if not d > 0.0:
                return False, 0.0
            ljj = np.sqrt(d)
            L[j, j] = ljj
            logdet += 2.0 * np.log(ljj)
            for i in range(j + 1, N):
                acc = S[i, j]
                for k in range(j):
                    acc -= L[i, k] * np.conj(L[j, k])
                L[i, j] = acc / ljj
        total += wt[b] * logdet
        for j in range(N):                       # Li = L^-1, lower triangular
            Li[j, j] = 1.0 / L[j, j]
            for i in range(j + 1, N):
                acc = 0j
                for k in range(j, i):
                    acc -= L[i, k] * Li[k, j]
                Li[i, j] = acc / L[i, i]
        for i in range(N):                       # K = L^-H L^-1
            for j in range(N):
                acc = 0j
                for k in range(max(i, j), N):
                    acc += np.conj(Li[k, i]) * Li[k, j]
                K[i, j] = acc
        for a in range(1, n_a):
            t = 0.0
            for i in range(N):
                for j in range(N):
                    t += (K[i, j] * Q[a, j, i]).real
            g_q[a - 1] += wt[b] * t
        for s in range(nsrc):
            t = 0.0
            for i in range(N):
                for j in range(N):
                    t += (K[i, j] * phi[s, b, j, i]).real
            g_s[s] += wt[b] * t
    return True, total


def linear_terms(MT: NDArray, w: NDArray, Psi: NDArray, phi: NDArray, wt: NDArray
                 ) -> tuple[bool, float, NDArray, NDArray]:
    """(S_b positive definite in every band, sum_b wt_b log det S_b, sum_b wt_b Re tr(K_b
    Q_ab) for a = 1.., sum_b wt_b Re tr(K_b Phi_sb)); module docstring.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> G = rng.standard_normal((3, 6, 4)) + 1j * rng.standard_normal((3, 6, 4))
    >>> M = np.einsum("akx,cky->acxy", G, G.conj()).reshape(3, 3, 1, 4, 4)
    >>> MT = np.ascontiguousarray(M.reshape(3, 3, -1).transpose(0, 2, 1))
    >>> phi = np.broadcast_to(np.eye(4), (2, 1, 4, 4)).astype(complex)
    >>> w, wt = np.array([1.0, 0.3, -0.2]), np.array([2.0])
    >>> ok, ld, gq, gs = linear_terms(MT, w, np.eye(4)[None] * (1 + 0j), phi, wt)
    >>> S = np.eye(4) + np.einsum("a,c,acxy->xy", w, w, M[:, :, 0])
    >>> Q = np.einsum("c,acxy->axy", w, M[:, :, 0])
    >>> K = np.linalg.inv(S)
    >>> bool(ok and np.isclose(ld, 2 * np.linalg.slogdet(S)[1]))
    True
    >>> bool(np.allclose(gq, [2 * np.trace(K @ Q[a]).real for a in (1, 2)]))
    True
    """
    MT = np.ascontiguousarray(MT, dtype=np.complex128)
    g_q = np.empty(MT.shape[0] - 1)
    g_s = np.empty(phi.shape[0])
    ok, total = _terms(MT, np.ascontiguousarray(w, dtype=np.float64),
                       np.ascontiguousarray(Psi, dtype=np.complex128),
                       np.ascontiguousarray(phi, dtype=np.complex128),
                       np.ascontiguousarray(wt, dtype=np.float64), g_q, g_s)
    return bool(ok), float(total), g_q, g_s
