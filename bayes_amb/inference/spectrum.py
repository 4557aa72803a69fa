"""A noise spectrum learned from the record: each source's intensity as a smooth function of
frequency, per channel.

identify's likelihood (whittle.py) puts three white sources through the exact closed-loop
noise filters of eq. 14: sensor noise n, r1 and r2, each with one intensity sigma_s^2 on
all four channels. A real rig's disturbance is coloured: a process or band-limited force
puts its power in one band, a probe's noise rises towards low frequency, one bearing is
disturbed and the other not. A white source then has to cover the loudest band at every
frequency: on a record with a 0.05 A force below 300 Hz the white sigma_r2 was 0.16 A at
every frequency, the sensor noise was pushed to nothing, and every stiffness interval
spanned its prior although the bands above 300 Hz hold the excitation's information as
before.

The model here keeps the loop filters H_s and lets each source's intensity vary with
frequency and channel:

    Phi(f) = sum_s H_s(f) diag(sigma_s^2 g_s,c(f)) H_s(f)^H,
    ln g_s,c(f) = piecewise linear in ln f over KNOTS knots,

under a smoothness prior (a second-order random walk of the knot values, sd SMOOTH_SD per
knot step) and a weak ridge (sd RIDGE_SD) towards the white model. It is fitted at the MAP
by penalised Whittle maximum likelihood over the band sums P_b the likelihood already
forms, then held fixed ("plug-in", like the noise filters): in a Gaussian model the
information about a mean parameter (theta, through S(theta) x) and about the covariance
(the spectrum) is orthogonal, so a consistent spectrum estimate costs the intervals of
theta nothing to first order. The sampled sigma_s then scale each source's learned shape.

Why this and not the alternatives (issue 46). The Student-t Whittle likelihood (Roever,
Meyer & Christensen 2011) and this project's own inverse-Wishart band integral
(discrepancy/likelihood.py) let each band's scale float freely: they are robust where the
colour is mild, but centred on a white model whose intensities are set by the loudest band
they keep the quiet bands' weight far too low (the diagnosis' nominal fit lost the same
information as identify). A spline in log frequency with a smoothness prior is the noise
model of gravitational-wave parameter estimation (BayesLine); fitted at the MAP it is the
nonparametric noise covariance of the local polynomial method (Pintelon & Schoukens) with
the loop's structure kept, so it extrapolates where a source is masked by another. It
costs nothing per likelihood evaluation: the learned gains are folded into the band
filter products ``phi_sources`` the likelihood already uses.

White costs nothing: the learned spectrum is adopted only where it beats the white model
by more than chance (a likelihood-ratio test at P_ADOPT with the fit's parameter count as
degrees of freedom); on a white record the likelihood is left exactly as it was.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import optimize, stats

from bayes_amb.control.discrete import ss_freqresp_modal
from bayes_amb.inference.hermitian_kernels import spectrum_terms
from bayes_amb.inference.priors import NOISE_LOG10_BOUNDS
from bayes_amb.rig import CHANNELS

KNOTS = 32
"""Knots of each source's log-intensity, spaced evenly in log frequency over the band (fewer
where MIN_KNOT_BINS spaces them out)."""

SMOOTH_SD = 1.0
"""Random-walk sd of the knot values' second difference (natural log of intensity)."""

RIDGE_SD = 10.0
"""Prior sd of a knot value about its start (natural log; see _start): keeps a source that
no band can see (masked by another at every frequency) near a level the record allows
instead of drifting."""

P_ADOPT = 1e-3
"""The learned spectrum replaces the white model where the likelihood-ratio test rejects
the white model at this level."""

LOG_RANGE = 40.0
"""Bound of a knot value about its start (natural log): a source may vanish in a band."""

