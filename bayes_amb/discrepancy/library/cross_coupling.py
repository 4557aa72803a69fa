"""Cross-coupled stiffness at a bearing or disc (seals, impellers, magnetic cross-coupling),
and the direct stiffness and damping that come with it at a node (DirectTerms)."""

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


def mid_span(rig) -> str:
    """The shaft node nearest the middle of the bearing span (a balance-piston or
    interstage seal sits between the bearings): tried by default besides LOCATIONS.

    >>> from bayes_amb.rig import load_rig
    >>> mid_span(load_rig("reference")), mid_span(load_rig("small_rotor"))
    ('n20', 'n17')
    """
    a, b = rig.bearing_nodes["A"], rig.bearing_nodes["B"]
    return f"n{round((a + b) / 2)}"


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
    side="plant", locations=(*LOCATIONS, "n20"),       # n20: the reference rig's mid span
    scan="n1 .. n<number of nodes> (any shaft node)",
    rig_locations=lambda rig: (*LOCATIONS, mid_span(rig)),
    sampled=(Sampled("kxy_{location}", Prior("uniform", -10.0, 10.0), 0.0, "-",
                     "kxy / k_ref"),),
    physical=(Quantity("kxy", "N/m", "cross-coupled stiffness"),),
    repeatable=True, make=_make)
CrossCoupling.entry = ENTRY


@dataclass(frozen=True)
class DirectTerms(Candidate):
    """Isotropic direct stiffness K and damping C at a disc or shaft node (LFT parameters
    kd_LOCATION, cd_LOCATION): f_x = -K x - C vx, f_y = -K y - C vy. Not a candidate the
    diagnosis selects: the companion of an accepted cross-coupling away from the bearings
    (a seal's or impeller's force has direct terms beside its cross-coupled one, Childs
    1993), fitted so that the bearing coefficients do not take them (direct_terms.py).
    Sampled: K / k_ref, C / c_ref (null 0)."""

    def lft_names(self):
        return (f"kd_{self.location}", f"cd_{self.location}")

    def physical(self, draws, ctx):
        return {"K": (draws[:, 0] * ctx.rig.k_ref, "N/m"),
                "C": (draws[:, 1] * ctx.rig.c_ref, "N s/m")}

    def describe(self, values):
        return (f"direct stiffness {values['K']:.3g} N/m and damping {values['C']:.3g} N s/m "
                f"at {self.location}")


DIRECT_ENTRY = EffectEntry(
    name="direct_terms", title="direct stiffness and damping at a node",
    description=("the direct part of a seal's or impeller's force at a disc or shaft node: "
                 "f = -K q - C dq/dt, the same on x and y"),
    fingerprint=("none of its own at a bearing-free node: between the bearings it looks like "
                 "a change of both bearings' k and c"),
    side="plant", locations=("D1", "D2"), scan="n1 .. n<number of nodes> (any shaft node)",
    sampled=(Sampled("kd_{location}", Prior("uniform", -10.0, 10.0), 0.0, "-", "K / k_ref"),
             Sampled("cd_{location}", Prior("uniform", -10.0, 10.0), 0.0, "-", "C / c_ref")),
    physical=(Quantity("K", "N/m", "direct stiffness"), Quantity("C", "N s/m", "direct damping")),
    make=lambda location: DirectTerms("direct_terms", location))
DirectTerms.entry = DIRECT_ENTRY
