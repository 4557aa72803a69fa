"""Band sums of the residual DFT for 4 inputs and 4 outputs in one pass over the walkers
per bin and block (issue 16).

:func:`bayes_amb.inference.walker_kernels._band_sums_pairs` runs, per bin and real 2 x 2
block, ten short loops over the walkers (the block's input, its resolvent, each output),
passing the intermediate values through memory. Here the four inputs and four outputs are
written out, so each bin and block is one loop over the walkers with the intermediate
values in registers: the same operations in the same order (the results are bit for bit
those of ``_band_sums_pairs``; tests/test_kernels.py checks it), about 30 % fewer
instructions. The walker-dependent data of a block are packed into one array D (block,
row, walker): with few arrays in the loop numba's compiler vectorises it across the
walkers; with the eight separate arrays it does not (the checks that they do not overlap
would be too many). The batch is taken in chunks of at most LANES walkers, so that the
running sums have a shape known to the compiler (their rows at fixed distances, which it
needs as well).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from bayes_amb.inference.band_algebra import LANES, ROW

N_IN = 4
"""Inputs (excitation channels) the written-out kernel is for."""
N_OUT = 4
"""Outputs (residual channels) the written-out kernel is for."""
_ROWS = 2 + 2 * N_IN + 4 + 2 * N_OUT


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def solve_block(zr, zi, m11, m12, m21, m22, w1r, w1i, w2r, w2i):  # pragma: no cover - compiled
    # u = (z I - M)^-1 w for one real 2 x 2 modal block M = [[m11, m12], [m21, m22]] and
    # z = zr + i zi, w and u as real and imaginary parts (Cramer's rule)
    t1 = zr - m11                       # z - m11 = t1 + i zi, z - m22 = t2 + i zi
    t2 = zr - m22
    dr = t1 * t2 - zi * zi - m12 * m21
    di = zi * (t1 + t2)
    g = 1.0 / (dr * dr + di * di)
    ir, ii = dr * g, -di * g            # 1 / det
    n1r = t2 * w1r - zi * w1i + m12 * w2r
    n1i = t2 * w1i + zi * w1r + m12 * w2i
    n2r = m21 * w1r + t1 * w2r - zi * w2i
    n2i = m21 * w1i + t1 * w2i + zi * w2r
    return n1r * ir - n1i * ii, n1r * ii + n1i * ir, n2r * ir - n2i * ii, n2r * ii + n2i * ir


@njit(cache=True, nogil=True)
def _pack_blocks(M, B2, C2, x2):  # pragma: no cover - compiled
    # The real block form (slot, ..., walker) as one array D (chunk, slot, 22, LANES): rows
    # 0-1 the state after the record x2, 2-5 and 6-9 the two rows of B2, 10-13 M (m11, m12,
    # m21, m22), 14-21 C2 by output (C2[i, 0], C2[i, 1]); walker b is lane b % LANES of
    # chunk b // LANES (the lanes past the batch are zero and never used)
    nsl, _, _, nb = M.shape
    D = np.zeros(((nb + LANES - 1) // LANES, nsl, _ROWS, LANES))
    for q in range(nsl):
        for b in range(nb):
            c, l = b // LANES, b % LANES
            D[c, q, 0, l] = x2[q, 0, b]
            D[c, q, 1, l] = x2[q, 1, b]
            for j in range(N_IN):
                D[c, q, 2 + j, l] = B2[q, 0, j, b]
                D[c, q, 6 + j, l] = B2[q, 1, j, b]
            D[c, q, 10, l] = M[q, 0, 0, b]
            D[c, q, 11, l] = M[q, 0, 1, b]
            D[c, q, 12, l] = M[q, 1, 0, b]
            D[c, q, 13, l] = M[q, 1, 1, b]
            for i in range(N_OUT):
                D[c, q, 14 + 2 * i, l] = C2[q, i, 0, b]
                D[c, q, 15 + 2 * i, l] = C2[q, i, 1, b]
    return D


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _bin_residual(D, ch, w, b0, k, Xr, Xi, zr, zi, Er, Ei, Lr, Li, coef, acc
                  ):  # pragma: no cover - compiled
    # The residual R_k of bin k for the w walkers of chunk ch into acc (2 p, LANES): per
    # block w = B2 X_k - z_k x2, u = (z_k I - M)^-1 w, C2 u summed, then R = E - (C u) -
    # lines . coef; the written-out kernels' shared arithmetic, in _band_sums_pairs' order
    nsl = D.shape[1]
    nl = coef.shape[0]
    p = N_OUT
    zrk, zik = zr[k], zi[k]
    xr0, xr1, xr2, xr3 = Xr[k, 0], Xr[k, 1], Xr[k, 2], Xr[k, 3]
    xi0, xi1, xi2, xi3 = Xi[k, 0], Xi[k, 1], Xi[k, 2], Xi[k, 3]
    for i in range(2 * p):
        for b in range(w):
            acc[i, b] = 0.0
    for q in range(nsl):
        for b in range(w):
            x1, x2 = D[ch, q, 0, b], D[ch, q, 1, b]
            w1r, w1i = -zrk * x1, -zik * x1
            w2r, w2i = -zrk * x2, -zik * x2
            a, c = D[ch, q, 2, b], D[ch, q, 6, b]
            w1r += a * xr0
            w1i += a * xi0
            w2r += c * xr0
            w2i += c * xi0
            a, c = D[ch, q, 3, b], D[ch, q, 7, b]
            w1r += a * xr1
            w1i += a * xi1
            w2r += c * xr1
            w2i += c * xi1
            a, c = D[ch, q, 4, b], D[ch, q, 8, b]
            w1r += a * xr2
            w1i += a * xi2
            w2r += c * xr2
            w2i += c * xi2
            a, c = D[ch, q, 5, b], D[ch, q, 9, b]
            w1r += a * xr3
            w1i += a * xi3
            w2r += c * xr3
            w2i += c * xi3
            u1r, u1i, u2r, u2i = solve_block(
                zrk, zik, D[ch, q, 10, b], D[ch, q, 11, b], D[ch, q, 12, b],
                D[ch, q, 13, b], w1r, w1i, w2r, w2i)
            a, c = D[ch, q, 14, b], D[ch, q, 15, b]
            acc[0, b] += a * u1r + c * u2r
            acc[4, b] += a * u1i + c * u2i
            a, c = D[ch, q, 16, b], D[ch, q, 17, b]
            acc[1, b] += a * u1r + c * u2r
            acc[5, b] += a * u1i + c * u2i
            a, c = D[ch, q, 18, b], D[ch, q, 19, b]
            acc[2, b] += a * u1r + c * u2r
            acc[6, b] += a * u1i + c * u2i
            a, c = D[ch, q, 20, b], D[ch, q, 21, b]
            acc[3, b] += a * u1r + c * u2r
            acc[7, b] += a * u1i + c * u2i
    for i in range(p):                  # R = E - (C u) - lines . coef
        eri, eii = Er[k, i], Ei[k, i]
        for b in range(w):
            acc[i, b] = eri - acc[i, b]
            acc[p + i, b] = eii - acc[p + i, b]
        for j in range(nl):
            lrj, lij = Lr[k, i, j], Li[k, i, j]
            for b in range(w):
                acc[i, b] -= lrj * coef[j, b0 + b]
                acc[p + i, b] -= lij * coef[j, b0 + b]


@njit(cache=True, nogil=True, error_model="numpy")
def _band_sums_blocks4(D, nb, Xr, Xi, zr, zi, Er, Ei, Lr, Li, coef, starts, counts, out,
                       packed):  # pragma: no cover - compiled
    # _band_sums_pairs for 4 inputs and 4 outputs, D from _pack_blocks, nb walkers; per bin
    # and block w = B2 X_k - z_k x2, u = (z_k I - M)^-1 w, R -= C2 u, then R = E - (C u) -
    # lines . coef and P_b += R R^H: the operations of _band_sums_pairs, in its order. P_b
    # into out (nb, nbands, 4, 4) complex or, where packed is not empty, into packed
    # (chunks, nbands, 16, LANES) as band_algebra's kernel reads it (the lower triangle:
    # real and imaginary parts of the conjugates of the upper triangle's sums)
    nch = D.shape[0]
    p = N_OUT
    acc = np.empty((2 * p, LANES))                  # R: real parts, then imaginary parts
    sr, si = np.empty((p, p, LANES)), np.empty((p, p, LANES))
    for ch in range(nch):
        b0 = ch * LANES
        w = min(LANES, nb - b0)
        for band in range(starts.size):
            for i in range(p):
                for j in range(i, p):
                    for b in range(w):
                        sr[i, j, b] = 0.0
                        si[i, j, b] = 0.0
            for k in range(starts[band], starts[band] + counts[band]):
                _bin_residual(D, ch, w, b0, k, Xr, Xi, zr, zi, Er, Ei, Lr, Li, coef, acc)
                for i in range(p):                  # upper triangle of P_b += R R^H
                    for j in range(i, p):
                        for b in range(w):
                            sr[i, j, b] += acc[i, b] * acc[j, b] + acc[p + i, b] * acc[p + j, b]
                            si[i, j, b] += acc[p + i, b] * acc[j, b] - acc[i, b] * acc[p + j, b]
            if packed.shape[0] > 0:                 # the lower triangle, packed
                for i in range(p):
                    r = ROW[i][i]
                    for b in range(w):
                        packed[ch, band, r, b] = sr[i, i, b]
                    for j in range(i):
                        r = ROW[i][j]
                        for b in range(w):
                            packed[ch, band, r, b] = sr[j, i, b]
                            packed[ch, band, r + 1, b] = -si[j, i, b]
                continue
            for b in range(w):                      # the Hermitian P_b into out
                for i in range(p):
                    for j in range(i, p):
                        out[b0 + b, band, i, j] = sr[i, j, b] + 1j * si[i, j, b]
                        if j > i:
                            out[b0 + b, band, j, i] = sr[i, j, b] - 1j * si[i, j, b]


@njit(cache=True, nogil=True, error_model="numpy")
def _residual_blocks4(D, nb, Xr, Xi, zr, zi, Er, Ei, Lr, Li, coef, out_r, out_i
                      ):  # pragma: no cover - compiled
    # The residual DFT itself, bin by bin, from the packed block form of _pack_blocks: the
    # operations of _band_sums_blocks4 up to R = E - (C u) - lines . coef, in its order,
    # with R stored (out_r, out_i: (nb, 4, nf)) instead of summed into bands
    nch = D.shape[0]
    p = N_OUT
    nf = zr.size
    acc = np.empty((2 * p, LANES))                  # R: real parts, then imaginary parts
    for ch in range(nch):
        b0 = ch * LANES
        w = min(LANES, nb - b0)
        for k in range(nf):
            _bin_residual(D, ch, w, b0, k, Xr, Xi, zr, zi, Er, Ei, Lr, Li, coef, acc)
            for i in range(p):
                for b in range(w):
                    out_r[b0 + b, i, k] = acc[i, b]
                    out_i[b0 + b, i, k] = acc[p + i, b]
