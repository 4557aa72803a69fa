"""Runout: a synchronous 1x signal seen by one displacement sensor (target out-of-round)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayes_amb.discrepancy.library.base import EffectEntry, Quantity, Sampled, SynchronousLine
from bayes_amb.inference.priors import Prior
from bayes_amb.rig import CHANNELS


@dataclass(frozen=True)
class Runout(SynchronousLine):
    """Synchronous runout at one sensor: the probe adds a cos(Omega t + phase) to the
    measured displacement (mechanical or electrical out-of-roundness of the target), a
    signal on the measurement, not a force. Sampled: a = amp cos(phase), b = amp sin(phase)
    in units of 1e-7 m (null 0)."""

    UNIT = 1e-7

    def line_output(self, ctx):
        e = np.zeros(len(CHANNELS))
        e[CHANNELS.index(self.location)] = 1.0
        return e

    def physical(self, draws, ctx):
        a, b = draws[:, 0] * self.UNIT, draws[:, 1] * self.UNIT
        return {"amplitude_m": (np.hypot(a, b), "m"),
                "phase_deg": (np.rad2deg(np.arctan2(b, a)), "deg")}

    def describe(self, values):
        return (f"runout {values['amplitude_m'] * 1e6:.3g} um at sensor {self.location} "
                f"(phase {values['phase_deg']:.0f} deg)")


ENTRY = EffectEntry(
    name="runout", title="sensor runout",
    description=("a synchronous signal added to one sensor's measurement by an out-of-round "
                 "or inhomogeneous target: seen by the controller, but not a force"),
    fingerprint=("a line at 1x the running speed on the measurement (through M~, like r1), "
                 "strongest on its own channel; it does not depend on the excitation"),
    side="sensor", locations=CHANNELS,
    sampled=(Sampled("run_a_{location}", Prior("normal", 0.0, 10.0), 0.0, "1e-7 m",
                     "amp cos(phase)"),
             Sampled("run_b_{location}", Prior("normal", 0.0, 10.0), 0.0, "1e-7 m",
                     "amp sin(phase)")),
    physical=(Quantity("amplitude_m", "m", "runout amplitude"),
              Quantity("phase_deg", "deg", "angle at t = 0 of the record")),
    repeatable=True, make=lambda loc: Runout("runout", loc))
Runout.entry = ENTRY
