"""Actuator lag: a first-order current-to-force lag on the coils of one or both bearings."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bayes_amb.discrepancy.library.base import (
    Candidate,
    EffectEntry,
    Equivalence,
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


def input_lag(A: NDArray, B: NDArray, C: NDArray, tau: NDArray, chans: list[int]
              ) -> tuple[NDArray, NDArray, NDArray]:
    """Append a first-order lag i' = (w - i)/tau on the input channels ``chans``: the plant
    is driven by i instead of w. Rows with tau = 0 get inert states (decoupled, pole -1/s),
    so that a batch may mix them; their map is the plant without lag."""
    q = len(chans)
    A, B, C, n = append_states(A, B, C, q)
    live, inv = live_inverse(tau)
    idx = n + np.arange(q)
    A[:, idx, idx] = -inv[:, None]
    for j, ch in enumerate(chans):
        col = B[:, :n, ch].copy()
        A[live, :n, n + j] = col[live]
        B[live, :n, ch] = 0.0
        B[live, n + j, ch] = inv[live]
    return A, B, C


@dataclass(frozen=True)
class ActuatorLag(Candidate):
    """First-order current-to-force lag 1/(1 + s tau) on the coils of one or both bearings
    (amplifier current loop and coil inductance), as a continuous added state per lagged
    coil, sampled exactly with the plant (so it composes with a delay). Sampled: tau in ms
    (null 0)."""

    def structure(self, phi, ctx):
        return positive_rows(phi)

    def continuous(self, A, B, C, phi, ctx):
        tau = time_constant_s(phi)
        return input_lag(A, B, C, tau, channels_of(self.location))

    def physical(self, draws, ctx):
        return {"bandwidth_hz": (corner_hz(draws), "Hz")}

    def describe(self, values):
        return (f"actuator bandwidth {values['bandwidth_hz']:.0f} Hz at "
                f"{where_text(self.location)}")


ENTRY = EffectEntry(
    name="actuator_lag", title="actuator lag",
    description=("first-order lag between the commanded current and the force (amplifier "
                 "current loop, coil inductance, eddy currents), per bearing or both"),
    fingerprint=("phase lag growing with frequency and a magnitude roll-off above the "
                 "actuator bandwidth, on the channels of the lagged bearing(s); input side"),
    side="actuator", locations=("both", "A", "B"),
    sampled=(Sampled("act_lag_ms_{location}", Prior("uniform", 0.0, 1.6), 0.0, "ms",
                     "time constant 1/(2 pi bandwidth); 0: no lag"),),
    physical=(Quantity("bandwidth_hz", "Hz", "-3 dB bandwidth of the current-to-force "
                       "path"),),
    equivalences=(Equivalence("both", "sensor_lag@both", "same bandwidth on all four "
                              "channels: a scalar h commutes with G"),),
    repeatable=True, make=lambda loc: ActuatorLag("actuator_lag", loc))
ActuatorLag.entry = ENTRY
