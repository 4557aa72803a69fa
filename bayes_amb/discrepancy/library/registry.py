"""The registry of the physics library: one record per effect, in one vocabulary.

Every effect module (one per effect) defines its class and its :class:`EffectEntry`; this
module collects them. The diagnosis (candidates tried, diagnosis.json), the CLI
(``bayes-amb library``, ``bayes-amb diagnose --effects``), the report and the studies read
names, parameters, units, priors, fingerprints, equivalences and descriptions from here.

Adding an effect: write ``library/<name>.py`` with the class and its ENTRY, add the module
to ``_MODULES`` below, and add its identity test (tests/test_library_identity.py).
"""

from __future__ import annotations

from typing import Any

from bayes_amb.discrepancy.library import (
    actuator_2nd,
    actuator_gain,
    actuator_lag,
    bearing_coefficient,
    cross_coupling,
    flexible_mode,
    residual_flexibility,
    runout,
    sensor_delay,
    sensor_gain,
    sensor_lag,
    time_delay,
    unbalance,
)
from bayes_amb.discrepancy.library.base import Candidate, EffectEntry
from bayes_amb.rig import Rig

_MODULES = (actuator_lag, actuator_2nd, time_delay, sensor_lag, sensor_delay, actuator_gain,
            sensor_gain, cross_coupling, flexible_mode, residual_flexibility, unbalance, runout)

REGISTRY: dict[str, EffectEntry] = {m.ENTRY.name: m.ENTRY for m in _MODULES}
"""The physics effects by name, in the order the diagnosis lists them."""

NOMINAL_FAMILY: dict[str, EffectEntry] = {bearing_coefficient.ENTRY.name:
                                          bearing_coefficient.ENTRY}
"""Parameters of the nominal model tried as explanations first (select._choose)."""

VOCABULARY: tuple[str, ...] = tuple(REGISTRY)
"""The public names of the physics effects."""


def entry(name: str) -> EffectEntry:
    """The registry record of an effect (physics or nominal family)."""
    if name in REGISTRY:
        return REGISTRY[name]
    if name in NOMINAL_FAMILY:
        return NOMINAL_FAMILY[name]
    raise KeyError(f"unknown effect {name!r}; known: {', '.join(VOCABULARY)}")


def equivalents_of(key: str) -> tuple[tuple[str, str], ...]:
    """(other key, condition) for every candidate declared equivalent to ``key``
    ('effect@location'), from either side's declaration."""
    name, _, loc = key.partition("@")
    out: dict[str, str] = {}
    for e in REGISTRY.values():
        for q in e.equivalences:
            if e.name == name and q.this in ("*", loc):
                out.setdefault(q.other, q.when)
            elif q.other == key:
                this = e.locations[0] if q.this == "*" else q.this
                out.setdefault(f"{e.name}@{this}", q.when)
    return tuple(out.items())


def make_candidate(key: str) -> Candidate:
    """The candidate 'effect@location' (any location the effect accepts)."""
    name, _, loc = key.partition("@")
    e = entry(name)
    return e.make(loc or e.locations[0])


def all_candidates(names: tuple[str, ...] | list[str] | None = None,
                   representatives: bool = True, rig: Rig | None = None
                   ) -> tuple[Candidate, ...]:
    """Every candidate the diagnosis tries: each effect (``names``, default all) at each of
    its default locations, on ``rig`` when given (the shaft nodes of unbalance sit at 1/4,
    1/2 and 3/4 of its bearing span; without a rig, the reference rig's n14, n20, n27).
    With ``representatives``, a candidate declared equivalent to one already in the list is
    left out (its class is reported with the one tried), unless ``names`` asks for its
    effect alone.

    >>> from bayes_amb.rig import load_rig
    >>> all_candidates() == all_candidates(rig=load_rig("reference"))
    True
    >>> [c.location for c in all_candidates(["unbalance"], rig=load_rig("small_rotor"))]
    ['D1', 'D2', 'n11', 'n17', 'n23']
    """
    wanted = VOCABULARY if names is None else tuple(names)
    for n in wanted:
        entry(n)
    out: list[Candidate] = []
    keys: set[str] = set()
    for n in VOCABULARY:
        if n not in wanted:
            continue
        for loc in REGISTRY[n].locations_on(rig):
            c = REGISTRY[n].make(loc)
            if representatives and any(k in keys for k, _ in equivalents_of(c.key)):
                continue
            out.append(c)
            keys.add(c.key)
    return tuple(out)


