"""The prewhitening FIR of the Whittle likelihood (whittle.py, "Prewhitening"): a scalar
minimum-phase filter w with |w|^2 the inverse of a residual power spectrum, designed from
the data first and then from the noise model (WhittleLikelihood.set_model_prewhitening).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.signal import welch


def minimum_phase_inverse(power: NDArray, n_taps: int) -> NDArray:
    """FIR taps of the minimum-phase filter w with |w|^2 = 1/power (power on a uniform grid
    of n_fft/2 + 1 points over [0, pi]), by the real cepstrum; truncated with a half-Hann
    taper and scaled to unit RMS gain."""
    n_fft = 2 * (power.size - 1)
    log_mag = -0.5 * np.log(np.maximum(power, 1e-300 + 1e-12 * power.max()))
    c = np.fft.irfft(log_mag, n_fft)                       # real cepstrum of log|w|
    fold = np.zeros(n_fft)
    fold[0] = c[0]
    fold[1:n_fft // 2] = 2 * c[1:n_fft // 2]
    fold[n_fft // 2] = c[n_fft // 2]
    w = np.fft.irfft(np.exp(np.fft.rfft(fold)), n_fft)[:n_taps]
    w = w * np.cos(0.5 * np.pi * np.arange(n_taps) / n_taps) ** 2
    return w / np.sqrt(np.mean(np.abs(np.fft.rfft(w, n_fft)) ** 2))


def data_prewhitening(eps: NDArray, dt: float, n_taps: int = 128) -> NDArray:
    """Prewhitening FIR from the data: |w|^2 ~ 1 / (Welch PSD of eps, mean over channels)."""
    n = eps.shape[0]
    nper = int(min(512, max(32, 2 ** int(np.log2(max(n // 8, 32))))))
    _, pxx = welch(eps, fs=1.0 / dt, nperseg=nper, axis=0)
    power = np.mean(pxx, axis=1)
    grid = np.linspace(0, 1, 2049)
    power = np.interp(grid, np.linspace(0, 1, power.size), power)
    return minimum_phase_inverse(power, n_taps)
