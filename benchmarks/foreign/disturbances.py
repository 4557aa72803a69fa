"""Coloured disturbances (issue 46): what a plant and its rig add to a record besides the
habits, drawn per case kind and played by :func:`disturbance_signals`.

Every signal is sampled at the loop's dt over the whole simulation (burn-in included),
shape (N, 4), channels Ax, Ay, Bx, By; unrecorded:

- ``r2_band``: a band-limited Gaussian current (A) at the amplifier input (added to w like
  the habits' r2): white N(0, 1) through a 4th-order Butterworth band-pass [lo, hi] Hz
  (run in from 1 s before), each forced channel scaled to its rms over the run;
- ``r2_narrow`` (held out): a resonant Gaussian current (A) at the amplifier input: white
  through the AR(2) resonator 1 / (1 - 2 r cos(w0) z^-1 + r^2 z^-2), w0 = 2 pi f0 dt,
  r = exp(-pi (f0 / Q) dt) (-3 dB bandwidth f0 / Q), run in for max(1 s, 10 / (pi f0 / Q)),
  each forced channel scaled to its rms over the run;
- ``mains_m``: lines on the measurement (m), per line a cos(2 pi f t + phase) with its own
  amplitude and phase per channel (phases refer to t = 0 of the record); they replace the
  habits' 50/150 Hz lines in the cases that draw them;
- ``current_line``: one line on the current (A) at a frequency that is neither a mains
  harmonic nor a multiple of the running speed (a pump or fan), per channel amplitude and
  phase;
- ``r1_band`` (held out): a band-limited Gaussian on the measurement (m), as ``r2_band``.

The pink sensor noise of ``pink_sensor`` is the habits' own (``noise_kind='pink'`` at a
larger ``noise_rms_m``); the Disturbance records its factor. Signals are drawn after every
habit signal (and the process force), in the order above, so a case's other draws do not
depend on them.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.signal import butter, lfilter

from benchmarks.foreign.habits import Habits, band_force

AXES = ("Ax", "Ay", "Bx", "By")
Quad = tuple[float, float, float, float]
_ZERO: Quad = (0.0, 0.0, 0.0, 0.0)

SEEN = ("coloured_r2", "mains", "pink_sensor", "coloured_mix")
"""Disturbance kinds the product may be tuned to."""
HELD_OUT = ("narrowband_r2", "r1_band")
"""Disturbance kinds held out for honest scoring (not to be tuned to)."""
KINDS = (*SEEN, *HELD_OUT)

COLOURED_R2_RMS_A = (0.03, 0.06)
COLOURED_R2_LO_HZ = (5.0, 40.0)
COLOURED_R2_HI_HZ = (80.0, 600.0)
MAINS_OVER_NOISE = (2.0, 10.0)
CURRENT_LINE_HZ = (20.0, 400.0)
CURRENT_LINE_A = (0.002, 0.006)
PINK_FACTOR = (2.0, 4.0)
NARROW_HZ = (30.0, 400.0)
NARROW_Q = (5.0, 20.0)
NARROW_RMS_A = (0.02, 0.05)
R1_BAND_LO_HZ = (20.0, 60.0)
R1_BAND_HI_HZ = (150.0, 300.0)
R1_BAND_OVER_NOISE = (1.0, 3.0)
LINE_CLEARANCE_HZ = 3.0
"""A current line stays this far from every mains harmonic and every multiple of the
running speed (Hz)."""


@dataclass(frozen=True)
class Disturbance:
    """The coloured disturbances of a case (SI; per-channel tuples Ax, Ay, Bx, By; a zero
    rms or amplitude is off). ``families``: the kind's families ('coloured_r2', 'mains',
    'pink_sensor', 'narrowband_r2', 'r1_band'); ``pink_factor``: the pink sensor noise rms
    over the case's base noise rms (the noise itself is in the habits); ``mains_m``:
    {Hz: per-channel amplitude (m)}; ``noise_ref_m``: the base sensor-noise rms the mains
    and r1_band amplitudes were drawn against."""

    families: tuple[str, ...] = ()
    r2_band_rms_a: Quad = _ZERO
    r2_band_hz: tuple[float, float] = (10.0, 300.0)
    r2_narrow_rms_a: Quad = _ZERO
    r2_narrow_hz: float = 100.0
    r2_narrow_q: float = 10.0
    mains_m: dict[float, Quad] = field(default_factory=dict)
    current_line_hz: float = 0.0
    current_line_a: Quad = _ZERO
    r1_band_rms_m: Quad = _ZERO
    r1_band_hz: tuple[float, float] = (20.0, 300.0)
    pink_factor: float = 0.0
    noise_ref_m: float = 5e-8

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["mains_m"] = {str(k): list(v) for k, v in self.mains_m.items()}
        d["held_out"] = [f for f in self.families if f in HELD_OUT]
        return d

    def lines_hz(self) -> tuple[float, ...]:
        """The frequencies of its deterministic lines (Hz)."""
        cur = (self.current_line_hz,) if any(self.current_line_a) else ()
        return (*self.mains_m, *cur)


def resonator(f0_hz: float, q: float, dt: float) -> tuple[NDArray, NDArray]:
    """(b, a) of the AR(2) resonator of ``r2_narrow`` (numerator 1)."""
    r = np.exp(-np.pi * f0_hz / q * dt)
    return np.array([1.0]), np.array([1.0, -2.0 * r * np.cos(2 * np.pi * f0_hz * dt), r * r])


def band_sos(band: tuple[float, float], dt: float) -> NDArray:
    """The 4th-order Butterworth band-pass of ``r2_band``, ``r1_band`` (and the process
    force of the habits: habits.band_force uses the same design)."""
    return butter(4, band, btype="bandpass", fs=1.0 / dt, output="sos")


def _channels(rng: np.random.Generator) -> tuple[bool, bool, bool, bool]:
    """All four channels (half the cases) or one bearing's two."""
    where = ["all", "all", "A", "B"][int(rng.integers(4))]
    return tuple(where == "all" or a[0] == where for a in AXES)    # type: ignore[return-value]


