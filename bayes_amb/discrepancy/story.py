"""The plain-language paragraph of a diagnosis: what was wrong, where it showed, what was
added, how much better the fit is."""

from __future__ import annotations

from typing import TYPE_CHECKING

from bayes_amb.discrepancy.library.registry import NOMINAL_FAMILY, REGISTRY
from bayes_amb.discrepancy.linearity import READ_AT
from bayes_amb.discrepancy.stand_ins import stand_in_sentence

if TYPE_CHECKING:
    from bayes_amb.results.diagnosis import CandidateScore, Diagnosis, Finding, Mismatch


def _library_titles() -> str:
    return ", ".join(e.title for e in REGISTRY.values())


def _bands(bands: list[list[float]]) -> str:
    parts = [f"{lo:.0f}" if abs(hi - lo) < 1 else f"{lo:.0f}-{hi:.0f}" for lo, hi in bands[:4]]
    more = f" and {len(bands) - 4} more" if len(bands) > 4 else ""
    return ", ".join(parts) + more + " Hz"


def _tests(findings: list[Finding]) -> str:
    names = {"coherence": "residual coherent with the excitation",
             "floor": "residual power above the fitted noise floor",
             "line": "a spectral line", "whiteness": "non-white residual",
             "crosscorr": "residual correlated with the excitation",
             "windows": "residual statistics changing over time"}
    seen = []
    for f in findings:
        if f.test not in seen:
            seen.append(f.test)
    return ", ".join(names[t] for t in seen)


def closest_unnamed(d: Diagnosis) -> CandidateScore | None:
    """The candidate of the search's last round that came closest to being named, where
    that round named nothing (the search stopped for want of evidence, not at its limit
    of effects) and the data favour it (log Bayes factor above 0) short of the threshold
    on its posterior odds: its row, or None. What an engineer should hear beside
    "unexplained": on ROSS's test rig a 1x line left unexplained was fitted by an
    unbalance of 5e-7 kg m that gained 8.8 nats, short of being named by its prior's
    Occam factor and the round's multiplicity (log Bayes factor 1.2, log posterior odds
    -2.3)."""
    rounds = [c.round for c in d.candidates if isinstance(c.round, int)]
    if not rounds or len(d.explanations) >= max(rounds):
        return None
    last = [c for c in d.candidates if c.round == max(rounds)
            and c.log_posterior_odds is not None and c.log_bayes_factor is not None
            and c.log_bayes_factor > 0.0]
    return max(last, key=lambda c: c.log_posterior_odds, default=None)


def closest_clause(c: CandidateScore) -> str:
    """'the unbalance at D2 (log Bayes factor 1.2, log posterior odds -2.3)'."""
    entry = REGISTRY.get(c.effect) or NOMINAL_FAMILY.get(c.effect)
    title = entry.title if entry is not None else c.effect.replace("_", " ")
    return (f"the {title} at {c.location} (log Bayes factor {c.log_bayes_factor:.1f}, "
            f"log posterior odds {c.log_posterior_odds:.1f})")


def _unexplained(d: Diagnosis) -> str:
    un = d.unexplained
    if not un.present:
        return ""
    where = f"on channel(s) {', '.join(un.channels)}" + (
        f", in {_bands(un.bands_hz)}" if un.bands_hz else "")
    expl = d.explanations
    tail = (" The effects named above fit part of it and are therefore only tentative."
            if expl else "")
    near = closest_unnamed(d)
    why = ("no model in the library explains it" if near is None else
           "no model in the library explains it with the evidence to be named; one comes "
           f"close, {closest_clause(near)}: the data favour it, but not by the naming "
           "threshold, so it is not named")
    return (f"Unexplained: the best model still leaves structure coherent with the excitation "
            f"{where}; {why} (see 'unexplained.estimate' for the "
            f"frequency response of the missing dynamics as an output-multiplicative error)."
            + tail)


def _noise(mm: Mismatch) -> str:
    """A sentence on the noise findings (floor, whiteness): a habit, not a mismatch."""
    nf = mm.noise_findings
    if not nf:
        return ""
    floor = [f.band_hz for f in nf if f.test == "floor"]
    white = sorted({c for f in nf if f.test == "whiteness" for c in f.channels or []})
    parts = ([f"residual power above the loop noise model in {_bands(floor)}"] if floor
             else []) + ([f"non-white residual on {', '.join(white)}"] if white else [])
    return ("The noise is not as the loop noise model has it (" + "; ".join(parts) + "): "
            "coloured sensor noise or a band-limited disturbance, a habit of the record. "
            "The likelihood integrates each band's noise spectrum out, so this is not "
            "counted as a mismatch.")


def _swaps(cands: list[CandidateScore]) -> str:
    """A sentence on the choices the revisit step (revisit.py) replaced, if any."""
    named: dict[str, CandidateScore] = {}
    for c in cands:
        if c.round == "revisit" and c.log_bayes_factor is not None \
                and c.chosen_log_bayes_factor is not None \
                and c.log_bayes_factor > c.chosen_log_bayes_factor:
            old = named.get(c.instead_of)
            if old is None or c.log_bayes_factor > old.log_bayes_factor:
                named[c.instead_of] = c
    if not named:
        return ""
    return "Once the later effects were in the model, " + "; ".join(
        f"{c.key} explained the data better than {k}, chosen first "
        f"(log Bayes factor {c.log_bayes_factor:.1f} against {c.chosen_log_bayes_factor:.1f}"
        " with the others held in the model), and replaced it" for k, c in named.items()) + "."


