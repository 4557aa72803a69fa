"""The report's diagnosis section: where the nominal model fails, the named physics, the
balancing answer, the fit and the parameters before and after, every candidate's score
(from diagnosis.json; assembled by :func:`bayes_amb.report.render.build_sections`)."""

from __future__ import annotations

from typing import Any

from bayes_amb.plots.discrepancy import round_number
from bayes_amb.report import figures as fg
from bayes_amb.report.collect import RunData
from bayes_amb.report.sections import SECTION_TITLES, Section, Table, g
from bayes_amb.results.diagnosis import BalancingPlane, CandidateScore


def _hdi(v: Any) -> str:
    """'[lo, hi]' of anything with a 90 % HDI."""
    return f"[{g(v.hdi90[0])}, {g(v.hdi90[1])}]"


def _correction(plane: BalancingPlane) -> str:
    """The correction of one balancing plane: m r (kg m) at the opposite angle, or none."""
    if not plane.nonzero:
        return "none (not told from 0)"
    return f"{g(plane.u_kgm.map)} kg m at {(plane.phase_deg.map + 180) % 360:.0f}°"


def discrepancy_section(run: RunData) -> Section:
    """The diagnosis: verdict, where it failed, the named physics, the fit before/after."""
    dg = run.diagnosis
    mm = dg.mismatch
    truth = run.true_theta()
    tables = []
    rows = [["detected", "yes" if mm.detected else "no"],
            ["channels", ", ".join(mm.channels) or "–"],
            ["bands", ", ".join(f"{g(a)}–{g(b)} Hz" for a, b in mm.bands_hz) or "–"],
            ["time window", "–" if not mm.time_s else
             f"{g(mm.time_s[0])}–{g(mm.time_s[1])} s"],
            ["evidence", mm.evidence.strength or "–"]]
    tables.append(Table("Where the nominal model fails", ["", ""], rows, compact=True))
    found = ([(f, f.test) for f in mm.findings]
             + [(f, f"{f.test} (noise, not a mismatch)") for f in mm.noise_findings])
    if found:
        tables.append(Table("Location tests (Holm-adjusted, family-wise 1 %)",
                            ["test", "band (Hz)", "channels", "adjusted p"],
                            [[name, "–" if f.band_hz is None else
                              f"{g(f.band_hz[0])}–{g(f.band_hz[1])}",
                              ", ".join(f.channels or []), g(f.p_adjusted, 2)]
                             for f, name in found[:20]]))
    if dg.explanations:
        tables.append(Table("Named physics (posterior of its parameters)",
                            ["effect", "location", "parameter", "mean", "90 % HDI", "unit",
                             "log BF", "naming", "cannot be told from"],
                            [[_effect_title(e.effect), e.location, k, g(v.mean),
                              _hdi(v), v.unit, g(e.score, 3), e.confidence,
                              "; ".join(e.equivalence_class[1:]) or "–"]
                             for e in dg.explanations for k, v in e.params.items()],
                            "Effect names and units from the physics library "
                            "(`bayes-amb library`); the last column is the effect's "
                            "equivalence class: explanations with the same u → y map.",
                            wrap=(0, 1, 4, 8)))
    if dg.stand_ins:
        tables.append(Table("Stand-ins: named effects fitted where their physics does not "
                            "allow them", ["effect", "location", "quantity", "90 % HDI",
                                           "plausible", "why"],
                            [[_effect_title(s.effect), s.location, s.quantity,
                              _hdi(s), f"[{g(s.plausible[0])}, {g(s.plausible[1])}]",
                              s.why] for s in dg.stand_ins],
                            "The data accept the named model, but not as the physics its "
                            "names claim: the naming is tentative and the library lacks "
                            "what the record holds.", wrap=(0, 5)))
    bal = dg.balancing.planes if dg.balancing is not None else []
    if bal:
        tables.append(Table("Unbalance as two correction planes", [
            "plane", "z (m)", "u (kg m)", "90 % HDI", "phase (deg)", "90 % HDI",
            "correction m r"],
            [[pl.plane, g(pl.z_m, 3), g(pl.u_kgm.map), _hdi(pl.u_kgm),
              g(pl.phase_deg.map, 3), _hdi(pl.phase_deg), _correction(pl)]
             for pl in bal],
            "The unbalance named, refitted as unbalance in two planes: the pair with the "
            "same 1x response at the sensors (the influence-coefficient answer). A "
            "correction mass m at radius r removes it when m r = u, placed at the phase + "
            "180° (phase at t = 0 of the record). 'none' where 0 lies inside the plane's "
            "90 % credible ellipse (the interval of u, a magnitude, never holds 0)."))
    fb, fa = dg.fit.before, dg.fit.after
    tables.append(Table("Fit before and after", [
        "channel", "NRMSE before", "NRMSE after", "whiteness p before",
        "whiteness p after"],
        [[c, g(fb.nrmse[c]), g(fa.nrmse[c]), g(fb.whiteness_p[c], 2),
          g(fa.whiteness_p[c], 2)] for c in fb.nrmse],
        "NRMSE = RMS(ε − ε̂)/RMS(ε); whiteness: Ljung–Box (20 lags) on the residual "
        "whitened by each model's fitted noise spectrum."))
    pb, pa = dg.parameters_before, dg.parameters_after
    if pb:
        tables.append(Table("Stiffness and damping before and after", [
            "parameter", "before: mean", "before: 90 % HDI", "after: mean", "after: 90 % HDI",
            "true"],
            [[n, g(pb[n].mean) + (" (prior bound)" if pb[n].at_prior_bound else ""),
              _hdi(pb[n]), g(pa[n].mean) + (" (prior bound)" if pa[n].at_prior_bound
                                            else ""), _hdi(pa[n]),
              g(truth.get(n)) if n in truth else "–"] for n in pb],
            "A MAP on a prior bound means the data pushed the parameter against its range: "
            "with the nominal model it often absorbs the missing physics."
            + (f" After: from {dg.parameters_after_from}."
               if dg.parameters_after_from else "")))
    if dg.direct_terms:
        tables.append(Table("Direct terms beside a cross-coupling at a node", [
            "location", "K (N/m): mean", "K: 90 % HDI", "C (N s/m): mean", "C: 90 % HDI"],
            [[d.location, g(d.params["K"].mean), _hdi(d.params["K"]),
              g(d.params["C"].mean), _hdi(d.params["C"])] for d in dg.direct_terms],
            "A seal's or impeller's force has direct stiffness and damping beside its "
            "cross-coupled stiffness; they are fitted so that the bearing coefficients do not "
            "take them. Between the bearings they are hard to tell from the bearings' own k "
            "and c: the coefficients' intervals widen where they cannot be told apart."))
    greedy = [c for c in dg.candidates if c.round != "revisit"]
    if greedy:
        tables.append(_candidate_table(greedy))
    revisited = [c for c in dg.candidates if c.round == "revisit"]
    if revisited:
        tables.append(Table("Earlier choices revisited", [
            "choice", "alternative", "log BF of the choice", "log BF of the alternative"],
            [[c.instead_of, c.key, g(c.chosen_log_bayes_factor, 5),
              g(c.log_bayes_factor, 5)] for c in revisited],
            "Each earlier choice and the other candidates its round fitted fully, refitted "
            "with the later effects held in the model; a larger log Bayes factor replaces "
            "the choice."))
    paras = [dg.story]
    if dg.criterion:
        paras.append(f"Criterion: {dg.criterion}. Inference: {dg.inference}.")
    return Section("discrepancy", SECTION_TITLES["discrepancy"], paragraphs=paras,
                   tables=tables,
                   figures=fg.discrepancy_figures(dg, run.diagnosis_residuals, truth))


