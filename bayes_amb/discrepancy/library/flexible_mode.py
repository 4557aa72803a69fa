"""Flexible modes: bending-mode pairs of the FE model that the 8-state model leaves out."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayes_amb.discrepancy.library.base import (
    Candidate,
    EffectEntry,
    Quantity,
    Sampled,
)
from bayes_amb.inference.priors import Prior

N_PAIRS = 3
"""Bending pairs the diagnosis tries (on the reference rig at 31 500 rpm: 1027/1286,
2542/3095 and 4466/5051 Hz backward/forward whirl; the last is aliased at 10 kHz)."""


@dataclass(frozen=True)
class FlexibleMode(Candidate):
    """The reduced model extended with bending-mode pair ``pair`` of the FE model (its
    backward and forward whirl modes, four states). Sampled: the log of a frequency scale of
    the pair (prior sd 3 %) and the log of a damping multiplier (prior lognormal, sd a factor
    e). The FE prediction is the null (0, 0). Repeatable: each pair is its own instance, and
    the model keeps exactly the pairs its instances name (a pair not named is left out, not
    carried at its FE values)."""

    pair: int = 1

    def bending_pairs(self):
        return (self.pair,)

    def modal(self, A, phi, ctx, first):
        s = np.exp(np.clip(phi[:, 0], -0.5, 0.5))
        md = np.exp(np.clip(phi[:, 1], -6.0, 6.0))
        A = A.copy()
        for i in range(first, first + 4, 2):
            sig, om = A[:, i, i], A[:, i + 1, i]
            mod = np.hypot(sig, om)
            zeta = np.clip(-sig / mod * md, -0.99, 0.99)
            mod2 = mod * s
            sig2 = -zeta * mod2
            om2 = np.sign(om) * mod2 * np.sqrt(1 - zeta**2)
            A[:, i, i] = A[:, i + 1, i + 1] = sig2
            A[:, i + 1, i] = om2
            A[:, i, i + 1] = -om2
        return A

    def physical(self, draws, ctx):
        j = 2 * (self.pair - 1)
        return {"frequency_hz": (ctx.bending_hz[j] * np.exp(draws[:, 0]), "Hz"),
                "forward_hz": (ctx.bending_hz[j + 1] * np.exp(draws[:, 0]), "Hz"),
                "damping_ratio": (ctx.bending_zeta[j] * np.exp(draws[:, 1]), "-")}

    def describe(self, values):
        return (f"bending pair {self.pair} near {values['frequency_hz']:.0f} Hz "
                f"(forward whirl {values['forward_hz']:.0f} Hz, damping ratio "
                f"{values['damping_ratio']:.2g}) missing from the model")


def _location(pair: int) -> str:
    return f"bending pair {pair}"


def _make(location: str) -> FlexibleMode:
    try:
        pair = int(location.rsplit(" ", 1)[-1])
    except ValueError:
        raise ValueError(f"flexible_mode: location {location!r} is not 'bending pair <k>'"
                         ) from None
    return FlexibleMode("flexible_mode", location, pair)


ENTRY = EffectEntry(
    name="flexible_mode", title="flexible (bending) modes",
    description=("a bending-mode pair (backward and forward whirl) of the FE rotor, which "
                 "the 8-state rigid-body model leaves out, with its frequency and damping "
                 "scaled; one instance per pair"),
    fingerprint=("a narrow band near a bending frequency of the FE model, on the channels "
                 "where the mode shape is seen"),
    side="plant", locations=tuple(_location(k) for k in range(1, N_PAIRS + 1)),
    sampled=(Sampled("log_freq_scale_{location}", Prior("normal", 0.0, 0.03), 0.0, "-",
                     "log of the pair's frequency scale (FE: 0)"),
             Sampled("log_damping_scale_{location}", Prior("normal", 0.0, 1.0), 0.0, "-",
                     "log of the pair's damping multiplier (FE: 0)")),
    physical=(Quantity("frequency_hz", "Hz", "backward-whirl bending frequency"),
              Quantity("forward_hz", "Hz", "forward-whirl bending frequency"),
              Quantity("damping_ratio", "-", "backward-whirl damping ratio",
                       plausible=(0.0, 0.2), relative=3.0,
                       why="a shaft's bending mode is lightly damped (about 0.001-0.05, or "
                           "what the rig's own material damping gives it); above 0.2, or 3 "
                           "times the FE model's ratio where that is more, it is not this "
                           "mode")),
    repeatable=True, make=_make)
FlexibleMode.entry = ENTRY


def past_kept(candidates: tuple[Candidate, ...], kept: int) -> tuple[Candidate, ...]:
    """The default candidates for a nominal model that already keeps bending pairs
    1..``kept`` (the control band's, inference/model_band.py): each flexible-mode candidate
    moved to the pair as many places past them, so that the diagnosis tries the first
    N_PAIRS pairs the model leaves out, as it does on an 8-state model.

    >>> from bayes_amb.discrepancy.library import all_candidates
    >>> [c.location for c in past_kept(all_candidates(["flexible_mode"]), 1)]
    ['bending pair 2', 'bending pair 3', 'bending pair 4']
    """
    if kept <= 0:
        return candidates
    return tuple(_make(_location(c.pair + kept)) if isinstance(c, FlexibleMode) else c
                 for c in candidates)
