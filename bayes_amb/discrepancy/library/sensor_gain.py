"""Sensor gain: a calibration error of one displacement sensor."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayes_amb.discrepancy.library.base import Candidate, EffectEntry, Quantity, Sampled
from bayes_amb.inference.priors import Prior
from bayes_amb.rig import CHANNELS


@dataclass(frozen=True)
class SensorGain(Candidate):
    """A calibration error of one displacement sensor: y_meas = (1 + g) y on that channel.
    Sampled: g (null 0), prior normal(0, 0.1)."""

    def discrete(self, Ad, Bd, Cd, phi, ctx):
        j = CHANNELS.index(self.location)
        Cd = np.array(np.broadcast_to(Cd, (phi.shape[0], *Cd.shape[-2:])))
        Cd[:, j, :] *= 1.0 + phi[:, 0][:, None]
        return Ad, Bd, Cd

    def physical(self, draws, ctx):
        return {"gain": (draws[:, 0], "-")}

    def describe(self, values):
        return f"sensor gain error {100 * values['gain']:+.1f} % on channel {self.location}"


ENTRY = EffectEntry(
    name="sensor_gain", title="sensor gain",
    description="a calibration error of one displacement sensor (y_meas = (1 + gain) y)",
    fingerprint=("a broadband scale error of one output row: that channel's response to every "
                 "input changes by the same factor"),
    side="sensor", locations=CHANNELS,
    sampled=(Sampled("gain_{location}", Prior("normal", 0.0, 0.1), 0.0, "-",
                     "relative sensitivity error"),),
    physical=(Quantity("gain", "-", "relative sensitivity error", plausible=(-0.5, 0.5),
                       why="a calibrated displacement probe is not off by half"),),
    repeatable=True, make=lambda loc: SensorGain("sensor_gain", loc))
SensorGain.entry = ENTRY
