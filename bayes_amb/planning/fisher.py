"""The Fisher information of a test design under the Whittle likelihood.

For a design (excitation x, record length, sample time) and a noise model (white sources
sigma = (sigma_n, sigma_1, sigma_2), as the likelihood has them, whittle.py), the residual
DFT R_k = E_k - S(theta) X_k is complex Gaussian with covariance N Phi_b(k). Its
information about theta at theta_0 is

    F = 2 Re sum_k J_k^H Phi_b(k)^-1 J_k,      J_k = -d(S(theta) X_k)/d theta,

the expected negative Hessian of the log-likelihood (the Gauss-Newton curvature is exact
in expectation). F does not depend on the data, only on x, the loop and the noise: the
posterior sd a record of this design will give is, to first order, sqrt(diag(F^-1)), with
the priors' curvature added. The likelihood is built exactly as identify builds it (same
forward model, validity band, bands and prewhitening from the noise model), so the
prediction is of the intervals identify will report.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import stats
from scipy.optimize import minimize

from bayes_amb.inference.forward import ForwardModel
from bayes_amb.inference.noise_check import P_DOUBT, residual_jacobian, segment_colour
from bayes_amb.inference.offline import dual_youla_eps
from bayes_amb.inference.priors import NOISE_LOG10_BOUNDS
from bayes_amb.inference.whittle import WhittleLikelihood
from bayes_amb.io.recording import Recording
from bayes_amb.planning.colour import NoiseColour, coloured_spectrum


@dataclass(frozen=True)
class Information:
    """What a design tells about ``names`` at ``theta``: F (p, p), the curvature of
    identify's likelihood (its Laplace precision); B (p, p), the variance of its score
    under the true noise (B = F when the noise is white, as the likelihood models it, so
    that the spread of the estimates is F^-1; else F^-1 B F^-1); ``log10_sigma`` the true
    white-equivalent intensities and ``log10_sigma_model`` the white ones identify fits
    (the same when the sources are white); ``n_bins`` the frequency bins that enter,
    ``f_max_hz`` the top of the band; ``F_true`` the information of an estimator that
    knows the true spectrum, and ``modelled`` whether identify will learn it (its
    whiteness test finds the colour: its intervals then come from F_true)."""

    names: tuple[str, ...]
    theta: NDArray
    log10_sigma: NDArray
    F: NDArray
    n_bins: int
    f_max_hz: float
    B: NDArray | None = None
    log10_sigma_model: NDArray | None = None
    F_true: NDArray | None = None
    modelled: bool = False


def log10_sigma_of(noise_rms: float, r1_rms: float, r2_rms: float) -> NDArray:
    """log10 of the three noise intensities, a zero one at the prior's lower bound."""
    out = []
    for v, (lo, _) in zip((noise_rms, r1_rms, r2_rms), NOISE_LOG10_BOUNDS.values(),
                          strict=True):
        out.append(max(np.log10(v), lo) if v > 0 else lo)
    return np.array(out)


def _linearised(recording: Recording, names: tuple[str, ...], theta: NDArray,
                log10_sigma: NDArray) -> tuple[WhittleLikelihood, NDArray, NDArray]:
    """identify's likelihood of ``recording`` prewhitened at (theta, log10_sigma), theta
    as floats, and its residual Jacobian there (nf, 4, p)."""
    fwd = ForwardModel(recording, names)
    eps = dual_youla_eps(fwd.parts, np.asarray(recording.y), np.asarray(recording.u))
    like = WhittleLikelihood(fwd, eps)
    theta = np.asarray(theta, dtype=float)
    like.set_model_prewhitening(theta, log10_sigma)
    return like, theta, residual_jacobian(like, theta)


def fisher_information(recording: Recording, names: tuple[str, ...], theta: NDArray,
                       log10_sigma: NDArray,
                       source_gain: Callable[[NDArray], NDArray] | None = None,
                       colour: NoiseColour | None = None) -> Information:
    """The information of ``recording``'s excitation (its y and u only set the likelihood's
    scale) about ``names`` at ``theta``, for white noise sources of log10 RMS
    ``log10_sigma``; ``source_gain(f)`` (3, nf), if given, the power gain of each source at
    the frequencies f (Hz) of a band-limited one (mean 1 to Nyquist, so that its RMS is
    kept): the noise spectrum is then the true one, not the likelihood's white model, and
    F the information of an estimator that knows it. ``colour`` (colour.py), if given: the
    white spectrum coloured as measured on an earlier recording is the true one."""
    like, theta, J = _linearised(recording, names, theta, log10_sigma)
    nb = like.starts.size
    sig2 = 10.0 ** (2 * np.asarray(log10_sigma, dtype=float))
    gain = np.ones((3, nb)) if source_gain is None else source_gain(like.band_freq_hz)
    phi_true = (_spectrum(like, gain * sig2[:, None]) if colour is None
                else coloured_spectrum(like, log10_sigma, colour))
    ls_model = (np.asarray(log10_sigma, dtype=float) if source_gain is None and colour is None
                else white_fit(like, phi_true, log10_sigma))
    phi_model = _spectrum(like, np.repeat(10.0 ** (2 * ls_model)[:, None], nb, axis=1))
    W_band = np.linalg.inv(phi_model)                                   # (n_bands, 4, 4)
    band = np.repeat(np.arange(nb), like.counts)
    WJ = np.einsum("kcd,kdj->kcj", W_band[band], J)
    F = 2 * np.einsum("kci,kcj->ij", J.conj(), WJ).real
    B = 2 * np.einsum("kci,kcd,kdj->ij", WJ.conj(), phi_true[band], WJ).real
    if source_gain is None and colour is None:
        return Information(tuple(names), theta, np.asarray(log10_sigma, dtype=float),
                           0.5 * (F + F.T), int(like.k.size), like.f_max_hz,
                           B=0.5 * (B + B.T), log10_sigma_model=ls_model)
    TJ = np.einsum("kcd,kdj->kcj", np.linalg.inv(phi_true)[band], J)
    F_true = 2 * np.einsum("kci,kcj->ij", J.conj(), TJ).real
    return Information(tuple(names), theta, np.asarray(log10_sigma, dtype=float),
                       0.5 * (F + F.T), int(like.k.size), like.f_max_hz,
                       B=0.5 * (B + B.T), log10_sigma_model=ls_model,
                       F_true=0.5 * (F_true + F_true.T),
                       modelled=colour_is_found(like, phi_model, phi_true))