LEARN_ROUNDS = 0
"""Fits of the noise spectrum to the residual at the MAP under the last one, after the first
(fitted to the noise cleaned of the excitation-coherent part). Such rounds sharpen the
spectrum where the cleaning smears it (the lowest bins of a steep force band's edge: on a
20-300 Hz force two rounds took the stiffness sds from 3-4x to 1.1-1.4x the true
spectrum's), but a round can take the misfit of a wrong MAP for noise and keep it: on
foreign records with a process force at the discs one round put k_Bx 25 sd off in one
of three. None by default: calibration first."""

MIN_KNOT_BINS = 4
"""Fewest frequency bins between two knots."""

LPM_HALF = 8
"""Half-width in bins of the local polynomial method's window (cleaned_band_sums)."""

LPM_DEGREE = 2
"""Degree in frequency of the local polynomial of the excitation's FRF (cleaned_band_sums)."""

SOURCES = ("sensor noise", "r1", "r2")


@dataclass(frozen=True)
class LearnedSpectrum:
    """Per source and channel the intensity's gain over the level ``log10_sigma`` (3,), ln g
    (3, 4, K) at the knots ``knot_hz`` (the levels: each source's mean over channels and
    knots, within the noise priors' bounds, where the sampler starts); ``adopted`` whether
    the likelihood uses the gains (the white sources otherwise), with the likelihood-ratio
    statistic and degrees of freedom that decided.

    ``lines``: narrowband lines the spectrum has as noise (find_lines).
    ``colour`` (n, 4, 4) at ``colour_hz`` (n,): what the sources, gains included, still
    miss, as the residual's whitened periodogram averaged over segments of at least
    noise_check.MIN_BINS bins (noise_check.colour_correction); the likelihood's spectrum is
    then L C L^H, L L^H the sources' spectrum at ``colour_log10_sigma``. None where the
    residual is as white as the sources have it."""

    knot_hz: NDArray
    log_gain: NDArray
    log10_sigma: NDArray
    adopted: bool
    lr_statistic: float
    dof: int
    colour_hz: NDArray | None = None
    colour: NDArray | None = None
    colour_log10_sigma: NDArray | None = None
    notes: tuple[str, ...] = field(default=())
    lines: tuple[dict[str, Any], ...] = field(default=())

    def gain(self, f_hz: NDArray) -> NDArray:
        """g_s,c(f) (3, 4, nf) at the frequencies f_hz (held constant beyond the knots;
        ones where the gains are not adopted)."""
        f_hz = np.asarray(f_hz, dtype=float)
        if not self.adopted:
            return np.ones((3, 4, f_hz.size))
        x = np.log(np.clip(f_hz, self.knot_hz[0], self.knot_hz[-1]))
        xk = np.log(self.knot_hz)
        flat = self.log_gain.reshape(-1, xk.size)
        return np.exp(np.stack([np.interp(x, xk, row) for row in flat])).reshape(
            *self.log_gain.shape[:2], x.size)

    def colour_at(self, f_hz: NDArray) -> NDArray:
        """The colour C at the frequencies f_hz (nf, 4, 4): each entry interpolated
        linearly between the segments (a convex combination of positive definite
        matrices), the end segments' held beyond them."""
        return interp_matrices(f_hz, self.colour_hz, self.colour)

    @property
    def in_use(self) -> bool:
        """Whether the likelihood's spectrum differs from the white sources'."""
        return self.adopted or self.colour is not None

    def to_dict(self) -> dict[str, Any]:
        out = {"adopted": self.adopted, "log10_sigma": self.log10_sigma.tolist(),
               "lr_statistic": self.lr_statistic, "dof": self.dof,
               "knot_hz": self.knot_hz.tolist(),
               "gain_db": {s: {c: (10 / np.log(10) * self.log_gain[i, j]).round(2).tolist()
                               for j, c in enumerate(CHANNELS)}
                           for i, s in enumerate(SOURCES)},
               "colour": self.colour is not None, "notes": list(self.notes)}
        if self.lines:
            out["lines"] = [dict(line) for line in self.lines]
        if self.colour is not None:
            out["colour_hz"] = self.colour_hz.tolist()
            out["colour_power"] = np.real(np.trace(self.colour, axis1=1, axis2=2)
                                          / 4).round(4).tolist()
        return out


