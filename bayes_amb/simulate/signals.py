"""Excitation and disturbance signals. Every generator takes a numpy Generator (rng).

Amplitudes are physical: currents in A, displacements in m. Signals are arrays of shape
(n_samples, n_channels).
"""

from __future__ import annotations

import numpy as np
import scipy.signal as sps
from numpy.typing import NDArray

from bayes_amb.errors import BayesAmbError

EXCITATIONS = ("random-binary", "prbs", "multisine", "odd-multisine")


def random_binary(n: int, n_ch: int, amplitude: float, rng: np.random.Generator,
                  hold: int = 1) -> NDArray:
    """Random binary signal +/-amplitude, each level held for ``hold`` samples (the paper's)."""
    k = -(-n // hold)
    levels = rng.choice([-1.0, 1.0], size=(k, n_ch))
    return amplitude * np.repeat(levels, hold, axis=0)[:n]


def prbs(n: int, n_ch: int, amplitude: float, rng: np.random.Generator,
         nbits: int = 12) -> NDArray:
    """Maximum-length binary sequence, +/-amplitude; channels use random circular shifts."""
    seq = sps.max_len_seq(nbits)[0].astype(float) * 2.0 - 1.0
    reps = -(-n // seq.size)
    base = np.tile(seq, reps)
    shifts = rng.permutation(seq.size)[:n_ch]
    return amplitude * np.stack([np.roll(base, s)[:n] for s in shifts], axis=1)


def multisine(n: int, n_ch: int, amplitude: float, rng: np.random.Generator, dt: float,
              band_hz: tuple[float, float] | None = None, n_lines: int = 200) -> NDArray:
    """Random-phase multisine with flat amplitude over band_hz, peak scaled to amplitude.

    band_hz None: 5 Hz to min(1000 Hz, 0.8 Nyquist), so the default also fits dt = 1e-3 s.

    Frequencies lie on the grid of the record (multiples of 1/(n dt)), so the signal is
    periodic over the record. Channels have independent phases.
    """
    f0 = 1.0 / (n * dt)
    lo, hi = _band(band_hz, dt)
    k = np.unique(np.round(np.geomspace(max(lo / f0, 1), hi / f0, n_lines)).astype(int))
    return _sum_of_lines(n, n_ch, amplitude, rng, dt, k)


def _band(band_hz: tuple[float, float] | None, dt: float) -> tuple[float, float]:
    """A multisine's band (Hz), checked; None: 5 Hz to min(1000 Hz, 0.8 Nyquist)."""
    lo, hi = (5.0, min(1000.0, 0.4 / dt)) if band_hz is None else band_hz
    if not (0 < lo < hi <= 0.5 / dt):
        raise BayesAmbError(f"multisine band {band_hz} Hz must satisfy 0 < lo < hi <= "
                            f"Nyquist {0.5 / dt:g} Hz")
    return lo, hi


def _sum_of_lines(n: int, n_ch: int, amplitude: float, rng: np.random.Generator, dt: float,
                  k: NDArray) -> NDArray:
    """Cosines at the multiples k of 1/(n dt), random phases per channel, each channel's
    peak scaled to amplitude (summed 256 lines at a time: bounded memory)."""
    f0 = 1.0 / (n * dt)
    t = np.arange(n) * dt
    out = np.empty((n, n_ch))
    for c in range(n_ch):
        ph = rng.uniform(0, 2 * np.pi, k.size)
        x = np.zeros(n)
        for i in range(0, k.size, 256):
            x += np.cos(2 * np.pi * f0 * np.outer(t, k[i:i + 256]) + ph[i:i + 256]).sum(axis=1)
        out[:, c] = x / np.max(np.abs(x))
    return amplitude * out


def odd_multisine(n: int, n_ch: int, amplitude: float, rng: np.random.Generator, dt: float,
                  band_hz: tuple[float, float] | None = None, group: int = 4) -> NDArray:
    """Random-odd multisine (Pintelon & Schoukens 2012, ch. 4): only odd multiples of the
    record's base frequency 1/(n dt) in band_hz, one odd line in each group of ``group``
    left out at random (a detection line), flat amplitude, random phases per channel, peak
    scaled to amplitude. A linear loop puts only noise on the left-out odd lines and on the
    even ones alike; an odd nonlinearity (a clip, the magnetic force at large orbits) adds
    distortion on the odd ones (discrepancy/detection_lines.py). Same default band as
    :func:`multisine`."""
    f0 = 1.0 / (n * dt)
    lo, hi = _band(band_hz, dt)
    k0, k1 = int(np.ceil(lo / f0)), int(np.floor(hi / f0))
    odd = np.arange(k0 + (k0 + 1) % 2, k1 + 1, 2)
    keep = np.ones(odd.size, dtype=bool)
    for g in range(0, odd.size, group):
        keep[g + rng.integers(min(group, odd.size - g))] = False
    k = odd[keep]
    if k.size < 2:
        raise BayesAmbError(f"odd multisine: the band {lo:g}-{hi:g} Hz holds too few odd "
                            f"lines of the record's {f0:g} Hz grid")
    return _sum_of_lines(n, n_ch, amplitude, rng, dt, k)


def binary_hold(band_hz: tuple[float, float] | None, dt: float) -> int:
    """Samples each level of a random binary is held for so that its first spectral null,
    1 / (hold dt), is at or above the band's upper edge: hold = floor(1 / (hi dt)) (1
    without a band). Holding puts the signal's power below the null: a band-limited random
    binary at the same peak current."""
    if band_hz is None:
        return 1
    return max(1, int(np.floor(1.0 / (band_hz[1] * dt) + 1e-9)))


def excitation(kind: str, n: int, n_ch: int, amplitude: float, rng: np.random.Generator,
               dt: float, band_hz: tuple[float, float] | None = None) -> NDArray:
    """Dispatch on the excitation name (random-binary, prbs, multisine, odd-multisine;
    band_hz for the multisines, and for random-binary its upper edge sets the hold)."""
    if kind == "random-binary":
        return random_binary(n, n_ch, amplitude, rng, binary_hold(band_hz, dt))
    if kind == "prbs":
        return prbs(n, n_ch, amplitude, rng)
    if kind in ("multisine", "odd-multisine"):
        make = multisine if kind == "multisine" else odd_multisine
        return make(n, n_ch, amplitude, rng, dt,
                    None if band_hz is None else (float(band_hz[0]), float(band_hz[1])))
    raise BayesAmbError(f"option --excitation: unknown value {kind!r}; known: "
                        f"{', '.join(EXCITATIONS)}")


def gaussian_noise(n: int, n_ch: int, rms: float, rng: np.random.Generator, dt: float,
                   band_hz: float | None = None) -> NDArray:
    """White (band_hz None) or low-pass band-limited Gaussian noise with the given RMS."""
    if rms == 0:
        return np.zeros((n, n_ch))
    w = rng.standard_normal((n, n_ch))
    if band_hz is not None:
        if not 0 < band_hz < 0.5 / dt:
            raise BayesAmbError(f"disturbance bandwidth {band_hz} Hz must lie below Nyquist "
                                f"{0.5 / dt:g} Hz")
        sos = sps.butter(4, band_hz, fs=1.0 / dt, output="sos")
        w = sps.sosfilt(sos, w, axis=0)
        w = w / np.sqrt(np.mean(w**2, axis=0, keepdims=True))
    return rms * w
