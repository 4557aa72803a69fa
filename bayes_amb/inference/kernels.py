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
``bayes_amb.inference.band_algebra.logdet_and_trace_numpy``, band by band.

Compiled on first use and cached on disk (numba ``cache=True``); single-threaded (the
parallelism is the batch over walkers and the tool's own worker pools). Which path a
likelihood takes is its model's :class:`Engine`, chosen once when the forward model is
built: ``BAYES_AMB_KERNEL=numpy`` then gives the numpy path, ``lapack`` the first compiled
path (both kept as references, KERNEL_MODES; benchmarks/README.md).
"""

from __future__ import annotations

import itertools
import os
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from bayes_amb.threads import over_rows

KERNEL_ENV = "BAYES_AMB_KERNEL"


KERNEL_MODES = ("numba", "lapack", "numpy")
"""Values of ``BAYES_AMB_KERNEL``: ``numba`` (the default) computes everything compiled,
the modal form included (bayes_amb.inference.eigen); ``lapack`` is the compiled path
before that (modal form by ``np.linalg.eig``, numpy ZOH and modal state, the walker-by-walker
band sums of this module): kept to be measured side by side; ``numpy`` is the path before
any kernel."""


def kernel_mode() -> str:
    """The likelihood path asked for in the environment: ``BAYES_AMB_KERNEL`` (one of
    KERNEL_MODES), default "numba". Read once per model (:func:`engine_from_env`)."""
    value = os.environ.get(KERNEL_ENV, "numba").strip().lower() or "numba"
    if value not in KERNEL_MODES:
        from bayes_amb.errors import BayesAmbError

        raise BayesAmbError(f"{KERNEL_ENV}: expected one of {', '.join(KERNEL_MODES)}, "
                            f"got {value!r}")
    return value


@dataclass(frozen=True)
class Engine:
    """The likelihood engine: which path computes the modal form, the residual DFT, the
    band sums and the band algebra. Chosen once when a forward model is built
    (``ForwardModel.engine``, from ``BAYES_AMB_KERNEL``); every likelihood of that model
    reads it there, so which path ran for a call is the model's ``engine.mode``.

    mode: "numba" (the default: everything compiled, the modal form included), "lapack"
    (the first compiled path: modal form by LAPACK, compiled band sums) or "numpy" (the
    reference path before any kernel). The two other paths are kept as references the
    default is measured and tested against (benchmarks/README.md, "likelihood paths";
    tests/test_kernels.py).
    """

    mode: str = "numba"

    def __post_init__(self) -> None:
        if self.mode not in KERNEL_MODES:
            from bayes_amb.errors import BayesAmbError

            raise BayesAmbError(f"likelihood engine: expected one of "
                                f"{', '.join(KERNEL_MODES)}, got {self.mode!r}")

    @property
    def compiled(self) -> bool:
        """Whether the residual DFT and band sums are compiled ("numba" or "lapack")."""
        return self.mode != "numpy"

    @property
    def compiled_modal(self) -> bool:
        """Whether the modal form, ZOH and band algebra are compiled too ("numba")."""
        return self.mode == "numba"


def engine_from_env() -> Engine:
    """The engine ``BAYES_AMB_KERNEL`` asks for (default "numba")."""
    return Engine(kernel_mode())


CHUNK_BINS = 512
"""Bins per pass of the kernel (whole bands; a band wider than this is one pass): the
modal responses of a pass, 2 x ns x CHUNK_BINS doubles, stay in the L2 cache."""


@njit(cache=True, nogil=True)
def _residual_rows(b, k0, n, lam, Bm, Cm, xi, Xr, Xi, zr, zi, Er, Ei, inv_scale, Lr, Li,
                   coef, ur, ui, rr, ri):  # pragma: no cover - compiled
    # The residual R_k of batch member b for the n bins from k0, into rr, ri (p, >= n).
    # Real arithmetic on (channel, bin) rows, so that the loops over bins are unit-stride
    # and vectorise (numba's complex division and per-bin temporaries cost 10x).
    ns = lam.shape[1]
    m = Xr.shape[0]
    p = Er.shape[0]
    nl = coef.shape[1]
    for s in range(ns):                         # u_s = (Bm_s . X_k - z_k xi_s) / (z_k - lam_s)
        lr, li = lam[b, s].real, lam[b, s].imag
        xr, xi_ = xi[b, s].real, xi[b, s].imag
        urs, uis = ur[s], ui[s]
        for k in range(n):
            urs[k] = -(zr[k0 + k] * xr - zi[k0 + k] * xi_)
            uis[k] = -(zr[k0 + k] * xi_ + zi[k0 + k] * xr)
        for c in range(m):
            br, bi = Bm[b, s, c].real, Bm[b, s, c].imag
            xrc, xic = Xr[c], Xi[c]
            for k in range(n):
                urs[k] += xrc[k0 + k] * br - xic[k0 + k] * bi
                uis[k] += xrc[k0 + k] * bi + xic[k0 + k] * br
        for k in range(n):                        # times conj(z - lam) / |z - lam|^2
            dr = zr[k0 + k] - lr
            di = zi[k0 + k] - li
            d = 1.0 / (dr * dr + di * di)
            a, e = urs[k], uis[k]
            urs[k] = (a * dr + e * di) * d
            uis[k] = (e * dr - a * di) * d
    for i in range(p):                          # R = E - (Cm u) / scale - lines . coef
        rri, rii = rr[i], ri[i]
        for k in range(n):
            rri[k] = 0.0
            rii[k] = 0.0
        for s in range(ns):
            cr, ci = Cm[b, i, s].real * inv_scale, Cm[b, i, s].imag * inv_scale
            urs, uis = ur[s], ui[s]
            for k in range(n):
                rri[k] += cr * urs[k] - ci * uis[k]
                rii[k] += cr * uis[k] + ci * urs[k]
        eri, eii = Er[i], Ei[i]
        for k in range(n):
            rri[k] = eri[k0 + k] - rri[k]
            rii[k] = eii[k0 + k] - rii[k]
        for j in range(nl):
            g = coef[b, j]
            lrj, lij = Lr[j, i], Li[j, i]
            for k in range(n):
                rri[k] -= lrj[k0 + k] * g
                rii[k] -= lij[k0 + k] * g


@njit(cache=True, nogil=True)
def _residual_band_sums(lam, Bm, Cm, xi, Xr, Xi, zr, zi, Er, Ei, inv_scale, Lr, Li, coef,
                        starts, counts, chunks, width, out):  # pragma: no cover - compiled
    # Bins are taken a few hundred at a time (whole bands) so that u stays in cache.
    nb, ns = lam.shape
    p = Er.shape[0]
    ur, ui = np.empty((ns, width)), np.empty((ns, width))
    rr, ri = np.empty((p, width)), np.empty((p, width))
    for b in range(nb):
        for q in range(chunks.size - 1):
            b0, b1 = chunks[q], chunks[q + 1]
            k0 = starts[b0]
            n = starts[b1 - 1] + counts[b1 - 1] - k0
            _residual_rows(b, k0, n, lam, Bm, Cm, xi, Xr, Xi, zr, zi, Er, Ei, inv_scale, Lr,
                           Li, coef, ur, ui, rr, ri)
            for band in range(b0, b1):          # P_b = sum_k R_k R_k^H
                lo = starts[band] - k0
                hi = lo + counts[band]
                for i in range(p):
                    for j in range(i, p):
                        ar = 0.0
                        ai = 0.0
                        for k in range(lo, hi):
                            ar += rr[i, k] * rr[j, k] + ri[i, k] * ri[j, k]
                            ai += ri[i, k] * rr[j, k] - rr[i, k] * ri[j, k]
                        out[b, band, i, j] = ar + 1j * ai
                        if j > i:
                            out[b, band, j, i] = ar - 1j * ai


@njit(cache=True, nogil=True)
def _residual_dft(lam, Bm, Cm, xi, Xr, Xi, zr, zi, Er, Ei, inv_scale, Lr, Li, coef,
                  width, out_r, out_i):  # pragma: no cover - compiled
    nb, ns = lam.shape
    nf = zr.size
    ur, ui = np.empty((ns, width)), np.empty((ns, width))
    for b in range(nb):
        for k0 in range(0, nf, width):
            n = min(width, nf - k0)
            _residual_rows(b, k0, n, lam, Bm, Cm, xi, Xr, Xi, zr, zi, Er, Ei, inv_scale, Lr,
                           Li, coef, ur, ui, out_r[b, :, k0:], out_i[b, :, k0:])


def _chunks(counts: NDArray, width: int) -> tuple[NDArray, int]:
    """Band indices where each pass of the kernel starts (and the end), and the widest
    pass in bins: consecutive whole bands of at most width bins (or one wider band)."""
    edges = [0]
    acc = 0
    for band, c in enumerate(counts):
        if acc and acc + c > width:
            edges.append(band)
            acc = 0
        acc += int(c)
    edges.append(counts.size)
    e = np.asarray(edges, dtype=np.int64)
    widest = max(int(counts[a:b].sum()) for a, b in itertools.pairwise(e))
    return e, widest


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
    out = np.empty((lam.shape[0], starts.size, E.shape[1], E.shape[1]), dtype=complex)
    chunks, width = _chunks(np.asarray(counts), CHUNK_BINS)
    args = _arguments(lam, Bm, Cm, xi, X, z, E, scale, lines, coef)
    starts = np.ascontiguousarray(starts, np.int64)
    counts = np.ascontiguousarray(counts, np.int64)
    over_rows(lambda lo, hi: _residual_band_sums(*rows_of(args, lo, hi), starts, counts,
                                                 chunks, width, out[lo:hi]), lam.shape[0])
    return out


def rows_of(args: tuple, lo: int, hi: int) -> tuple:
    """The kernels' common arguments (:func:`_arguments`) for the rows lo:hi of the batch:
    the modal form, the state after the record and the line coefficients are per row."""
    lam, Bm, Cm, xi, *shared, coef = args
    return (lam[lo:hi], Bm[lo:hi], Cm[lo:hi], xi[lo:hi], *shared, coef[lo:hi])


def lines_or_empty(E: NDArray, nb: int, lines: NDArray | None, coef: NDArray | None
                   ) -> tuple[NDArray, NDArray]:
    """The synchronous-line bases (nf, p, nl) and coefficients (nb, nl) as given, or empty
    ones (nl = 0) when there are none."""
    if lines is None or coef is None or coef.shape[1] == 0:
        return np.zeros((E.shape[0], E.shape[1], 0), dtype=complex), np.zeros((nb, 0))
    return lines, coef


def _arguments(lam: NDArray, Bm: NDArray, Cm: NDArray, xi: NDArray, X: NDArray, z: NDArray,
               E: NDArray, scale: float, lines: NDArray | None, coef: NDArray | None
               ) -> tuple:
    """The kernels' common arguments, contiguous, in real arithmetic where they loop."""
    nb = lam.shape[0]
    lines, coef = lines_or_empty(E, nb, lines, coef)
    c128, f64 = np.complex128, np.float64
    X = np.asarray(X, dtype=c128)
    z = np.asarray(z, dtype=c128)
    E = np.asarray(E, dtype=c128)
    L = np.asarray(lines, dtype=c128).transpose(2, 1, 0)              # (nl, p, nf)
    return (np.ascontiguousarray(lam, c128), np.ascontiguousarray(Bm, c128),
            np.ascontiguousarray(Cm, c128), np.ascontiguousarray(xi, c128),
            np.ascontiguousarray(X.real.T), np.ascontiguousarray(X.imag.T),
            np.ascontiguousarray(z.real), np.ascontiguousarray(z.imag),
            np.ascontiguousarray(E.real.T), np.ascontiguousarray(E.imag.T),
            1.0 / scale, np.ascontiguousarray(L.real), np.ascontiguousarray(L.imag),
            np.ascontiguousarray(coef, f64))


def residual_dft(lam: NDArray, Bm: NDArray, Cm: NDArray, xi: NDArray, X: NDArray,
                 z: NDArray, E: NDArray, scale: float, lines: NDArray | None = None,
                 coef: NDArray | None = None) -> NDArray:
    """The residual DFT R_k = E_k - (Cm u_k) / scale - lines_k . coef itself, (nb, nf, p):
    the same arithmetic as :func:`residual_band_sums` (arguments as there), without the
    band sums. With E = 0 and no lines it is minus the scaled response DFT."""
    nb, nf, p = lam.shape[0], z.size, E.shape[1]
    out_r, out_i = np.empty((nb, p, nf)), np.empty((nb, p, nf))
    args = _arguments(lam, Bm, Cm, xi, X, z, E, scale, lines, coef)
    over_rows(lambda lo, hi: _residual_dft(*rows_of(args, lo, hi), CHUNK_BINS, out_r[lo:hi],
                                           out_i[lo:hi]), nb)
    out = np.empty((nb, nf, p), dtype=complex)
    out.real = out_r.transpose(0, 2, 1)
    out.imag = out_i.transpose(0, 2, 1)
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

    The same Cholesky algebra as
    ``bayes_amb.inference.band_algebra.logdet_and_trace_numpy``.
    """
    shape = Phi.shape[:2]
    logdet, quad = np.empty(shape), np.empty(shape)
    ok = np.empty(shape, dtype=np.bool_)
    _logdet_and_trace(np.ascontiguousarray(Phi, np.complex128),
                      np.ascontiguousarray(P, np.complex128), logdet, quad, ok)
    return logdet, quad, ok
