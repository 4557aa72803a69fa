"""Real-record habits: what a rig adds to a recording that is not rotor physics.

All signals are sampled at the loop's dt over the whole simulation (burn-in included), shape
(N, 4), channels Ax, Ay, Bx, By:

- sensor noise (m), independent per channel, stationary rms sigma: ``noise_kind="ar1"``:
  n[k] = a n[k-1] + sqrt(1 - a^2) sigma v[k], v white N(0, 1), low-pass for a > 0;
  ``"pink"``: a sum of four AR(1) sections with poles 0.5, 0.9, 0.99, 0.999 and equal
  variances (about 1/f between a few Hz and a few kHz at 10 kHz), scaled to rms sigma;
- sensor DC offsets (m) and a linear drift (m/s) on y, seen by the controller;
- an amplifier offset current (A), added to the commanded current (not to the recorded u);
- mains lines (m) on the measurement: amplitude a_f cos(2 pi f t + phase), f = 50, 150 Hz;
- r1 (m, on the measurement) and r2 (A, at the plant input): white, unrecorded disturbances;
- a burn-in (s) simulated with everything running before the record starts, so that the
  record begins mid-operation with non-zero plant and controller states;
- the excitation eta: random binary +/-amplitude (A), independent per channel and sample
  (on ``eta_channels`` only; the others drawn and then zeroed, so that the other draws do
  not depend on it);
- a process force (N) at the discs (aerodynamic / process forcing; unrecorded, like r2):
  Gaussian, band-limited by a 4th-order Butterworth band-pass to [f_lo, f_hi] Hz,
  independent per forced axis, each scaled to the rms ``force_rms_n`` over the whole run.
  Off unless drawn (:func:`draw_force`, the benchmark's ``control_force`` kind).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.signal import butter, lfilter, sosfilt


@dataclass(frozen=True)
class Habits:
    """Record habits (SI). Defaults: a clean record (white 50 nm noise, 0.3 A eta, no offset,
    no drift, no lines, no r1/r2, start at rest)."""

    noise_rms_m: float = 5e-8
    noise_ar: float = 0.0
    noise_kind: str = "ar1"
    sensor_offset_m: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    drift_m_per_s: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    amp_offset_a: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    mains_m: dict[float, float] = field(default_factory=dict)
    r1_rms_m: float = 0.0
    r2_rms_a: float = 0.0
    burn_in_s: float = 0.0
    eta_amplitude_a: float = 0.3
    force_rms_n: float = 0.0
    force_band_hz: tuple[float, float] = (10.0, 300.0)
    force_at: tuple[str, ...] = ()
    eta_channels: tuple[str, ...] = ("Ax", "Ay", "Bx", "By")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["mains_m"] = {str(k): v for k, v in self.mains_m.items()}
        return d


def draw_habits(rng: np.random.Generator, noise_rms_m: float = 5e-8) -> Habits:
    """Realistic habits: offsets of a few um, amplifier offsets of tens of mA, drift of
    up to 0.2 um/s, AR(1) noise with a in [0.5, 0.9] (or pink noise, one case in three),
    50/150 Hz lines of 0.3-1 x the noise rms,
    small r1/r2, and a 0.2-0.5 s burn-in."""
    return Habits(
        noise_rms_m=noise_rms_m,
        noise_ar=float(rng.uniform(0.5, 0.9)),
        noise_kind="pink" if rng.uniform() < 1 / 3 else "ar1",
        sensor_offset_m=tuple(rng.uniform(-5e-6, 5e-6, 4).tolist()),
        drift_m_per_s=tuple(rng.uniform(-2e-7, 2e-7, 4).tolist()),
        amp_offset_a=tuple(rng.uniform(-0.05, 0.05, 4).tolist()),
        mains_m={50.0: float(rng.uniform(0.3, 1.0) * noise_rms_m),
                 150.0: float(rng.uniform(0.1, 0.5) * noise_rms_m)},
        r1_rms_m=float(rng.uniform(0.0, 0.3) * noise_rms_m),
        r2_rms_a=float(rng.uniform(0.0, 0.01)),
        burn_in_s=float(rng.uniform(0.2, 0.5)),
    )


def draw_force(h: Habits, rng: np.random.Generator, ki: float) -> Habits:
    """The habits with a process force drawn: at 'D1', 'D2' or both discs, band
    [5-20, 150-300] Hz, rms per axis equivalent to 10-50 mA of bearing current
    (force_rms_n = ki * I_eq, ki in N/A)."""
    at = [("D1",), ("D2",), ("D1", "D2")][int(rng.integers(3))]
    band = (float(rng.uniform(5.0, 20.0)), float(rng.uniform(150.0, 300.0)))
    return replace(h, force_rms_n=float(ki * rng.uniform(0.01, 0.05)), force_band_hz=band,
                   force_at=at)


def band_force(n: int, dt: float, rms: float, band: tuple[float, float],
               rng: np.random.Generator, n_axes: int) -> NDArray:
    """Gaussian force (n, n_axes), band-pass [band] Hz (Butterworth, 4th order, run in
    from 1 s before so it is stationary), each column scaled to rms ``rms``."""
    lead = round(1.0 / dt)
    v = rng.standard_normal((n + lead, n_axes))
    sos = butter(4, band, btype="bandpass", fs=1.0 / dt, output="sos")
    f = sosfilt(sos, v, axis=0)[lead:]
    return rms * f / np.sqrt(np.mean(f**2, axis=0))


def ar1_noise(n: int, rms: float, a: float, rng: np.random.Generator) -> NDArray:
    """AR(1) noise (n, 4) with stationary rms ``rms`` and pole ``a`` (started stationary)."""
    v = rng.standard_normal((n, 4)) * rms
    if a == 0.0:
        return v
    out = np.empty_like(v)
    out[0] = v[0]
    g = np.sqrt(1.0 - a * a)
    out[1:] = lfilter([g], [1.0, -a], v[1:], axis=0, zi=a * v[0][None, :])[0]
    return out


PINK_POLES = (0.5, 0.9, 0.99, 0.999)


def pink_noise(n: int, rms: float, rng: np.random.Generator) -> NDArray:
    """Pink-ish noise (n, 4): equal-variance AR(1) sections at PINK_POLES, rms ``rms``."""
    parts = [ar1_noise(n, 1.0, a, rng) for a in PINK_POLES]
    return rms * np.sum(parts, axis=0) / np.sqrt(len(PINK_POLES))


def habit_signals(h: Habits, n: int, dt: float, rng: np.random.Generator, t0: float = 0.0
                  ) -> tuple[dict[str, NDArray], dict[str, Any]]:
    """Sampled habit signals over n samples, the first at time t0 (s; the record starts
    at t = 0, so a burn-in has t0 < 0; line phases and the drift refer to t = 0).

    Returns ({'eta', 'w_add', 'm', 'noise', 'force'}, drawn): eta (A), w_add = r2 +
    amplifier offset (A), m = everything added to the measurement (m; noise included), noise
    alone, force (N, [D1x, D1y, D2x, D2y]; None without a process force, drawn last so the
    other draws do not depend on it), and the random draws worth keeping in the truth (line
    phases).
    """
    t = t0 + np.arange(n) * dt
    eta = h.eta_amplitude_a * rng.choice([-1.0, 1.0], size=(n, 4))
    eta[:, [c not in h.eta_channels for c in ("Ax", "Ay", "Bx", "By")]] = 0.0
    if h.noise_kind == "pink":
        noise = pink_noise(n, h.noise_rms_m, rng)
    elif h.noise_kind == "ar1":
        noise = ar1_noise(n, h.noise_rms_m, h.noise_ar, rng)
    else:
        raise ValueError(f"noise_kind must be 'ar1' or 'pink', got {h.noise_kind!r}")
    m = noise + np.asarray(h.sensor_offset_m)[None, :] + np.outer(t, h.drift_m_per_s)
    phases = {}
    for f, a in h.mains_m.items():
        ph = rng.uniform(0, 2 * np.pi, 4)
        phases[str(f)] = ph.tolist()
        m = m + a * np.cos(2 * np.pi * f * t[:, None] + ph[None, :])
    if h.r1_rms_m:
        m = m + h.r1_rms_m * rng.standard_normal((n, 4))
    w_add = np.broadcast_to(np.asarray(h.amp_offset_a, dtype=float), (n, 4)).copy()
    if h.r2_rms_a:
        w_add += h.r2_rms_a * rng.standard_normal((n, 4))
    force = None
    if h.force_rms_n > 0 and h.force_at:
        force = np.zeros((n, 4))
        cols = [2 * ("D1", "D2").index(d) + i for d in h.force_at for i in (0, 1)]
        force[:, cols] = band_force(n, dt, h.force_rms_n, h.force_band_hz, rng, len(cols))
    return ({"eta": eta, "w_add": w_add, "m": m, "noise": noise, "force": force},
            {"mains_phase_rad": phases})
