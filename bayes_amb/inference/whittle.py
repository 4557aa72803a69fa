"""Banded frequency-domain (Whittle) likelihood of the residual eps - S(theta) x.

The residual is coloured (eq. 14): sensor noise n, r1 and r2 reach eps through the loop's
noise filters H_n, H_1, H_2 (computed exactly from the loop model, see loop_model.py). With
white sources of RMS sigma = (sigma_n, sigma_1, sigma_2) the residual spectral density is

    Phi(w) = sigma_n^2 H_n H_n^H + sigma_1^2 H_1 H_1^H + sigma_2^2 H_2 H_2^H   (4 x 4)

and the DFT R_k of the residual is asymptotically complex Gaussian with covariance N Phi(w_k),
independent across k = 1 .. N/2 - 1 (Whittle). DC and Nyquist are left out (sensor offsets).
The filters are evaluated at a reference theta (the MAP, "plug-in", refreshed by the caller);
their dependence on theta is second order (through S, small against Mt). Bins are grouped
into bands over which Phi is nearly constant, which makes each evaluation cheap:

    log L = - sum_b [ n_b log det(pi N Phi_b) + tr((N Phi_b)^-1 P_b) ],
    P_b = sum_{k in b} R_k R_k^H.

The per-band terms are the pointwise log-likelihood used for PSIS-LOO.

Prewhitening: the residual spectrum of an AMB loop spans six decades (the innovation
filter Mt is high-pass), and the rectangular-window leakage of a raw DFT would then swamp
the low-frequency bins, biasing the Whittle likelihood. eps and x are therefore both filtered
with the same scalar minimum-phase FIR w(z), |w|^2 ~ 1 / (Welch spectrum of eps averaged
over channels), designed from the data; :func:`identify` then replaces it by the FIR from the
noise model's residual spectrum at the MAP and refits (set_model_prewhitening says why), and
keeps it fixed for the Laplace approximation and the sampler. A scalar filter commutes with
S(theta), so w*eps - S(theta)(w*x) = w*(noise) exactly (everything from rest), and its
spectrum |w|^2 Phi is nearly flat: leakage becomes negligible. The filtering is a fixed
invertible transform of the data (lower-triangular Toeplitz, diagonal w_0), so log p(eps) =
log p(w*eps) + 4 N log|w_0|, which is added: likelihoods stay comparable across models.

Band limit: only bins up to f_max_hz enter. By default that is the validity band of the
nominal model, half the frequency of the lowest mode the reduction left out (514 Hz for the
8-state model of the reference rig at 31500 rpm: the band in which the reduced model's
singular values are within 1 dB of the full model's), or Nyquist if lower. Whittle terms of
different frequencies are independent, so this is the exact (asymptotic) likelihood of the
band-limited data. Above it the reduced model is not meant to be right (residual flexible
modes would bias theta), and those bins would cost most of each evaluation. The residual
diagnostics of the discrepancy analysis look at the whole band.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

from bayes_amb.control.discrete import ss_freqresp_modal
from bayes_amb.errors import BayesAmbError
from bayes_amb.inference import band_algebra, kernels, residual_rows, walker_kernels
from bayes_amb.inference.band_algebra import logdet_and_trace_numpy
from bayes_amb.inference.forward import _TRANSIENT_TOL, ForwardModel, ModalBatch, dft_response
from bayes_amb.inference.fused import FusedLikelihood
from bayes_amb.inference.narrow_lines import NarrowLines, find_narrow_lines
from bayes_amb.inference.prewhitening import data_prewhitening, minimum_phase_inverse
from bayes_amb.inference.row_memory import RowMemory
from bayes_amb.inference.spectrum import LearnedSpectrum, fold_colour

NOISE_SOURCES = ("sigma_noise", "sigma_r1", "sigma_r2")
NOISE_UNITS = ("m", "m", "A")

LONG_TAPS = 2048
"""Prewhitening FIR length under a learned noise spectrum (set_model_prewhitening)."""


def band_edges(n_bins: int, n_bands: int = 256) -> NDArray:
    """Start indices of bands over n_bins bins: one bin each at low frequency, growing
    geometrically above, at most n_bands bands."""
    edges = np.unique(np.round(np.geomspace(1, n_bins + 1, n_bands + 1)).astype(int)) - 1
    edges = edges[edges < n_bins]
    return edges


class WhittleLikelihood(RowMemory):
    """log p(eps | theta, sigma) for a recording, vectorised over a batch of parameters.

    Parameters are passed as theta (nb, p) and log10 sigma (nb, 3).
    """

    def __init__(self, forward: ForwardModel, eps: NDArray, n_bands: int = 256,
                 f_max_hz: float | str | None = "auto", noise_model: str = "loop"):
        if noise_model not in ("loop", "iid"):
            raise BayesAmbError(f"unknown noise model {noise_model!r}; known: loop, iid")
        self.noise_model = noise_model
        self.forward = forward
        n = eps.shape[0]
        self.n = n
        k = np.arange(1, (n - 1) // 2 + 1)            # excludes DC and (for even n) Nyquist
        if f_max_hz == "auto":
            f_max_hz = forward.validity_band_hz()
        if f_max_hz is not None:
            k = k[k / (n * forward.dt) <= f_max_hz]
        self.f_max_hz = float(k[-1] / (n * forward.dt))
        self.eps = np.asarray(eps, dtype=float)
        self.scale = float(np.sqrt(np.mean(eps**2))) or 1.0
        self._n_bands = n_bands
        self._set_bins(k)
        self.lines_left_out: NarrowLines | None = None   # leave_out_lines: the lines found
        self.prefilter = np.ones(1)
        self.spectrum: LearnedSpectrum | None = None   # set_spectrum: a learned noise colour
        self._colour_ratio: NDArray | None = None      # its folded colour's power per band
        self.initial_state = False      # set_initial_state: fit the record's start transient
        self._transient_pinv: NDArray | None = None
        if noise_model == "loop":
            self.prefilter = data_prewhitening(self.eps, forward.dt)
        self._apply_prefilter()
        self.set_noise_reference(np.zeros(len(forward.params)))

    def _set_bins(self, k: NDArray) -> None:
        """The likelihood's bins k (DFT indices) and their bands."""
        self.k = k
        self.z = np.exp(2j * np.pi * k / self.n)
        self.starts = self._band_starts(k, self.n, self._n_bands)
        self.counts = np.diff(np.append(self.starts, k.size))
        self.band_freq_hz = (k[self.starts] + 0.5 * (self.counts - 1)) / (self.n
                                                                         * self.forward.dt)

    def leave_out_lines(self, theta0: NDArray) -> NarrowLines:
        """Find the record's narrowband lines on the residual at theta0 (the nominal
        model) and leave their bins out of the likelihood (narrow_lines.py); call before
        any fit. The lines found (none with the naive 'iid' model, or where the controller
        does not stabilise theta0)."""
        none = NarrowLines(np.zeros(self.k.size, dtype=bool))
        if self.noise_model != "loop":
            return none
        R, stable = self.residual_dft(np.atleast_2d(np.asarray(theta0, dtype=float)))
        if not stable[0]:
            return none
        speed = getattr(getattr(self.forward, "recording", None), "speed_rpm", None)
        found = find_narrow_lines(R[0], self.X, self.k / (self.n * self.forward.dt), speed)
        self.lines_left_out = found
        if found.drop.any():
            self._rebin(self.k[~found.drop])
        return found

    def limit_band(self, f_max_hz: float) -> None:
        """Keep only the bins up to f_max_hz (a likelihood built over the whole band, read
        over a model's validity band as identify's is; studies/static_residual.py)."""
        self._rebin(self.k[self.k / (self.n * self.forward.dt) <= f_max_hz])

    def _rebin(self, k: NDArray) -> None:
        """The likelihood over the bins k from here on: bands, filtered DFTs, the fused
        path's and the remembered rows' state, and the noise filters at the reference."""
        self._set_bins(k)
        self._apply_prefilter()
        self._fused = None
        if getattr(self, "_row_sums", None) is not None:
            self.remember_rows(self._row_capacity)
        self.set_noise_reference(self.theta_ref)

    def _band_starts(self, k: NDArray, n: int, n_bands: int) -> NDArray:
        """Index of each band's first bin (band_edges; the diagnosis' likelihood widens
        the band of the running speed's line, discrepancy.likelihood.RobustWhittle)."""
        return band_edges(k.size, n_bands)

    def _apply_prefilter(self) -> None:
        """Filter eps and x with the scalar FIR self.prefilter (from rest); DFT both."""
        w = self.prefilter
        self.x_w = lfilter(w, [1.0], self.forward.x, axis=0)
        eps_w = lfilter(w, [1.0], self.eps, axis=0)
        self.E = np.fft.rfft(eps_w / self.scale, axis=0)[self.k]
        self.X = np.fft.rfft(self.x_w, axis=0)[self.k]
        self.w_gain2 = np.abs(np.polyval(w[::-1], 1.0 / self.z)) ** 2     # |w(z_k)|^2

    @property
    def jacobian(self) -> float:
        """log |d(w*eps)/d eps| = 4 N log|w_0| (added to the log-likelihood)."""
        return 4 * self.n * float(np.log(abs(self.prefilter[0])))

    @property
    def n_bands(self) -> int:
        return self.starts.size

    def model_power(self, theta_ref: NDArray, log10_sigma: NDArray, n_grid: int = 2049
                    ) -> NDArray:
        """Residual power density of the noise model at (theta_ref, sigma), mean over the
        channels: trace(Phi(w)) / 4 on a uniform grid of n_grid points over [0, pi]."""
        A, B, C, D = self.forward.noise_system(np.asarray(theta_ref, dtype=float))
        H = ss_freqresp_modal(A, B, C, D, np.exp(1j * np.pi * np.linspace(0.0, 1.0, n_grid)))
        sig2 = 10.0 ** (2 * np.asarray(log10_sigma, dtype=float))
        gain = np.abs(H) ** 2                                        # (n_grid, 4, 12)
        f = np.linspace(0.0, 0.5 / self.forward.dt, n_grid)
        if self.spectrum is not None:
            gain = gain * self.spectrum.gain(f).reshape(12, -1).T[:, None, :]
        power = sum(sig2[s] * gain[:, :, 4 * s:4 * (s + 1)].sum(axis=(1, 2))
                    for s in range(3)) / 4
        if self._colour_ratio is not None:   # the folded colour's power, between the bands
            power = power * np.interp(f, self.band_freq_hz, self._colour_ratio)
        return power

    def set_model_prewhitening(self, theta_ref: NDArray, log10_sigma: NDArray,
                               n_taps: int = 128) -> None:
        """Replace the data-designed prewhitening FIR by one designed from the noise model:
        |w|^2 ~ 1 / (mean over channels of Phi(w) at theta_ref, sigma), the spectrum of the
        residual the likelihood models; then refresh the noise filters at theta_ref.

        Why: the data-designed w whitens eps, whose low-frequency part is S(theta) x, not
        noise. The residual spectrum rises by ~3 decades over 0-500 Hz (Mt is high-pass),
        so after that w its lowest bins are left ~20 dB under the rest, and the
        rectangular-window leakage of a short record fills them: at the true theta the
        residual power of the 0-35 Hz bins was 1.39 times N Phi (30 seeded 0.5 s records at
        1 kHz, 3e-7 m sensor noise), 1.00 with this w. The excess made sigma_r2 take spurious
        values and c_By's 90 % intervals cover its truth in 25 of 30 records (z-scores with
        sd 1.22). With noise_model "iid" nothing changes (no prewhitening).

        With a learned spectrum (set_spectrum) the FIR is LONG_TAPS long (at most an
        eighth of the record), designed on a grid as fine: a force band's edge climbs
        five decades within a few hertz, which 128 taps (78 Hz resolution at 10 kHz) cannot
        follow, and the leakage of the band then fills the bins below it (a flat floor
        three decades above the true noise at 0.5-9 Hz on a 20-300 Hz force record).
        """
        if self.noise_model != "loop":
            return
        n_grid = 2049
        if self.spectrum is not None:
            n_taps = max(n_taps, min(LONG_TAPS, self.n // 8))
            n_grid = max(n_grid, 4 * n_taps + 1)
        self.prefilter = minimum_phase_inverse(self.model_power(theta_ref, log10_sigma,
                                                                n_grid), n_taps)
        self._apply_prefilter()
        self.set_noise_reference(theta_ref)

    def set_noise_reference(self, theta_ref: NDArray) -> None:
        """Evaluate the noise filters at theta_ref (plug-in) and band-average Phi per source.

        With noise_model "iid" (the naive model, for comparison only) Phi = sigma_noise^2 I.
        """
        if self.noise_model == "iid":
            eye = np.broadcast_to(np.eye(4) / self.scale**2, (self.n_bands, 4, 4))
            self.phi_sources = np.stack([eye, 0 * eye, 0 * eye]).astype(complex)
            self.theta_ref = np.array(theta_ref, dtype=float)
            self._last_sums = None
            return
        A, B, C, D = self.forward.noise_system(np.asarray(theta_ref, dtype=float))
        H = ss_freqresp_modal(A, B, C, D, self.z) / self.scale            # (nf, 4, 12)
        if self.spectrum is not None:           # each input's intensity gain at each bin
            f = self.k / (self.n * self.forward.dt)
            H = H * np.sqrt(self.spectrum.gain(f).reshape(12, -1).T)[:, None, :]
        phi = []
        for s in range(3):
            Hs = H[:, :, 4 * s:4 * (s + 1)]
            P = Hs @ np.conj(np.swapaxes(Hs, 1, 2)) * self.w_gain2[:, None, None]
            phi.append(np.add.reduceat(P, self.starts, axis=0) / self.counts[:, None, None])
        self.phi_sources = np.stack(phi)                            # (3, nbands, 4, 4)
        self._colour_ratio = None
        if self.spectrum is not None and self.spectrum.colour is not None:
            self.phi_sources, self._colour_ratio = fold_colour(
                self.phi_sources, self.spectrum, self.band_freq_hz)
        self.theta_ref = np.array(theta_ref, dtype=float)
        self._last_sums = None
        if getattr(self, "_row_sums", None) is not None:
            self._row_sums.clear()
        if self.initial_state:
            self._transient_basis()

    def set_spectrum(self, spectrum: LearnedSpectrum | None) -> None:
        """Use a learned noise colour (spectrum.py: each source's intensity a smooth
        function of frequency per channel; None: the white sources) and refresh the noise
        filters at the current reference."""
        self.spectrum = spectrum
        self.set_noise_reference(self.theta_ref)

    def set_initial_state(self, on: bool = True) -> None:
        """Fit the transient of the record's start (on: the default off keeps the
        likelihood as it was). A real record starts mid-operation: the loop's states are
        not at rest at its first sample, and eps carries their free response, which S(theta)
        x from rest does not. Its DFT is T_k = w(z_k) C (z_k I - A)^-1 z_k s0 (w the
        prewhitening FIR, s0 the start state in the modal coordinates of x -> eps): a fixed
        rational shape per mode with unknown weights. The modes are those at the noise
        reference theta (set_noise_reference; the MAP once identify has one), and the
        weights are fitted by least squares at every theta (variable projection, so the
        curvature is that of the profile likelihood)."""
        self.initial_state = bool(on)
        self._transient_pinv = None
        if self.initial_state:
            self._transient_basis()
        self._last_sums = None
        self._fused = None
        if getattr(self, "_row_sums", None) is not None:
            self._row_sums.clear()

    def _transient_basis(self) -> None:
        """The start transient's basis L (nf, 4, ns) at the noise reference and its
        pseudo-inverse over the stacked bins and channels (set_initial_state)."""
        mb, _ = self.forward.modal(np.atleast_2d(self.theta_ref), self.x_w)
        lam, Cm = mb.lam[0], mb.Cm[0]                                 # (ns,), (4, ns)
        wz = np.polyval(self.prefilter[::-1], 1.0 / self.z)          # FIR gain at z_k
        g = (wz * self.z)[:, None] / (self.z[:, None] - lam[None, :])  # (nf, ns)
        L = g[:, None, :] * Cm[None, :, :] / self.scale                 # (nf, 4, ns)
        L = np.concatenate([L, 1j * L], axis=-1)      # real weights: a + i b per mode
        self._transient_L = np.ascontiguousarray(L)
        flat = L.reshape(-1, L.shape[-1])
        self._transient_pinv = np.linalg.pinv(np.vstack([flat.real, flat.imag]), rcond=1e-10)

    def residual_dft(self, theta: NDArray) -> tuple[NDArray, NDArray]:
        """DFT of eps - S(theta) x (scaled, minus any line terms) for a batch, and the
        stability mask (the compiled kernel, or the numpy path with the engine "numpy")."""
        mb, xi = self.modal_state(theta)
        lines, coef = self._line_terms(theta, (mb, xi))
        if self.engine.compiled:
            return residual_rows.residual_dft_rows(
                mb.lam, mb.Bm, mb.Cm, xi, self.X, self.z, self.E, self.scale, lines, coef,
                lanes=self.engine.compiled_modal), mb.stable
        R = self.E[None] - dft_response(mb, self.X, self.z, xi) / self.scale
        if lines is not None:
            R = R - np.einsum("kcl,bl->bkc", lines, coef)
        return R, mb.stable

    def sum_squares(self, theta: NDArray) -> NDArray:
        """The paper's eq. 15 cost, sum |eps - S(theta) x|^2 (scaled, via Parseval), (nb,)."""
        R, stable = self.residual_dft(np.atleast_2d(theta))
        out = np.sum(np.abs(R) ** 2, axis=(1, 2))
        out[~stable] = np.inf
        return out

    _I, _J = np.triu_indices(4)

    def _band_sums(self, R: NDArray) -> NDArray:
        """P_b = sum over the bins of each band of R_k R_k^H (only the 10 unique entries)."""
        prods = R[..., self._I] * np.conj(R[..., self._J])
        sums = np.add.reduceat(prods, self.starts, axis=1)           # (nb, nbands, 10)
        P = np.empty((*sums.shape[:2], 4, 4), dtype=complex)
        P[..., self._I, self._J] = sums
        P[..., self._J, self._I] = np.conj(sums)
        return P

    @property
    def engine(self) -> kernels.Engine:
        """The likelihood path, chosen once with the forward model (kernels.Engine)."""
        return self.forward.engine

    def modal_state(self, theta: NDArray) -> tuple[ModalBatch, NDArray]:
        """Modal form of x -> eps for a batch, and xi, the modal state after the record, so
        that DFT(S x)_k = C (z_k I - A)^-1 [B X_k - z_k xi] (the discrepancy likelihood
        subtracts the state at its window start)."""
        mb, xi = self.forward.modal(theta, self.x_w)
        return mb, xi

    def _line_terms(self, theta: NDArray, modal: tuple[ModalBatch, NDArray] | None = None
                    ) -> tuple[NDArray | None, NDArray | None]:
        """Extra terms subtracted from the residual DFT: bases (nf, 4, nl) and coefficients
        (nb, nl); none here unless the start transient is fitted (set_initial_state; the
        discrepancy likelihood adds its spectral lines). ``modal``: modal_state(theta),
        which the caller has formed already (None: formed here)."""
        if not self.initial_state or self._transient_pinv is None:
            return None, None
        mb, xi = modal if modal is not None else self.modal_state(np.atleast_2d(theta))
        if self.engine.compiled:
            R0 = residual_rows.residual_dft_rows(mb.lam, mb.Bm, mb.Cm, xi, self.X, self.z,
                                                  self.E, self.scale,
                                                  lanes=self.engine.compiled_modal)
        else:
            R0 = self.E[None] - dft_response(mb, self.X, self.z, xi) / self.scale
        flat = R0.reshape(R0.shape[0], -1)
        coef = np.hstack([flat.real, flat.imag]) @ self._transient_pinv.T   # (nb, 2 ns)
        coef[~mb.stable] = 0.0
        return self._transient_L, coef

    def band_sums(self, theta: NDArray) -> tuple[NDArray, NDArray]:
        """P_b = sum over the bins of each band of R_k R_k^H, (nb, n_bands, 4, 4), and the
        stability mask: the compiled kernel (bayes_amb.inference.kernels), or the numpy path
        (residual_dft, then _band_sums) with BAYES_AMB_KERNEL=numpy.

        P_b depends on theta only, not on the noise intensities: rows of a batch with the
        same theta (a gradient's steps along the noise coordinates) are computed once, and
        the last batch is remembered (a noise-only fit evaluates one theta many times)
        until set_noise_reference. The arrays returned may be shared: do not modify them.
        """
        theta = np.ascontiguousarray(np.atleast_2d(theta), dtype=float)
        key = self._sums_key(theta)
        last = getattr(self, "_last_sums", None)
        if last is not None and last[0] == key:
            if last[1] is None:                     # the fused call left them packed
                last = self._last_sums = (key, band_algebra.unpack_band_sums(
                    last[3], theta.shape[0]), last[2], None)
            return last[1], last[2]
        memo = getattr(self, "_row_sums", None)
        if memo is not None:
            return self._band_sums_by_row(theta, memo)
        rows: dict[bytes, int] = {}
        inverse = np.array([rows.setdefault(r.tobytes(), len(rows)) for r in theta])
        if len(rows) < theta.shape[0]:
            first = np.unique(inverse, return_index=True)[1]
            Pb, stable = self._compute_band_sums(theta[first])
            Pb, stable = Pb[inverse], stable[inverse]
        else:
            Pb, stable = self._compute_band_sums(theta)
        self._last_sums = (key, Pb, stable, None)
        return Pb, stable

    def _sums_key(self, theta: NDArray) -> tuple:
        """Key of the remembered last batch of band sums (theta C-contiguous float64)."""
        return (id(self.forward), self.engine.mode, theta.shape, theta.tobytes())

    def _pointwise_fused(self, theta: NDArray, ls: NDArray) -> NDArray | None:
        """pointwise in one compiled call (bayes_amb.inference.fused), or None where the
        staged path applies: another likelihood path, a subclass, a loop not in observer
        form, a batch below walker_kernels.LANES_MIN_BATCH rows, band sums to be taken from
        memory (the last batch again, remembered rows, repeated rows) or a member the
        compiled modal form rejects. Remembers the batch's band sums as band_sums does."""
        if (type(self) is not WhittleLikelihood or type(self.forward) is not ForwardModel
                or self.initial_state
                or not self.forward.fast or theta.shape[0] < walker_kernels.LANES_MIN_BATCH
                or getattr(self, "_row_sums", None) is not None
                or not self.engine.compiled_modal):
            return None
        theta = np.ascontiguousarray(theta, dtype=float)
        key = self._sums_key(theta)
        last = self._last_sums
        if last is not None and last[0] == key:
            return None
        if len({row.tobytes() for row in theta}) < theta.shape[0]:
            return None
        fused = getattr(self, "_fused", None)
        if fused is None or not fused.matches(self):
            fused = self._fused = FusedLikelihood(self, _TRANSIENT_TOL)
        out = fused(theta, np.ascontiguousarray(10.0 ** (2 * ls), dtype=float))
        if out is None:
            return None
        ll, Pb, stable, packed = out
        self._last_sums = (key, Pb, stable, packed)
        return ll

    def _compute_band_sums(self, theta: NDArray) -> tuple[NDArray, NDArray]:
        if not self.engine.compiled:
            R, stable = self.residual_dft(theta)
            return self._band_sums(R), stable
        mb, xi = self.modal_state(theta)
        lines, coef = self._line_terms(theta, (mb, xi))
        kernel = kernels.residual_band_sums
        if self.engine.compiled_modal and theta.shape[0] >= walker_kernels.LANES_MIN_BATCH:
            kernel = walker_kernels.residual_band_sums_lanes
        Pb = kernel(mb.lam, mb.Bm, mb.Cm, xi, self.X, self.z, self.E, self.scale, self.starts,
                    self.counts, lines, coef)
        return Pb, mb.stable

    def pointwise(self, theta: NDArray, log10_sigma: NDArray) -> NDArray:
        """Per-band log-likelihood (nb, n_bands); -inf rows where G(theta) is not stabilised."""
        theta = np.atleast_2d(theta)
        ls = np.atleast_2d(log10_sigma)
        ll = self._pointwise_fused(theta, ls)
        if ll is not None:
            return ll
        sig2 = 10.0 ** (2 * ls)
        ps = self.phi_sources
        memo = getattr(self, "_row_sums", None)
        if (memo is not None and self.engine.compiled_modal
                and ps.shape[0] == band_algebra.N_SRC):
            # the remembered rows' band sums, packed for the algebra from the store itself
            slots, stable = self._row_slots(np.ascontiguousarray(theta, dtype=float), memo)
            logdet, quad, ok = walker_kernels.whittle_terms(
                sig2, ps, self.n, band_algebra.pack_rows(self._row_store, slots),
                packed_sums=True)
        else:
            Pb, stable = self.band_sums(theta)                      # (nb, nbands, 4, 4)
            if self.engine.compiled_modal:
                logdet, quad, ok = walker_kernels.whittle_terms(sig2, ps, self.n, Pb)
            else:
                Phi = (sig2 @ ps.reshape(3, -1)).reshape(sig2.shape[0], *ps.shape[1:]) * self.n
                if self.engine.compiled:
                    logdet, quad, ok = kernels.logdet_and_trace(Phi, Pb)
                else:
                    logdet, quad, ok = logdet_and_trace_numpy(Phi, Pb)
        ll = -(self.counts * (logdet + 4 * np.log(np.pi)) + quad)
        bad = ~stable | ~np.all(ok, axis=1) | ~np.all(np.isfinite(ll), axis=1)
        ll[bad] = -np.inf
        return ll

    def noise_spectrum(self, log10_sigma: NDArray) -> NDArray:
        """Phi_b, the 4 x 4 noise spectrum of a residual bin in each band at one row of
        log10 sigma (as pointwise forms it for a batch); (n_bands, 4, 4)."""
        sig2 = 10.0 ** (2 * np.asarray(log10_sigma, dtype=float))
        return np.tensordot(sig2, self.phi_sources, axes=(0, 0)) * self.n

    def curvature_weights(self, theta: NDArray, log10_sigma: NDArray) -> NDArray:
        """Per band the weight W_b of a residual bin in the Gauss-Newton curvature,
        -d2 log L = 2 Re sum_k J_k^H W_b J_k (J = dR_k/dparameter): here Phi_b^-1, the
        inverse noise spectrum at log10 sigma (theta: where the filters were set);
        (n_bands, 4, 4). Used by discrepancy.model_error."""
        return np.linalg.inv(self.noise_spectrum(log10_sigma))

    def __call__(self, theta: NDArray, log10_sigma: NDArray) -> NDArray:
        """Total log-likelihood (nb,), including the Jacobian of the eps scaling."""
        return self.with_bands(theta, log10_sigma)[0]

    def with_bands(self, theta: NDArray, log10_sigma: NDArray) -> tuple[NDArray, NDArray]:
        """The total log-likelihood (nb,) and the per-band terms it sums (pointwise,
        (nb, n_bands)): the sampler keeps the latter for the posterior's log_likelihood
        group."""
        ll = self.pointwise(theta, log10_sigma)
        total = ll.sum(axis=1) - 2 * 4 * self.k.size * np.log(self.scale) + self.jacobian
        return total, ll
