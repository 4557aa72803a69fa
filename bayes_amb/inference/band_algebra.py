"""The 4 x 4 noise algebra of every band written out, one pass over the bands per walker
(issue 16).

:func:`bayes_amb.inference.walker_kernels._whittle_terms` forms, per walker, Phi_b = n sum_s
sigma_s^2 Phi_{s,b}, its factors L D L^H, M = L^-1, Phi_b^-1 = M^H D^-1 M and
tr(Phi_b^-1 P_b), each step a loop over the bands through arrays of (4, 4, bands)
temporaries, about a hundred short loops per walker. :func:`_whittle_terms4` writes the
4 x 4 algebra out (three noise sources, 4 channels), so that each band is one pass with its
temporaries in registers, vectorised across the bands: the same operations in the same
order (the results are ``_whittle_terms``' bit for bit; tests/test_kernels.py checks it).
The band sums and the noise spectra come packed (:func:`pack_band_sources`,
:func:`_pack_band_sums`): per chunk of FB bands, the 16 real numbers of the lower triangle
(the real diagonal, then the real and imaginary parts of (1, 0), (2, 0), (2, 1), (3, 0),
(3, 1), (3, 2)), bands last; the results of a chunk go through a scratch array of fixed
shape (the compiler vectorises the pass only when its stores have fixed distances).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

FB = 32
"""Bands per chunk."""
N_CH = 4
"""Channels of the written-out algebra."""
N_SRC = 3
"""Noise sources of the written-out algebra (n, r1, r2)."""
ROW = ((0, 4, 6, 10), (4, 1, 8, 12), (6, 8, 2, 14), (10, 12, 14, 3))
"""Packed row of the real part of entry (i, j), i >= j (the imaginary part is the next
row off the diagonal)."""


@njit(cache=True, nogil=True)
def _pack(P, out):  # pragma: no cover - compiled
    # P (nb, nbands, 4, 4) complex -> out (nb, nch, 16, FB): the lower triangle, packed
    nb, nbands = P.shape[0], P.shape[1]
    for b in range(nb):
        for f in range(nbands):
            c, l = f // FB, f % FB
            for i in range(N_CH):
                out[b, c, ROW[i][i], l] = P[b, f, i, i].real
                for j in range(i):
                    out[b, c, ROW[i][j], l] = P[b, f, i, j].real
                    out[b, c, ROW[i][j] + 1, l] = P[b, f, i, j].imag


def pack_band_sources(phi_sources: NDArray) -> NDArray:
    """The noise spectra Phi_{s,b} (n_src, n_bands, 4, 4), packed for :func:`_whittle_terms4`:
    (n_chunks, n_src, 16, FB), zero past the last band."""
    nsrc, nbands = phi_sources.shape[:2]
    out = np.zeros(((nbands + FB - 1) // FB, nsrc, 16, FB))
    _pack(np.ascontiguousarray(phi_sources, np.complex128), out.transpose(1, 0, 2, 3))
    return out


@njit(cache=True, nogil=True)
def _pack_band_sums(P):  # pragma: no cover - compiled
    # P (nb, nbands, 4, 4) -> (nb, nch, 16, FB)
    nb, nbands = P.shape[0], P.shape[1]
    out = np.zeros((nb, (nbands + FB - 1) // FB, 16, FB))
    _pack(P, out)
    return out


@njit(cache=True, nogil=True)
def _unpack(packed, out):  # pragma: no cover - compiled
    # the inverse of _pack: out (nb, nbands, 4, 4) Hermitian from its packed lower triangle
    nb, nbands = out.shape[0], out.shape[1]
    for b in range(nb):
        for f in range(nbands):
            c, l = f // FB, f % FB
            for i in range(N_CH):
                out[b, f, i, i] = packed[b, c, ROW[i][i], l]
                for j in range(i):
                    re, im = packed[b, c, ROW[i][j], l], packed[b, c, ROW[i][j] + 1, l]
                    out[b, f, i, j] = re + 1j * im
                    out[b, f, j, i] = re - 1j * im


def unpack_band_sums(packed: NDArray, n_bands: int) -> NDArray:
    """Band sums P_b (nb, n_bands, 4, 4) from their packed form (nb, n_chunks, 16, FB)."""
    out = np.empty((packed.shape[0], n_bands, N_CH, N_CH), dtype=np.complex128)
    _unpack(packed, out)
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _whittle_terms4(sig2, ps, scale, P, logdet, quad, ok):  # pragma: no cover - compiled
    # walker_kernels._whittle_terms for 4 channels and 3 sources, written out: sig2 (nb, 3),
    # ps (nch, 3, 16, FB) and P (nb, nch, 16, FB) packed; logdet, quad, ok (nb, nbands)
    nb = sig2.shape[0]
    nbands = logdet.shape[1]
    nch = ps.shape[0]
    T = np.empty((7, FB))                # per band of a chunk: the pivots, det, quad, ok
    for b in range(nb):
        g0, g1, g2 = sig2[b, 0], sig2[b, 1], sig2[b, 2]
        for c in range(nch):
            f0 = c * FB
            w = min(FB, nbands - f0)
            for l in range(w):
                # Phi = scale sum_s sig2_s Phi_s
                t = (0.0 + g0 * ps[c, 0, 0, l]) + g1 * ps[c, 1, 0, l]
                ar00 = (t + g2 * ps[c, 2, 0, l]) * scale
                t = (0.0 + g0 * ps[c, 0, 4, l]) + g1 * ps[c, 1, 4, l]
                ar10 = (t + g2 * ps[c, 2, 4, l]) * scale
                t = (0.0 + g0 * ps[c, 0, 5, l]) + g1 * ps[c, 1, 5, l]
                ai10 = (t + g2 * ps[c, 2, 5, l]) * scale
                t = (0.0 + g0 * ps[c, 0, 1, l]) + g1 * ps[c, 1, 1, l]
                ar11 = (t + g2 * ps[c, 2, 1, l]) * scale
                t = (0.0 + g0 * ps[c, 0, 6, l]) + g1 * ps[c, 1, 6, l]
                ar20 = (t + g2 * ps[c, 2, 6, l]) * scale
                t = (0.0 + g0 * ps[c, 0, 7, l]) + g1 * ps[c, 1, 7, l]
                ai20 = (t + g2 * ps[c, 2, 7, l]) * scale
                t = (0.0 + g0 * ps[c, 0, 8, l]) + g1 * ps[c, 1, 8, l]
                ar21 = (t + g2 * ps[c, 2, 8, l]) * scale
                t = (0.0 + g0 * ps[c, 0, 9, l]) + g1 * ps[c, 1, 9, l]
                ai21 = (t + g2 * ps[c, 2, 9, l]) * scale
                t = (0.0 + g0 * ps[c, 0, 2, l]) + g1 * ps[c, 1, 2, l]
                ar22 = (t + g2 * ps[c, 2, 2, l]) * scale
                t = (0.0 + g0 * ps[c, 0, 10, l]) + g1 * ps[c, 1, 10, l]
                ar30 = (t + g2 * ps[c, 2, 10, l]) * scale
                t = (0.0 + g0 * ps[c, 0, 11, l]) + g1 * ps[c, 1, 11, l]
                ai30 = (t + g2 * ps[c, 2, 11, l]) * scale
                t = (0.0 + g0 * ps[c, 0, 12, l]) + g1 * ps[c, 1, 12, l]
                ar31 = (t + g2 * ps[c, 2, 12, l]) * scale
                t = (0.0 + g0 * ps[c, 0, 13, l]) + g1 * ps[c, 1, 13, l]
                ai31 = (t + g2 * ps[c, 2, 13, l]) * scale
                t = (0.0 + g0 * ps[c, 0, 14, l]) + g1 * ps[c, 1, 14, l]
                ar32 = (t + g2 * ps[c, 2, 14, l]) * scale
                t = (0.0 + g0 * ps[c, 0, 15, l]) + g1 * ps[c, 1, 15, l]
                ai32 = (t + g2 * ps[c, 2, 15, l]) * scale
                t = (0.0 + g0 * ps[c, 0, 3, l]) + g1 * ps[c, 1, 3, l]
                ar33 = (t + g2 * ps[c, 2, 3, l]) * scale
                # Phi = L D L^H (L in the lower triangle of a), det = prod D
                det = 1.0
                good = True
                v = ar00
                good = good & (v > 0.0)
                d0 = v if v > 0.0 else 1.0
                e0 = 1.0 / d0
                det = det * d0
                ar10, ai10 = ar10 * e0, ai10 * e0
                ar20, ai20 = ar20 * e0, ai20 * e0
                ar30, ai30 = ar30 * e0, ai30 * e0
                v = ar11
                v = v - (ar10 * ar10 + ai10 * ai10) * d0
                good = good & (v > 0.0)
                d1 = v if v > 0.0 else 1.0
                e1 = 1.0 / d1
                det = det * d1
                vr, vi = ar21, ai21
                lr, li = ar20 * d0, ai20 * d0
                vr, vi = vr - (lr * ar10 + li * ai10), vi - (li * ar10 - lr * ai10)
                ar21, ai21 = vr * e1, vi * e1
                vr, vi = ar31, ai31
                lr, li = ar30 * d0, ai30 * d0
                vr, vi = vr - (lr * ar10 + li * ai10), vi - (li * ar10 - lr * ai10)
                ar31, ai31 = vr * e1, vi * e1
                v = ar22
                v = v - (ar20 * ar20 + ai20 * ai20) * d0
                v = v - (ar21 * ar21 + ai21 * ai21) * d1
                good = good & (v > 0.0)
                d2 = v if v > 0.0 else 1.0
                e2 = 1.0 / d2
                det = det * d2
                vr, vi = ar32, ai32
                lr, li = ar30 * d0, ai30 * d0
                vr, vi = vr - (lr * ar20 + li * ai20), vi - (li * ar20 - lr * ai20)
                lr, li = ar31 * d1, ai31 * d1
                vr, vi = vr - (lr * ar21 + li * ai21), vi - (li * ar21 - lr * ai21)
                ar32, ai32 = vr * e2, vi * e2
                v = ar33
                v = v - (ar30 * ar30 + ai30 * ai30) * d0
                v = v - (ar31 * ar31 + ai31 * ai31) * d1
                v = v - (ar32 * ar32 + ai32 * ai32) * d2
                good = good & (v > 0.0)
                d3 = v if v > 0.0 else 1.0
                e3 = 1.0 / d3
                det = det * d3
                # M = L^-1 (unit lower)
                mr, mi = -ar10, -ai10
                mr10, mi10 = mr, mi
                mr, mi = -ar20, -ai20
                mr, mi = mr - (ar21 * mr10 - ai21 * mi10), mi - (ar21 * mi10 + ai21 * mr10)
                mr20, mi20 = mr, mi
                mr, mi = -ar21, -ai21
                mr21, mi21 = mr, mi
                mr, mi = -ar30, -ai30
                mr, mi = mr - (ar31 * mr10 - ai31 * mi10), mi - (ar31 * mi10 + ai31 * mr10)
                mr, mi = mr - (ar32 * mr20 - ai32 * mi20), mi - (ar32 * mi20 + ai32 * mr20)
                mr30, mi30 = mr, mi
                mr, mi = -ar31, -ai31
                mr, mi = mr - (ar32 * mr21 - ai32 * mi21), mi - (ar32 * mi21 + ai32 * mr21)
                mr31, mi31 = mr, mi
                mr, mi = -ar32, -ai32
                mr32, mi32 = mr, mi
                # tr(Phi^-1 P) with Phi^-1 = M^H D^-1 M, P Hermitian
                q = 0.0
                ar, ai = 1.0 * e0, 0.0 * e0
                vr = 0.0 + (ar * 1.0 + ai * 0.0)
                ar, ai = mr10 * e1, mi10 * e1
                vr = vr + (ar * mr10 + ai * mi10)
                ar, ai = mr20 * e2, mi20 * e2
                vr = vr + (ar * mr20 + ai * mi20)
                ar, ai = mr30 * e3, mi30 * e3
                vr = vr + (ar * mr30 + ai * mi30)
                q = q + vr * P[b, c, 0, l]
                ar, ai = 1.0 * e1, 0.0 * e1
                vr = 0.0 + (ar * mr10 + ai * mi10)
                vi = 0.0 + (ar * mi10 - ai * mr10)
                ar, ai = mr21 * e2, mi21 * e2
                vr = vr + (ar * mr20 + ai * mi20)
                vi = vi + (ar * mi20 - ai * mr20)
                ar, ai = mr31 * e3, mi31 * e3
                vr = vr + (ar * mr30 + ai * mi30)
                vi = vi + (ar * mi30 - ai * mr30)
                q = q + 2.0 * (vr * P[b, c, 4, l] + vi * P[b, c, 5, l])
                ar, ai = 1.0 * e1, 0.0 * e1
                vr = 0.0 + (ar * 1.0 + ai * 0.0)
                ar, ai = mr21 * e2, mi21 * e2
                vr = vr + (ar * mr21 + ai * mi21)
                ar, ai = mr31 * e3, mi31 * e3
                vr = vr + (ar * mr31 + ai * mi31)
                q = q + vr * P[b, c, 1, l]
                ar, ai = 1.0 * e2, 0.0 * e2
                vr = 0.0 + (ar * mr20 + ai * mi20)
                vi = 0.0 + (ar * mi20 - ai * mr20)
                ar, ai = mr32 * e3, mi32 * e3
                vr = vr + (ar * mr30 + ai * mi30)
                vi = vi + (ar * mi30 - ai * mr30)
                q = q + 2.0 * (vr * P[b, c, 6, l] + vi * P[b, c, 7, l])
                ar, ai = 1.0 * e2, 0.0 * e2
                vr = 0.0 + (ar * mr21 + ai * mi21)
                vi = 0.0 + (ar * mi21 - ai * mr21)
                ar, ai = mr32 * e3, mi32 * e3
                vr = vr + (ar * mr31 + ai * mi31)
                vi = vi + (ar * mi31 - ai * mr31)
                q = q + 2.0 * (vr * P[b, c, 8, l] + vi * P[b, c, 9, l])
                ar, ai = 1.0 * e2, 0.0 * e2
                vr = 0.0 + (ar * 1.0 + ai * 0.0)
                ar, ai = mr32 * e3, mi32 * e3
                vr = vr + (ar * mr32 + ai * mi32)
                q = q + vr * P[b, c, 2, l]
                ar, ai = 1.0 * e3, 0.0 * e3
                vr = 0.0 + (ar * mr30 + ai * mi30)
                vi = 0.0 + (ar * mi30 - ai * mr30)
                q = q + 2.0 * (vr * P[b, c, 10, l] + vi * P[b, c, 11, l])
                ar, ai = 1.0 * e3, 0.0 * e3
                vr = 0.0 + (ar * mr31 + ai * mi31)
                vi = 0.0 + (ar * mi31 - ai * mr31)
                q = q + 2.0 * (vr * P[b, c, 12, l] + vi * P[b, c, 13, l])
                ar, ai = 1.0 * e3, 0.0 * e3
                vr = 0.0 + (ar * mr32 + ai * mi32)
                vi = 0.0 + (ar * mi32 - ai * mr32)
                q = q + 2.0 * (vr * P[b, c, 14, l] + vi * P[b, c, 15, l])
                ar, ai = 1.0 * e3, 0.0 * e3
                vr = 0.0 + (ar * 1.0 + ai * 0.0)
                q = q + vr * P[b, c, 3, l]
                T[0, l] = d0
                T[1, l] = d1
                T[2, l] = d2
                T[3, l] = d3
                T[4, l] = det
                T[5, l] = q
                T[6, l] = 1.0 if good else 0.0
            for l in range(w):
                det = T[4, l]
                if 1e-290 < det < 1e290:
                    ld = np.log(det)
                else:                        # the product would lose range
                    ld = 0.0
                    for j in range(N_CH):
                        ld += np.log(T[j, l])
                logdet[b, f0 + l] = ld
                quad[b, f0 + l] = T[5, l]
                ok[b, f0 + l] = T[6, l] != 0.0
