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

from bayes_amb.inference.forward import ForwardModel
from bayes_amb.inference.offline import dual_youla_eps
from bayes_amb.inference.priors import NOISE_LOG10_BOUNDS
from bayes_amb.inference.whittle import WhittleLikelihood
from bayes_amb.io.recording import Recording

STEP = 1e-4
"""Central-difference step of the Jacobian (theta units; S is smooth in theta)."""


@dataclass(frozen=True)
class Information:
    """F (p, p) about ``names`` at ``theta`` for the noise ``log10_sigma``; ``n_bins`` the
    frequency bins that enter, ``f_max_hz`` the top of the band."""

    names: tuple[str, ...]
    theta: NDArray
    log10_sigma: NDArray
    F: NDArray
    n_bins: int
    f_max_hz: float


def log10_sigma_of(noise_rms: float, r1_rms: float, r2_rms: float) -> NDArray:
    """log10 of the three noise intensities, a zero one at the prior's lower bound."""
    out = []
    for v, (lo, _) in zip((noise_rms, r1_rms, r2_rms), NOISE_LOG10_BOUNDS.values(),
                          strict=True):
        out.append(max(np.log10(v), lo) if v > 0 else lo)
    return np.array(out)


def fisher_information(recording: Recording, names: tuple[str, ...], theta: NDArray,
                       log10_sigma: NDArray,
                       source_gain: Callable[[NDArray], NDArray] | None = None
                       ) -> Information:
    """The information of ``recording``'s excitation (its y and u only set the likelihood's
    scale) about ``names`` at ``theta``, for white noise sources of log10 RMS
    ``log10_sigma``; ``source_gain(f)`` (3, nf), if given, the power gain of each source at
    the frequencies f (Hz) of a band-limited one (mean 1 to Nyquist, so that its RMS is
    kept): the noise spectrum is then the true one, not the likelihood's white model, and
    F the information of an estimator that knows it."""
    fwd = ForwardModel(recording, names)
    eps = dual_youla_eps(fwd.parts, np.asarray(recording.y), np.asarray(recording.u))
    like = WhittleLikelihood(fwd, eps)
    theta = np.asarray(theta, dtype=float)
    like.set_model_prewhitening(theta, log10_sigma)
    p = theta.size
    rows = np.tile(theta, (2 * p, 1))
    for j in range(p):
        rows[2 * j, j] += STEP
        rows[2 * j + 1, j] -= STEP
    R, stable = like.residual_dft(rows)
    if not np.all(stable):
        raise ValueError("the controller does not stabilise the model next to theta")
    J = np.stack([(R[2 * j] - R[2 * j + 1]) / (2 * STEP) for j in range(p)], axis=-1)
    if source_gain is None:
        W_band = like.curvature_weights(theta, log10_sigma)            # (n_bands, 4, 4)
    else:
        g = source_gain(like.band_freq_hz) * 10.0 ** (2 * log10_sigma)[:, None]
        W_band = np.linalg.inv(np.einsum("sb,sbcd->bcd", g, like.phi_sources) * like.n)
    W = W_band[np.repeat(np.arange(like.starts.size), like.counts)]
    F = 2 * np.einsum("kci,kcd,kdj->ij", J.conj(), W, J).real
    return Information(tuple(names), theta, np.asarray(log10_sigma, dtype=float),
                       0.5 * (F + F.T), int(like.k.size), like.f_max_hz)
