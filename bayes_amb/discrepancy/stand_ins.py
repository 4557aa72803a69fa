"""Stand-ins: named effects fitted where their own physics does not allow them.

An effect the library has can still be the best fit to an effect it lacks. A half-order
lag of the bearing force (eddy currents) is then fitted as a first-order lag plus a
"bending mode" with a damping ratio of 0.7, or a residual flexibility of 5 % of the FE
value: the data accept the model, but the fitted numbers say it is not the physics its
name claims. Each library quantity may declare the range its physics allows
(``Quantity.plausible``, with the reason in ``Quantity.why``). An effect whose whole 90 %
interval lies outside that range is a stand-in; the diagnosis then reports it, marks the
naming tentative (as for unexplained structure, unexplained.py) and averages the
coefficients after with the nominal model's (direct_terms.averaged).

The range is the physics' own, written with the library, never fitted to recordings; an
interval merely reaching past it is not enough: the data must put the effect outside.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from bayes_amb.discrepancy.library.registry import REGISTRY

if TYPE_CHECKING:
    from bayes_amb.results.diagnosis import StandIn


def stand_ins(effects: list[dict[str, Any]],
              nominal: dict[tuple[str, str], dict[str, float]] | None = None
              ) -> list[dict[str, Any]]:
    """The stand-ins among effect summaries (fitstats.effect_summaries): per effect and
    quantity whose 90 % interval lies wholly outside its plausible range, the effect,
    location, quantity, interval, range, reason and one line. ``nominal`` (fitstats.
    nominal_physical): each effect's quantities in the rig's own model, which widen the
    range of a ``Quantity.relative``."""
    out = []
    for e in effects:
        entry = REGISTRY.get(e["effect"])
        if entry is None:
            continue
        for q in entry.physical:
            if q.plausible is None or q.name not in e["params"]:
                continue
            lo, hi = e["params"][q.name]["hdi90"]
            a, b = q.plausible
            own = (nominal or {}).get((e["effect"], e["location"]), {}).get(q.name)
            if q.relative is not None and own is not None:
                b = max(b, q.relative * abs(own))
            if hi >= a and lo <= b:
                continue
            unit = "" if q.unit == "-" else f" {q.unit}"
            out.append({
                "effect": e["effect"], "location": e["location"], "quantity": q.name,
                "hdi90": [lo, hi], "plausible": [a, b], "why": q.why,
                "line": (f"{entry.title} at {e['location']}: {q.name} 90 % interval "
                         f"[{lo:.3g}, {hi:.3g}]{unit} lies outside the plausible "
                         f"[{a:g}, {b:g}], since {q.why}")})
    return out


def stand_in_sentence(found: list[StandIn]) -> str:
    """The plain-language sentence on stand-ins ('' without any)."""
    if not found:
        return ""
    return (" ".join(f"Stand-in: {s.line}." for s in found) + " The data accept the "
            "named model, but not as the physics its names claim: those effects stand in "
            "for physics the library lacks, so the naming is tentative.")
