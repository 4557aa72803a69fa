"""Narrowband lines left out of identify's likelihood.

A rig's record holds lines the model has no part for: mains pick-up on the probes (50 or
60 Hz and its harmonics), a pump or a fan, and for identify also the unbalance and runout
at multiples of the running speed (physics a diagnosis looks for, but nothing S(theta) x
holds). A line is noise from none of the three white sources: in the Whittle likelihood
its few bins weigh as much as thousands of noise bins, and the white model raises an
intensity to cover it at every frequency. On foreign records with mains lines of
0.14-0.43 um on the probes (60, 180 and 300 Hz; studies/plan_replicates.py, mains family,
seed 46) the white sigma_r2 was 0.14 A against the true 0.008 A, the information of every
other bin was drowned, and the MAP put a damping coefficient on its prior's bound in 23 of
30 replicates. With the 9 line bins left out the same record gave sigma_r2 0.0085 A and
every coefficient within 1.7 sd of its truth.

The lines are found before any fit, on the residual at the nominal model,
R_k = eps_k - S(theta_0) x_k: a line is not in x, so R keeps it whatever theta is, while
the model's misfit is as smooth in frequency as S. Per channel each bin's power is set
against the local level, the larger of the medians of the HALF bins on either side beyond
GUARD bins (a steep edge of a coloured spectrum stands level with one side; a line stands
above both). Under noise |R_k|^2 is sigma^2 E, E ~ Exp(1), and a side's median is sigma^2
ln 2 times that of HALF unit exponentials; a bin is a line where u = |R_k|^2 ln 2 / level
of its largest channel passes LINE_P, Bonferroni over the bins and channels. The level's
own scatter fattens the tail of u (taken as Exp(1), the test found a line in 2 of 300
records of pure noise at LINE_P = 1e-3): the threshold bounds P(u > t) <= E exp(-t m / ln 2)
over one side's median m (the larger of two medians is at least either), whose moment
generating function is exact (Renyi's representation of exponential order statistics).
Never lines: bins where the excitation itself stands out (a multisine's lines: EXCITED
times the local level of |x|^2; their power is the model's to explain) and the lowest
LOW_BINS bins (the record's offset and drift). Adjacent line bins are one line.

What it costs: the information of the bins left out, a few of thousands. On a record
without lines nothing is left out and the likelihood is as it was.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import NDArray
from scipy.optimize import brentq

from bayes_amb.rig import CHANNELS

HALF = 32
"""Bins on each side whose median is the local level."""

GUARD = 2
"""Bins next to the tested one left out of its local level (a line's leakage)."""

LINE_P = 1e-3
"""Level of the line test, Bonferroni over the bins and the channels."""

EXCITED = 10.0
"""A bin whose excitation power |x_k|^2 exceeds this times its local level is the
excitation's (a multisine's line), never a line to leave out."""

LOW_BINS = 2
"""The lowest bins, the record's offset and drift: never lines."""

SPEED_TOLERANCE = 0.01
"""Relative tolerance of the running speed written in a recording: a line within it (or 2
bins) of a multiple of the speed is synchronous (unbalance, runout). The diagnosis' 1x
band and locate.py's 1x tests and speed search use it too."""


def local_level(p: NDArray, half: int = HALF, guard: int = GUARD) -> NDArray:
    """Per bin and column of p (nf, c): the larger of the medians of the ``half`` values
    on either side beyond ``guard`` (mirrored at the ends).

    Examples
    --------
    >>> p = np.ones((200, 1)); p[100] = 50.0
    >>> lv = local_level(p)
    >>> float(lv[100, 0]), float(lv[0, 0])
    (1.0, 1.0)
    """
    nf = p.shape[0]
    edge = half + guard
    pad = np.pad(p, ((edge, edge), (0, 0)), mode="symmetric" if nf >= edge else "edge")
    med = np.median(sliding_window_view(pad, half, axis=0), axis=-1)   # med[i]: pad[i:i+half]
    left = med[:nf]                                  # p[k - guard - half : k - guard]
    right = med[half + 2 * guard + 1:half + 2 * guard + 1 + nf]   # p[k + guard + 1 : ...]
    return np.maximum(left, right)


def tail_bound(t: float, half: int = HALF) -> float:
    """Upper bound of P(u > t) under noise (module docstring): E exp(-a m), a = t / ln 2,
    m the median of ``half`` (even) unit exponentials, the mean of the order statistics h
    and h + 1 = X_h + E / half (h = half / 2).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> m = np.median(rng.exponential(size=(200000, 32)), axis=1)
    >>> mc = float(np.mean(np.exp(-4.0 / np.log(2) * m)))
    >>> abs(tail_bound(4.0) / mc - 1) < 0.02
    True
    """
    a = t / np.log(2.0)
    h = half // 2
    i = np.arange(1, h + 1)
    return float(np.exp(np.sum(np.log((half - i + 1) / (half - i + 1 + a)))
                        + np.log(half / (half + a))))


def threshold(n_tests: int, level: float = LINE_P, half: int = HALF) -> float:
    """The u above which a bin is a line: tail_bound(t) = level / n_tests."""
    target = np.log(level / n_tests)
    return float(brentq(lambda t: np.log(tail_bound(t, half)) - target, 1e-6, 1e4))


@dataclass(frozen=True)
class NarrowLines:
    """The bins of the likelihood that are lines (``drop``, over its bins) and the lines
    they form: frequency (Hz, the strongest bin's), bins, level over the local noise (dB),
    channels that carry it, and whether it is synchronous with the running speed."""

    drop: NDArray
    lines: tuple[dict[str, Any], ...] = field(default=())

    def to_list(self) -> list[dict[str, Any]]:
        return [dict(line) for line in self.lines]


def find_narrow_lines(R: NDArray, X: NDArray, f_hz: NDArray, speed_rpm: float | None = None,
                      ) -> NarrowLines:
    """The narrowband lines of a residual DFT R (nf, 4) at the nominal model, with the
    excitation's DFT X (nf, m) at the same bins of frequency f_hz (module docstring)."""
    nf = R.shape[0]
    drop = np.zeros(nf, dtype=bool)
    if nf < 2 * (HALF + GUARD) + 1:
        return NarrowLines(drop)
    power = np.abs(R) ** 2
    level = local_level(power)
    u = np.where(level > 0, power * np.log(2.0) / np.where(level > 0, level, 1.0), 0.0)
    px = np.sum(np.abs(X) ** 2, axis=1, keepdims=True)
    excited = (px > EXCITED * local_level(px))[:, 0]
    drop = (u.max(axis=1) > threshold(power.size)) & ~excited
    drop[:LOW_BINS] = False
    idx = np.flatnonzero(drop)
    df = float(f_hz[1] - f_hz[0]) if nf > 1 else 1.0
    lines = []
    for group in np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1) if idx.size else []:
        k = group[np.argmax(u[group].max(axis=1))]
        ratio = u[k] / np.log(2.0)                     # power over the local mean level
        lines.append({"f_hz": float(f_hz[k]), "bins": int(group.size),
                      "level_db": float(10 * np.log10(ratio.max())),
                      "channels": [CHANNELS[c] for c in range(R.shape[1])
                                   if ratio[c] > ratio.max() / 4],
                      "synchronous": _synchronous(float(f_hz[k]), speed_rpm, df)})
    return NarrowLines(drop, tuple(lines))


def _synchronous(f: float, speed_rpm: float | None, df: float) -> bool:
    """Whether f is a multiple of the running speed (within SPEED_TOLERANCE of it or two
    bins)."""
    if not speed_rpm:
        return False
    f_rot = speed_rpm / 60.0
    order = round(f / f_rot)
    return order >= 1 and abs(f - order * f_rot) <= max(SPEED_TOLERANCE * f_rot, 2 * df)
