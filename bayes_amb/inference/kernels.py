"""Compiled (numba) kernels of the Whittle likelihood: residual DFT fused with band sums.

The numpy path (:func:`bayes_amb.inference.forward.dft_response`, then
``WhittleLikelihood._band_sums``) builds the residual DFT R (nb, nf, 4) in full, then the
10 unique products R_i conj(R_j) of every bin (nb, nf, 10), then reduces them per band:
three passes over arrays of megabytes on the diagnosis' whole-band records (10 000 bins),
where the arithmetic per bin is a few hundred flops. :func:`residual_band_sums` does all of
it bin by bin in registers,

    u_s  = (Bm_s . X_k - z_k xi_s) / (z_k - lam_s)            (modal response, s = 1..ns)
    R_k  = E_k - (Cm u) / scale - lines_k . coef              (residual DFT, 4 channels)
    P_b += R_k R_k^H                                         (band sums, k in band b)

in the same arithmetic, term by term, as the numpy path (only the order of the sums
differs, so the two agree to a few units of rounding per term: tests/test_kernels.py).
:func:`logdet_and_trace` is the 4 x 4 Cholesky algebra of
``bayes_amb.inference.whittle._logdet_and_trace``, band by band.

Compiled on first use and cached on disk (numba ``cache=True``); single-threaded (the
parallelism is the batch over walkers and the tool's own worker pools). Set
``BAYES_AMB_KERNEL=numpy`` to use the numpy path instead (for comparison).
"""

from __future__ import annotations

import os

import numpy as np
from numba import njit
from numpy.typing import NDArray

KERNEL_ENV = "BAYES_AMB_KERNEL"


def use_compiled() -> bool:
    """Whether the likelihood uses these kernels (``BAYES_AMB_KERNEL`` unset or "numba")."""
    value = os.environ.get(KERNEL_ENV, "numba").strip().lower() or "numba"
    if value not in ("numba", "numpy"):
        from bayes_amb.errors import BayesAmbError

        raise BayesAmbError(f"{KERNEL_ENV}: expected 'numba' or 'numpy', got {value!r}")
    return value == "numba"


@njit(cache=True, nogil=True)
def _residual_band_sums(lam, Bm, Cm, xi, X, z, E, inv_scale, lines, coef, starts, counts,
                        out):  # pragma: no cover - compiled
    nb, ns = lam.shape
    m = X.shape[1]
    p = E.shape[1]
    nl = coef.shape[1]
    u = np.empty(ns, dtype=np.complex128)
    r = np.empty(p, dtype=np.complex128)
    for b in range(nb):
        for band in range(starts.size):
            acc = np.zeros((p, p), dtype=np.complex128)
            for k in range(starts[band], starts[band] + counts[band]):
                zk = z[k]
                for s in range(ns):
                    v = X[k, 0] * Bm[b, s, 0]
                    for c in range(1, m):
                        v += X[k, c] * Bm[b, s, c]
                    u[s] = (v - zk * xi[b, s]) / (zk - lam[b, s])
                for i in range(p):
                    y = Cm[b, i, 0] * u[0]
                    for s in range(1, ns):
                        y += Cm[b, i, s] * u[s]
                    ri = E[k, i] - y * inv_scale
                    for j in range(nl):
                        ri -= lines[k, i, j] * coef[b, j]
                    r[i] = ri
                for i in range(p):
                    for j in range(i, p):
                        acc[i, j] += r[i] * np.conj(r[j])
            for i in range(p):
                out[b, band, i, i] = acc[i, i]
                for j in range(i + 1, p):
                    out[b, band, i, j] = acc[i, j]
                    out[b, band, j, i] = np.conj(acc[i, j])


