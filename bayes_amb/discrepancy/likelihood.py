"""The likelihood the diagnosis compares models with: Whittle over the whole band, with the
noise spectrum of each band integrated out under a complex inverse-Wishart prior.

Why not the identification likelihood as it is. Model comparison must stay valid when the
residual is autocorrelated, and must not mistake a wrong noise *spectrum* for missing
physics (a band-limited r2, a sensor with coloured noise). In the frequency domain the DFT
bins of a stationary residual are asymptotically independent (Whittle), which is what makes
a likelihood of autocorrelated residuals tractable; the loop noise model of eq. 14 fixes the
spectrum's shape. Here each band's 4x4 spectral matrix Sigma_b is given a conjugate complex
inverse-Wishart prior centred on the loop noise model,

    Sigma_b ~ CW^-1(Psi_b, nu_b),   Psi_b = (nu_b - a_b) N Phi_b(sigma),   p = 4,

and integrated out in closed form. With P_b = sum_{k in b} R_k R_k^H over its n_b bins:

    log p(R_b) = log G_p(nu_b + n_b) - log G_p(nu_b) + nu_b log|Psi_b|
                 - (nu_b + n_b) log|Psi_b + P_b| - p n_b log(pi),

G_p the complex multivariate gamma function. The shift a_b = 2 + 1.35 / sqrt(n_b) (see
:func:`scale_shift`) makes the expected score of the noise scale vanish when Phi_b is the
true spectrum, so the noise intensities are estimated without bias even from bands of a
single bin (a_b = p centres the prior mean instead, and overestimates them by up to 3x in
such bands; a_b = 0 underestimates them). As nu_b -> infinity this is the plug-in Whittle
likelihood; with nu_b = n_b + p + 1 (the default: the prior weighs as much as the band's own
bins) a band whose noise differs from the model by a constant factor costs little, while a
residual correlated with the excitation or a line still costs its full price. Evidence
(Laplace) and PSIS-LOO over bands computed with it are therefore valid under autocorrelated
residuals and robust to the noise model's shape.

Deterministic lines (unbalance) enter the mean through precomputed basis responses.

Pre-history. With ``start`` > 0 only the window [start, N) of the record is compared: the
first samples drive the model (its state at ``start`` is exact, since the excitation is
known from sample 0) but their residual is not used. For a stable system with state s at
the window's first sample and s_N after its last, the window's DFT on the grid z_k is

    DFT(y)_k = C (z_k I - A)^-1 [B X_k + z_k (s - s_N)],

so the pre-history costs one more modal state per evaluation. This keeps the start-up
transient of a record that begins mid-operation (and of removed offsets) out of the
likelihood (checks.py).
"""

from __future__ import annotations

import copy

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter
from scipy.special import gammaln

from bayes_amb.discrepancy.model import ExtendedForwardModel
from bayes_amb.inference import residual_rows
from bayes_amb.inference.forward import ModalBatch, dft_response, state_after
from bayes_amb.inference.narrow_lines import SPEED_TOLERANCE
from bayes_amb.inference.whittle import WhittleLikelihood

P_CH = 4


def log_complex_gamma(a: NDArray, p: int = P_CH) -> NDArray:
    """log of the complex multivariate gamma function G_p(a) = pi^(p(p-1)/2) prod Gamma(a-i)."""
    a = np.asarray(a, dtype=float)
    return 0.5 * p * (p - 1) * np.log(np.pi) + sum(gammaln(a - i) for i in range(p))


def scale_shift(n_bins: NDArray) -> NDArray:
    """a(n) with E[d log p(R_b) / d log c] = 0 at Psi_b = (nu_b - a) N Phi_b, Phi_b true,
    nu_b = n_b + 5, p = 4: a(1) = 3.35, a(8) = 2.47, a(32) = 2.24 (Monte Carlo with
    complex Wishart P_b, 20000 draws; fitted as 2 + 1.35 / sqrt(n); tested)."""
    return 2.0 + 1.35 / np.sqrt(np.asarray(n_bins, dtype=float))


LINE_BAND_BINS = 16
"""The fewest bins of the band that holds the running speed's 1x line in the diagnosis'
likelihood. Each band's noise spectrum is integrated out, so a line alone in a band of one
or two bins (the low bands of a short record) is taken for that band's noise: on ROSS's
test rig (1 s at 10 kHz, 3000 rpm, its 1x at 50 Hz in a band of 2 bins) an unbalance whose
line stood 3-10 times the noise rms gained 6 nats, and was not named in 3 of 6 foreign
records; with the line's band 18 bins wide it was named in those 3 (2 confident)."""


def alias_hz(f: float, fs: float) -> float:
    """Frequency at which a tone at f appears after sampling at fs."""
    r = f % fs
    return min(r, fs - r)


