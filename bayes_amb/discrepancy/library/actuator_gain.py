"""Actuator gain: the force constant ki of one axis is off (ki_true = (1 + g) ki)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayes_amb.discrepancy.library.base import Candidate, EffectEntry, Quantity, Sampled
from bayes_amb.inference.priors import Prior
from bayes_amb.rig import CHANNELS


@dataclass(frozen=True)
class ActuatorGain(Candidate):
    """A force-constant error on one actuator axis: the plant sees (1 + g) times the current
    of that coil (G diag(1 + g e_j), a column of G scaled). Sampled: g (null 0)."""

    def continuous(self, A, B, C, phi, ctx):
        j = CHANNELS.index(self.location)
        B = np.array(B, copy=True)
        B[:, :, j] *= 1.0 + phi[:, 0][:, None]
        return A, B, C

    def physical(self, draws, ctx):
        return {"gain": (draws[:, 0], "-")}

    def describe(self, values):
        return (f"actuator force-constant error {100 * values['gain']:+.1f} % on axis "
                f"{self.location}")


ENTRY = EffectEntry(
    name="actuator_gain", title="actuator gain (ki)",
    description=("the force constant ki of one bearing axis differs from its nominal value "
                 "(ki_true = (1 + gain) ki): a gain on one current input"),
    fingerprint=("a broadband scale error of one input column: every channel's response to "
                 "that axis's current changes by the same factor"),
    side="actuator", locations=CHANNELS,
    sampled=(Sampled("act_gain_{location}", Prior("normal", 0.0, 0.1), 0.0, "-",
                     "relative ki error"),),
    physical=(Quantity("gain", "-", "relative ki error (ki_true / ki - 1)",
                       plausible=(-0.5, 0.5),
                       why="a bearing's force constant is not off by half of its design "
                           "value"),),
    repeatable=True, make=lambda loc: ActuatorGain("actuator_gain", loc))
ActuatorGain.entry = ENTRY
