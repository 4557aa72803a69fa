"""Compiled likelihood kernels vectorised across the walkers of a batch (issue 16).

:func:`bayes_amb.inference.kernels.residual_band_sums` runs walker by walker and vectorises
over the bins of a pass. Its loops over the modes are short and its per-mode rows leave the
L1 cache; over a batch of walkers the same arithmetic vectorises better the other way round:
bin by bin and mode by mode, every operation on one vector of the batch's walkers (the
modal form laid out (mode, ..., walker)). :func:`residual_band_sums_lanes` is that kernel,
term for term the arithmetic of the walker-by-walker one (the same order of the sums, so
the two agree to rounding and in practice bit for bit). It pays from about a dozen walkers
(``LANES_MIN_BATCH``; emcee hands half the ensemble to the posterior at once); smaller
batches keep the walker-by-walker kernel. With exactly conjugate pairs (the compiled modal
form's) it runs on real 2 x 2 blocks, and for 4 inputs and 4 outputs on the written-out
form of that kernel (bayes_amb.inference.block_sums; the same results bit for bit).

:func:`whittle_terms` is the band algebra of the Whittle likelihood with the spectral
densities formed in place: Phi_b = n sum_s sigma_s^2 Phi_{s,b}, its Cholesky factor, log det
Phi_b and tr(Phi_b^-1 P_b), as ``band_algebra.logdet_and_trace_numpy`` computes them but
with one logarithm per band (of the product of the pivots) instead of one per pivot; for 4 channels
and 3 noise sources written out (bayes_amb.inference.band_algebra; bit for bit the same).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from bayes_amb.inference import band_algebra
from bayes_amb.inference.block_sums import (
    N_IN,
    N_OUT,
    _band_sums_blocks4,
    _pack_blocks,
    solve_block,
)
from bayes_amb.inference.kernels import lines_or_empty
from bayes_amb.threads import over_rows

_NOT_PACKED = np.zeros((0, 0, 16, 1))     # _lanes_call: the band sums into its `out`
LANES_MIN_BATCH = 12
"""Smallest batch for which :func:`residual_band_sums_lanes` beats the walker-by-walker
kernel (measured: at 8 walkers it is 1.2x slower, at 16 1.5x faster, at 32 1.6x)."""


@njit(cache=True, nogil=True, inline="always")
def _zero_sums(sr, si):  # pragma: no cover - compiled
    # the upper triangle of a band's running sums (p, p, nb), real and imaginary parts
    p, _, nb = sr.shape
    for i in range(p):
        for j in range(i, p):
            for b in range(nb):
                sr[i, j, b] = 0.0
                si[i, j, b] = 0.0


@njit(cache=True, nogil=True, inline="always")
def _finish_residual(rr, ri, Er, Ei, Lr, Li, coef, k):  # pragma: no cover - compiled
    # rr, ri (p, nb) hold the model part (C u) / scale of bin k; make them the residual
    # R = E_k - (C u) / scale - lines_k . coef
    p, nb = rr.shape
    nl = coef.shape[0]
    for i in range(p):
        eri, eii = Er[k, i], Ei[k, i]
        for b in range(nb):
            rr[i, b] = eri - rr[i, b]
            ri[i, b] = eii - ri[i, b]
        for j in range(nl):
            lrj, lij = Lr[k, i, j], Li[k, i, j]
            for b in range(nb):
                rr[i, b] -= lrj * coef[j, b]
                ri[i, b] -= lij * coef[j, b]


@njit(cache=True, nogil=True, inline="always")
def _accumulate(sr, si, rr, ri):  # pragma: no cover - compiled
    # upper triangle of P_b += R_k R_k^H for every walker
    p, nb = rr.shape
    for i in range(p):
        for j in range(i, p):
            for b in range(nb):
                sr[i, j, b] += rr[i, b] * rr[j, b] + ri[i, b] * ri[j, b]
                si[i, j, b] += ri[i, b] * rr[j, b] - rr[i, b] * ri[j, b]


@njit(cache=True, nogil=True, inline="always")
def _store_band(out, sr, si, band):  # pragma: no cover - compiled
    # the Hermitian P_b of every walker into out (nb, nbands, p, p)
    p, _, nb = sr.shape
    for b in range(nb):
        for i in range(p):
            for j in range(i, p):
                out[b, band, i, j] = sr[i, j, b] + 1j * si[i, j, b]
                if j > i:
                    out[b, band, j, i] = sr[i, j, b] - 1j * si[i, j, b]


@njit(cache=True, nogil=True, error_model="numpy")
def _band_sums_lanes(lr, li, Br, Bi, Cr, Ci, xr, xi, Xr, Xi, zr, zi, Er, Ei, Lr, Li, coef,
                     starts, counts, out):  # pragma: no cover - compiled
    # lr, li, xr, xi (ns, nb); Br, Bi (ns, m, nb); Cr, Ci (p, ns, nb), scaled; Xr, Xi (nf, m);
    # Er, Ei (nf, p); Lr, Li (nf, p, nl); coef (nl, nb); out (nb, nbands, p, p) complex
    ns, nb = lr.shape
    m = Br.shape[1]
    p = Cr.shape[0]
    rr, ri = np.empty((p, nb)), np.empty((p, nb))
    ur, ui = np.empty(nb), np.empty(nb)
    sr, si = np.empty((p, p, nb)), np.empty((p, p, nb))
    for band in range(starts.size):
        _zero_sums(sr, si)
        for k in range(starts[band], starts[band] + counts[band]):
            zrk, zik = zr[k], zi[k]
            for i in range(p):
                for b in range(nb):
                    rr[i, b] = 0.0
                    ri[i, b] = 0.0
            for s in range(ns):        # u_s = (Bm_s . X_k - z_k xi_s) / (z_k - lam_s)
                for b in range(nb):
                    ur[b] = -(zrk * xr[s, b] - zik * xi[s, b])
                    ui[b] = -(zrk * xi[s, b] + zik * xr[s, b])
                for c in range(m):
                    xrc, xic = Xr[k, c], Xi[k, c]
                    for b in range(nb):
                        ur[b] += xrc * Br[s, c, b] - xic * Bi[s, c, b]
                        ui[b] += xrc * Bi[s, c, b] + xic * Br[s, c, b]
                for b in range(nb):
                    dr = zrk - lr[s, b]
                    di = zik - li[s, b]
                    d = 1.0 / (dr * dr + di * di)
                    a, e = ur[b], ui[b]
                    ur[b] = (a * dr + e * di) * d
                    ui[b] = (e * dr - a * di) * d
                for i in range(p):     # (Cm u) / scale
                    for b in range(nb):
                        rr[i, b] += Cr[i, s, b] * ur[b] - Ci[i, s, b] * ui[b]
                        ri[i, b] += Cr[i, s, b] * ui[b] + Ci[i, s, b] * ur[b]
            _finish_residual(rr, ri, Er, Ei, Lr, Li, coef, k)   # R = E - (C u) - lines . coef
            _accumulate(sr, si, rr, ri)                          # P_b += R_k R_k^H
        _store_band(out, sr, si, band)


def residual_band_sums_lanes(lam: NDArray, Bm: NDArray, Cm: NDArray, xi: NDArray,
                             X: NDArray, z: NDArray, E: NDArray, scale: float,
                             starts: NDArray, counts: NDArray, lines: NDArray | None = None,
                             coef: NDArray | None = None) -> NDArray:
    """Band sums P_b = sum_{k in b} R_k R_k^H of the residual DFT, vectorised across the
    batch: arguments and result as :func:`bayes_amb.inference.kernels.residual_band_sums`.

    Examples
    --------
    >>> from bayes_amb.inference.kernels import residual_band_sums
    >>> rng = np.random.default_rng(0)
    >>> c = lambda *s: rng.standard_normal(s) + 1j * rng.standard_normal(s)
    >>> lam, Bm, Cm, xi = 0.5 * c(16, 6), c(16, 6, 2), c(16, 3, 6), c(16, 6)
    >>> z = np.exp(2j * np.pi * np.arange(1, 41) / 100)
    >>> args = (lam, Bm, Cm, xi, c(40, 2), z, c(40, 3), 2.0, np.array([0, 1, 5, 20]),
    ...         np.array([1, 4, 15, 20]))
    >>> bool(np.allclose(residual_band_sums_lanes(*args), residual_band_sums(*args)))
    True
    """
    nb = lam.shape[0]
    p = E.shape[1]
    lines, coef = lines_or_empty(E, nb, lines, coef)
    c128, f64 = np.complex128, np.float64
    out = np.empty((nb, starts.size, p, p), dtype=c128)
    lam, Bm, Cm, xi = (np.ascontiguousarray(a, c128) for a in (lam, Bm, Cm, xi))
    coef = np.ascontiguousarray(coef, f64)
    shared = (np.ascontiguousarray(X, c128), np.ascontiguousarray(z, c128),
              np.ascontiguousarray(E, c128), 1.0 / scale, np.ascontiguousarray(lines, c128))
    bands = (np.ascontiguousarray(starts, np.int64), np.ascontiguousarray(counts, np.int64))
    # rows of the batch in parallel (threads.over_rows): each row's sums are its own
    over_rows(lambda lo, hi: _lanes_call(lam[lo:hi], Bm[lo:hi], Cm[lo:hi], xi[lo:hi],
                                         *shared, coef[lo:hi], *bands, out[lo:hi],
                                         _NOT_PACKED), nb, 2 * LANES_MIN_BATCH)
    return out


@njit(cache=True, nogil=True)
def _lanes_call(lam, Bm, Cm, xi, X, z, E, inv_scale, lines, coef, starts, counts, out,
                packed):  # pragma: no cover - compiled: the walker-last layout, the kernel
    # P_b into out (nb, nbands, p, p), or, where packed is not empty and the written-out
    # kernel applies, into packed (band_algebra's layout) only; returns whether out holds
    # them
    nb, ns = lam.shape
    m = Bm.shape[2]
    p = Cm.shape[1]
    nl = coef.shape[1]
    coef_t = np.empty((nl, nb))
    for b in range(nb):
        for j in range(nl):
            coef_t[j, b] = coef[b, j]
    M, B2, C2, x2 = _real_blocks(lam, Bm, Cm, xi, inv_scale)
    if M.shape[0] > 0 and m == N_IN and p == N_OUT:   # written out (block_sums)
        _band_sums_blocks4(_pack_blocks(M, B2, C2, x2), nb, X.real.copy(), X.imag.copy(),
                           z.real.copy(), z.imag.copy(), E.real.copy(), E.imag.copy(),
                           lines.real.copy(), lines.imag.copy(), coef_t, starts, counts, out,
                           packed)
        return packed.shape[0] == 0
    if M.shape[0] > 0 or ns == 0:
        _band_sums_pairs(M, B2, C2, x2, X.real.copy(), X.imag.copy(), z.real.copy(),
                         z.imag.copy(), E.real.copy(), E.imag.copy(), lines.real.copy(),
                         lines.imag.copy(), coef_t, starts, counts, out)
        return True
    lr, li, xr, xim = (np.empty((ns, nb)), np.empty((ns, nb)), np.empty((ns, nb)),
                       np.empty((ns, nb)))
    Br, Bi = np.empty((ns, m, nb)), np.empty((ns, m, nb))
    Cr, Ci = np.empty((p, ns, nb)), np.empty((p, ns, nb))
    for b in range(nb):
        for s in range(ns):
            lr[s, b] = lam[b, s].real
            li[s, b] = lam[b, s].imag
            xr[s, b] = xi[b, s].real
            xim[s, b] = xi[b, s].imag
            for c in range(m):
                Br[s, c, b] = Bm[b, s, c].real
                Bi[s, c, b] = Bm[b, s, c].imag
            for i in range(p):
                Cr[i, s, b] = Cm[b, i, s].real * inv_scale
                Ci[i, s, b] = Cm[b, i, s].imag * inv_scale
    _band_sums_lanes(lr, li, Br, Bi, Cr, Ci, xr, xim, X.real.copy(), X.imag.copy(),
                     z.real.copy(), z.imag.copy(), E.real.copy(), E.imag.copy(),
                     lines.real.copy(), lines.imag.copy(), coef_t, starts, counts, out)
    return True


@njit(cache=True, nogil=True, error_model="numpy")
def _band_sums_pairs(M, B2, C2, x2, Xr, Xi, zr, zi, Er, Ei, Lr, Li, coef, starts, counts,
                     out):  # pragma: no cover - compiled
    # The same band sums from the real block form: slot q of walker b is a real 2 x 2 block
    # M[q, :, :, b] with inputs B2[q, :, :, b] (2, m), outputs C2[q, :, :, b] (p, 2, scaled)
    # and state after the record x2[q, :, b]; per bin w = B2 X_k - z_k x2 (complex 2-vector),
    # u = (z_k I - M)^-1 w = [[z - m22, m12], [m21, z - m11]] w / det, R -= C2 u.
    nsl = M.shape[0]
    nb = M.shape[3]
    m = B2.shape[2]
    p = C2.shape[1]
    rr, ri = np.empty((p, nb)), np.empty((p, nb))
    sr, si = np.empty((p, p, nb)), np.empty((p, p, nb))
    w1r, w1i, w2r, w2i = np.empty(nb), np.empty(nb), np.empty(nb), np.empty(nb)
    for band in range(starts.size):
        _zero_sums(sr, si)
        for k in range(starts[band], starts[band] + counts[band]):
            zrk, zik = zr[k], zi[k]
            for i in range(p):
                for b in range(nb):
                    rr[i, b] = 0.0
                    ri[i, b] = 0.0
            for q in range(nsl):
                for b in range(nb):
                    w1r[b] = -zrk * x2[q, 0, b]
                    w1i[b] = -zik * x2[q, 0, b]
                    w2r[b] = -zrk * x2[q, 1, b]
                    w2i[b] = -zik * x2[q, 1, b]
                for c in range(m):
                    xrc, xic = Xr[k, c], Xi[k, c]
                    for b in range(nb):
                        w1r[b] += B2[q, 0, c, b] * xrc
                        w1i[b] += B2[q, 0, c, b] * xic
                        w2r[b] += B2[q, 1, c, b] * xrc
                        w2i[b] += B2[q, 1, c, b] * xic
                for b in range(nb):
                    w1r[b], w1i[b], w2r[b], w2i[b] = solve_block(
                        zrk, zik, M[q, 0, 0, b], M[q, 0, 1, b], M[q, 1, 0, b], M[q, 1, 1, b],
                        w1r[b], w1i[b], w2r[b], w2i[b])
                for i in range(p):
                    for b in range(nb):
                        rr[i, b] += C2[q, i, 0, b] * w1r[b] + C2[q, i, 1, b] * w2r[b]
                        ri[i, b] += C2[q, i, 0, b] * w1i[b] + C2[q, i, 1, b] * w2i[b]
            _finish_residual(rr, ri, Er, Ei, Lr, Li, coef, k)   # R = E - (C u) - lines . coef
            _accumulate(sr, si, rr, ri)                          # P_b += R_k R_k^H
        _store_band(out, sr, si, band)


@njit(cache=True, nogil=True)
def _real_blocks(lam, Bm, Cm, xi, inv_scale):  # pragma: no cover - compiled
    # The modal form as real 2 x 2 blocks (slot, ..., walker), or an empty M if a member is
    # not in that form: complex modes must come as adjacent exactly conjugate pairs (lam, Bm,
    # Cm, xi all conjugate), real modes with real Bm, Cm, xi (paired two by two).
    nb, ns = lam.shape
    m = Bm.shape[2]
    p = Cm.shape[1]
    nsl = ns                                        # at most one slot per mode
    M = np.zeros((nsl, 2, 2, nb))
    B2 = np.zeros((nsl, 2, m, nb))
    C2 = np.zeros((nsl, p, 2, nb))
    x2 = np.zeros((nsl, 2, nb))
    used = 0
    for b in range(nb):
        q = 0
        half = -1                                   # a slot holding one real mode so far
        s = 0
        while s < ns:
            lr, li = lam[b, s].real, lam[b, s].imag
            if li != 0.0:
                t = s + 1
                if t >= ns or lam[b, t] != np.conj(lam[b, s]) or xi[b, t] != np.conj(xi[b, s]):
                    return M[:0], B2, C2, x2
                for c in range(m):
                    if Bm[b, t, c] != np.conj(Bm[b, s, c]):
                        return M[:0], B2, C2, x2
                for i in range(p):
                    if Cm[b, i, t] != np.conj(Cm[b, i, s]):
                        return M[:0], B2, C2, x2
                # eta = (zeta_r - i zeta_i) / 2 for the mode lam, x = sum 2 Re(c eta)
                M[q, 0, 0, b] = lr
                M[q, 0, 1, b] = li
                M[q, 1, 0, b] = -li
                M[q, 1, 1, b] = lr
                for c in range(m):
                    B2[q, 0, c, b] = 2.0 * Bm[b, s, c].real
                    B2[q, 1, c, b] = -2.0 * Bm[b, s, c].imag
                for i in range(p):
                    C2[q, i, 0, b] = Cm[b, i, s].real * inv_scale
                    C2[q, i, 1, b] = Cm[b, i, s].imag * inv_scale
                x2[q, 0, b] = 2.0 * xi[b, s].real
                x2[q, 1, b] = -2.0 * xi[b, s].imag
                q += 1
                s += 2
                continue
            if xi[b, s].imag != 0.0:
                return M[:0], B2, C2, x2
            for c in range(m):
                if Bm[b, s, c].imag != 0.0:
                    return M[:0], B2, C2, x2
            for i in range(p):
                if Cm[b, i, s].imag != 0.0:
                    return M[:0], B2, C2, x2
            if half < 0:
                half = q
                r = 0
                q += 1
            else:
                r = 1
            M[half, r, r, b] = lr
            for c in range(m):
                B2[half, r, c, b] = Bm[b, s, c].real
            for i in range(p):
                C2[half, i, r, b] = Cm[b, i, s].real * inv_scale
            x2[half, r, b] = xi[b, s].real
            if r == 1:
                half = -1
            s += 1
        used = max(used, q)
    return M[:used], B2[:used], C2[:used], x2[:used]


@njit(cache=True, nogil=True, error_model="numpy")
def _whittle_terms(sig2, ps, scale, P, logdet, quad, ok):  # pragma: no cover
    # Per walker, every band at once (vectors over the bands): Phi = scale sum_s sig2[b, s]
    # ps[s]; Phi = L D L^H (L unit lower, D > 0); log det Phi = log prod D; with M = L^-1,
    # Phi^-1 = M^H D^-1 M and tr(Phi^-1 P) from its lower triangle (real arithmetic).
    # ps (n_src, nbands, n, n), P (nb, nbands, n, n) complex
    nb = sig2.shape[0]
    nsrc, nbands, n, _ = ps.shape
    psr, psi = np.empty((nsrc, n, n, nbands)), np.empty((nsrc, n, n, nbands))
    for s in range(nsrc):                    # bands last: the loops below run over them
        for f in range(nbands):
            for i in range(n):
                for j in range(i + 1):
                    psr[s, i, j, f] = ps[s, f, i, j].real
                    psi[s, i, j, f] = ps[s, f, i, j].imag
    Ar, Ai = np.empty((n, n, nbands)), np.empty((n, n, nbands))
    Pr, Pi = np.empty((n, n, nbands)), np.empty((n, n, nbands))
    D, Dinv, det = np.empty((n, nbands)), np.empty((n, nbands)), np.empty(nbands)
    Mr, Mi = np.empty((n, n, nbands)), np.empty((n, n, nbands))
    vr, vi = np.empty(nbands), np.empty(nbands)
    for b in range(nb):
        for f in range(nbands):
            for i in range(n):
                for j in range(i + 1):
                    Pr[i, j, f] = P[b, f, i, j].real
                    Pi[i, j, f] = P[b, f, i, j].imag
        for i in range(n):                   # the lower triangle of Phi
            for j in range(i + 1):
                for f in range(nbands):
                    Ar[i, j, f] = 0.0
                    Ai[i, j, f] = 0.0
                for s in range(nsrc):
                    g = sig2[b, s]
                    for f in range(nbands):
                        Ar[i, j, f] += g * psr[s, i, j, f]
                        Ai[i, j, f] += g * psi[s, i, j, f]
                for f in range(nbands):
                    Ar[i, j, f] *= scale
                    Ai[i, j, f] *= scale
        for f in range(nbands):
            det[f] = 1.0
            ok[b, f] = True
        for j in range(n):                   # L D L^H, L stored in A's lower triangle
            for f in range(nbands):
                vr[f] = Ar[j, j, f]
            for k in range(j):               # - |L_jk|^2 D_k
                for f in range(nbands):
                    vr[f] -= (Ar[j, k, f] * Ar[j, k, f] + Ai[j, k, f] * Ai[j, k, f]) * D[k, f]
            for f in range(nbands):
                d = vr[f]
                if not d > 0:
                    ok[b, f] = False
                    d = 1.0
                D[j, f] = d
                Dinv[j, f] = 1.0 / d
                det[f] *= d
            for i in range(j + 1, n):
                for f in range(nbands):
                    vr[f] = Ar[i, j, f]
                    vi[f] = Ai[i, j, f]
                for k in range(j):           # - L_ik D_k conj(L_jk)
                    for f in range(nbands):
                        lr = Ar[i, k, f] * D[k, f]
                        li = Ai[i, k, f] * D[k, f]
                        vr[f] -= lr * Ar[j, k, f] + li * Ai[j, k, f]
                        vi[f] -= li * Ar[j, k, f] - lr * Ai[j, k, f]
                for f in range(nbands):
                    Ar[i, j, f] = vr[f] * Dinv[j, f]
                    Ai[i, j, f] = vi[f] * Dinv[j, f]
        for f in range(nbands):
            if 1e-290 < det[f] < 1e290:
                logdet[b, f] = np.log(det[f])
            else:                            # the product would lose range
                ld = 0.0
                for j in range(n):
                    ld += np.log(D[j, f])
                logdet[b, f] = ld
        for i in range(n):                   # M = L^-1 (unit lower)
            for j in range(i):
                for f in range(nbands):
                    Mr[i, j, f] = -Ar[i, j, f]
                    Mi[i, j, f] = -Ai[i, j, f]
                for k in range(j + 1, i):    # - L_ik M_kj
                    for f in range(nbands):
                        Mr[i, j, f] -= Ar[i, k, f] * Mr[k, j, f] - Ai[i, k, f] * Mi[k, j, f]
                        Mi[i, j, f] -= Ar[i, k, f] * Mi[k, j, f] + Ai[i, k, f] * Mr[k, j, f]
            for f in range(nbands):
                Mr[i, i, f] = 1.0
                Mi[i, i, f] = 0.0
        for f in range(nbands):
            quad[b, f] = 0.0
        for j in range(n):                   # Phi^-1 = M^H D^-1 M; tr(Phi^-1 P) =
            for k in range(j + 1):           # sum_jk Re(Phi^-1_kj P_jk), P Hermitian
                for f in range(nbands):
                    vr[f] = 0.0
                    vi[f] = 0.0
                for i in range(j, n):        # (Phi^-1)_jk = sum_i conj(M_ij) M_ik / D_i
                    for f in range(nbands):
                        ar = Mr[i, j, f] * Dinv[i, f]
                        ai = Mi[i, j, f] * Dinv[i, f]
                        vr[f] += ar * Mr[i, k, f] + ai * Mi[i, k, f]
                        vi[f] += ar * Mi[i, k, f] - ai * Mr[i, k, f]
                if j == k:
                    for f in range(nbands):
                        quad[b, f] += vr[f] * Pr[j, j, f]
                else:                        # 2 Re(Phi^-1_jk P_kj), P_kj = conj(P_jk)
                    for f in range(nbands):
                        quad[b, f] += 2.0 * (vr[f] * Pr[j, k, f] + vi[f] * Pi[j, k, f])


def whittle_terms(sig2: NDArray, phi_sources: NDArray, scale: float, P: NDArray,
                  packed_sums: bool = False) -> tuple[NDArray, NDArray, NDArray]:
    """log det Phi_b, tr(Phi_b^-1 P_b) and positive definiteness, (nb, n_bands) each, for
    Phi_b = scale sum_s sig2[:, s] phi_sources[s, b] (sig2 (nb, n_src), phi_sources
    (n_src, n_bands, n, n) Hermitian, P (nb, n_bands, n, n), or with ``packed_sums`` P
    already packed as band_algebra.pack_band_sums packs it, for 4 channels and 3 sources).

    Examples
    --------
    >>> from bayes_amb.inference.band_algebra import logdet_and_trace_numpy
    >>> rng = np.random.default_rng(0)
    >>> A = rng.standard_normal((2, 5, 4, 4)) + 1j * rng.standard_normal((2, 5, 4, 4))
    >>> ps = A @ np.conj(np.swapaxes(A, -1, -2))
    >>> sig2, P = np.array([[1.0, 0.5], [2.0, 0.1]]), ps[::-1]
    >>> Phi = 3.0 * np.einsum("bs,sfij->bfij", sig2, ps)
    >>> new, old = whittle_terms(sig2, ps, 3.0, P), logdet_and_trace_numpy(Phi, P)
    >>> bool(np.allclose(new[0], old[0]) and np.allclose(new[1], old[1]))
    True
    """
    nb = sig2.shape[0]
    shape = (nb, phi_sources.shape[1])
    logdet, quad = np.empty(shape), np.empty(shape)
    ok = np.empty(shape, dtype=np.bool_)
    sig2 = np.ascontiguousarray(sig2, np.float64)
    if packed_sums and phi_sources.shape[0] != band_algebra.N_SRC:
        raise ValueError(f"whittle_terms: packed band sums need {band_algebra.N_SRC} noise "
                         f"sources, not {phi_sources.shape[0]}")
    if packed_sums or (P.shape[-1] == band_algebra.N_CH
                       and phi_sources.shape[0] == band_algebra.N_SRC):
        packed = P if packed_sums else band_algebra.pack_band_sums(
            np.ascontiguousarray(P, np.complex128))
        band_algebra._whittle_terms4(sig2, band_algebra.packed_sources(phi_sources),
                                     float(scale), packed, logdet, quad, ok)  # written out
    else:
        phi_sources = np.ascontiguousarray(phi_sources, np.complex128)
        P = np.ascontiguousarray(P, np.complex128)
        _whittle_terms(sig2, phi_sources, float(scale), P, logdet, quad, ok)
    return logdet, quad, ok