def interp_matrices(f: NDArray, f_at: NDArray, M: NDArray) -> NDArray:
    """Matrices M (n, ...) given at the frequencies f_at (n,), at the frequencies f: each
    entry interpolated linearly (for Hermitian positive definite M a convex combination,
    so positive definite), the end ones held beyond f_at; (f.size, ...)."""
    f = np.asarray(f, dtype=float)
    flat = M.reshape(M.shape[0], -1)
    out = np.empty((f.size, flat.shape[1]), dtype=complex)
    for j in range(flat.shape[1]):
        out[:, j] = (np.interp(f, f_at, flat[:, j].real)
                     + 1j * np.interp(f, f_at, flat[:, j].imag))
    return out.reshape(f.size, *M.shape[1:])


def colour_transform(Phi: NDArray, C: NDArray) -> NDArray:
    """T (n, 4, 4) with T Phi T^H = L C L^H, L the Cholesky factor of Phi: T = L C^1/2
    L^-1 (the congruence that folds a colour into each source's spectrum alike)."""
    L = np.linalg.cholesky(Phi)
    w, V = np.linalg.eigh(0.5 * (C + np.conj(np.swapaxes(C, -1, -2))))
    half = V @ (np.sqrt(np.maximum(w, 1e-12))[..., None] * np.conj(np.swapaxes(V, -1, -2)))
    return L @ half @ np.linalg.inv(L)


def fold_colour(phi_sources: NDArray, spectrum: LearnedSpectrum, band_hz: NDArray
                ) -> tuple[NDArray, NDArray]:
    """The band filter products of the sources (3, n_bands, 4, 4) with the spectrum's
    colour folded into each alike (colour_transform at the levels it was measured at), and
    each band's power gain tr(new) / tr(old), which the prewhitening design follows."""
    sig2 = 10.0 ** (2 * spectrum.colour_log10_sigma)
    Phi = np.tensordot(sig2, phi_sources, axes=(0, 0))
    T = colour_transform(Phi, spectrum.colour_at(band_hz))
    folded = T[None] @ phi_sources @ np.conj(np.swapaxes(T, -1, -2))[None]
    new = np.tensordot(sig2, folded, axes=(0, 0))
    return folded, (np.trace(new, axis1=1, axis2=2).real
                    / np.trace(Phi, axis1=1, axis2=2).real)


def hat_basis(x: NDArray, knots: NDArray) -> NDArray:
    """Piecewise-linear interpolation matrix (x.size, knots.size) of the knot values."""
    B = np.zeros((x.size, knots.size))
    j = np.clip(np.searchsorted(knots, x) - 1, 0, knots.size - 2)
    t = np.clip((x - knots[j]) / (knots[j + 1] - knots[j]), 0.0, 1.0)
    B[np.arange(x.size), j] = 1.0 - t
    B[np.arange(x.size), j + 1] = t
    return B


def channel_filters(like: Any, theta_ref: NDArray) -> NDArray:
    """Band means of the per-channel filter products |w|^2 h h^H of each source at
    theta_ref, (3, 4, n_bands, 4, 4) (h: the column of H_s for that channel's input;
    scaled like the likelihood's residual). Summed over channels: like.phi_sources of the
    white model."""
    A, B, C, D = like.forward.noise_system(np.asarray(theta_ref, dtype=float))
    H = ss_freqresp_modal(A, B, C, D, like.z) / like.scale            # (nf, 4, 12)
    out = np.empty((3, 4, like.n_bands, 4, 4), dtype=complex)
    for s in range(3):
        for c in range(4):
            h = H[:, :, 4 * s + c]
            P = h[:, :, None] * np.conj(h[:, None, :]) * like.w_gain2[:, None, None]
            out[s, c] = np.add.reduceat(P, like.starts, axis=0) / like.counts[:, None, None]
    return out


