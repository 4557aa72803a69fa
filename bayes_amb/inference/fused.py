"""The whole default likelihood path in one compiled call (issue 16).

On the default path (``BAYES_AMB_KERNEL=numba``) one evaluation of a batch is a chain of
compiled stages: plant A(theta) = A + B_w Theta C_z, its ZOH, the loop in error coordinates
S(theta), the modal form, the modal state after the record, the residual band sums and the
4 x 4 band algebra. Called one by one from Python they cost ~11 us per evaluation more than
their arithmetic (argument checks, dispatch, conversions and temporary arrays between the
stages). :func:`fused_log_likelihood` runs them all in one call, stage for stage the same
compiled functions (bayes_amb.inference.batched, loop_model, eigen, walker_kernels,
block_sums, band_algebra), so its results are those of the staged path to rounding (the
plant's matrix product is summed in a fixed order here, by BLAS there). The band sums stay
packed for the band algebra (bayes_amb.inference.band_algebra) and are unpacked only if
the staged path asks for the remembered batch.

Every stage computes each member from that member's data alone, with the same operations
whatever the rest of the batch (the QR iteration runs the members in lock-step but each on
its own windows; the vectorised loops run over the members), so a row's result does not
depend on the batch it comes in (tests/test_kernels.py).

It applies to the observer-form loop (``ForwardModel.fast``) of a plain
:class:`~bayes_amb.inference.whittle.WhittleLikelihood` and batches of at least
``walker_kernels.LANES_MIN_BATCH`` rows; members the compiled modal form rejects
(repeated or defective eigenvalues) make the whole batch go the staged path.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from bayes_amb.inference.band_algebra import (
    LANES,
    N_CH,
    N_SRC,
    _whittle_terms4,
    n_chunks,
    pack_band_sources,
)
from bayes_amb.inference.batched import _zoh
from bayes_amb.inference.eigen import _final_state_batch, _modal_batch
from bayes_amb.inference.loop_model import _error_form
from bayes_amb.inference.walker_kernels import _lanes_call, _whittle_terms


@njit(cache=True, nogil=True, error_model="numpy")
def _fused(theta, rep, pA, pBw, pCz, pB, dt, Ad, Bd, F, LC, C_S, x, tol, X, z, E,
           inv_scale, starts, counts, sig2, phi_sources, packed_sources, n_rec, log_pi4,
           lines, coef, Pb, packed, stable, ll):  # pragma: no cover - compiled
    # returns 0 when a finite member failed the compiled modal form's checks (the caller
    # then takes the staged path, which sends such members to LAPACK); 1 when the band sums
    # are in Pb, 2 when they are in packed only (band_algebra's layout; packed is empty
    # where the written-out band algebra does not apply)
    nb = theta.shape[0]
    n = pA.shape[0]
    r = pBw.shape[1]
    m = pB.shape[1]
    p = C_S.shape[0]
    ns = 2 * n
    A = np.empty((nb, n, n))            # A(theta) = A + (B_w diag(theta)) C_z
    Bb = np.empty((nb, n, m))
    w = np.empty((n, r))
    for b in range(nb):
        for i in range(n):
            for q in range(r):
                w[i, q] = pBw[i, q] * theta[b, rep[q]]
        for i in range(n):
            for j in range(n):
                s = 0.0
                for q in range(r):
                    s += w[i, q] * pCz[q, j]
                A[b, i, j] = pA[i, j] + s
            for j in range(m):
                Bb[b, i, j] = pB[i, j]
    Fz = np.empty((nb, n, n))
    Gz = np.empty((nb, n, m))
    _zoh(A, Bb, dt, Fz, Gz)
    A_S = np.empty((nb, ns, ns))
    B_S = np.empty((nb, ns, m))
    _error_form(Ad, Bd, F, LC, Fz, Gz, A_S, B_S)
    Cb = np.empty((nb, p, ns))
    for b in range(nb):
        for i in range(p):
            for j in range(ns):
                Cb[b, i, j] = C_S[i, j]
    lam = np.zeros((nb, ns), dtype=np.complex128)
    Bm = np.zeros((nb, ns, m), dtype=np.complex128)
    Cm = np.zeros((nb, p, ns), dtype=np.complex128)
    ok = np.zeros(nb, dtype=np.bool_)
    _modal_batch(A_S, B_S, Cb, lam, Bm, Cm, ok)
    lam_s = np.empty((nb, ns), dtype=np.complex128)
    for b in range(nb):
        finite = True
        for i in range(ns):
            for j in range(ns):
                if not np.isfinite(A_S[b, i, j]):
                    finite = False
        if finite and not ok[b]:
            return 0
        rho = 0.0
        for s in range(ns):
            rho = max(rho, abs(lam[b, s]))
        stable[b] = finite and rho < 1.0 - 1e-12
        for s in range(ns):
            lam_s[b, s] = lam[b, s] if stable[b] else 0.0
    xi = np.empty((nb, ns), dtype=np.complex128)
    _final_state_batch(lam_s, Bm, x, tol, xi)
    full = _lanes_call(lam, Bm, Cm, xi, X, z, E, inv_scale, lines, coef, starts, counts, Pb,
                       packed)
    nbands = starts.size
    logdet, quad = np.empty((nb, nbands)), np.empty((nb, nbands))
    okw = np.empty((nb, nbands), dtype=np.bool_)
    if full:
        _whittle_terms(sig2, phi_sources, n_rec, Pb, logdet, quad, okw)
    else:                                   # written out (band_algebra), the same results
        _whittle_terms4(sig2, packed_sources, n_rec, packed, logdet, quad, okw)
    for b in range(nb):
        bad = not stable[b]
        for f in range(nbands):
            v = -(counts[f] * (logdet[b, f] + log_pi4) + quad[b, f])
            ll[b, f] = v
            if not okw[b, f] or not np.isfinite(v):
                bad = True
        if bad:
            for f in range(nbands):
                ll[b, f] = -np.inf
    return 1 if full else 2


class FusedLikelihood:
    """The constant arrays of one WhittleLikelihood's fused call, converted once.

    Parameters
    ----------
    like : WhittleLikelihood
        A plain Whittle likelihood on an observer-form ForwardModel (``forward.fast``).
    tol : float
        Tail tolerance of the modal state after the record (forward._TRANSIENT_TOL).
    """

    def __init__(self, like, tol: float):
        fm = like.forward
        pl = fm.plant
        f64, c128 = np.float64, np.complex128
        Ad, Bd, C, F, _ = fm._error_parts
        self.rep = np.repeat(np.arange(len(pl.blocks)), pl.blocks).astype(np.int64)
        self.plant = tuple(np.ascontiguousarray(a, f64) for a in (pl.A, pl.B_w, pl.C_z, pl.B))
        self.dt = float(fm.dt)
        self.loop = (Ad, Bd, F, fm._LC,
                     np.ascontiguousarray(np.hstack([C, np.zeros_like(C)]), f64))
        self.x = np.ascontiguousarray(like.x_w, f64)
        self.tol = float(tol)
        self.data = (np.ascontiguousarray(like.X, c128), np.ascontiguousarray(like.z, c128),
                     np.ascontiguousarray(like.E, c128), 1.0 / like.scale,
                     np.ascontiguousarray(like.starts, np.int64),
                     np.ascontiguousarray(like.counts, np.int64))
        self.phi_sources = np.ascontiguousarray(like.phi_sources, c128)
        n_src, nbands, p = like.phi_sources.shape[:3]
        self.packs = p == N_CH and n_src == N_SRC          # band_algebra's kernel applies
        self.packed_sources = (pack_band_sources(self.phi_sources) if self.packs
                               else np.zeros((nbands, n_src, 16)))
        self.n = float(like.n)
        self.lines = np.zeros((like.E.shape[0], like.E.shape[1], 0), dtype=c128)
        self.n_bands = like.starts.size
        self.log_pi4 = 4 * np.log(np.pi)
        self._sources = _sources(like)

    def matches(self, like) -> bool:
        """Whether like's data and noise filters are still the ones converted here."""
        return all(a is b for a, b in zip(self._sources, _sources(like), strict=True))

    def __call__(self, theta: NDArray, sig2: NDArray
                 ) -> tuple[NDArray, NDArray | None, NDArray, NDArray | None] | None:
        """(log-likelihood per band (nb, n_bands), P_b (nb, n_bands, 4, 4), stable (nb,),
        P_b packed) for theta (nb, p) and sig2 (nb, 3), both C-contiguous float64: P_b in
        one of the two forms, the other None (packed as bayes_amb.inference.band_algebra
        reads them where its kernel applies); None where a member needs the staged path
        (its modal form by LAPACK)."""
        nb = theta.shape[0]
        Pb = np.empty((nb, self.n_bands, 4, 4), dtype=np.complex128)
        packed = np.empty((n_chunks(nb) if self.packs else 0, self.n_bands, 16, LANES))
        stable = np.empty(nb, dtype=np.bool_)
        ll = np.empty((nb, self.n_bands))
        done = _fused(theta, self.rep, *self.plant, self.dt, *self.loop, self.x, self.tol,
                      *self.data, sig2, self.phi_sources, self.packed_sources, self.n,
                      self.log_pi4, self.lines, np.zeros((nb, 0)), Pb, packed, stable, ll)
        if done == 0:
            return None
        return (ll, Pb, stable, None) if done == 1 else (ll, None, stable, packed)


def _sources(like) -> tuple:
    """The likelihood's arrays a FusedLikelihood converts (compared by identity)."""
    fm = like.forward
    return (fm, fm.plant, like.x_w, like.X, like.z, like.E, like.scale, like.starts,
            like.counts, like.phi_sources)
