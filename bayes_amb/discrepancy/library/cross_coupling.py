"""Cross-coupled stiffness at a bearing or disc (seals, impellers, magnetic cross-coupling)."""

from __future__ import annotations

from dataclasses import dataclass

from bayes_amb.discrepancy.library.base import Candidate, EffectEntry, Quantity, Sampled
from bayes_amb.inference.priors import Prior
from bayes_amb.rig import node_label


@dataclass(frozen=True)
class CrossCoupling(Candidate):
    """Cross-coupled stiffness kxy at a bearing or disc (f_x = -kxy y, f_y = +kxy x), through
    the LFT parameter kxy_LOCATION (eqs. 48-52). Sampled: theta = kxy / k_ref (null 0)."""

    def lft_names(self):
        return (f"kxy_{self.location}",)

    def physical(self, draws, ctx):
        return {"kxy": (draws[:, 0] * ctx.rig.k_ref, "N/m")}

    def describe(self, values):
        return f"cross-coupled stiffness {values['kxy']:.3g} N/m at {self.location}"


LOCATIONS = ("A", "B", "D1", "D2")


def _make(location: str) -> CrossCoupling:
    if location not in LOCATIONS and node_label(location) is None:
        raise ValueError(f"cross_coupling: location {location!r} is not one of "
                         f"{', '.join(LOCATIONS)} or n<node>")
    return CrossCoupling("cross_coupling", location)


ENTRY = EffectEntry(
    name="cross_coupling", title="cross-coupled stiffness",
    description=("a stiffness coupling the x and y motion at one place (seal or impeller "
                 "forces): f_x = -kxy y, f_y = +kxy x"),
    fingerprint=("x-y coupling at one location: the residual of one axis is driven by the "
                 "excitation of the other, with opposite signs (forward/backward whirl "
                 "asymmetry)"),
    side="plant", locations=LOCATIONS, scan="n1 .. n<number of nodes> (any shaft node)",
    sampled=(Sampled("kxy_{location}", Prior("uniform", -10.0, 10.0), 0.0, "-",
                     "kxy / k_ref"),),
    physical=(Quantity("kxy", "N/m", "cross-coupled stiffness"),),
    repeatable=True, make=_make)
CrossCoupling.entry = ENTRY
