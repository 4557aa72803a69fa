"""Channels held at an extreme: the flat tops of a clipped amplifier current or a probe at
the end of its range (the linearity check's first test, linearity.py), and the samples
where they sit (the controller check reads them too, checks.py)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from bayes_amb.io.recording import Recording
from bayes_amb.rig import CHANNELS

__all__ = ["FLAT_SHARE", "at_extremes", "flat_top_channels", "held_samples"]

FLAT_SHARE = 1e-3
"""A channel is clipped when at least this share of its samples (and 5) sit at one of its
two extremes."""


def flat_top_channels(rec: Recording) -> list[tuple[str, int, float]]:
    """(group 'u' or 'y', channel index, share) of every channel held at an extreme."""
    found = []
    for g, v in (("u", rec.u), ("y", rec.y)):
        v = np.asarray(v, dtype=float)
        n = v.shape[0]
        for c in range(len(CHANNELS)):
            if np.ptp(v[:, c]) <= 0:
                continue
            top, bottom = at_extremes(v[:, c])
            share = max(np.sum(top), np.sum(bottom)) / n
            if share >= FLAT_SHARE and share * n >= 5:
                found.append((g, c, float(share)))
    return found


def at_extremes(x: NDArray) -> tuple[NDArray, NDArray]:
    """Masks of the samples of x at its maximum and at its minimum (within 1e-9 of its
    span)."""
    tol = 1e-9 * float(np.ptp(x))
    return x >= x.max() - tol, x <= x.min() + tol


def held_samples(rec: Recording) -> NDArray:
    """(N, 4) mask of the recorded currents' samples at an extreme of a u channel held
    there (flat_top_channels); all False where no u channel is held."""
    u = np.asarray(rec.u, dtype=float)
    held = np.zeros(u.shape, dtype=bool)
    for g, c, _ in flat_top_channels(rec):
        if g == "u":
            top, bottom = at_extremes(u[:, c])
            held[:, c] = top | bottom
    return held


def held_half_spans(u: NDArray) -> list[float]:
    """The amplifier's limit as the recorded coil currents show it: per u channel held at
    both extremes, half the distance between them (the limit about the amplifier's own
    centre, whatever offset the amplifier or the DAQ adds); per channel held at one
    extreme only, that extreme's distance from the channel's median. Empty where no
    channel is held."""
    u = np.asarray(u, dtype=float)
    n = u.shape[0]
    out = []
    for c in range(u.shape[1]):
        if np.ptp(u[:, c]) <= 0:
            continue
        top, bottom = at_extremes(u[:, c])
        held = [m.sum() >= max(FLAT_SHARE * n, 5) for m in (top, bottom)]
        if all(held):
            out.append(0.5 * float(np.ptp(u[:, c])))
        elif any(held):
            end = u[:, c].max() if held[0] else u[:, c].min()
            out.append(abs(float(end - np.median(u[:, c]))))
    return out