def residual_band_sums(lam: NDArray, Bm: NDArray, Cm: NDArray, xi: NDArray, X: NDArray,
                       z: NDArray, E: NDArray, scale: float, starts: NDArray,
                       counts: NDArray, lines: NDArray | None = None,
                       coef: NDArray | None = None) -> NDArray:
    """Band sums P_b = sum_{k in b} R_k R_k^H of the residual DFT, for a batch of systems.

    Parameters
    ----------
    lam, Bm, Cm : ndarray
        Modal form of the batch (``ModalBatch``): (nb, ns), (nb, ns, m), (nb, p, ns).
    xi : ndarray
        Modal state after the record, (nb, ns).
    X, z : ndarray
        Input DFT (nf, m) and the points z_k = exp(2 pi j k / N), (nf,).
    E : ndarray
        Data DFT (scaled), (nf, p).
    scale : float
        The response is divided by it (the likelihood's eps scale).
    starts, counts : ndarray
        First bin and number of bins of each band (int).
    lines, coef : ndarray, optional
        Extra terms subtracted from R_k: lines (nf, p, nl) times coef (nb, nl).

    Returns
    -------
    ndarray
        (nb, n_bands, p, p), Hermitian per band.
    """
    nb = lam.shape[0]
    p = E.shape[1]
    if lines is None or coef is None or coef.shape[1] == 0:
        lines = np.zeros((1, p, 0), dtype=complex)
        coef = np.zeros((nb, 0))
    out = np.empty((nb, starts.size, p, p), dtype=complex)
    c128 = np.complex128
    _residual_band_sums(np.ascontiguousarray(lam, c128), np.ascontiguousarray(Bm, c128),
                        np.ascontiguousarray(Cm, c128), np.ascontiguousarray(xi, c128),
                        np.ascontiguousarray(X, c128), np.ascontiguousarray(z, c128),
                        np.ascontiguousarray(E, c128), 1.0 / scale,
                        np.ascontiguousarray(lines, c128),
                        np.ascontiguousarray(coef, np.float64),
                        np.ascontiguousarray(starts, np.int64),
                        np.ascontiguousarray(counts, np.int64), out)
    return out


@njit(cache=True, nogil=True)
def _logdet_and_trace(Phi, P, logdet, quad, ok):  # pragma: no cover - compiled
    nb, nbands, n, _ = Phi.shape
    L = np.zeros((n, n), dtype=np.complex128)
    M = np.zeros((n, n), dtype=np.complex128)
    for b in range(nb):
        for band in range(nbands):
            good = True
            ld = 0.0
            for j in range(n):
                s = Phi[b, band, j, j].real
                for k in range(j):
                    s -= L[j, k].real ** 2 + L[j, k].imag ** 2
                if not s > 0:
                    good = False
                    s = 1.0
                d = np.sqrt(s)
                ld += 2 * np.log(d)
                L[j, j] = d
                for i in range(j + 1, n):
                    acc = Phi[b, band, i, j]
                    for k in range(j):
                        acc -= L[i, k] * np.conj(L[j, k])
                    L[i, j] = acc / d
            for i in range(n):
                M[i, i] = 1.0 / L[i, i]
                for j in range(i):
                    acc = L[i, j] * M[j, j]
                    for k in range(j + 1, i):
                        acc += L[i, k] * M[k, j]
                    M[i, j] = -acc / L[i, i]
            q = 0.0
            for i in range(n):
                for k in range(i + 1):
                    v = M[i, 0] * P[b, band, 0, k]
                    for j in range(1, i + 1):
                        v += M[i, j] * P[b, band, j, k]
                    q += (v * np.conj(M[i, k])).real
            logdet[b, band] = ld
            quad[b, band] = q
            ok[b, band] = good


def logdet_and_trace(Phi: NDArray, P: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """log det Phi, tr(Phi^-1 P) and positive definiteness, for (nb, n_bands, n, n) stacks.

    The same Cholesky algebra as ``bayes_amb.inference.whittle._logdet_and_trace``.
    """
    shape = Phi.shape[:2]
    logdet, quad = np.empty(shape), np.empty(shape)
    ok = np.empty(shape, dtype=np.bool_)
    _logdet_and_trace(np.ascontiguousarray(Phi, np.complex128),
                      np.ascontiguousarray(P, np.complex128), logdet, quad, ok)
    return logdet, quad, ok
