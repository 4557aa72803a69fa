"""Compiled algebra of 4 x 4 Hermitian band matrices for two fits that call it thousands of
times: the diagnosis' Gauss-Newton linear model (discrepancy/gauss_newton.LinearModel
.value_grad: linear_terms) and the learned noise spectrum's smoothing fit
(inference/spectrum._Objective: spectrum_terms). Each band's matrix is Hermitian positive
definite, so one Cholesky factor gives its log determinant and its inverse (_chol_inverse).
Their numpy forms stay beside their callers (BAYES_AMB_KERNEL=numpy), and the tests hold
the two to each other.

The linear model, per band b at delta (w = (1, delta)) and noise spectrum Psi_b:

    Q_ab = sum_c w_c M_b[a, c],   S_b = Psi_b + sum_a w_a Q_ab,   K_b = S_b^-1,

and the sums over the bands, weighted by wt_b, of log det S_b, of Re tr(K_b Q_ab) for
a >= 1 (the gradient along delta) and of Re tr(K_b Phi_sb) (along the noise intensities).
S_b is positive definite: Psi_b is, and P_b = sum_k (G_k w)(G_k w)^H is a Gram matrix. In
numpy (batched slogdet, inv and einsum) 7 280 calls took 3.3 s of a 21 s diagnosis (the
diagnosis benchmark's record, profiled); compiled, 1.0 s.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

N = 4
"""Channels: the band matrices are 4 x 4."""


@njit(cache=True, nogil=True, error_model="numpy")
def _chol_inverse(S, L, Li, K):  # pragma: no cover - compiled
    # Hermitian positive definite S (4 x 4): K = S^-1 through S = L L^H; returns
    # (positive definite, log det S)
    logdet = 0.0
    for j in range(N):
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
    for j in range(N):
        Li[j, j] = 1.0 / L[j, j]
        for i in range(j + 1, N):
            acc = 0j
            for k in range(j, i):
                acc -= L[i, k] * Li[k, j]
            Li[i, j] = acc / L[i, i]
    for i in range(N):
        for j in range(N):
            acc = 0j
            for k in range(max(i, j), N):
                acc += np.conj(Li[k, i]) * Li[k, j]
            K[i, j] = acc
    return True, logdet


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
        ok, logdet = _chol_inverse(S, L, Li, K)
        if not ok:
            return False, 0.0
        total += wt[b] * logdet
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


@njit(cache=True, nogil=True, error_model="numpy")
def _spectrum_terms(W, G, Pb, counts, grad):  # pragma: no cover - compiled
    # W (Q, nb) intensities, G (Q, nb, 4, 4), Pb (nb, 4, 4), counts (nb,); writes grad
    # (Q, nb) = W Re tr(M G_q), M = counts Pi - Pi P Pi; returns (ok, -log L)
    n_q, nb = W.shape
    S = np.empty((N, N), dtype=np.complex128)
    L = np.zeros((N, N), dtype=np.complex128)
    Li = np.zeros((N, N), dtype=np.complex128)
    Pi = np.empty((N, N), dtype=np.complex128)
    PiP = np.empty((N, N), dtype=np.complex128)
    M = np.empty((N, N), dtype=np.complex128)
    val = 0.0
    for b in range(nb):
        for i in range(N):
            for j in range(N):
                acc = 0j
                for q in range(n_q):
                    acc += W[q, b] * G[q, b, i, j]
                S[i, j] = acc
        ok, logdet = _chol_inverse(S, L, Li, Pi)
        if not ok:
            return False, 0.0
        tr = 0.0
        for i in range(N):
            for j in range(N):
                acc = 0j
                for k in range(N):
                    acc += Pi[i, k] * Pb[b, k, j]
                PiP[i, j] = acc
            tr += PiP[i, i].real
        val += counts[b] * logdet + tr
        for i in range(N):
            for j in range(N):
                acc = 0j
                for k in range(N):
                    acc += PiP[i, k] * Pi[k, j]
                M[i, j] = counts[b] * Pi[i, j] - acc
        for q in range(n_q):
            t = 0.0
            for i in range(N):
                for j in range(N):
                    t += (M[i, j] * G[q, b, j, i]).real
            grad[q, b] = W[q, b] * t
    return True, val


def spectrum_terms(W: NDArray, G: NDArray, Pb: NDArray, counts: NDArray
                   ) -> tuple[float, NDArray]:
    """-log L of a noise spectrum Phi_b = sum_q W_qb G_qb on band sums P_b (constants
    dropped: sum_b counts_b log det Phi_b + tr(Phi_b^-1 P_b)) and its gradient in ln W,
    (Q, nb); (inf, zeros) where a Phi_b is not positive definite. The compiled form of
    inference/spectrum._Objective.likelihood_terms (its numpy form kept there).

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> A = rng.standard_normal((2, 3, 4, 4)) + 1j * rng.standard_normal((2, 3, 4, 4))
    >>> G = A @ np.conj(np.swapaxes(A, -1, -2))
    >>> Pb, W, counts = G[0] * 2.0, np.exp(rng.standard_normal((2, 3))), np.ones(3) * 5
    >>> val, grad = spectrum_terms(W, G, Pb, counts)
    >>> Phi = np.einsum("qb,qbij->bij", W, G)
    >>> ref = (counts * np.linalg.slogdet(Phi)[1]).sum() + np.trace(
    ...     np.linalg.inv(Phi) @ Pb, axis1=1, axis2=2).real.sum()
    >>> bool(np.isclose(val, ref))
    True
    """
    grad = np.empty(W.shape)
    ok, val = _spectrum_terms(np.ascontiguousarray(W, dtype=np.float64),
                              np.ascontiguousarray(G, dtype=np.complex128),
                              np.ascontiguousarray(Pb, dtype=np.complex128),
                              np.ascontiguousarray(counts, dtype=np.float64), grad)
    if not ok:
        return np.inf, np.zeros(W.shape)
    return float(val), grad