def colour_is_found(like: WhittleLikelihood, phi_model: NDArray, phi_true: NDArray) -> bool:
    """Whether identify's whiteness test will find the colour of phi_true against the white
    sources phi_model (its expected statistic, noise_check's segments), so that identify
    models the spectrum (inference/noise_fit.fit_noise_spectrum) instead of the white
    sources: then its intervals are those of the true spectrum's information."""
    L = np.linalg.cholesky(phi_model)
    Li = np.linalg.inv(L)
    Cb = Li @ phi_true @ np.conj(np.swapaxes(Li, -1, -2))
    colour, groups = segment_colour(like.counts, Cb)
    stat = sum(float(like.counts[g].sum() * np.sum(np.abs(colour[g[0]] - np.eye(4)) ** 2))
               for g in groups)
    dof = 16 * len(groups)
    return bool(stats.chi2.sf(stat + dof, dof) < P_DOUBT)


def defect_shift(recording: Recording, names: tuple[str, ...], theta: NDArray,
                 log10_sigma: NDArray, d: NDArray) -> NDArray:
    """How far a linear fit of ``recording`` moves ``names`` from ``theta`` when the plant
    received the recorded current plus a defect d (N, 4) (a nonlinearity's, as a
    transform of the data, discrepancy/nonlinear.py): d enters where r2 does, so the
    residual holds T_r2 d, and one Gauss-Newton step gives the move,
    -F^-1 2 Re(J^H W T_r2 D), with the white sources' weights W. First order in d."""
    from bayes_amb.discrepancy.linearity import r2_bins, r2_filter
    like, theta, J = _linearised(recording, names, theta, log10_sigma)
    TD = r2_bins(like, r2_filter(like, theta), d)
    nb = like.starts.size
    sig2 = 10.0 ** (2 * np.asarray(log10_sigma, dtype=float))
    W = np.linalg.inv(_spectrum(like, np.repeat(sig2[:, None], nb, axis=1)))
    WJ = np.einsum("kcd,kdj->kcj", W[np.repeat(np.arange(nb), like.counts)], J)
    F = 2 * np.einsum("kci,kcj->ij", J.conj(), WJ).real
    g = 2 * np.einsum("kci,kc->i", WJ.conj(), TD).real
    return -np.linalg.solve(0.5 * (F + F.T), g)


def _spectrum(like: WhittleLikelihood, sig2_band: NDArray) -> NDArray:
    """N Phi_b (n_bands, 4, 4) from per-band source intensities (3, n_bands)."""
    return np.einsum("sb,sbcd->bcd", sig2_band, like.phi_sources) * like.n


def white_fit(like: WhittleLikelihood, phi_true: NDArray, start: NDArray) -> NDArray:
    """The white intensities (log10) identify's likelihood converges to on data of true
    spectrum phi_true: the minimum over sigma of the expected negative log-likelihood,
    sum_b n_b [log det Phi_b(sigma) + tr(Phi_b(sigma)^-1 Phi_true,b)] (Whittle's KL)."""
    nb = like.starts.size
    bounds = list(NOISE_LOG10_BOUNDS.values())

    def loss(ls: NDArray) -> float:
        phi = _spectrum(like, np.repeat(10.0 ** (2 * ls)[:, None], nb, axis=1))
        _, logdet = np.linalg.slogdet(phi)
        tr = np.einsum("bcd,bdc->b", np.linalg.inv(phi), phi_true).real
        return float(np.sum(like.counts * (logdet + tr)))

    x0 = np.clip(np.asarray(start, dtype=float), [b[0] for b in bounds],
                 [b[1] for b in bounds])
    res = minimize(loss, x0, method="L-BFGS-B", bounds=bounds)
    return np.asarray(res.x, dtype=float)
