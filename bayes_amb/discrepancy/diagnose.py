"""Diagnosis of a recording: the Python API behind ``bayes-amb diagnose``.

    rec = load_recording("realistic.csv")
    d = diagnose(rec)                  # all eight bearing coefficients fitted
    d.mismatch.detected, [e.effect for e in d.explanations]
    d.save("runs/realistic_diag")      # diagnosis.json, residuals.nc, models/*.nc

The result is a :class:`bayes_amb.results.Diagnosis` (results/diagnosis.py).

Steps: the data are checked and record habits removed (checks.py: controller consistency,
start at rest, offsets and drift, excitation); the nominal model (by default with all eight
bearing coefficients free) is fitted over the whole band (noise-marginalised Whittle
likelihood); its residual is located (locate.py); left-out coefficients, then candidate
physics, are screened, fitted and accepted greedily by Bayes factor (select.py); the
chosen model's residual is located again, and what it still leaves is reported as
unexplained, with a nonparametric estimate (unexplained.py); the fit before and after is
compared. The recording's ``truth`` (if simulated) is never read here.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bayes_amb import __version__
from bayes_amb.discrepancy.adequacy import judge, nominal_assessment
from bayes_amb.discrepancy.amplitude_answer import nonlinearity_block
from bayes_amb.discrepancy.balancing import balancing, check_planes
from bayes_amb.discrepancy.checks import DataChecks
from bayes_amb.discrepancy.current_loop import CAP_Z_GATE
from bayes_amb.discrepancy.direct_terms import averaged, direct_companions, with_direct_terms
from bayes_amb.discrepancy.fitstats import (
    draws,
    effect_summaries,
    fit_quality,
    nominal_physical,
    residual_spectrum,
    theta_summary,
)
from bayes_amb.discrepancy.fitting import FittedModel, own_noise_fit
from bayes_amb.discrepancy.library import (
    BEARING_COEFFICIENTS,
    Candidate,
    all_candidates,
    equivalents_of,
    left_out_coefficients,
)
from bayes_amb.discrepancy.library.flexible_mode import past_kept
from bayes_amb.discrepancy.locate import (
    LocateOptions,
    Location,
    locate,
    merge_spans,
    synchronous_speed,
)
from bayes_amb.discrepancy.loop_alternative import WEIGHT_NAMED, loop_alternative, mixed
from bayes_amb.discrepancy.model_error import model_error
from bayes_amb.discrepancy.nonlinear import LOOP, Nonlinearity
from bayes_amb.discrepancy.revisit import revisit
from bayes_amb.discrepancy.select import SelectOptions, select
from bayes_amb.discrepancy.stand_ins import stand_ins
from bayes_amb.discrepancy.story import plain_language
from bayes_amb.discrepancy.unexplained import unexplained_block
from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.priors import Prior
from bayes_amb.inference.sampler import initial_ball, run_emcee
from bayes_amb.io.recording import Recording, require_excitation
from bayes_amb.results.diagnosis import FILE, Diagnosis
from bayes_amb.rig import CHANNELS, node_label
from bayes_amb.threads import limited_threads
from bayes_amb.uncertainty import parse_param_list

if TYPE_CHECKING:     # xarray (with pandas) takes half a second to import: only where written
    import xarray as xr


@dataclass
class DiagnoseOptions:
    """log_bf_threshold and max_effects of the greedy search, the candidates tried (default
    None: the whole library at its default locations on the recording's rig,
    ``all_candidates(rig=recording.rig)``), prescreen (route candidates by their
    fingerprint, prescreen.py; False screens every one fully), sample (run emcee on the
    nominal and the final model; otherwise their posteriors are Laplace approximations),
    steps per sampled model, seed, progress callback(text), planes (the two correction
    planes of the balancing answer when unbalance is named: discs, bearings or nodes
    'n<j>'; default the two discs furthest apart, balancing.py)."""

    log_bf_threshold: float = 3.0
    max_effects: int = 4
    candidates: tuple[Candidate, ...] | None = None
    prescreen: bool = True
    sample: bool = False
    steps: int = 2000
    seed: int = 0
    progress: Callable[[str], None] | None = None
    planes: tuple[str, str] | None = None


def residuals_dataset(loc: Location, eps: np.ndarray, residual_before: np.ndarray,
                      residual_after: np.ndarray, dt: float) -> xr.Dataset:
    """Residuals before/after, their Welch spectra and the location arrays: a run folder's
    residuals.nc (plots and the report then recompute nothing)."""
    t = np.arange(eps.shape[0]) * dt
    f, p_before = residual_spectrum(residual_before, dt)
    _, p_after = residual_spectrum(residual_after, dt)
    _, p_eps = residual_spectrum(eps, dt)
    import xarray as xr
    return xr.Dataset(
        {"eps": (("time", "channel"), eps),
         "residual_before": (("time", "channel"), residual_before),
         "residual_after": (("time", "channel"), residual_after),
         "psd_eps": (("freq", "channel"), p_eps),
         "psd_before": (("freq", "channel"), p_before),
         "psd_after": (("freq", "channel"), p_after),
         "band_lo_hz": (("band",), loc.band_lo_hz), "band_hi_hz": (("band",), loc.band_hi_hz),
         "coherence": (("band", "channel"), loc.coherence),
         "coherence_p": (("band", "channel"), loc.coherence_p),
         "floor_ratio": (("band", "channel"), loc.floor_ratio),
         "whiteness_p": (("channel",), loc.whiteness_p),
         "xcorr": (("channel", "input", "lag"), loc.xcorr),
         "autocorr": (("channel", "lag_ac"), loc.autocorr)},
        coords={"time": t, "channel": list(CHANNELS), "input": list(CHANNELS), "freq": f},
        attrs={"xcorr_bound": loc.xcorr_bound, "dt": dt})


def improvement_location(nominal: FittedModel, final: FittedModel,
                         residual_before: np.ndarray, residual_after: np.ndarray,
                         share: float = 0.8) -> dict[str, Any]:
    """Where the chosen model fits better than the nominal one: the likelihood bands that
    hold ``share`` of the total log-likelihood gain (merged to spans, Hz) and the channels
    whose prediction changes by at least 30 % of the largest change (the prediction change
    is the difference of the two residuals)."""
    if final is nominal:
        return {"bands_hz": [], "channels": [], "gain_by_band": []}
    like = final.like
    d = (final.like.pointwise(final.params[None], final.log10_sigma[None])[0]
         - nominal.like.pointwise(nominal.params[None], nominal.log10_sigma[None])[0])
    order = np.argsort(-d)
    pos = np.clip(d, 0, None)
    total = pos.sum()
    keep, acc = [], 0.0
    for i in order:
        if total <= 0 or acc >= share * total or d[i] <= 0:
            break
        keep.append(int(i))
        acc += d[i]
    f0 = like.k[like.starts] / (like.n * like.forward.dt)
    f1 = like.k[np.append(like.starts[1:], like.k.size) - 1] / (like.n * like.forward.dt)
    spans = merge_spans([[float(f0[i]), float(f1[i])] for i in keep])
    change = np.sqrt(np.mean((residual_before - residual_after) ** 2, axis=0))
    chans = [c for c, v in zip(CHANNELS, change, strict=True) if v >= 0.3 * change.max()]
    return {"bands_hz": spans, "channels": chans, "share": share,
            "gain_by_band": [[float(a), float(b), float(g)] for a, b, g in zip(f0, f1, d,
                                                                              strict=True)]}


def _sample(fm: FittedModel, steps: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    n_walkers = max(24, 2 * fm.x.size + 2)
    n_walkers += n_walkers % 2
    start = initial_ball(fm.post, fm.x, fm.cov if fm.cov is not None and
                         np.all(np.diag(fm.cov) > 0) else None, n_walkers, rng)
    run = run_emcee(fm.post, start, rng, n_steps=steps)
    fm.samples = run.samples


def _model_error_dict(fm: FittedModel) -> dict[str, Any] | None:
    return None if fm.model_error is None else fm.model_error.to_dict()


def _after_from(named: FittedModel, reported: FittedModel, mixed: bool,
                alt_weight: float | None = None) -> str:
    """How parameters_after was obtained (direct_terms.py), in one line."""
    parts = ["the named model" if named.candidates else "the nominal model"]
    if reported is not named:
        parts.append("with the direct stiffness and damping of its node forces fitted beside "
                     "them (" + ", ".join(c.location for c in direct_companions(named)) + ")")
    parts.append("its model error integrated out")
    if mixed:
        parts.append("averaged with the nominal model in equal parts, since the naming is "
                     "tentative")
    if alt_weight is not None:
        parts.append(f"mixed with the fit that models the amplifier's capped current loop "
                     f"instead (weight {alt_weight:.2f}), which fits as well")
    return ", ".join(parts)


def _verdict(checks: DataChecks, loc: Location, accepted: list[FittedModel],
             unexplained: dict[str, Any], substitutes: list[dict[str, Any]]) -> str:
    if checks.failed == ["linearity"] and next(
            c for c in checks.checks if c.name == "linearity").values.get("modelled"):
        return "nonlinear"
    if checks.failed:
        return "data check failed"
    if unexplained["present"] or substitutes:
        return "partly explained" if accepted else "unexplained"
    if accepted:
        return "explained"
    return "mismatch, unexplained" if loc.detected else "no mismatch"


def _carry_modelled_spread(nominal: FittedModel, reported: FittedModel) -> None:
    """A nonlinearity the nominal fit modelled (the rig file's force law, a clip) is in the
    named model too, at the same parameter: its uncertainty (the nominal's extra_cov, from
    refits at its parameter's ends) goes into the named model's coefficients as well.
    Without it, a lag named beside a force law whose bias is known to 5 % left the
    stiffnesses intervals a third as wide as the law's own spread allows (3 of the 8
    stiffnesses of one foreign force law + lag record outside)."""
    if reported is nominal or nominal.extra_cov is None or reported.extra_cov is not None:
        return
    p = nominal.p
    if tuple(reported.names[:p]) != tuple(nominal.names):
        return
    extra = np.zeros((reported.p, reported.p))
    extra[:p, :p] = nominal.extra_cov[:p, :p]
    reported.extra_cov = extra


def _running_speed(nominal: FittedModel, loc: Location, residual: np.ndarray
                   ) -> dict[str, Any] | None:
    """When the nominal residual holds a line at 1x, the running speed is estimated from it
    and the line candidates use that (the extended models share the nominal's context).
    Returns the check line, or None without a 1x line."""
    if not any(ln["synchronous"] for ln in loc.lines):
        return None
    fwd = nominal.forward
    written = fwd.recording.speed_rpm
    est = synchronous_speed(residual, fwd.dt, written)
    fwd.ctx = replace(fwd.ctx, speed_rpm=est)
    rel = est / written - 1.0
    return {"check": "speed", "ok": True, "speed_rpm": est, "written_rpm": written,
            "line": f"speed: the 1x line is at {est:.1f} rpm ({100 * rel:+.2f} % from the "
                    f"{written:g} rpm written in the record); synchronous candidates use it"}


NOMINAL_ADVICE = ("This diagnosis locates it and names what it can (verdict, explanations, "
                  "unexplained).")
FINAL_ADVICE = ("The library has no further explanation (see unexplained): read the "
                "corrected estimates as partly explained.")


def _check_locations(candidates: tuple[Candidate, ...], recording: Recording) -> None:
    """Refuse, before any fitting, a candidate at a shaft node or disc the recording's rig
    does not have (one line naming the candidate and the rig's range)."""
    rig = recording.rig
    for c in candidates:
        node = node_label(c.location)
        if node is not None and node > rig.n_nodes:
            raise BayesAmbError(f"candidate {c.key}: rig {rig.name!r} of recording "
                                f"{recording.source} has nodes n1 .. n{rig.n_nodes}")


def _search(recording: Recording, names: tuple[str, ...], priors: dict[str, Prior] | None,
            opt: DiagnoseOptions, candidates: tuple[Candidate, ...],
            say: Callable[[str], None], forced: Nonlinearity | None = None):
    """The data checks, the nominal fit (with any nonlinearity modelled; forced: one found
    after a first search), its location and the greedy search: checks, nominal, eps,
    location, fit quality before, the speed check line, and the selection."""
    checks, nominal, eps = nominal_assessment(recording, names, priors, opt.seed,
                                              forced=forced)
    if not np.isfinite(nominal.log_post):
        raise BayesAmbError(f"recording {recording.source}: the nominal model gives no finite "
                            "likelihood anywhere in the prior range")
    if opt.candidates is None:      # the bending pairs the nominal model does not keep
        candidates = past_kept(candidates, nominal.forward.reduced.n_bending)
    say("locating the mismatch")
    loc = locate(nominal.like, nominal.params, nominal.log10_sigma, nominal.cov,
                 LocateOptions(seed=opt.seed))
    before = fit_quality(nominal, eps)
    speed = _running_speed(nominal, loc, before["residual"])
    pool = (*left_out_coefficients(names), *candidates)
    sel_opt = SelectOptions(log_bf_threshold=opt.log_bf_threshold,
                            max_effects=0 if checks.failed else opt.max_effects,
                            candidates=pool, prescreen=opt.prescreen)
    sel = revisit(select(nominal, sel_opt, priors, progress=say), priors, progress=say)
    return checks, nominal, eps, loc, before, speed, sel


@limited_threads
def diagnose(recording: Recording, params: str | tuple[str, ...] | list[str] | None = None,
             priors: dict[str, Prior] | None = None,
             options: DiagnoseOptions | None = None) -> Diagnosis:
    """Locate, explain and model the discrepancy between a recording and the nominal model
    (bayes_amb.api.diagnose also takes a list of recordings: records.diagnose_records).

    params: the bearing coefficients fitted in the nominal model (default: all eight, k_Ax
    .. c_By); any left out is itself a candidate, tried first and preferred to physics unless the
    physics is stronger by the threshold (select._choose).
    """
    opt = options or DiagnoseOptions()
    t0 = time.perf_counter()
    require_excitation(recording)
    if opt.planes is not None:
        check_planes(recording.rig, opt.planes)
    names = parse_param_list(",".join(BEARING_COEFFICIENTS) if params is None else params)
    candidates = (all_candidates(rig=recording.rig) if opt.candidates is None
                  else tuple(opt.candidates))
    _check_locations(candidates, recording)
    say = opt.progress or (lambda _: None)
    say("checking the data and fitting the nominal model over the whole band")
    checks, nominal, eps, loc, before, speed, sel = _search(
        recording, names, priors, opt, candidates, say)
    alt = None
    lin = next(c for c in checks.checks if c.name == "linearity").values
    hint = next((n["z"] for n in lin.get("screens", ()) if n["name"] == LOOP), 0.0)
    if sel.accepted and not checks.failed and hint >= CAP_Z_GATE:
        # the first screen's cap stage saw a hint of a cap beside the lag (its z, not
        # its detection threshold): is the named lag the capped loop?
        alt = loop_alternative(recording, names, priors, checks.start, checks.u, eps,
                               nominal, sel.final)
        if alt is not None and alt.weight >= WEIGHT_NAMED:
            say("the actuator dynamics named are the amplifier's current loop with its "
                "rate capped: fitting again with the loop modelled")
            checks, nominal, eps, loc, before, speed, sel = _search(
                recording, names, priors, opt, candidates, say, forced=alt.nonlinearity)
            alt = None
    if sel.accepted:
        say("refitting the chosen model with its own noise filters")
        sel.final = sel.accepted[-1] = own_noise_fit(sel.final)
        say("locating what the chosen model still leaves")
        final_loc = locate(sel.final.like, sel.final.params, sel.final.log10_sigma,
                           sel.final.cov, LocateOptions(seed=opt.seed))
    else:
        final_loc = loc
    unexplained = unexplained_block(final_loc, sel.final)
    reported = with_direct_terms(sel.final, priors)
    _carry_modelled_spread(nominal, reported)
    if reported is not sel.final:
        say("fitting the direct stiffness and damping beside the cross-coupling at "
            + ", ".join(c.location for c in direct_companions(sel.final)))
    if opt.sample:
        for i, fm in enumerate({id(m): m for m in (nominal, reported)}.values()):
            say(f"sampling the posterior of model {i + 1}")
            _sample(fm, opt.steps, opt.seed + i)
    after = fit_quality(sel.final, eps)
    adequacy = judge(checks, loc, max(before["nrmse"].values()), advice=NOMINAL_ADVICE)
    adequacy_after = judge(checks, final_loc, max(after["nrmse"].values()),
                           advice=FINAL_ADVICE)
    say("integrating the model error out of the posteriors")
    doubted = {id(nominal): not adequacy.adequate,      # (one model: the final verdict)
               id(reported): not adequacy_after.adequate}
    for fm in {id(m): m for m in (nominal, reported)}.values():
        fm.model_error = model_error(fm.like, fm.x, fm.p, fm.cov, fm.names,
                                     robust=doubted[id(fm)])
    s_nom, s_fin = draws(nominal, seed=opt.seed), draws(reported, seed=opt.seed)
    # the nominal model's own candidates (a modelled current loop's lag) come first
    all_effects = effect_summaries(reported, s_fin)[len(nominal.candidates):]
    effects, direct = all_effects[:len(sel.accepted)], all_effects[len(sel.accepted):]
    substitutes = stand_ins(effects, nominal_physical(reported))
    with_nominal = bool((unexplained["present"] or substitutes) and sel.accepted)
    s_coef = averaged(s_fin, s_nom, nominal.p) if with_nominal else s_fin
    if alt is not None:             # the capped loop fits as well: both, in their weights
        s_coef = mixed(s_coef, draws(alt.fit, seed=opt.seed), alt.weight, len(names))
        substitutes.append(alt.stand_in(sel.accepted[0].candidates[-1].key))
    confidence = "tentative" if unexplained["present"] or substitutes else "confident"
    explanations = []
    for fm, eff in zip(sel.accepted, effects, strict=True):
        cand = fm.candidates[-1]
        odds = fm.log_odds if fm.log_odds is not None else np.nan
        explanations.append({**eff, "title": cand.entry.title, "side": cand.entry.side,
                             "score": fm.log_bf, "log_posterior_odds": fm.log_odds,
                             "kind": "model" if cand.nominal_family else "physics",
                             "equivalence_class": [cand.key, *(f"{k} ({when})" for k, when
                                                                 in equivalents_of(cand.key))],
                             "confidence": confidence,
                             **({"node_range": [f"n{n}" for n in fm.node_range]}
                                if fm.node_range else {}),
                             "evidence": f"log Bayes factor {fm.log_bf:.1f} against the model "
                                         f"without it (log posterior odds {odds:.1f})"})
    mismatch = loc.to_dict()
    mismatch["improvement"] = improvement_location(nominal, sel.final, before["residual"],
                                                   after["residual"])
    if sel.accepted and not loc.detected:
        # the model comparison is more powerful than the model-free tests: report where
        # the accepted physics improves the fit
        imp = mismatch["improvement"]
        mismatch.update(detected=True, channels=imp["channels"], bands_hz=imp["bands_hz"])
        mismatch["evidence"] = {**mismatch["evidence"], "strength": "model comparison",
                                "log_bayes_factor": sel.accepted[0].log_bf}
    source = Path(recording.source)
    report: dict[str, Any] = {
        "format": "bayes-amb-diagnosis/1",
        "package_version": __version__,
        "recording": source.name,
        "parameters_estimated": list(names),
        "checks": checks.to_list() + ([speed] if speed else []),
        "record_window": {"start_s": checks.start * recording.dt,
                          "at_rest": checks.at_rest,
                          "meaning": "samples before start_s drive the model but are not "
                                     "compared (start-up transient of a record that does "
                                     "not start at rest, or of removed offsets)"},
        "verdict": _verdict(checks, loc, sel.accepted, unexplained, substitutes),
        "adequacy": adequacy.to_dict(),
        "adequacy_after": adequacy_after.to_dict(),
        "mismatch": mismatch,
        "explanations": explanations,
        "unexplained": unexplained,
        "stand_ins": substitutes,
        "balancing": balancing(sel.final, opt.planes, priors, seed=opt.seed),
        "candidates": sel.scores,
        "fit": {"before": {k: before[k] for k in ("nrmse", "whiteness_p")},
                "after": {k: after[k] for k in ("nrmse", "whiteness_p")},
                "log_likelihood_gain": float(sel.final.log_post - nominal.log_post)},
        "parameters_before": theta_summary(nominal, s_nom),
        "parameters_after": theta_summary(reported, s_coef),
        "parameters_after_from": _after_from(sel.final, reported, with_nominal,
                                             None if alt is None else alt.weight),
        "direct_terms": direct,
        "nonlinearity": nonlinearity_block(
            next(c for c in checks.checks if c.name == "linearity").values,
            recording.rig, checks.u, recording.dt, theta_summary(reported, s_coef),
            recording.u),
        "model_error": {"before": _model_error_dict(nominal),
                        "after": _model_error_dict(reported)},
        "criterion": ("Laplace Bayes factor on the noise-marginalised whole-band Whittle "
                      "likelihood; prior odds 1/K for each of the K candidates of a round; "
                      f"accept above log posterior odds {opt.log_bf_threshold:g}"),
        "inference": "emcee" if opt.sample else "MAP with Laplace approximation",
        "seed": opt.seed,
        "summary": "",
    }
    d = Diagnosis.from_dict(report, FILE)
    d = replace(d, story=plain_language(d), wall_s=time.perf_counter() - t0,
                residuals=residuals_dataset(loc, eps, before["residual"], after["residual"],
                                            recording.dt),
                location=loc, selection=sel)
    return d