def knot_frequencies(f_band: NDArray, df: float) -> NDArray:
    """Knots from the lowest to the highest band frequency, about KNOTS of them evenly in
    log frequency, but at least MIN_KNOT_BINS bins of width df apart (below that no band
    lies between two knots at the lowest frequencies, and their values are the prior's)."""
    lo, hi = float(f_band[0]), float(f_band[-1])
    ratio = (hi / lo) ** (1.0 / (KNOTS - 1))
    knots = [lo]
    while knots[-1] < hi:
        knots.append(max(knots[-1] * ratio, knots[-1] + MIN_KNOT_BINS * df))
    knots[-1] = hi
    if len(knots) > 2 and knots[-1] - knots[-2] < MIN_KNOT_BINS * df:
        del knots[-2]
    return np.array(knots)


def cleaned_band_sums(like: Any, theta: NDArray, mask: NDArray | None = None) -> NDArray:
    """Band sums of the noise alone, whatever the model's misfit (n_bands, 4, 4): per bin
    the covariance of what a local polynomial fit of eps on the excitation leaves, over a
    window of 2 LPM_HALF + 1 bins (the local polynomial method of Pintelon & Schoukens:
    the excitation-coherent part of eps, S(theta) x at any theta and a smooth transient, is
    fitted away; what stays is the noise, with LPM_DEGREE + 1 excitation terms per excited
    channel taken from each window's degrees of freedom), summed over each band's bins.

    A noise spectrum learned from the residual at a wrong theta takes the misfit for
    noise and down-weights the very bins that would correct it: on a record with a
    20-300 Hz force at the bearings the misfit of k_Ay at the white model's MAP put 3.5
    decades of "noise" below 5 Hz on that channel, and its interval stayed 37x the width
    the true spectrum gives."""
    R, stable = like.residual_dft(np.atleast_2d(np.asarray(theta, dtype=float)))
    if not stable[0]:
        raise ValueError("the model is not stabilised at the fitted parameters")
    E, X = R[0], like.X
    power = np.sum(np.abs(X) ** 2, axis=0)
    X = X[:, power > 1e-12 * power.max()]
    nf = X.shape[0]
    nw = 2 * LPM_HALF + 1
    first = np.clip(np.arange(nf) - LPM_HALF, 0, max(nf - nw, 0))
    idx = first[:, None] + np.arange(min(nw, nf))[None, :]                 # (nf, nw)
    d = (idx - np.arange(nf)[:, None]) / LPM_HALF                          # (nf, nw)
    design = np.concatenate([X[idx] * d[..., None] ** r for r in range(LPM_DEGREE + 1)],
                            axis=2)                                         # (nf, nw, npar)
    Q, _ = np.linalg.qr(design)
    Y = E[idx]                                                              # (nf, nw, 4)
    res = Y - Q @ (np.conj(np.swapaxes(Q, 1, 2)) @ Y)
    dof = idx.shape[1] - design.shape[2]
    C = np.conj(np.swapaxes(res, 1, 2)) @ res / max(dof, 1)                 # (nf, 4, 4)
    if mask is not None:
        C[mask] = 0.0
    return np.add.reduceat(C, like.starts, axis=0)


def synchronous_bins(like: Any, speed_rpm: float | None, width: int = 2) -> NDArray | None:
    """The likelihood's bins within ``width`` bins of a multiple of the running speed, or
    None without a speed: lines there are physics (unbalance, runout), which a diagnosis
    must find in the residual, not learn as noise."""
    if not speed_rpm:
        return None
    f = like.k / (like.n * like.forward.dt)
    f_rot = speed_rpm / 60.0
    order = np.round(f / f_rot)
    return (order >= 1) & (np.abs(f - f_rot * order) <= width / (like.n * like.forward.dt))


def kept_counts(like: Any, mask: NDArray | None) -> NDArray:
    """Each band's bins without the masked ones."""
    if mask is None:
        return like.counts
    return like.counts - np.add.reduceat(mask.astype(int), like.starts)


def _second_difference(K: int) -> NDArray:
    D = np.zeros((K - 2, K))
    for i in range(K - 2):
        D[i, i:i + 3] = (1.0, -2.0, 1.0)
    return D