def _on(rms: NDArray, on: tuple[bool, ...]) -> Quad:
    """The drawn rms on the forced channels, 0 elsewhere."""
    return tuple(float(r) if o else 0.0 for r, o in zip(rms, on, strict=True))  # type: ignore


def _current_line_hz(rng: np.random.Generator, mains_hz: float, speed_rpm: float) -> float:
    """A pump/fan line in CURRENT_LINE_HZ, LINE_CLEARANCE_HZ away from every multiple of
    the mains frequency and of the running speed."""
    run = speed_rpm / 60.0
    for _ in range(1000):
        f = float(rng.uniform(*CURRENT_LINE_HZ))
        if all(abs(f - base * round(f / base)) > LINE_CLEARANCE_HZ
               for base in (mains_hz, run) if base > 0):
            return f
    raise RuntimeError("no current-line frequency clear of the mains and running speed")


def draw_disturbance(kind: str, rng: np.random.Generator, hab: Habits,
                     speed_rpm: float) -> tuple[Habits, Disturbance]:
    """The habits (changed by 'pink_sensor' and 'mains') and the Disturbance of a kind in
    KINDS (see the module doc and README for the ranges). ``hab``: the case's drawn habits
    (its noise_rms_m is the base the amplitudes are drawn against)."""
    if kind not in KINDS:
        raise ValueError(f"unknown disturbance kind {kind!r}; known: {KINDS}")
    u = rng.uniform
    noise = hab.noise_rms_m
    families = ("coloured_r2", "mains", "pink_sensor") if kind == "coloured_mix" else (kind,)
    d = Disturbance(families=families, noise_ref_m=noise)
    if "coloured_r2" in families:
        on = _channels(rng)
        rms = _on(u(*COLOURED_R2_RMS_A, 4), on)
        d = replace(d, r2_band_rms_a=rms,
                    r2_band_hz=(float(u(*COLOURED_R2_LO_HZ)), float(u(*COLOURED_R2_HI_HZ))))
    if "mains" in families:
        base = 60.0 if rng.uniform() < 1 / 3 else 50.0
        lines = {base * h: tuple(float(a) for a in u(*MAINS_OVER_NOISE, 4) * noise)
                 for h in (1, 3, 5)}
        d = replace(d, mains_m=lines)
        hab = replace(hab, mains_m={})          # the drawn lines replace the habits' hum
        if rng.uniform() < 0.5:
            d = replace(d, current_line_hz=_current_line_hz(rng, base, speed_rpm),
                        current_line_a=tuple(float(a) for a in u(*CURRENT_LINE_A, 4)))
    if "pink_sensor" in families:
        f = float(u(*PINK_FACTOR))
        d = replace(d, pink_factor=f)
        hab = replace(hab, noise_kind="pink", noise_rms_m=f * noise)
    if "narrowband_r2" in families:
        on = _channels(rng)
        rms = _on(u(*NARROW_RMS_A, 4), on)
        d = replace(d, r2_narrow_rms_a=rms,
                    r2_narrow_hz=float(u(*NARROW_HZ)), r2_narrow_q=float(u(*NARROW_Q)))
    if "r1_band" in families:
        d = replace(d, r1_band_rms_m=tuple(float(a) for a in u(*R1_BAND_OVER_NOISE, 4) * noise),
                    r1_band_hz=(float(u(*R1_BAND_LO_HZ)), float(u(*R1_BAND_HI_HZ))))
    return hab, d


