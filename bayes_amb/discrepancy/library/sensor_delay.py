"""Sensor-side delay: between the rotor displacement and its sample."""

from __future__ import annotations

from dataclasses import dataclass

from bayes_amb.discrepancy.library.base import EffectEntry, Equivalence, Quantity, Sampled
from bayes_amb.discrepancy.library.time_delay import PRIOR_TEXT, TimeDelay
from bayes_amb.inference.priors import Prior


@dataclass(frozen=True)
class SensorDelay(TimeDelay):
    """A delay between the displacement and its sample (sensor electronics, anti-alias
    filter group delay, sampling skew), common to all four channels. The same scalar delay
    on every channel commutes with G: its u -> y map is that of the control delay, so it is
    computed as one (the phase of a 1x line absorbs the rest)."""

    def describe(self, values):
        return f"sensor-side delay {values['delay_s'] * 1e6:.1f} us"



ENTRY = EffectEntry(
    name="sensor_delay", title="sensor-side delay",
    description=("delay between the rotor displacement and its sample (probe electronics, "
                 "anti-alias filter group delay), common to all four channels"),
    fingerprint=("phase lag growing linearly with frequency, no change of magnitude, on "
                 "every channel (as the control delay)"),
    side="sensor", locations=("sensors",),
    sampled=(Sampled("sen_delay_ms", Prior("uniform", 0.0, 0.4), 0.0, "ms", "delay",
                     PRIOR_TEXT),),
    physical=(Quantity("delay_s", "s", "delay"),),
    equivalences=(Equivalence("*", "time_delay@controller", "same delay: a delay common to "
                              "all channels commutes with G"),),
    make=lambda loc: SensorDelay("sensor_delay", loc))
SensorDelay.entry = ENTRY
