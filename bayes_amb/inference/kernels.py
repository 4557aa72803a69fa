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
    # complex products written out in real arithmetic and 1/(z - lam) as conj / |.|^2 (as
    # dft_response does): numba's complex division and per-band temporaries cost 10x
    nb, ns = lam.shape
    m = X.shape[1]
    p = E.shape[1]
    nl = coef.shape[1]
    ur, ui = np.empty(ns), np.empty(ns)
    rr, ri = np.empty(p), np.empty(p)
    accr, acci = np.empty((p, p)), np.empty((p, p))
    for b in range(nb):
        for band in range(starts.size):
            accr[:] = 0.0
            acci[:] = 0.0
            for k in range(starts[band], starts[band] + counts[band]):
                zr, zi = z[k].real, z[k].imag
                for s in range(ns):
                    v = X[k, 0] * Bm[b, s, 0]
                    for c in range(1, m):
                        v += X[k, c] * Bm[b, s, c]
                    v -= z[k] * xi[b, s]
                    dr = zr - lam[b, s].real
                    di = zi - lam[b, s].imag
                    d = 1.0 / (dr * dr + di * di)
                    ur[s] = (v.real * dr + v.imag * di) * d
                    ui[s] = (v.imag * dr - v.real * di) * d
                for i in range(p):
                    yr = 0.0
                    yi = 0.0
                    for s in range(ns):
                        cr, ci = Cm[b, i, s].real, Cm[b, i, s].imag
                        yr += cr * ur[s] - ci * ui[s]
                        yi += cr * ui[s] + ci * ur[s]
                    er = E[k, i].real - yr * inv_scale
                    ei = E[k, i].imag - yi * inv_scale
                    for j in range(nl):
                        er -= lines[k, i, j].real * coef[b, j]
                        ei -= lines[k, i, j].imag * coef[b, j]
                    rr[i] = er
                    ri[i] = ei
                for i in range(p):
                    for j in range(i, p):
                        accr[i, j] += rr[i] * rr[j] + ri[i] * ri[j]
                        acci[i, j] += ri[i] * rr[j] - rr[i] * ri[j]
            for i in range(p):
                out[b, band, i, i] = accr[i, i]
                for j in range(i + 1, p):
                    out[b, band, i, j] = accr[i, j] + 1j * acci[i, j]
                    out[b, band, j, i] = accr[i, j] - 1j * acci[i, j]


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
    # Cholesky Phi = L L^H, M = L^-1, tr(M P M^H), in real arithmetic (see above)
    nb, nbands, n, _ = Phi.shape
    Lr, Li = np.zeros((n, n)), np.zeros((n, n))
    Mr, Mi = np.zeros((n, n)), np.zeros((n, n))
    for b in range(nb):
        for band in range(nbands):
            good = True
            ld = 0.0
            for j in range(n):
                s = Phi[b, band, j, j].real
                for k in range(j):
                    s -= Lr[j, k] * Lr[j, k] + Li[j, k] * Li[j, k]
                if not s > 0:
                    good = False
                    s = 1.0
                d = np.sqrt(s)
                ld += 2 * np.log(d)
                Lr[j, j] = d
                Li[j, j] = 0.0
                for i in range(j + 1, n):
                    ar = Phi[b, band, i, j].real
                    ai = Phi[b, band, i, j].imag
                    for k in range(j):           # - L_ik conj(L_jk)
                        ar -= Lr[i, k] * Lr[j, k] + Li[i, k] * Li[j, k]
                        ai -= Li[i, k] * Lr[j, k] - Lr[i, k] * Li[j, k]
                    Lr[i, j] = ar / d
                    Li[i, j] = ai / d
            for i in range(n):
                Mr[i, i] = 1.0 / Lr[i, i]
                Mi[i, i] = 0.0
                for j in range(i):
                    ar = Lr[i, j] * Mr[j, j]
                    ai = Li[i, j] * Mr[j, j]
                    for k in range(j + 1, i):    # + L_ik M_kj
                        ar += Lr[i, k] * Mr[k, j] - Li[i, k] * Mi[k, j]
                        ai += Lr[i, k] * Mi[k, j] + Li[i, k] * Mr[k, j]
                    Mr[i, j] = -ar / Lr[i, i]
                    Mi[i, j] = -ai / Lr[i, i]
            q = 0.0
            for i in range(n):
                for k in range(i + 1):
                    vr = 0.0
                    vi = 0.0
                    for j in range(i + 1):       # v = sum_j M_ij P_jk
                        pr = P[b, band, j, k].real
                        pi = P[b, band, j, k].imag
                        vr += Mr[i, j] * pr - Mi[i, j] * pi
                        vi += Mr[i, j] * pi + Mi[i, j] * pr
                    q += vr * Mr[i, k] + vi * Mi[i, k]    # Re(v conj(M_ik))
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
