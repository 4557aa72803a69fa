"""Sensor lag: first-order dynamics of the displacement probes' electronics."""

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


def output_lag(A: NDArray, B: NDArray, C: NDArray, tau: NDArray, chans: list[int]
               ) -> tuple[NDArray, NDArray, NDArray]:
    """Append s' = (y - s)/tau on the output channels ``chans``; those channels then deliver
    s. Rows with tau = 0 get inert states (not observed)."""
    q = len(chans)
    A, B, C, n = append_states(A, B, C, q)
    live, inv = live_inverse(tau)
    idx = n + np.arange(q)
    A[:, idx, idx] = -inv[:, None]
    for j, ch in enumerate(chans):
        row = C[:, ch, :n].copy()
        A[live, n + j, :n] = inv[live, None] * row[live]
        C[live, ch, :] = 0.0
        C[live, ch, n + j] = 1.0
    return A, B, C


@dataclass(frozen=True)
class SensorLag(Candidate):
    """First-order probe dynamics 1/(1 + s tau) on the channels of one or both bearings, as
    a continuous added state per channel, sampled exactly with the plant. Sampled: tau in ms
    (null 0)."""

    def structure(self, phi, ctx):
        return positive_rows(phi)

    def continuous(self, A, B, C, phi, ctx):
        tau = time_constant_s(phi)
        return output_lag(A, B, C, tau, channels_of(self.location))

    def physical(self, draws, ctx):
        return {"bandwidth_hz": (corner_hz(draws), "Hz")}

    def describe(self, values):
        return (f"sensor bandwidth {values['bandwidth_hz']:.0f} Hz at "
                f"{where_text(self.location)}")


ENTRY = EffectEntry(
    name="sensor_lag", title="sensor lag",
    description=("first-order dynamics of the displacement probes (sensor electronics, "
                 "anti-alias filter), per bearing or both"),
    fingerprint=("phase lag growing with frequency and a roll-off above the sensor bandwidth "
                 "on the rows of the lagged channels; output side"),
    side="sensor", locations=("both", "A", "B"),
    sampled=(Sampled("sen_lag_ms_{location}", Prior("uniform", 0.0, 1.6), 0.0, "ms",
                     "time constant 1/(2 pi bandwidth); 0: no lag"),),
    physical=(Quantity("bandwidth_hz", "Hz", "-3 dB bandwidth of the probe"),),
    equivalences=(Equivalence("both", "actuator_lag@both", "same bandwidth on all four "
                              "channels: a scalar h commutes with G"),),
    repeatable=True, make=lambda loc: SensorLag("sensor_lag", loc))
SensorLag.entry = ENTRY
