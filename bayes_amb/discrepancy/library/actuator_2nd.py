"""Second-order actuator dynamics: natural frequency and damping of the current-to-force
path (amplifier bandwidth with eddy currents), per bearing or both."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bayes_amb.discrepancy.library.base import (
    Candidate,
    EffectEntry,
    Quantity,
    Sampled,
    append_states,
    channels_of,
    corner_hz,
    live_inverse,
    positive_rows,
    time_constant_s,
    where_text,
)
from bayes_amb.inference.priors import Prior


def input_second_order(A: NDArray, B: NDArray, C: NDArray, tau: NDArray, zeta: NDArray,
                       chans: list[int]) -> tuple[NDArray, NDArray, NDArray]:
    """Append i'' + 2 zeta wn i' + wn^2 i = wn^2 w (tau = 1/wn, s) on the input channels,
    in the well-scaled states (i, tau i'): d/dt [i, v] = [v, w - i - 2 zeta v] / tau. Rows
    with tau = 0 get inert states (no filter)."""
    q = len(chans)
    A, B, C, n = append_states(A, B, C, 2 * q)
    live, inv = live_inverse(tau)
    for j, ch in enumerate(chans):
        i, v = n + 2 * j, n + 2 * j + 1
        A[:, i, i] = A[:, v, v] = -1.0                       # inert rows
        col = B[:, :n, ch].copy()
        L = np.flatnonzero(live)
        A[L, i, i] = 0.0
        A[L, i, v] = inv[L]
        A[L, v, i] = -inv[L]
        A[L, v, v] = -2.0 * zeta[L] * inv[L]
        A[L, :n, i] = col[L]
        B[L, :n, ch] = 0.0
        B[L, v, ch] = inv[L]
    return A, B, C


@dataclass(frozen=True)
class Actuator2nd(Candidate):
    """Second-order current-to-force dynamics wn^2 / (s^2 + 2 zeta wn s + wn^2) on the coils
    of one or both bearings. Sampled: tau = 1/wn in ms (null 0) and zeta."""

    def structure(self, phi, ctx):
        return positive_rows(phi)

    def continuous(self, A, B, C, phi, ctx):
        tau = time_constant_s(phi)
        zeta = np.clip(np.nan_to_num(phi[:, 1], nan=0.7), 1e-3, None)
        return input_second_order(A, B, C, tau, zeta, channels_of(self.location))

    def physical(self, draws, ctx):
        return {"natural_hz": (corner_hz(draws), "Hz"), "zeta": (draws[:, 1], "-")}

    def describe(self, values):
        return (f"second-order actuator dynamics {values['natural_hz']:.0f} Hz, damping ratio "
                f"{values['zeta']:.2f} at {where_text(self.location)}")


ENTRY = EffectEntry(
    name="actuator_2nd", title="second-order actuator dynamics",
    description=("current-to-force dynamics of second order (amplifier bandwidth and eddy "
                 "currents), natural frequency and damping, per bearing or both"),
    fingerprint=("magnitude and phase change above a few hundred Hz on the channels of the "
                 "bearing(s), with a resonant peak when lightly damped; input side"),
    side="actuator", locations=("both", "A", "B"),
    sampled=(Sampled("act2_ms_{location}", Prior("uniform", 0.0, 0.5), 0.0, "ms",
                     "1/(2 pi natural frequency); 0: no dynamics"),
             Sampled("act2_zeta_{location}", Prior("uniform", 0.05, 2.0), 0.7, "-",
                     "damping ratio (free at the null)")),
    physical=(Quantity("natural_hz", "Hz", "natural frequency"),
              Quantity("zeta", "-", "damping ratio")),
    repeatable=True, make=lambda loc: Actuator2nd("actuator_2nd", loc))
Actuator2nd.entry = ENTRY