class _Objective:
    """-log L(spectrum) + penalty over the knot values a (12 K,), at fixed band sums."""

    def __init__(self, G: NDArray, Pb: NDArray, counts: NDArray, n: int, basis: NDArray,
                 compiled: bool = True):
        self.G = G.reshape(12, *G.shape[2:])                  # (12, nb, 4, 4)
        self.Pb, self.counts, self.n, self.B = Pb, counts, n, basis
        self.compiled = compiled
        self.centre: NDArray | None = None                     # (12, K): the ridge's centre
        K = basis.shape[1]
        D2 = _second_difference(K)
        self.Q = D2.T @ D2 / SMOOTH_SD**2 + np.eye(K) / RIDGE_SD**2

    def likelihood_terms(self, a: NDArray) -> tuple[float, NDArray]:
        """-log L (constants dropped) and its gradient in the per-band ln intensities:
        hermitian_kernels.spectrum_terms, or its numpy form (terms_numpy) with
        BAYES_AMB_KERNEL=numpy."""
        W = np.exp(a.reshape(12, -1) @ self.B.T) * self.n       # (12, nb)
        if self.compiled:
            return spectrum_terms(W, self.G, self.Pb, self.counts)
        return self.terms_numpy(W)

    def terms_numpy(self, W: NDArray) -> tuple[float, NDArray]:
        """likelihood_terms at the intensities W (12, nb), in numpy."""
        Phi = np.einsum("qb,qbij->bij", W, self.G)
        sign, logdet = np.linalg.slogdet(Phi)
        if np.any(sign.real <= 0):
            return np.inf, np.zeros_like(W)
        Pi = np.linalg.inv(Phi)
        PiP = Pi @ self.Pb
        val = float(np.sum(self.counts * logdet) + np.sum(np.trace(PiP, axis1=1, axis2=2).real))
        M = self.counts[:, None, None] * Pi - PiP @ Pi
        grad = W * np.einsum("bij,qbji->qb", M, self.G).real
        return val, grad

    def __call__(self, a: NDArray) -> tuple[float, NDArray]:
        val, g_band = self.likelihood_terms(a)
        if not np.isfinite(val):
            return 1e300, np.zeros_like(a)
        A = a.reshape(12, -1) - self.centre
        pen = 0.5 * float(np.einsum("qi,ij,qj->", A, self.Q, A))
        grad = g_band @ self.B + A @ self.Q
        return val + pen, grad.ravel()


def learn_spectrum(like: Any, theta_ref: NDArray, log10_sigma: NDArray,
                   cleaned: bool = True, mask: NDArray | None = None) -> LearnedSpectrum:
    """The smooth per-source, per-channel noise spectrum of the record at the loop's noise
    filters at theta_ref, fitted to the residual's band sums there, or (``cleaned``) to
    the noise alone (cleaned_band_sums: what a misfit of theta would put in the residual
    fitted away); and whether it beats the white sources by more than chance: the
    likelihood-ratio test on the residual's band sums (fitted there too; the cleaned sums
    are no Wishart sums, so no test of them is calibrated: on a white record their ratio
    was 1766 on 285 degrees of freedom). ``mask``: bins left out (synchronous_bins)."""
    theta_ref = np.asarray(theta_ref, dtype=float)
    G = channel_filters(like, theta_ref)
    R, stable = like.residual_dft(np.atleast_2d(theta_ref))
    if not stable[0]:
        raise ValueError("the model is not stabilised at the fitted parameters")
    counts = kept_counts(like, mask)
    if mask is not None:
        R = np.where(mask[None, :, None], 0.0, R)
    Pb = like._band_sums(R)
    f_band = like.band_freq_hz
    knot_hz = knot_frequencies(f_band, 1.0 / (like.n * like.forward.dt))
    K = knot_hz.size
    B = hat_basis(np.log(f_band), np.log(knot_hz))
    compiled = bool(getattr(getattr(like, "engine", None), "compiled", True))
    obj = _Objective(G, np.asarray(Pb[0]), counts, like.n, B, compiled)
    white, _ = _white_fit(obj, np.asarray(log10_sigma, dtype=float))
    a, learned = _smooth_fit(obj)
    lr = float(max(2.0 * (white - learned), 0.0))  # 2 x the log-likelihood gain
    dof = 12 * K - 3
    adopted = bool(np.isfinite(learned) and stats.chi2.sf(lr, dof) < P_ADOPT)
    if cleaned and adopted:
        a, _ = _smooth_fit(_Objective(G, cleaned_band_sums(like, theta_ref, mask), counts,
                                      like.n, B, compiled))
    a = a.reshape(3, 4 * K)
    lo, hi = np.array(list(NOISE_LOG10_BOUNDS.values())).T + np.array([[0.5], [-0.5]])
    level = np.clip(a.mean(axis=1) / (2 * np.log(10.0)), lo, hi)     # log10 sigma_s
    log_gain = (a - 2 * np.log(10.0) * level[:, None]).reshape(3, 4, K)
    return LearnedSpectrum(knot_hz=knot_hz, log_gain=log_gain, log10_sigma=level,
                           adopted=adopted, lr_statistic=lr, dof=dof)