def _read_at(checks) -> str:
    """What one linear record cannot say when the rig file gives the magnets no force
    law (the linearity line's caveat, linearity.READ_AT), as one sentence; '' otherwise."""
    lin = next((c for c in checks if c.check == "linearity"), None)
    if lin is None or READ_AT not in lin.line:
        return ""
    return (" The coefficients are the linearisation at this record's current: without the "
            "magnets' bias current and their iron's saturation in the rig file, one record at "
            "one level cannot show a smooth nonlinearity of the magnets, which can move them "
            "beyond their intervals (the linearity check says up to which bias they hold; "
            "records at two levels, or the rig file's values, tell it).")


def plain_language(d: Diagnosis) -> str:
    """One paragraph from the numbers of a diagnosis."""
    mm = d.mismatch
    expl = d.explanations
    checks = d.checks
    failed = [c.line for c in checks if not c.ok]
    nl = d.nonlinearity
    if d.verdict == "nonlinear" and nl is not None:
        return (f"The loop is not linear: the record holds the {nl.title}, modelled as a "
                "transform of the recorded signals, so no linear physics is named and the "
                "bearing coefficients are estimated with it in the model (its uncertainty "
                "in their intervals). " + "; ".join(failed) + "."
                + (f" Where the linearisation holds: {nl.linear_range}." if nl.linear_range
                   else ""))
    if failed:
        return ("The data failed a check, so no physics is named: " + "; ".join(failed)
                + ".")
    habits = [c.line for c in checks if c.check in ("offsets", "start")
              and ("removed" in c.line or "mid-operation" in c.line)]
    prefix = ("Record habits handled as nuisance, not physics: " + "; ".join(habits) + ". "
              if habits else "")
    unexpl = _unexplained(d)
    noise = _noise(mm)
    if not mm.detected and not expl:
        return prefix + ("No mismatch: the residual of the nominal model holds no structure "
                "physics could leave (no excitation-coherent band, no line at 1x, no "
                "cross-correlation with the excitation, no change over time, at a family-wise "
                f"{100 * mm.evidence.alpha:g} % level), and no candidate physics "
                "improves the fit enough to be named." + (" " + noise if noise else "")
                + _read_at(checks))
    where = (f"on channel(s) {', '.join(mm.channels)}"
             + (f", in {_bands(mm.bands_hz)}" if mm.bands_hz else "")
             + (f", between {mm.time_s[0]:.2f} and {mm.time_s[1]:.2f} s"
                if mm.time_s else ""))
    text = [prefix.strip()] if prefix else []
    if mm.detected:
        text.append(f"The nominal model does not explain this recording: "
                    f"{_tests(mm.findings)} {where} (evidence "
                    f"{mm.evidence.strength}, smallest adjusted p = "
                    f"{mm.evidence.p_adjusted_min:.1e}).")
    else:
        text.append("The location tests found nothing significant at their family-wise level,"
                    " but a candidate model still fits clearly better.")
    if expl:
        what = "; ".join(f"{e.description} (90 % HDI of "
                         + ", ".join(f"{k} [{v.hdi90[0]:.3g}, {v.hdi90[1]:.3g}] {v.unit}"
                                     for k, v in e.params.items())
                         + f"; log Bayes factor {e.score:.1f})" for e in expl)
        text.append(f"Added to the model: {what}.")
        direct = d.direct_terms
        if direct:
            text.append("Beside it, the direct stiffness and damping " + "; ".join(
                f"at {t.location} (K [{t.params['K'].hdi90[0]:.3g}, "
                f"{t.params['K'].hdi90[1]:.3g}] N/m, C "
                f"[{t.params['C'].hdi90[0]:.3g}, {t.params['C'].hdi90[1]:.3g}] "
                "N s/m)" for t in direct) + " were fitted, as a seal or impeller has them, "
                "so that the bearing coefficients do not take them.")
        if d.parameters_after_from.endswith("tentative"):
            text.append("The coefficients after are averaged with the nominal model's, since "
                        "the naming is tentative.")
        swaps = _swaps(d.candidates)
        if swaps:
            text.append(swaps)
        fb, fa = d.fit.before, d.fit.after
        nr = ", ".join(f"{c} {fb.nrmse[c]:.3f} -> {fa.nrmse[c]:.3f}" for c in fb.nrmse)
        wp = min(fa.whiteness_p.values())
        text.append(f"The log-likelihood rises by {d.fit.log_likelihood_gain:.0f}; "
                    f"NRMSE per channel {nr}; smallest whiteness p-value after: {wp:.2g}.")
        pb, pa = d.parameters_before, d.parameters_after
        moved = [f"{n} {pb[n].mean:+.3f} -> {pa[n].mean:+.3f}" for n in pb
                 if abs(pa[n].mean - pb[n].mean) > pb[n].sd]
        if moved:
            text.append("Estimates that moved by more than their sd once the physics was "
                        f"added: {', '.join(moved)}.")
        bound = [n for n in pb if pb[n].at_prior_bound and not pa[n].at_prior_bound]
        if bound:
            text.append(f"With the nominal model {', '.join(bound)} sat on its prior bound, "
                        "absorbing the missing physics; with it added it no longer does.")
    elif not unexpl:
        text.append(f"None of the candidate physics ({_library_titles()}) explains it.")
    if unexpl:
        text.append(unexpl)
    subst = stand_in_sentence(d.stand_ins)
    if subst:
        text.append(subst)
    if noise:
        text.append(noise)
    return " ".join(text)