def _scaled(sig: NDArray, rms: Quad) -> NDArray:
    """Columns scaled to their rms over the run (zero rms: a zero column)."""
    out = np.zeros_like(sig)
    for c, r in enumerate(rms):
        if r > 0:
            out[:, c] = r * sig[:, c] / np.sqrt(np.mean(sig[:, c] ** 2))
    return out


def narrowband(n: int, dt: float, f0_hz: float, q: float, rms: Quad,
               rng: np.random.Generator) -> NDArray:
    """Resonant Gaussian noise (n, 4) through :func:`resonator`, run in, columns scaled to
    ``rms``."""
    lead = round(max(1.0, 10.0 * q / (np.pi * f0_hz)) / dt)
    b, a = resonator(f0_hz, q, dt)
    v = lfilter(b, a, rng.standard_normal((n + lead, 4)), axis=0)[lead:]
    return _scaled(v, rms)


def disturbance_signals(d: Disturbance, n: int, dt: float, rng: np.random.Generator,
                        t0: float = 0.0) -> tuple[NDArray, NDArray, dict[str, Any]]:
    """(w_add (n, 4) A at the amplifier input, m_add (n, 4) m on the measurement, draws):
    the disturbance's signals over n samples, the first at time t0 (s; phases refer to
    t = 0 of the record); draws: the line phases (rad, per channel)."""
    t = t0 + np.arange(n) * dt
    w, m = np.zeros((n, 4)), np.zeros((n, 4))
    draws: dict[str, Any] = {}
    if any(d.r2_band_rms_a):
        w += _scaled(band_force(n, dt, 1.0, d.r2_band_hz, rng, 4), d.r2_band_rms_a)
    if any(d.r2_narrow_rms_a):
        w += narrowband(n, dt, d.r2_narrow_hz, d.r2_narrow_q, d.r2_narrow_rms_a, rng)
    if d.mains_m:
        draws["mains_phase_rad"] = {}
        for f, amp in d.mains_m.items():
            ph = rng.uniform(0, 2 * np.pi, 4)
            draws["mains_phase_rad"][str(f)] = ph.tolist()
            m += np.asarray(amp) * np.cos(2 * np.pi * f * t[:, None] + ph[None, :])
    if any(d.current_line_a):
        ph = rng.uniform(0, 2 * np.pi, 4)
        draws["current_line_phase_rad"] = ph.tolist()
        w += np.asarray(d.current_line_a) * np.cos(2 * np.pi * d.current_line_hz * t[:, None]
                                                   + ph[None, :])
    if any(d.r1_band_rms_m):
        m += _scaled(band_force(n, dt, 1.0, d.r1_band_hz, rng, 4), d.r1_band_rms_m)
    return w, m, draws