def _candidate_table(cands: list[CandidateScore]) -> Table:
    """Every candidate tried, one row per effect and location (in the order of first
    trial) and two columns per round: screening gain and log Bayes factor ("–": not
    fitted fully; blank: not tried in that round, e.g. after it was accepted). A node
    refit's row ("2 node") counts in its round."""
    rounds = sorted({round_number(c) for c in cands})
    keys: dict[tuple[str, str], dict[int, CandidateScore]] = {}
    for c in cands:
        keys.setdefault((c.effect, c.location), {})[round_number(c)] = c
    header = ["effect", "location"]
    for r in rounds:
        header += [f"round {r}: gain (nats)", f"round {r}: log BF"]
    rows = []
    for (effect, loc), by_round in keys.items():
        row = [effect, loc]
        for r in rounds:
            c = by_round.get(r)
            row += ["", ""] if c is None else [
                g(c.screen_gain, 3)
                + {"pruned": " (predicted)", "outranked": " (predicted)",
                   "family": " (scan)"}.get(c.screen or "", ""),
                g(c.log_bayes_factor, 3)]
        rows.append(row)
    return Table("Every candidate tried", header, rows,
                 "Gain: the screening fit of the candidate's own parameters (its fingerprint "
                 "against the residual), in nats; the best are fitted fully and scored by "
                 "their log Bayes factor (–: not fitted fully). Blank: not tried in that "
                 "round. 'predicted': the linearised screen put the candidate well below the "
                 "bar or below the best of the round, and it was not fitted. 'scan': a "
                 "location of a node scan, its screen projected from one linearisation of "
                 "the whole scan.")


def _effect_title(name: str) -> str:
    """'actuator_lag (actuator lag)' from the registry; the bare name if it is unknown."""
    from bayes_amb.discrepancy.library.registry import NOMINAL_FAMILY, REGISTRY
    e = REGISTRY.get(name) or NOMINAL_FAMILY.get(name)
    return f"{name} ({e.title})" if e is not None else name