def scanned_effects() -> tuple[str, ...]:
    """The effects that can be tried at every shaft node (:func:`node_scan`)."""
    return tuple(k for k, v in REGISTRY.items() if v.scan)


def node_scan(names: tuple[str, ...] | list[str], n_nodes: int,
              have: tuple[Candidate, ...] = ()) -> tuple[Candidate, ...]:
    """The effects ``names`` (each with a ``scan``: unbalance, cross_coupling) at every
    shaft node n1 .. n<n_nodes>, less the candidates ``have`` already holds. The diagnosis
    screens each such scan with one linearisation (family.py).

    >>> len(node_scan(["unbalance", "cross_coupling"], 40, all_candidates()))
    76
    """
    keys = {c.key for c in have}
    out = []
    for n in names:
        e = entry(n)
        if not e.scan:
            raise ValueError(f"effect {n!r} has no node scan; effects with one: "
                             + ", ".join(scanned_effects()))
        out += [c for c in (e.make(f"n{j}") for j in range(1, n_nodes + 1))
                if c.key not in keys]
    return tuple(out)


def library_table(with_nominal: bool = False) -> list[dict[str, Any]]:
    """One row per effect for listings (CLI, README, report): name, title, side, locations,
    parameters with units and priors, reported quantities, fingerprint, equivalences,
    description."""
    rows = []
    entries = list(REGISTRY.values()) + (list(NOMINAL_FAMILY.values()) if with_nominal else [])
    for e in entries:
        eq = sorted({f"{k} ({w})" for loc in e.locations
                     for k, w in equivalents_of(f"{e.name}@{loc}")})
        rows.append({
            "effect": e.name, "title": e.title, "side": e.side,
            "locations": list(e.locations) + ([e.scan] if e.scan else []),
            "repeatable": e.repeatable,
            "parameters": [{"name": q.name, "unit": q.unit, "meaning": q.meaning,
                            "plausible": None if q.plausible is None else list(q.plausible),
                            "why": q.why} for q in e.physical],
            "sampled": [{"name": s.name, "unit": s.unit, "prior": s.describe_prior(),
                         "null": s.null, "meaning": s.meaning} for s in e.sampled],
            "fingerprint": e.fingerprint, "equivalences": eq,
            "description": e.description})
    return rows


def markdown_table() -> str:
    """The library as a Markdown table (docs/diagnose.md): effect, parameters (units), sampled
    parameters (priors), fingerprint, equivalences."""
    head = ("| effect | parameters (units) | sampled (prior, null) | fingerprint | "
            "cannot be told from |\n|---|---|---|---|---|")
    lines = [head]
    for r in library_table():
        par = ", ".join(f"`{p['name']}` ({p['unit']}" + (
            "" if p["plausible"] is None else
            f"; plausible {p['plausible'][0]:g} to {p['plausible'][1]:g}") + ")"
            for p in r["parameters"])
        smp = ", ".join(f"`{s['name']}` {s['prior']}, {s['null']:g}" for s in r["sampled"])
        where = ", ".join(r["locations"])
        eq = "; ".join(r["equivalences"]) or "–"
        lines.append(f"| `{r['effect']}` ({r['title']}; at {where}"
                     f"{'; repeatable' if r['repeatable'] else ''}) | {par} | {smp} | "
                     f"{r['fingerprint']} | {eq} |")
    return "\n".join(lines)


def admissible(cand: Candidate, chosen: tuple[Candidate, ...] | list[Candidate]) -> bool:
    """Whether the greedy search may add ``cand`` to a model that has ``chosen``: not the
    same candidate twice; a second instance of an effect only if it is repeatable (at
    another location: two channels, two planes); not two own-sampling candidates (the
    delays add up to one); nothing declared equivalent to a chosen one."""
    keys = {c.key for c in chosen}
    if cand.key in keys:
        return False
    if cand.own_sampling and any(c.own_sampling for c in chosen):
        return False
    if not cand.entry.repeatable and any(c.effect == cand.effect for c in chosen):
        return False
    return not any(k in keys for k, _ in equivalents_of(cand.key))
