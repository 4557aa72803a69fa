"""Channels held at an extreme: the flat tops of a clipped amplifier current or a probe at
the end of its range (the linearity check's first test, linearity.py), and the samples
where they sit (the controller check reads them too, checks.py)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from bayes_amb.io.recording import Recording
from bayes_amb.rig import CHANNELS

__all__ = ["FLAT_SHARE", "at_extremes", "flat_top_channels", "held_ends", "held_half_spans",
           "held_mask", "held_samples"]

FLAT_SHARE = 1e-3
"""A channel is clipped when at least this share of its samples (and 5) sit at one of its
two extremes."""


def held_ends(x: NDArray) -> tuple[NDArray, NDArray, bool, bool] | None:
    """A channel's masks at its maximum and minimum (at_extremes) and whether each end is
    held (at least FLAT_SHARE of the samples, and 5); None for a constant channel."""
    x = np.asarray(x, dtype=float)
    if np.ptp(x) <= 0:
        return None
    top, bottom = at_extremes(x)
    need = max(FLAT_SHARE * x.size, 5)
    return top, bottom, bool(top.sum() >= need), bool(bottom.sum() >= need)


def flat_top_channels(rec: Recording) -> list[tuple[str, int, float]]:
    """(group 'u' or 'y', channel index, share) of every channel held at an extreme."""
    found = []
    for g, v in (("u", rec.u), ("y", rec.y)):
        v = np.asarray(v, dtype=float)
        for c in range(len(CHANNELS)):
            ends = held_ends(v[:, c])
            if ends is not None and (ends[2] or ends[3]):
                share = max(np.sum(ends[0]), np.sum(ends[1])) / v.shape[0]
                found.append((g, c, float(share)))
    return found


def at_extremes(x: NDArray) -> tuple[NDArray, NDArray]:
    """Masks of the samples of x at its maximum and at its minimum (within 1e-9 of its
    span)."""
    tol = 1e-9 * float(np.ptp(x))
    return x >= x.max() - tol, x <= x.min() + tol


def held_mask(u: NDArray) -> NDArray:
    """(N, 4) mask of the samples of the currents ``u`` at an extreme of a channel held
    there (held_ends); all False where no channel is held."""
    u = np.asarray(u, dtype=float)
    held = np.zeros(u.shape, dtype=bool)
    for c in range(u.shape[1]):
        ends = held_ends(u[:, c])
        if ends is not None and (ends[2] or ends[3]):
            held[:, c] = ends[0] | ends[1]
    return held


def held_samples(rec: Recording) -> NDArray:
    """held_mask of the recording's currents (the u channels of flat_top_channels)."""
    return held_mask(rec.u)


def held_half_spans(u: NDArray) -> list[float]:
    """The amplifier's limit as the recorded coil currents show it: per u channel held at
    both extremes, half the distance between them (the limit about the amplifier's own
    centre, whatever offset the amplifier or the DAQ adds); per channel held at one
    extreme only, that extreme's distance from the channel's median. Empty where no
    channel is held."""
    u = np.asarray(u, dtype=float)
    out = []
    for c in range(u.shape[1]):
        ends = held_ends(u[:, c])
        if ends is None or not (ends[2] or ends[3]):
            continue
        if ends[2] and ends[3]:
            out.append(0.5 * float(np.ptp(u[:, c])))
        else:
            end = u[:, c].max() if ends[2] else u[:, c].min()
            out.append(abs(float(end - np.median(u[:, c]))))
    return out