def _smooth_fit(obj: _Objective) -> tuple[NDArray, float]:
    """The penalised fit of the knot values (12 K,) and its -log L (penalty left out)."""
    a0 = _start(obj)
    obj.centre = a0.reshape(12, -1)
    bounds = [(v - LOG_RANGE, v + LOG_RANGE) for v in a0]
    res = optimize.minimize(obj, a0, jac=True, method="L-BFGS-B", bounds=bounds,
                            options={"maxiter": 500})
    return res.x, obj.likelihood_terms(res.x)[0]


def _white_fit(obj: _Objective, log10_sigma: NDArray) -> tuple[float, NDArray]:
    """-log L of the best white sources (one intensity per source on every channel and
    frequency) on the same band sums, from log10_sigma; and their ln intensities (12,)."""
    K = obj.B.shape[1]

    def f(lev: NDArray) -> tuple[float, NDArray]:
        a = np.repeat(lev, 4 * K)
        val, g_band = obj.likelihood_terms(a)
        if not np.isfinite(val):
            return 1e300, np.zeros(3)
        return val, (g_band @ obj.B).reshape(3, -1).sum(axis=1)

    lev0 = 2 * np.log(10.0) * log10_sigma
    best = min((optimize.minimize(f, x0, jac=True, method="L-BFGS-B",
                                  bounds=[(v - LOG_RANGE, v + LOG_RANGE) for v in x0])
                for x0 in (lev0, _start(obj).reshape(3, -1).mean(axis=1))),
               key=lambda r: r.fun)
    return float(best.fun), np.repeat(best.x, 4)


def _start(obj: _Objective) -> NDArray:
    """Knot values to start from: each source alone explaining a third of each band's
    power (least squares onto the knots), so a source the white fit pushed to nothing
    (masked by a louder one at every frequency) starts where the record can move it.
    Bands whose every bin is masked (a lone bin at the running speed) have no power to
    read and are left out of the fit."""
    nb = obj.B.shape[0]
    seen = obj.counts > 0
    power = np.trace(obj.Pb, axis1=1, axis2=2).real / np.maximum(obj.counts, 1)   # (nb,)
    start = np.empty((12, obj.B.shape[1]))
    G = obj.G.reshape(3, 4, nb, 4, 4)
    for s in range(3):
        tr = np.trace(G[s].sum(axis=0), axis1=1, axis2=2).real * obj.n    # (nb,)
        lev = np.log(np.maximum(power / 3.0, 1e-300) / np.maximum(tr, 1e-300))
        knots = np.linalg.lstsq(obj.B[seen], lev[seen], rcond=None)[0]
        start[4 * s:4 * s + 4] = knots[None, :]
    return start.ravel()
