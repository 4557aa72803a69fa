"""The noise spectrum fitted to a record and the MAP under it: the driver identify and its
adequacy test share (the spectrum itself, its fit and its algebra: spectrum.py).

From the white model's MAP: the whiteness test of the residual (noise_check.py) decides
whether anything is learned; then the sources' smooth gains (learn_spectrum), the colour
they still miss folded in where the test still rejects (noise_check.colour_correction),
the MAP again after each, and the narrowband lines the spectrum takes as noise reported.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from bayes_amb.inference.noise_check import P_DOUBT, colour_correction
from bayes_amb.inference.spectrum import (
    CHANNELS,
    LEARN_ROUNDS,
    LearnedSpectrum,
    learn_spectrum,
    synchronous_bins,
)

LINE_P = 1e-3
"""Level (Bonferroni over the bins) at which a bin's residual is a line over the spectrum."""

SYNCHRONOUS_BINS = 2
"""Bins either side of a multiple of the running speed that are left to the physics."""


def find_lines(like: Any, theta: NDArray, log10_sigma: NDArray, speed_rpm: float | None
               ) -> list[dict[str, Any]]:
    """Narrowband lines in the residual at the MAP that the learned spectrum has as noise:
    bins whose whitened power q_k = R_k^H (N Phi_b)^-1 R_k (Gamma(4, 1) under the model)
    passes LINE_P over all bins, not within SYNCHRONOUS_BINS of a multiple of the running
    speed (unbalance and runout are physics), adjacent bins merged. Per line: frequency
    (Hz, the strongest bin's), level in dB over the noise there, and the channels that
    carry it (whitened power above a quarter of the strongest channel's)."""
    R, stable = like.residual_dft(np.atleast_2d(np.asarray(theta, dtype=float)))
    if not stable[0]:
        return []
    R = R[0]
    band = np.repeat(np.arange(like.counts.size), like.counts)
    try:
        L = np.linalg.cholesky(like.noise_spectrum(log10_sigma))[band]
    except np.linalg.LinAlgError:       # a noise spectrum that is not positive definite
        return []                       # whitens nothing: no line can be read against it
    Wh = np.linalg.solve(L, R[..., None])[..., 0]                 # whitened residual bins
    q = np.sum(np.abs(Wh) ** 2, axis=1)
    f = like.k / (like.n * like.forward.dt)
    hit = stats.gamma.sf(q, 4) < LINE_P / q.size
    sync = synchronous_bins(like, speed_rpm, SYNCHRONOUS_BINS)
    if sync is not None:
        hit &= ~sync
    lines: list[dict[str, Any]] = []
    idx = np.flatnonzero(hit)
    for group in np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1) if idx.size else []:
        k = group[np.argmax(q[group])]
        per = np.abs(Wh[k]) ** 2
        lines.append({"f_hz": float(f[k]), "level_db": float(10 * np.log10(q[k] / 4.0)),
                      "channels": [CHANNELS[c] for c in range(4) if per[c] > per.max() / 4]})
    return lines


Refit = Callable[[NDArray, NDArray], tuple[NDArray, NDArray]]
"""(theta, log10 sigma) -> the MAP from there under the likelihood's current spectrum."""


def fit_noise_spectrum(like: Any, theta: NDArray, log10_sigma: NDArray, refit: Refit,
                       mask: NDArray | None = None
                       ) -> tuple[NDArray, NDArray, LearnedSpectrum | None]:
    """The record's noise spectrum and the MAP under it, from the white model's MAP (theta,
    log10_sigma): the sources' smooth gains (learn_spectrum; first from the residual
    cleaned of the excitation-coherent part, then LEARN_ROUNDS times from the residual at
    the MAP they moved), then, where the residual is still not as white as the sources
    have it (the whiteness test of noise_check at its level), the colour measured there
    folded in (noise_check.colour_correction) and the MAP again. The likelihood keeps the
    spectrum, with its prewhitening designed from it (set_model_prewhitening). Returns the
    MAP and the spectrum (None, the likelihood unchanged: a record whose residual passes
    the whiteness test at the white model's MAP, which costs one residual). ``mask``:
    bins the spectrum is not learned from (the diagnosis: lines at multiples of the
    running speed, which are physics)."""
    theta, ls = np.asarray(theta, dtype=float), np.asarray(log10_sigma, dtype=float)
    theta0, ls0 = theta.copy(), ls.copy()
    found = colour_correction(like, theta, ls, mask=mask)
    if found is None or found[0] >= P_DOUBT:
        return theta, ls, None            # as white as the sources have it: nothing to learn
    learned = learn_spectrum(like, theta, ls, mask=mask)
    spectrum = None
    if learned.adopted:
        spectrum = learned
        for r in range(LEARN_ROUNDS + 1):
            theta, ls = _use(like, spectrum, theta, spectrum.log10_sigma, refit)
            if r == LEARN_ROUNDS:
                break
            like.set_spectrum(None)
            spectrum = replace(learn_spectrum(like, theta, ls, cleaned=False, mask=mask),
                               adopted=True)
    found = colour_correction(like, theta, ls, mask=mask)
    if found is not None and found[0] < P_DOUBT:
        base = spectrum or replace(learned, log_gain=np.zeros_like(learned.log_gain),
                                   log10_sigma=ls.copy())
        corrected = replace(base, colour_hz=found[1], colour=found[2],
                            colour_log10_sigma=ls.copy(),
                            notes=(f"the colour the sources miss (whiteness test p = "
                                   f"{found[0]:.2g}) folded in per segment",))
        new_theta, new_ls = _use(like, corrected, theta, ls, refit)
        if _finite(like, new_theta, new_ls):
            spectrum, theta, ls = corrected, new_theta, new_ls
        else:       # the correction left no positive-definite noise spectrum to fit under
            like.set_spectrum(spectrum)
            like.set_model_prewhitening(theta, ls)
    if spectrum is not None and not _finite(like, theta, ls):
        like.set_spectrum(None)         # nothing learned gives a finite likelihood here
        like.set_model_prewhitening(theta0, ls0)
        return theta0, ls0, None
    if spectrum is not None:
        speed = getattr(getattr(like.forward, "recording", None), "speed_rpm", None)
        spectrum = replace(spectrum, lines=tuple(find_lines(like, theta, ls, speed)))
    return theta, ls, spectrum


def _finite(like: Any, theta: NDArray, log10_sigma: NDArray) -> bool:
    """Whether the likelihood is finite at (theta, log10 sigma) under its spectrum."""
    return bool(np.all(np.isfinite(like(np.atleast_2d(theta), np.atleast_2d(log10_sigma)))))


def _use(like: Any, spectrum: LearnedSpectrum, theta: NDArray, log10_sigma: NDArray,
         refit: Refit) -> tuple[NDArray, NDArray]:
    """The likelihood under ``spectrum`` (prewhitening designed from it at theta), and the
    MAP from (theta, log10_sigma)."""
    like.set_spectrum(spectrum)
    like.set_model_prewhitening(theta, log10_sigma)
    return refit(theta, log10_sigma)