def line_band_starts(starts: NDArray, k: NDArray, n: int, dt: float, f_rot_hz: float
                     ) -> NDArray:
    """Band starts (indices into the bins k of an n-sample DFT at dt) with the band of the
    1x bin (its alias below Nyquist) widened where it holds fewer than LINE_BAND_BINS
    bins: every band that meets [1x - h, 1x + h] becomes one, h = max(LINE_BAND_BINS / 2,
    the speed tolerance plus two bins) bins. A band already as wide is left as it is, so
    records whose 1x band is wide (the reference rig's 525 Hz in a 2 s record: about 50
    bins) keep their bands.

    >>> k = np.arange(1, 101)                   # 100 bins of 1 Hz (n = 1000, dt = 1 ms)
    >>> line_band_starts(np.arange(100), k, 1000, 1e-3, 40.0)[30:34].tolist()
    [30, 31, 48, 49]
    >>> line_band_starts(np.array([0, 10, 60]), k, 1000, 1e-3, 40.0).tolist()
    [0, 10, 60]
    """
    df = 1.0 / (n * dt)
    f1 = alias_hz(f_rot_hz, 1.0 / dt)            # where a 1x line shows after sampling
    c = int(np.argmin(np.abs(k * df - f1)))
    if abs(k[c] * df - f1) > 1.5 * df:           # 1x outside the likelihood's bins
        return starts
    band = int(np.searchsorted(starts, c, side="right") - 1)
    ends = np.append(starts[1:], k.size)
    if ends[band] - starts[band] >= LINE_BAND_BINS:
        return starts
    h = max(LINE_BAND_BINS // 2, int(np.ceil(SPEED_TOLERANCE * f1 / df)) + 2)
    lo, hi = max(c - h, 0), min(c + h + 1, k.size)
    first = int(np.searchsorted(starts, lo, side="right") - 1)
    last = int(np.searchsorted(starts, hi - 1, side="right") - 1)
    return np.concatenate([starts[:first + 1], starts[last + 1:]])


class RobustWhittle(WhittleLikelihood):
    """Whole-band Whittle likelihood of an extended model with the band noise spectra
    integrated out (see module docstring). Called like WhittleLikelihood: parameters
    (nb, p + q) and log10 sigma (nb, 3).

    Its engine is its model's (``forward.engine``, kernels.Engine): the compiled modal
    form, residual DFT and band sums as for identify. It does not take the fused path
    (inference/fused.py), which is written for the observer-form error system of the
    nominal loop with white-noise band algebra: an extended model's candidates change the
    loop (delays, lags, bending pairs: ``fast`` is False), the window starts after a
    pre-history whose state is subtracted, spectral lines enter the residual, and the band
    algebra here is the noise-marginalised one (nu, shift), not the plug-in Phi."""

    def __init__(self, forward: ExtendedForwardModel, eps: NDArray, n_bands: int = 192,
                 prior_weight: float = 1.0, noise_filters: NDArray | None = None,
                 start: int = 0):
        self.prior_weight = prior_weight
        self.start = int(start)
        self._eps_full = np.asarray(eps, dtype=float)
        eps = self._eps_full[self.start:]
        self.lines: list[NDArray] = []
        self.fixed_filters = noise_filters
        super().__init__(forward, eps, n_bands=n_bands, f_max_hz=None, noise_model="loop")

    def _set_bins(self, k: NDArray) -> None:
        """The bins and bands (WhittleLikelihood), and each band's prior weight nu, scale
        shift and Gamma term, which follow its bin count (also after leave_out_lines)."""
        super()._set_bins(k)
        self.nu = self.prior_weight * self.counts + P_CH + 1.0
        self.shift = scale_shift(self.counts)
        self._gamma_term = (log_complex_gamma(self.nu + self.counts)
                            - log_complex_gamma(self.nu))

    def _band_starts(self, k: NDArray, n: int, n_bands: int) -> NDArray:
        """The bands, with the one holding the running speed's 1x bin widened to at least
        LINE_BAND_BINS bins, and to the speed's tolerance either side, where it is
        narrower (line_band_starts)."""
        starts = super()._band_starts(k, n, n_bands)
        speed = getattr(getattr(self.forward, "recording", None), "speed_rpm", None)
        if not speed:
            return starts
        return line_band_starts(starts, k, n, self.forward.dt, speed / 60.0)

    def _apply_prefilter(self) -> None:
        """Filter eps and x over the whole record (from rest), DFT the window [start, N)."""
        w = self.prefilter
        x_w = lfilter(w, [1.0], self.forward.x, axis=0)
        eps_w = lfilter(w, [1.0], self._eps_full, axis=0)[self.start:]
        self.x_w = x_w                                  # the whole record drives the model
        self.x_pre = x_w[:self.start]
        self.x_window = np.asarray(self.forward.x, dtype=float)[self.start:]
        self.E = np.fft.rfft(eps_w / self.scale, axis=0)[self.k]
        self.X = np.fft.rfft(x_w[self.start:], axis=0)[self.k]
        self.w_gain2 = np.abs(np.polyval(w[::-1], 1.0 / self.z)) ** 2

    def modal_state(self, theta: NDArray) -> tuple[ModalBatch, NDArray]:
        """As in WhittleLikelihood, with the state at the window start (driven by the
        pre-history from rest) subtracted: xi = s_N - s_start (module docstring)."""
        mb, xi = self.forward.modal(theta, self.x_w)
        if self.start:
            lam_s = np.where(mb.stable[:, None], mb.lam, 0.0)
            xi = xi - state_after(lam_s, mb.Bm, self.x_pre, self.engine)
        return mb, xi

    def prediction_dft(self, P: NDArray) -> tuple[NDArray, NDArray]:
        """DFT of S(theta) x over the window (scaled), and the stability mask, for a batch
        of parameter rows P (nb, p + q); lines not included."""
        mb, xi = self.modal_state(P)
        if self.engine.compiled:
            zero = np.zeros_like(self.E)
            return -residual_rows.residual_dft_rows(
                mb.lam, mb.Bm, mb.Cm, xi, self.X, self.z, zero, self.scale,
                lanes=self.engine.compiled_modal), mb.stable
        return dft_response(mb, self.X, self.z, xi) / self.scale, mb.stable

    def for_model(self, forward: ExtendedForwardModel, theta_ref: NDArray,
                  eps: NDArray | None = None) -> RobustWhittle:
        """The same data, bands and prewhitening for another model of the same recording,
        with this likelihood's noise filters held fixed (see set_noise_reference); eps:
        other data (the record's eps with a modelled defect taken out) under the same
        bands, prewhitening and scale, so that the log likelihoods compare."""
        new = copy.copy(self)
        new.forward = forward
        if eps is not None:
            new._eps_full = np.asarray(eps, dtype=float)
            new.eps = new._eps_full[new.start:]
            new._apply_prefilter()
        new.fixed_filters = self.phi_sources
        new.set_noise_reference(theta_ref)
        return new

    def set_noise_reference(self, theta_ref: NDArray) -> None:
        """Noise filters and the line bases at theta_ref (plug-in, refreshed by the fit).

        With ``noise_filters`` given at construction (the band-averaged filter products of
        another model, ``phi_sources``), only the line bases follow theta_ref: models
        compared with each other then share one noise-spectrum family, and their Bayes
        factors weigh the physics of the excitation path only.
        """
        if self.fixed_filters is None:
            super().set_noise_reference(theta_ref)
        else:
            self.phi_sources = self.fixed_filters
            self.theta_ref = np.array(theta_ref, dtype=float)
        fwd: ExtendedForwardModel = self.forward  # type: ignore[assignment]
        self.lines = []
        for resp in fwd.line_responses(np.atleast_2d(theta_ref)):
            filt = lfilter(self.prefilter, [1.0], resp, axis=0)
            self.lines.append(np.fft.rfft(filt[self.start:] / self.scale,
                                          axis=0)[self.k])                   # (nf, 4, 2)
        self._last_sums = None                      # the band sums depend on the lines

    def _line_terms(self, theta: NDArray, modal: tuple[ModalBatch, NDArray] | None = None
                    ) -> tuple[NDArray | None, NDArray | None]:
        """The spectral-line bases (nf, 4, 2 per line candidate) and their coefficients
        (theta's line parameters; ``modal`` is not needed)."""
        fwd: ExtendedForwardModel = self.forward  # type: ignore[assignment]
        if not self.lines:
            return None, None
        P = np.atleast_2d(theta)
        coef = np.hstack([P[:, fwd.slices[fwd.candidates.index(c)]]
                          for c in fwd.line_candidates])
        return np.concatenate(self.lines, axis=2), coef

    def curvature_weights(self, theta: NDArray, log10_sigma: NDArray) -> NDArray:
        """W_b = (nu_b + n_b) (Psi_b + P_b)^-1 at (theta, log10 sigma): the weight of a
        residual bin in the Gauss-Newton curvature of the band's log p(R_b) (the noise
        spectrum integrated out); (n_bands, 4, 4)."""
        Pb, _ = self.band_sums(np.atleast_2d(theta))
        Psi = self.noise_spectrum(log10_sigma) * (self.nu - self.shift)[:, None, None]
        return (self.nu + self.counts)[:, None, None] * np.linalg.inv(Psi + Pb[0])

    def pointwise(self, theta: NDArray, log10_sigma: NDArray) -> NDArray:
        theta = np.atleast_2d(theta)
        ls = np.atleast_2d(log10_sigma)
        Pb, stable = self.band_sums(theta)
        sig2 = 10.0 ** (2 * ls)
        ps = self.phi_sources
        Phi = (sig2 @ ps.reshape(3, -1)).reshape(sig2.shape[0], *ps.shape[1:]) * self.n
        Psi = Phi * (self.nu - self.shift)[None, :, None, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            s0, ld0 = np.linalg.slogdet(Psi)
            s1, ld1 = np.linalg.slogdet(Psi + Pb)
        ll = (self._gamma_term + self.nu * ld0 - (self.nu + self.counts) * ld1
              - P_CH * self.counts * np.log(np.pi))
        ok = np.all(s0.real > 0, axis=1) & np.all(s1.real > 0, axis=1)
        bad = ~stable | ~ok | ~np.all(np.isfinite(ll), axis=1)
        ll[bad] = -np.inf
        return ll
