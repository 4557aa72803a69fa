"""Diagnosis across several recordings (issue 29, first path): each record diagnosed, and
every effect named in one record tested in all the others.

A record that names an effect gives a hypothesis chosen before the other records are looked
at, so in each other record it is tested alone: that record's nominal model (as its own
diagnosis fitted it, so no fit is repeated) extended by that one candidate, its log Bayes
factor with prior odds 1 (no multiplicity: one pre-specified hypothesis), present when
above the diagnosis' threshold (absent when the candidate gives no likelihood gain at all,
which the search does not refine). An effect present in every record is a property of the
machine; one present in some records only depends on what differs between them (speed,
amplitude, time), and the table says which.

Its size tells more. Where it was fitted in two or more records, the records' posteriors
of each of its physical quantities are tested for equality (Cochran's Q,
inference/consistency.py). An unbalance has the same u (kg m) at every speed and a runout
the same amplitude at the probe; a 1x line fitted as the wrong one of the two has a size
that changes with speed (a runout read as unbalance needs u ~ 1 / Omega^2), so a size that
disagrees across speeds says the name is wrong. A cross-coupling whose kxy changes with
speed is a seal's or an impeller's (their forces grow with speed), itself a finding.

Together the records can name what none names alone (joint_search). Each record's last
round screened every physics candidate on top of what that record's diagnosis accepted;
the screens' likelihood gains add up across records. A candidate of an effect no record
named whose summed gain could pass the threshold (sum over the records of its gain minus
the Occam factor the screen does not see, as the records' own refined candidates of that
effect show it, - log K > threshold; K the candidates of a round) is fitted in every
record on top of its accepted effects, and its log Bayes factors are added: the Bayes
factor of "this effect is in every record, with a size of its own in each" against "in
none", the records being independent. With the prior odds 1/K each record's search uses,
it is named when that joint log posterior odds passes the same threshold. At most
JOINT_FITS candidates are fitted, the best by that sum, so the search costs a few fits per
record, and only when the screens point somewhere.

Records at different excitation levels also tell the magnets' force law from a stiffness
change, which one record cannot: the stiffnesses a linear fit reads rise with the current
as ks (1 + <(i/i0)^2>), so a regression of the records' stiffness estimates on their levels
gives the bias i0 and the small-signal stiffnesses (levels.py, the ``force_law`` block).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from bayes_amb.discrepancy.diagnose import DiagnoseOptions, diagnose
from bayes_amb.discrepancy.fitstats import draws, effect_summaries
from bayes_amb.discrepancy.levels import force_law_levels
from bayes_amb.discrepancy.library import make_candidate
from bayes_amb.discrepancy.library.registry import NOMINAL_FAMILY
from bayes_amb.discrepancy.select import NODE_FREE, posterior_log_odds, try_candidate
from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.consistency import agreement
from bayes_amb.inference.priors import Prior
from bayes_amb.io.recording import Recording
from bayes_amb.results.diagnosis import CandidateScore, Diagnosis, Explanation
from bayes_amb.results.records import FILE, RecordsDiagnosis


def _size_of(e: Explanation, d: Diagnosis) -> dict[str, Any]:
    """The physical size of a record's explanation for the agreement across records: its
    parameters, or for an unbalance its two-plane balancing answer (u per correction
    plane, which does not depend on the node the search named; the u at that node does)."""
    if e.effect in NODE_FREE and d.balancing is not None and d.balancing.planes:
        return {f"u_{pl.plane}": pl.u_kgm.to_dict() for pl in d.balancing.planes}
    return {k: v.to_dict() for k, v in e.params.items()}


def _named_elsewhere(key: str, d: Diagnosis) -> Explanation | None:
    """The explanation of a record that names the effect of ``key`` at another location,
    for an effect in NODE_FREE (else None)."""
    effect = key.split("@")[0]
    if effect not in NODE_FREE:
        return None
    return next((e for e in d.explanations if e.effect == effect), None)


JOINT_FITS = 2
"""Candidates the joint search fits in every record (the best by summed screen gain)."""


def _tested_in(d: Diagnosis, key: str, priors: dict[str, Prior] | None, seed: int,
               force: bool = False, parent: str = "nominal"
               ) -> tuple[float | None, dict[str, Any] | None, bool]:
    """An effect tested alone on a record's nominal model (``parent="final"``: on top of
    what the record's own diagnosis accepted): (log Bayes factor, its physical size where
    one was fitted, whether it gave any likelihood gain). ``force``: fit it even when its
    screening gain is below the search's screen_min (the joint search adds weak evidence
    up)."""
    cand = make_candidate(key)
    base = d.selection.final if parent == "final" else d.selection.nominal
    fm, c = try_candidate(base, cand, priors, force=force)
    size = (effect_summaries(fm, draws(fm, seed=seed))[-1]["params"]
            if fm is not None and cand.effect not in NODE_FREE else None)
    # (an unbalance's size is its balancing answer, which only a diagnosis naming it has)
    return c["log_bayes_factor"], size, (c.get("screen_gain") or 0.0) > 0.0


def _last_screens(d: Diagnosis) -> list[CandidateScore]:
    """The physics screens of the record's round that accepted nothing, which screened
    what its final model still lacks (none when the search stopped at max_effects)."""
    last = len(d.selection.accepted) + 1
    return [c for c in d.candidates if c.round == last and c.effect not in NOMINAL_FAMILY]


def _in_every_record(row: dict[str, Any]) -> bool:
    """Present in every record where it was tested (``row["present"]``, None: untested)."""
    tested = [v for v in row["present"].values() if v is not None]
    return bool(tested) and all(tested)


def _occam_factors(diags: list[Diagnosis]) -> dict[str, float]:
    """Per effect, how far a refined log Bayes factor fell below its screening gain in
    these records (median over their refined candidates, >= 0): the Occam factor the screen
    does not see (about 4.7 nats for a gain, 8 for a runout, ~0 for a cross-coupling, whose
    node scan's refit gains more than its screen; the foreign benchmark's diagnoses)."""
    gaps: dict[str, list[float]] = {}
    for d in diags:
        for c in d.candidates:
            if isinstance(c.round, int) and c.screen_gain is not None \
                    and c.log_bayes_factor is not None:
                gaps.setdefault(c.effect, []).append(c.screen_gain - c.log_bayes_factor)
    return {e: max(float(np.median(v)), 0.0) for e, v in gaps.items()}


def joint_search(diags: list[Diagnosis], named: set[str], priors: dict[str, Prior] | None,
                 opt: DiagnoseOptions, speeds: list[float]) -> list[dict[str, Any]]:
    """Effects the records name together that none names alone (module docstring): one row
    per candidate fitted, with each record's log Bayes factor, the joint one, the joint log
    posterior odds and ``named_jointly``."""
    usable = [i for i, d in enumerate(diags) if not d.checks_failed]
    if len(usable) < 2:
        return []
    gains: dict[str, list[float]] = {}
    n_pool = [0]
    for i in usable:
        screens = _last_screens(diags[i])
        n_pool.append(len(screens))
        for c in screens:
            gains.setdefault(c.key, []).append(max(c.screen_gain or 0.0, 0.0))
    K = max(n_pool)
    occam = _occam_factors([diags[i] for i in usable])
    named_effects = {k.split("@")[0] for k in named}

    def expected(key: str) -> float:      # the joint log BF the screens point to
        return sum(g - occam.get(key.split("@")[0], 0.0) for g in gains[key])

    pointed = sorted((k for k in gains if k.split("@")[0] not in named_effects
                      and posterior_log_odds(expected(k), K) > opt.log_bf_threshold),
                     key=lambda k: -expected(k))[:JOINT_FITS]
    rows = []
    for key in pointed:
        row: dict[str, Any] = {"effect": key, "named_in": [], "log_bayes_factor": {},
                               "present": {}, "screen_gain_sum": float(sum(gains[key]))}
        sizes: dict[str, dict[str, Any]] = {}
        for i in usable:
            lbf, size, _ = _tested_in(diags[i], key, priors, opt.seed, force=True,
                                      parent="final")
            row["log_bayes_factor"][str(i + 1)] = lbf
            row["present"][str(i + 1)] = None if lbf is None else bool(
                lbf > opt.log_bf_threshold)
            if size is not None:
                sizes[str(i + 1)] = size
        lbfs = [v for v in row["log_bayes_factor"].values() if v is not None]
        joint = float(sum(lbfs)) if len(lbfs) >= 2 else None
        row["joint_log_bayes_factor"] = joint
        row["joint_log_posterior_odds"] = (None if joint is None
                                           else posterior_log_odds(joint, K))
        row["named_jointly"] = bool(joint is not None and row["joint_log_posterior_odds"]
                                    > opt.log_bf_threshold)
        row["in_every_record"] = _in_every_record(row)
        row["size"] = size_agreement(key, sizes, speeds)
        rows.append(row)
    best = [r for r in rows if r["named_jointly"]]
    if best:
        # one joint name per effect: the location the records favour together
        top = max(best, key=lambda r: r["joint_log_bayes_factor"])
        for r in best:
            r["named_jointly"] = r is top or r["effect"].split("@")[0] != \
                top["effect"].split("@")[0]
    return rows


def diagnose_records(recordings: list[Recording], params: str | tuple[str, ...] | None = None,
                     priors: dict[str, Prior] | None = None,
                     options: DiagnoseOptions | None = None) -> RecordsDiagnosis:
    """Diagnose each recording, then test every effect named in one record in each of the
    others, and search for effects the records name only together (module docstring)."""
    if len(recordings) < 2:
        raise BayesAmbError("diagnose: several recordings are needed to diagnose across "
                            f"records (got {len(recordings)})")
    opt = options or DiagnoseOptions()
    speeds = [float(r.speed_rpm) for r in recordings]
    diags = [diagnose(r, params, priors, opt) for r in recordings]
    named: dict[str, list[int]] = {}
    for i, d in enumerate(diags):
        for e in d.explanations:
            if e.kind == "physics":
                named.setdefault(e.key, []).append(i)
    across = []
    for key, where in named.items():
        row: dict[str, Any] = {"effect": key, "named_in": [i + 1 for i in where],
                               "log_bayes_factor": {}, "present": {}}
        sizes: dict[str, dict[str, Any]] = {}
        for i, d in enumerate(diags):
            if i in where:
                e = next(e for e in d.explanations if e.key == key)
                lbf = e.score
                sizes[str(i + 1)] = _size_of(e, d)
            elif d.checks_failed:
                lbf = None                              # a failed data check: not tested
            elif (same := _named_elsewhere(key, d)) is not None:
                lbf = same.score                        # the same physics at another place
                sizes[str(i + 1)] = _size_of(same, d)
            else:
                lbf, size, gain = _tested_in(d, key, priors, opt.seed)
                if size is not None:
                    sizes[str(i + 1)] = size
                if lbf is None and not gain:
                    # no likelihood gain at all: the fit is not refined, the effect absent
                    row["log_bayes_factor"][str(i + 1)] = None
                    row["present"][str(i + 1)] = False
                    continue
            row["log_bayes_factor"][str(i + 1)] = lbf
            row["present"][str(i + 1)] = (None if lbf is None
                                          else bool(lbf > opt.log_bf_threshold))
        row["in_every_record"] = _in_every_record(row)
        row["size"] = size_agreement(key, sizes, speeds)
        across.append(row)
    across += joint_search(diags, set(named), priors, opt, speeds)
    prefer_locations(across)
    result = RecordsDiagnosis.from_dict(
        {"recordings": [str(r.source) for r in recordings], "speeds_rpm": speeds,
         "verdicts": [d.verdict for d in diags], "across": across,
         "force_law": force_law_levels(recordings, diags)}, FILE)
    return replace(result, diagnoses=diags)


def prefer_locations(across: list[dict[str, Any]]) -> None:
    """Where the records named one effect at several places (a cross-coupling at A in two
    records, at D1 in the third), the place the records favour together is the one whose
    log Bayes factor, summed over the records both were tested in, is the larger: each
    such row gets ``preferred_location`` (that row's key), and the others ``weaker_by``
    (nats below it). One record may prefer the wrong place by a few nats where the two
    are nearly equivalent at its speed; the records together tell them apart. An effect
    whose place is not physics (NODE_FREE: an unbalance's node) is left alone."""
    by_effect: dict[str, list[dict[str, Any]]] = {}
    for row in across:
        effect = row["effect"].split("@")[0]
        if effect not in NODE_FREE and (row["named_in"] or row.get("named_jointly")):
            by_effect.setdefault(effect, []).append(row)
    for rows in by_effect.values():
        common = set.intersection(*({k for k, v in r["log_bayes_factor"].items()
                                     if v is not None} for r in rows))
        if len(rows) < 2 or not common:
            continue
        total = {r["effect"]: sum(r["log_bayes_factor"][k] for k in common) for r in rows}
        best = max(total, key=total.__getitem__)
        for r in rows:
            r["preferred_location"] = best
            if r["effect"] != best:
                r["weaker_by"] = float(total[best] - total[r["effect"]])


SIZE_QUANTITIES = {"unbalance": ("u_kgm", "u_*"), "runout": ("amplitude_m",),
                   "cross_coupling": ("kxy",)}
"""The physical quantities whose agreement across records is read ('u_*': the u of every
balancing plane; phases are left out: a record without a once-per-revolution reference
starts at any angle)."""


def size_agreement(key: str, sizes: dict[str, dict[str, Any]], speeds: list[float]
                   ) -> dict[str, Any] | None:
    """Whether an effect fitted in several records has the same size in each (module
    doc): ``sizes`` maps a record number to its fitted physical parameters. The sd of each
    record's value is its 90 % interval's width / 3.29 (Laplace: normal). None where the
    effect has no size quantity or was fitted in fewer than two records."""
    effect = key.split("@")[0]
    quantities = SIZE_QUANTITIES.get(effect, ())
    if len(sizes) < 2 or not quantities:
        return None
    recs = sorted(sizes, key=int)
    shared = set.intersection(*(set(sizes[r]) for r in recs))
    quantities = sorted(q for q in shared if q in quantities
                        or any(p.endswith("*") and q.startswith(p[:-1]) for p in quantities))
    if not quantities:
        return None
    means = {q: [sizes[r][q]["mean"] for r in recs] for q in quantities}
    sds = {q: [(sizes[r][q]["hdi90"][1] - sizes[r][q]["hdi90"][0]) / 3.29 for r in recs]
           for q in quantities}
    out = agreement(means, sds)
    rpm = [speeds[int(r) - 1] for r in recs]
    if not out["disagree"]:
        reading = (f"the same size in records {', '.join(recs)} "
                   f"({', '.join(f'{v:g}' for v in rpm)} rpm): a property of the machine")
    elif effect in ("unbalance", "runout"):
        other = "runout" if effect == "unbalance" else "unbalance"
        reading = (f"its size changes between records {', '.join(recs)} "
                   f"({', '.join(f'{v:g}' for v in rpm)} rpm), which {effect} does not: the "
                   f"1x line is more likely {other} or another synchronous effect")
    else:
        reading = (f"its size changes with the record ({', '.join(f'{v:g}' for v in rpm)} "
                   "rpm): speed-dependent, as a seal's or an impeller's force is")
    return {"records": [int(r) for r in recs], "test": out, "agree": not out["disagree"],
            "reading": reading}
