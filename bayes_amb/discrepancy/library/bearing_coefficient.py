"""A coefficient of the nominal model left out of the fit (tried first; select._choose)."""

from __future__ import annotations

from dataclasses import dataclass

from bayes_amb.discrepancy.library.base import (
    Candidate,
    EffectEntry,
    EffectParam,
    Quantity,
    Sampled,
)
from bayes_amb.inference.priors import Prior, default_prior
from bayes_amb.uncertainty import get_spec

BEARING_COEFFICIENTS = ("k_Ax", "k_Ay", "k_Bx", "k_By", "c_Ax", "c_Ay", "c_Bx", "c_By")
"""The eight bearing coefficients the diagnosis fits by default."""


@dataclass(frozen=True)
class BearingCoefficient(Candidate):
    """A stiffness or damping coefficient of the nominal model that was left out of the fit
    (``location`` is its name, e.g. k_Ax): before any physics is blamed, the nominal model
    with that coefficient freed is tried, and preferred unless physics is stronger by the
    threshold. Sampled: theta (null 0), the parameter's default
    prior, through its LFT column (eqs. 48-52)."""

    def params(self, ctx):
        return (EffectParam(self.location, default_prior(self.location), 0.0, "-"),)

    def lft_names(self):
        return (self.location,)

    def physical(self, draws, ctx):
        spec = get_spec(self.location)
        scale = spec.physical_scale(ctx.rig)
        return {"value": (draws[:, 0] * scale, spec.unit)}

    def describe(self, values):
        return (f"{self.location} differs from nominal by {values['value']:.3g} "
                "(a coefficient left out of the fit)")


def left_out_coefficients(fitted: tuple[str, ...]) -> tuple[Candidate, ...]:
    """A BearingCoefficient candidate for every bearing coefficient not in ``fitted``."""
    return tuple(BearingCoefficient("bearing_coefficient", n) for n in BEARING_COEFFICIENTS
                 if n not in fitted)


ENTRY = EffectEntry(
    name="bearing_coefficient", title="bearing coefficient left out of the fit",
    description=("a stiffness or damping coefficient of the nominal model that the fit held "
                 "at its nominal value"),
    fingerprint=("a frequency-dependent change of the loop at one bearing axis, like the "
                 "fitted coefficients'"),
    side="model", locations=BEARING_COEFFICIENTS,
    sampled=(Sampled("{location}", Prior("uniform", -1.0, 1.0), 0.0, "-",
                     "theta of the coefficient", "its default prior (bayes-amb params)"),),
    physical=(Quantity("value", "N/m or N s/m", "change from nominal"),),
    nominal_family=True, make=lambda loc: BearingCoefficient("bearing_coefficient", loc))
BearingCoefficient.entry = ENTRY
