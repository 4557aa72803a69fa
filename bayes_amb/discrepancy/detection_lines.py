"""The classical detection lines of a random-odd multisine (Pintelon & Schoukens 2012,
ch. 4), a linearity data check.

An odd multisine excites only odd multiples of the record's base frequency 1/(N dt), and
leaves one odd line in each small group out (signals.odd_multisine). In a linear loop,
whatever reaches y and u at the left-out odd lines and at the even lines is noise, with the
same smooth spectrum on both (they interleave). An odd nonlinearity (an amplifier clip,
the magnetic force at large orbits, a probe's cubic characteristic) turns the excited odd
lines into odd combinations of them, which are odd lines again: the left-out odd lines then
carry more power than their even neighbours. Even-order distortion lands on the even lines,
where the loop's start transient and the leakage of the excited lines land as well, so
only the odd test is a check (the even ratio is reported).

Per frequency band and channel of y and u: R = mean |Z|^2 on the left-out odd lines / mean
|Z|^2 on the even lines, F(2 n_odd, 2 n_even) distributed under a linear loop (each |Z|^2
is its local spectrum times an exponential variable). The check fails where R's p-value is
below ALPHA / (the number of tests) and R >= MIN_RATIO (a distortion an engineer can see).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from bayes_amb.io.recording import Recording
from bayes_amb.rig import CHANNELS

ALPHA = 1e-4
"""Family-wise level of the odd-line test (Bonferroni over bands and channels)."""

MIN_RATIO = 1.5
"""The smallest odd / even power ratio reported as distortion (1.8 dB)."""

N_BANDS = 6
MIN_LINES = 8


@dataclass(frozen=True)
class DetectionLines:
    """The test's outcome: whether the record has an odd-multisine design at all
    (``design``), the failing (signal, band Hz, ratio, p) and the largest odd ratio."""

    design: bool
    failing: list[dict[str, Any]] = field(default_factory=list)
    worst: dict[str, Any] | None = None

    @property
    def found(self) -> bool:
        return bool(self.failing)

    def to_dict(self) -> dict[str, Any]:
        return {"odd_multisine": self.design, "failing": self.failing, "worst": self.worst}

    def problem(self) -> str:
        """One phrase naming the strongest distortion."""
        w = max(self.failing, key=lambda f: f["ratio"])
        lo, hi = w["band_hz"]
        return (f"{w['signal']} carries {10 * np.log10(w['ratio']):.1f} dB more power on the "
                f"odd multisine's left-out odd lines than on the even lines in "
                f"{lo:.0f}-{hi:.0f} Hz (p {w['p']:.1g}; {len(self.failing)} band(s) and "
                "channel(s) in all): odd nonlinear distortion")


def odd_design(x: NDArray) -> tuple[NDArray, NDArray] | None:
    """(left-out odd bins, even bins) inside the excited band of an odd-multisine
    excitation x (N, m), or None when x is not one (an excited even bin, too few lines)."""
    X = np.fft.rfft(np.asarray(x, dtype=float) - np.mean(x, axis=0), axis=0)
    P = np.sum(np.abs(X) ** 2, axis=1)
    if not np.any(P > 0):
        return None
    exc = P > 1e-8 * P.max()
    k = np.flatnonzero(exc)
    if k.size < 2 * MIN_LINES or np.any(k % 2 == 0):
        return None
    odd = np.arange(k.min(), k.max() + 1, 2)
    left = odd[~exc[odd]]
    if left.size < MIN_LINES:
        return None
    return left, np.arange(k.min() + 1, k.max(), 2)


def detection_line_test(rec: Recording) -> DetectionLines:
    """The odd-line test on y and u of a record excited by an odd multisine (all its
    excitation ports together); design False otherwise."""
    x = sum(np.asarray(v, dtype=float) for v in rec.excitation.values())
    design = odd_design(x)
    if design is None:
        return DetectionLines(False)
    left, even = design
    n = rec.t.size
    f = np.fft.rfftfreq(n, rec.dt)
    lo, hi = max(f[even[0]], f[1]), f[even[-1]]
    edges = np.geomspace(lo, hi * (1 + 1e-9), N_BANDS + 1)
    tests = []
    for g, v in (("y", rec.y), ("u", rec.u)):
        Z = np.abs(np.fft.rfft(np.asarray(v, dtype=float), axis=0)) ** 2
        for a, b in itertools.pairwise(edges):
            lo_b = left[(f[left] >= a) & (f[left] < b)]
            ev_b = even[(f[even] >= a) & (f[even] < b)]
            if lo_b.size < MIN_LINES or ev_b.size < MIN_LINES:
                continue
            for c, ch in enumerate(CHANNELS):
                pe = float(np.mean(Z[ev_b, c]))
                if pe <= 0:
                    continue
                r = float(np.mean(Z[lo_b, c])) / pe
                p = float(stats.f.sf(r, 2 * lo_b.size, 2 * ev_b.size))
                tests.append({"signal": f"{g}_{ch}", "band_hz": [float(a), float(b)],
                              "ratio": r, "p": p})
    if not tests:
        return DetectionLines(True)
    level = ALPHA / len(tests)
    failing = [t for t in tests if t["p"] < level and t["ratio"] >= MIN_RATIO]
    return DetectionLines(True, failing, max(tests, key=lambda t: t["ratio"]))
