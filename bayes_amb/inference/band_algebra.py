"""The 4 x 4 noise algebra of every band written out, vectorised across the walkers
(issue 16).

:func:`bayes_amb.inference.walker_kernels._whittle_terms` forms, per walker, Phi_b = n sum_s
sigma_s^2 Phi_{s,b}, its factors L D L^H, M = L^-1, Phi_b^-1 = M^H D^-1 M and
tr(Phi_b^-1 P_b), each step a loop over the bands through arrays of (4, 4, bands)
temporaries: about a hundred short loops per walker. :func:`_whittle_terms4` writes the
4 x 4 algebra out (4 channels, three noise sources), so that each band of each walker is
one pass with its temporaries in registers, band by band and vectorised across the walkers:
the same operations in the same order (the results are ``_whittle_terms``' bit for bit;
tests/test_kernels.py checks it).

The band sums come packed (:func:`pack_band_sums`, or straight from the written-out band
sums of bayes_amb.inference.block_sums): per chunk of LANES walkers and per band, the 16
real numbers of the lower triangle (the real diagonal, then the real and imaginary parts
of (1, 0), (2, 0), (2, 1), (3, 0), (3, 1), (3, 2); ROW), walkers last: (chunk, band, 16,
LANES). The noise intensities likewise (chunk, 3, LANES). The results of a band go through
a scratch array of fixed shape (the compiler vectorises the pass only when its stores are
at fixed distances).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

LANES = 32
"""Walkers per chunk (as bayes_amb.inference.block_sums)."""
N_CH = 4
"""Channels of the written-out algebra."""
N_SRC = 3
"""Noise sources of the written-out algebra (n, r1, r2)."""
ROW = ((0, 4, 6, 10), (4, 1, 8, 12), (6, 8, 2, 14), (10, 12, 14, 3))
"""Packed row of the real part of entry (i, j), i >= j (off the diagonal the imaginary part
is the next row)."""


def n_chunks(nb: int) -> int:
    """Chunks of LANES walkers for a batch of nb."""
    return (nb + LANES - 1) // LANES


@njit(cache=True, nogil=True)
def _pack_rows(store, rows, out):  # pragma: no cover - compiled
    # store[rows] (nb, nbands, 4, 4) complex -> out (chunks, nbands, 16, LANES): the lower
    # triangle, read in place from a store (m, nbands, 4, 4)
    nbands = store.shape[1]
    for b in range(rows.size):
        c, l, r = b // LANES, b % LANES, rows[b]
        for f in range(nbands):
            for i in range(N_CH):
                out[c, f, ROW[i][i], l] = store[r, f, i, i].real
                for j in range(i):
                    out[c, f, ROW[i][j], l] = store[r, f, i, j].real
                    out[c, f, ROW[i][j] + 1, l] = store[r, f, i, j].imag


def pack_rows(store: NDArray, rows: NDArray) -> NDArray:
    """pack_band_sums(store[rows]) for band sums kept in a store (m, n_bands, 4, 4)."""
    out = np.zeros((n_chunks(rows.size), store.shape[1], 16, LANES))
    _pack_rows(store, np.ascontiguousarray(rows, dtype=np.int64), out)
    return out


@njit(cache=True, nogil=True)
def _unpack(packed, out):  # pragma: no cover - compiled
    # the inverse of _pack_rows: out (nb, nbands, 4, 4) Hermitian from its packed lower triangle
    nb, nbands = out.shape[0], out.shape[1]
    for b in range(nb):
        c, l = b // LANES, b % LANES
        for f in range(nbands):
            for i in range(N_CH):
                out[b, f, i, i] = packed[c, f, ROW[i][i], l]
                for j in range(i):
                    re, im = packed[c, f, ROW[i][j], l], packed[c, f, ROW[i][j] + 1, l]
                    out[b, f, i, j] = re + 1j * im
                    out[b, f, j, i] = re - 1j * im


def pack_band_sums(P: NDArray) -> NDArray:
    """Band sums P_b (nb, n_bands, 4, 4) packed for :func:`_whittle_terms4`."""
    return pack_rows(np.ascontiguousarray(P, np.complex128), np.arange(P.shape[0]))


def unpack_band_sums(packed: NDArray, nb: int) -> NDArray:
    """Band sums P_b (nb, n_bands, 4, 4) from their packed form."""
    out = np.empty((nb, packed.shape[1], N_CH, N_CH), dtype=np.complex128)
    _unpack(packed, out)
    return out


def pack_band_sources(phi_sources: NDArray) -> NDArray:
    """The noise spectra Phi_{s,b} (n_src, n_bands, 4, 4) as :func:`_whittle_terms4` reads
    them: (n_bands, n_src, 16), the packed lower triangle."""
    nsrc, nbands = phi_sources.shape[:2]
    out = np.empty((nbands, nsrc, 16))
    for i in range(N_CH):
        out[:, :, ROW[i][i]] = phi_sources[:, :, i, i].real.T
        for j in range(i):
            out[:, :, ROW[i][j]] = phi_sources[:, :, i, j].real.T
            out[:, :, ROW[i][j] + 1] = phi_sources[:, :, i, j].imag.T
    return out


_PACKED: tuple[Any, Any] = (None, None)
"""The last noise spectra packed for _whittle_terms4, and the array they came from: a
likelihood replaces its phi_sources (set_noise_reference, set_spectrum), never changes it
in place, so the same object is the same spectra (a sampler's noise steps pack it once,
not once a call)."""


def packed_sources(phi_sources: NDArray) -> NDArray:
    """pack_band_sources(phi_sources), remembered for the same array."""
    global _PACKED
    ref, packed = _PACKED
    if ref is not phi_sources:
        packed = pack_band_sources(
            np.ascontiguousarray(phi_sources, np.complex128))
        _PACKED = (phi_sources, packed)
    return packed


@njit(cache=True, nogil=True)
def _pack_noise(sig2, out):  # pragma: no cover - compiled
    # sig2 (nb, 3) -> out (chunks, 3, LANES)
    for b in range(sig2.shape[0]):
        for s in range(sig2.shape[1]):
            out[b // LANES, s, b % LANES] = sig2[b, s]


@njit(cache=True, nogil=True, error_model="numpy")
def _whittle_terms4(sig2, ps, scale, P, logdet, quad, ok):  # pragma: no cover - compiled
    # walker_kernels._whittle_terms for 4 channels and 3 sources, written out: sig2 (nb, 3),
    # ps (nbands, 3, 16) and P (chunks, nbands, 16, LANES) packed; logdet, quad, ok (nb,
    # nbands)
    nb, nbands = logdet.shape
    S = np.zeros((P.shape[0], N_SRC, LANES))
    _pack_noise(sig2, S)
    T = np.empty((7, LANES))             # per walker of a chunk: the pivots, det, quad, ok
    for ch in range(P.shape[0]):
        b0 = ch * LANES
        w = min(LANES, nb - b0)
        for f in range(nbands):
            for l in range(w):
                g0, g1, g2 = S[ch, 0, l], S[ch, 1, l], S[ch, 2, l]
                # Phi = scale sum_s sig2_s Phi_s
                t = (0.0 + g0 * ps[f, 0, 0]) + g1 * ps[f, 1, 0]
                ar00 = (t + g2 * ps[f, 2, 0]) * scale
                t = (0.0 + g0 * ps[f, 0, 4]) + g1 * ps[f, 1, 4]
                ar10 = (t + g2 * ps[f, 2, 4]) * scale
                t = (0.0 + g0 * ps[f, 0, 5]) + g1 * ps[f, 1, 5]
                ai10 = (t + g2 * ps[f, 2, 5]) * scale
                t = (0.0 + g0 * ps[f, 0, 1]) + g1 * ps[f, 1, 1]
                ar11 = (t + g2 * ps[f, 2, 1]) * scale
                t = (0.0 + g0 * ps[f, 0, 6]) + g1 * ps[f, 1, 6]
                ar20 = (t + g2 * ps[f, 2, 6]) * scale
                t = (0.0 + g0 * ps[f, 0, 7]) + g1 * ps[f, 1, 7]
                ai20 = (t + g2 * ps[f, 2, 7]) * scale
                t = (0.0 + g0 * ps[f, 0, 8]) + g1 * ps[f, 1, 8]
                ar21 = (t + g2 * ps[f, 2, 8]) * scale
                t = (0.0 + g0 * ps[f, 0, 9]) + g1 * ps[f, 1, 9]
                ai21 = (t + g2 * ps[f, 2, 9]) * scale
                t = (0.0 + g0 * ps[f, 0, 2]) + g1 * ps[f, 1, 2]
                ar22 = (t + g2 * ps[f, 2, 2]) * scale
                t = (0.0 + g0 * ps[f, 0, 10]) + g1 * ps[f, 1, 10]
                ar30 = (t + g2 * ps[f, 2, 10]) * scale
                t = (0.0 + g0 * ps[f, 0, 11]) + g1 * ps[f, 1, 11]
                ai30 = (t + g2 * ps[f, 2, 11]) * scale
                t = (0.0 + g0 * ps[f, 0, 12]) + g1 * ps[f, 1, 12]
                ar31 = (t + g2 * ps[f, 2, 12]) * scale
                t = (0.0 + g0 * ps[f, 0, 13]) + g1 * ps[f, 1, 13]
                ai31 = (t + g2 * ps[f, 2, 13]) * scale
                t = (0.0 + g0 * ps[f, 0, 14]) + g1 * ps[f, 1, 14]
                ar32 = (t + g2 * ps[f, 2, 14]) * scale
                t = (0.0 + g0 * ps[f, 0, 15]) + g1 * ps[f, 1, 15]
                ai32 = (t + g2 * ps[f, 2, 15]) * scale
                t = (0.0 + g0 * ps[f, 0, 3]) + g1 * ps[f, 1, 3]
                ar33 = (t + g2 * ps[f, 2, 3]) * scale
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
                q = q + vr * P[ch, f, 0, l]
                ar, ai = 1.0 * e1, 0.0 * e1
                vr = 0.0 + (ar * mr10 + ai * mi10)
                vi = 0.0 + (ar * mi10 - ai * mr10)
                ar, ai = mr21 * e2, mi21 * e2
                vr = vr + (ar * mr20 + ai * mi20)
                vi = vi + (ar * mi20 - ai * mr20)
                ar, ai = mr31 * e3, mi31 * e3
                vr = vr + (ar * mr30 + ai * mi30)
                vi = vi + (ar * mi30 - ai * mr30)
                q = q + 2.0 * (vr * P[ch, f, 4, l] + vi * P[ch, f, 5, l])
                ar, ai = 1.0 * e1, 0.0 * e1
                vr = 0.0 + (ar * 1.0 + ai * 0.0)
                ar, ai = mr21 * e2, mi21 * e2
                vr = vr + (ar * mr21 + ai * mi21)
                ar, ai = mr31 * e3, mi31 * e3
                vr = vr + (ar * mr31 + ai * mi31)
                q = q + vr * P[ch, f, 1, l]
                ar, ai = 1.0 * e2, 0.0 * e2
                vr = 0.0 + (ar * mr20 + ai * mi20)
                vi = 0.0 + (ar * mi20 - ai * mr20)
                ar, ai = mr32 * e3, mi32 * e3
                vr = vr + (ar * mr30 + ai * mi30)
                vi = vi + (ar * mi30 - ai * mr30)
                q = q + 2.0 * (vr * P[ch, f, 6, l] + vi * P[ch, f, 7, l])
                ar, ai = 1.0 * e2, 0.0 * e2
                vr = 0.0 + (ar * mr21 + ai * mi21)
                vi = 0.0 + (ar * mi21 - ai * mr21)
                ar, ai = mr32 * e3, mi32 * e3
                vr = vr + (ar * mr31 + ai * mi31)
                vi = vi + (ar * mi31 - ai * mr31)
                q = q + 2.0 * (vr * P[ch, f, 8, l] + vi * P[ch, f, 9, l])
                ar, ai = 1.0 * e2, 0.0 * e2
                vr = 0.0 + (ar * 1.0 + ai * 0.0)
                ar, ai = mr32 * e3, mi32 * e3
                vr = vr + (ar * mr32 + ai * mi32)
                q = q + vr * P[ch, f, 2, l]
                ar, ai = 1.0 * e3, 0.0 * e3
                vr = 0.0 + (ar * mr30 + ai * mi30)
                vi = 0.0 + (ar * mi30 - ai * mr30)
                q = q + 2.0 * (vr * P[ch, f, 10, l] + vi * P[ch, f, 11, l])
                ar, ai = 1.0 * e3, 0.0 * e3
                vr = 0.0 + (ar * mr31 + ai * mi31)
                vi = 0.0 + (ar * mi31 - ai * mr31)
                q = q + 2.0 * (vr * P[ch, f, 12, l] + vi * P[ch, f, 13, l])
                ar, ai = 1.0 * e3, 0.0 * e3
                vr = 0.0 + (ar * mr32 + ai * mi32)
                vi = 0.0 + (ar * mi32 - ai * mr32)
                q = q + 2.0 * (vr * P[ch, f, 14, l] + vi * P[ch, f, 15, l])
                ar, ai = 1.0 * e3, 0.0 * e3
                vr = 0.0 + (ar * 1.0 + ai * 0.0)
                q = q + vr * P[ch, f, 3, l]
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
                logdet[b0 + l, f] = ld
                quad[b0 + l, f] = T[5, l]
                ok[b0 + l, f] = T[6, l] != 0.0


def logdet_and_trace_numpy(Phi: NDArray, P: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """log det Phi and tr(Phi^-1 P) for stacks (..., n, n) of Hermitian matrices, and
    whether each Phi is positive definite (where it is not, the values are meaningless):
    the band algebra in numpy (the Whittle likelihood's path with BAYES_AMB_KERNEL=numpy,
    and the reference the compiled forms are held to).

    Cholesky Phi = L L^H, M = L^-1 and tr(M P M^H), all written out elementwise over the
    stack (for 4 x 4 matrices, a few dozen array operations beat one LAPACK call per
    matrix by an order of magnitude).
    """
    n = Phi.shape[-1]
    A = [[Phi[..., i, j] for j in range(n)] for i in range(n)]
    L: list[list[NDArray]] = [[None] * n for _ in range(n)]  # type: ignore[list-item]
    ok = np.ones(Phi.shape[:-2], dtype=bool)
    logdet = np.zeros(Phi.shape[:-2])
    for j in range(n):
        s = A[j][j].real - sum((np.abs(L[j][k]) ** 2 for k in range(j)),
                               start=np.zeros(Phi.shape[:-2]))
        good = s > 0
        ok &= good
        d = np.sqrt(np.where(good, s, 1.0))
        logdet += 2 * np.log(d)
        L[j][j] = d
        for i in range(j + 1, n):
            acc = A[i][j]
            for k in range(j):
                acc = acc - L[i][k] * np.conj(L[j][k])
            L[i][j] = acc / d
    M: list[list[NDArray]] = [[None] * n for _ in range(n)]  # type: ignore[list-item]
    for i in range(n):
        M[i][i] = 1.0 / L[i][i]
        for j in range(i):
            acc = L[i][j] * M[j][j]
            for k in range(j + 1, i):
                acc = acc + L[i][k] * M[k][j]
            M[i][j] = -acc / L[i][i]
    quad = np.zeros(Phi.shape[:-2])
    for i in range(n):                       # row i of M P M^H: sum_jk M_ij P_jk conj(M_ik)
        for k in range(i + 1):
            v = M[i][0] * P[..., 0, k]
            for j in range(1, i + 1):
                v = v + M[i][j] * P[..., j, k]
            quad += (v * np.conj(M[i][k])).real
    return logdet, quad, ok
