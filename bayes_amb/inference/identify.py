"""Identification of a recording: the Python API behind ``bayes-amb identify``.

    rec = load_recording("paper.csv")
    result = identify(rec, "k_By")
    result.parameters["k_By"].mean
    result.save("runs/paper")          # posterior.nc and summary.json

The result is a :class:`bayes_amb.results.Identification` (results/identification.py).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from bayes_amb import __version__
from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.bounded import (
    bounded_laplace,
    bounded_notes,
    bounded_summary,
)
from bayes_amb.inference.doubted import with_model_error
from bayes_amb.inference.estimate import (
    LogPosterior,
    MapResult,
    _theta_start,
    at_prior_bound,
    find_map,
    free_theta_covariance,
    laplace_covariance,
)
from bayes_amb.inference.forward import ForwardModel
from bayes_amb.inference.laplace_rows import (
    bound_notes,
    laplace_summary,
    not_sampled_note,
    warn_bound,
)
from bayes_amb.inference.noise_check import (
    NoiseCheck,
    record_check,
    sandwich_rows,
)
from bayes_amb.inference.noise_fit import fit_noise_spectrum
from bayes_amb.inference.offline import dual_youla_eps
from bayes_amb.inference.pending import Doubted, PendingAdequacy
from bayes_amb.inference.posterior import (
    identifiability,
    summarise,
    to_datatree,
)
from bayes_amb.inference.priors import Prior, PriorSet
from bayes_amb.inference.sampler import (
    SamplerRun,
    chains_converged,
    initial_ball,
    run_emcee,
    sampler_block,
)
from bayes_amb.inference.spectrum import LearnedSpectrum
from bayes_amb.inference.start import start_transient, transient_kept
from bayes_amb.inference.whittle import NOISE_SOURCES, NOISE_UNITS, WhittleLikelihood
from bayes_amb.io.recording import Recording, require_excitation
from bayes_amb.results.identification import FILE, Identification
from bayes_amb.threads import limited_threads
from bayes_amb.uncertainty import parse_param_list

NOISE_MODEL = ("banded Whittle likelihood; white sensor noise n, r1 and r2 through the exact "
               "closed-loop noise filters (eq. 14) evaluated at the MAP; intensities sampled "
               "(log-uniform priors)")


@dataclass
class IdentifyOptions:
    """walkers (None: max(24, 2 ndim + 2)), steps (None: run to 50 tau), map_only (MAP and
    Laplace, no sample; without it identify still does not sample where the adequacy test
    doubts the model, the noise check doubts the noise model, or the record does not
    inform a coefficient on its prior's bound: the summary's inference_note says which),
    map_method (lbfgs or nelder-mead), seed, max_steps, progress callback(steps, target, tau_max),
    adequacy (run the diagnosis' data checks and location tests on the same model and
    report the verdict as summary['adequacy'], discrepancy/adequacy.py; one nominal fit),
    noise_model ("loop": the coloured loop noise model; "iid": white Gaussian eps, the naive
    model, kept to show that it is overconfident), moves ("laplace": differential evolution
mixed with independence proposals from the Laplace approximation at the MAP, the default;
"de": differential evolution alone, the sampler before issue 16, kept for comparison),
initial_state (fit the transient of the record's start, WhittleLikelihood.set_initial_state:
True or False; None, the default, fits it when the data check finds that the record starts
mid-operation, as a rig's records do: start_transient), learn_spectrum (learn the noise
spectrum from the record, inference/spectrum.py, the default; False: the three white
sources, with the noise check's sandwich where the record's noise is not white),
leave_out_lines (leave the record's narrowband lines, mains pick-up, a pump, the unbalance,
out of the likelihood, inference/narrow_lines.py, the default; False: every bin of the
band enters)."""

    walkers: int | None = None
    steps: int | None = None
    map_only: bool = False
    map_method: str = "lbfgs"
    seed: int = 0
    max_steps: int = 20000
    progress: Callable[[int, int, float], None] | None = None
    noise_model: str = "loop"
    moves: str = "laplace"
    adequacy: bool = True
    initial_state: bool | None = None
    learn_spectrum: bool = True
    leave_out_lines: bool = True


def _absolute(source: str) -> str:
    """The recording's path made absolute when it names a file (reports find it later)."""
    p = Path(source)
    return str(p.resolve()) if p.is_file() else source


def _from_nominal_too(post: LogPosterior, m: MapResult, method: str) -> MapResult:
    """When the MAP has a parameter on its prior bound, search again from the nominal model
    (the noise intensities kept) and keep the better of the two, each with the noise
    filters at its own estimate. A record that informs a parameter weakly (one channel
    excited) lets the search run into a corner from which the gradient does not lead back:
    on an effect-free one-channel foreign record the corner's log posterior was 2.8 below
    the truth's, and the search from the nominal model found one 13 above the corner's."""
    if not at_prior_bound(post, np.concatenate([m.theta, m.log10_sigma]))[:post.p].any():
        return m
    alt = find_map(post, method, x0=np.concatenate([_theta_start(post), m.log10_sigma]))
    if alt.log_post > m.log_post:
        return alt
    post.likelihood.set_noise_reference(m.theta)
    return m


def learned_noise(post: LogPosterior, m: MapResult, method: str
                  ) -> tuple[MapResult, LearnedSpectrum | None]:
    """The noise spectrum learned from the record at the white model's MAP m and the MAP
    under it (noise_fit.fit_noise_spectrum); m and None where the residual is as white as
    the three sources have it. The likelihood keeps the spectrum for the Laplace
    approximation and the sampler."""
    if post.likelihood.noise_model != "loop":
        return m, None
    last = [m]

    def refit(theta: np.ndarray, ls: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        last[0] = find_map(post, method, x0=np.concatenate([theta, ls]))
        return last[0].theta, last[0].log10_sigma

    _, _, spectrum = fit_noise_spectrum(post.likelihood, m.theta, m.log10_sigma, refit)
    return last[0], spectrum


@limited_threads
def identify(recording: Recording, params: str | tuple[str, ...] | list[str],
             priors: dict[str, Prior] | None = None,
             options: IdentifyOptions | None = None) -> Identification:
    """MAP and emcee posterior of the named parameters from one recording (bayes_amb.api
    .identify also takes a list, for their joint posterior).

    The recording's ``truth`` (if simulated) is never read here.
    """
    opt = options or IdentifyOptions()
    t0 = time.perf_counter()
    require_excitation(recording)
    names = parse_param_list(params)
    prior_set = PriorSet.build(names, priors)
    # the adequacy test beside this fit (pending.py): its verdict decides the sampling
    pending = PendingAdequacy(recording, names, priors, opt.seed) if opt.adequacy else None
    try:
        forward = ForwardModel(recording, names)
        eps = dual_youla_eps(forward.parts, np.asarray(recording.y), np.asarray(recording.u))
        like = WhittleLikelihood(forward, eps, noise_model=opt.noise_model)
        if pending is not None:
            pending.set_band(like.f_max_hz)
        return _fitted(recording, names, prior_set, forward, eps, like, pending, opt, t0)
    finally:
        if pending is not None:
            pending.close()      # a test still running when the fit failed is ended


def _fitted(recording: Recording, names: tuple[str, ...], prior_set: PriorSet,
            forward: ForwardModel, eps: np.ndarray, like: WhittleLikelihood,
            pending: PendingAdequacy | None, opt: IdentifyOptions, t0: float
            ) -> Identification:
    """identify after its likelihood is built and its adequacy test started: the MAP, the
    noise spectrum, the Laplace approximation or the sample, and the summary."""
    post = LogPosterior(like, prior_set)
    if opt.leave_out_lines:       # before any fit: a line's bins outweigh thousands of others
        like.leave_out_lines(_theta_start(post))
    start = start_transient(recording, forward, opt.initial_state)
    if start["fitted"]:
        like.set_initial_state(True)
    m = find_map(post, opt.map_method)
    if not np.isfinite(m.log_post):
        raise BayesAmbError(f"recording {recording.source}: no parameter value in the prior "
                            "gives a finite likelihood (the controller does not stabilise the "
                            "model anywhere in the prior range?)")
    # prewhitening from the noise model at the MAP, then the MAP again under it
    # (WhittleLikelihood.set_model_prewhitening: the data-designed FIR leaves leakage)
    like.set_model_prewhitening(m.theta, m.log10_sigma)
    m = find_map(post, opt.map_method, x0=np.concatenate([m.theta, m.log10_sigma]))
    m = _from_nominal_too(post, m, opt.map_method)
    m = transient_kept(post, m, opt.map_method, start)
    m, spectrum = learned_noise(post, m, opt.map_method) if opt.learn_spectrum else (m, None)
    x_map = np.concatenate([m.theta, m.log10_sigma])
    cov = laplace_covariance(post, x_map)
    on_bound = cov is None and at_prior_bound(post, x_map)[:post.p].any()
    bounded = bounded_laplace(post, x_map) if on_bound else None
    # a coefficient the record does not inform, on its prior's bound: its posterior is its
    # prior, known without sampling it (the others' integrated over it, below)
    weak = bounded.weak(prior_set) if bounded is not None else np.zeros(post.p, bool)
    prior_wide = bool(weak.any())
    check = _checked(like, m, names, spectrum)
    # a noise model the check doubts: the sandwich posterior at the MAP (Mueller 2013),
    # not a sample of a likelihood known to be wrong (module noise_check, docs/identify.md)
    misspecified = check is not None and check.doubted and cov is not None
    sampled = None
    if pending is not None and not (opt.map_only or prior_wide or misspecified):
        # sampled on speculation, stopped as soon as the adequacy test doubts the model
        sampled = _sampled(post, x_map, cov, opt, stop=pending.doubted)
    drawn = _drawn(like, names, eps, forward, sampled, opt, recording) if sampled else None
    verdict, nominal = pending.result() if pending is not None else (None, None)
    # a model that is not adequate reports the model-error posterior of the adequacy's
    # fit (with_model_error), which sampling this likelihood would not change: not sampled
    model_error = nominal is not None and nominal.model_error is not None
    map_only = opt.map_only or prior_wide or misspecified or model_error
    bound = notes = None
    center = m.theta
    seen = bounded               # formed once at the MAP; the sampled path's warn_bound too
    if on_bound and map_only:
        # a parameter ran to its prior bound, where the central stencil leaves the prior:
        # the Laplace approximation truncated to the prior (bounded.py) when every bound
        # one is informed and near it; else the others' over the free dimensions,
        # integrated over the priors of those the record does not inform, and the bound
        # ones' priors (laplace_summary). With none on a bound the theta Hessian is the
        # one laplace_covariance tried.
        cut = bounded is not None and not bounded.to_prior(prior_set).any()
        if bounded is not None:
            notes = bounded_notes(names, bounded, prior_set, cut)
        if not cut:
            cov, bound = free_theta_covariance(post, x_map)
            if cov is None:
                bound = None
            elif bounded is not None:
                center, cov = bounded.integrated(m.theta, cov, prior_set)
            bounded = None
    else:
        bounded = None
    summary: dict[str, Any] = {
        "format": "bayes-amb-summary/1",
        "package_version": __version__,
        "recording": _absolute(recording.source),
        "parameters_estimated": list(names),
        "priors": prior_set.to_dict(),
        "map": {n: float(v) for n, v in zip(names, m.theta, strict=True)},
        "map_method": m.method,
        "map_wall_s": m.wall_s,
        "noise": {"model": NOISE_MODEL + ("; the record's start transient fitted (a free "
                                          "response of the loop's modes, weights by least "
                                          "squares)" if like.initial_state else ""),
                  "map": {s: {"value": float(10 ** v), "unit": u}
                          for s, v, u in zip(NOISE_SOURCES, m.log10_sigma, NOISE_UNITS,
                                             strict=True)},
                  **({"spectrum": spectrum.to_dict()} if spectrum is not None else {}),
                  **({"lines_left_out": like.lines_left_out.to_list()}
                     if like.lines_left_out is not None and like.lines_left_out.lines
                     else {})},
        "fast_path": forward.fast,
        "excitation_port": forward.port,
        "n_bands": like.n_bands,
        **({"model": forward.band.to_dict()} if forward.band and forward.band.n_bending else {}),
        "start_transient": start,
        "seed": opt.seed,
    }
    if verdict is not None:
        summary["adequacy"] = verdict.to_dict()
        if verdict.adequate and nominal.extra_cov is None and not (
                map_only and cov is None and bounded is None):
            nominal = None
    if map_only:
        summary["inference"] = "MAP with Laplace approximation"
        if not opt.map_only and model_error:
            summary["inference_note"] = (
                "not sampled: the model is not adequate, and the intervals reported are "
                "those of the posterior with the band-wise model error integrated out (the "
                "adequacy's fit), which a sample of this likelihood would not change; its "
                "own Laplace intervals are under parameters_model_only")
        elif not opt.map_only:
            summary["inference_note"] = not_sampled_note(
                [n for n, w in zip(names, weak, strict=True) if w], misspecified)
        if notes is not None or bound is not None:
            summary["identifiability"] = notes or bound_notes(names, bound)
        if bounded is not None:
            summary["parameters"] = bounded_summary(names, bounded, recording.rig,
                                                     opt.seed)
        else:
            summary["parameters"] = laplace_summary(names, center, cov, recording.rig,
                                                     prior_set, bound, opt.seed)
        if cov is not None and bound is None:   # theta block: derived quantities need
            summary["laplace_cov"] = {          # the correlations, not only the sds
                "names": list(names), "theta": np.asarray(cov)[:len(names),
                                                               :len(names)].tolist()}
        if check is not None and check.widens and cov is not None and bounded is None:
            wide, check = check.sandwich(np.asarray(cov)[:post.p, :post.p])
            if check.doubted:
                summary["parameters_white_noise"] = summary["parameters"]
            summary["parameters"] = laplace_summary(names, center, wide, recording.rig,
                                                     prior_set, bound, opt.seed)
            if "laplace_cov" in summary:
                summary["laplace_cov"]["theta"] = wide.tolist()
        if check is not None:
            summary["noise"]["check"] = check.to_dict()
        summary["converged"] = bool(m.success and (cov is not None or bounded is not None))
        with_model_error(summary, nominal, opt.seed)
        summary["wall_s"] = time.perf_counter() - t0
        return _result(summary, names, m, eps, like)
    sampled = sampled or _sampled(post, x_map, cov, opt)
    run, n_walkers, laplace = sampled
    dt, params_summary = drawn or _drawn(like, names, eps, forward, sampled, opt, recording)
    noise_post = {}
    for j, (s, u) in enumerate(zip(NOISE_SOURCES, NOISE_UNITS, strict=True)):
        v = 10.0 ** run.samples[:, :, post.p + j].ravel()
        noise_post[s] = {"mean": float(v.mean()), "q05": float(np.quantile(v, 0.05)),
                         "q95": float(np.quantile(v, 0.95)), "unit": u,
                         "tau": float(run.tau[post.p + j])}
    summary["noise"]["posterior"] = noise_post
    summary["inference"] = "emcee posterior"
    summary["parameters"] = params_summary
    summary["sampler"] = sampler_block(run, n_walkers, laplace is not None, post.n_evals)
    samples = run.samples
    if check is not None and check.widens:
        rows, samples, check = sandwich_rows(check, run, post.bounds()[:post.p],
                                             recording.rig, params_summary)
        if check.doubted:
            summary["parameters_white_noise"] = params_summary
        summary["parameters"] = rows
    if check is not None:
        summary["noise"]["check"] = check.to_dict()
    summary["identifiability"] = identifiability(samples, names, prior_set)
    warn_bound(summary, post, x_map, names, prior_set, recording.rig, opt.seed, seen)
    summary["converged"] = chains_converged(params_summary, run)   # the sampler's own draws
    with_model_error(summary, nominal, opt.seed)
    summary["wall_s"] = time.perf_counter() - t0
    return _result(summary, names, m, eps, like, posterior=dt, samples=run.samples)


def _drawn(like: WhittleLikelihood, names: tuple[str, ...], eps: np.ndarray,
           forward: ForwardModel, sampled: tuple[SamplerRun, int, Any], opt: IdentifyOptions,
           recording: Recording) -> tuple[Any, dict[str, dict[str, Any]]]:
    """The sample's DataTree (with its pointwise log-likelihood) and its summary rows:
    formed while the adequacy verdict is still coming, used when the sample stands."""
    run, _, laplace = sampled
    loglik = run.bands            # kept by the sampler (run_emcee(bands=True))
    attrs = {"package_version": __version__, "recording": recording.source,
             "n_steps": run.n_steps, "burn": run.burn, "thin": run.thin, "seed": opt.seed,
             "inference": ("emcee ensemble (differential-evolution moves"
                           + (" and Laplace independence proposals" if laplace else "")
                           + "), walkers as chains")}
    dt = to_datatree(names, run.samples, run.log_post, loglik, like, eps, forward.x, run.tau,
                     attrs)
    return dt, summarise(dt, names, run.tau, recording.rig)


def _sampled(post: LogPosterior, x_map: np.ndarray, cov: np.ndarray | None,
             opt: IdentifyOptions, stop: Callable[[], bool] | None = None
             ) -> tuple[SamplerRun, int, tuple[np.ndarray, np.ndarray] | None] | None:
    """The emcee posterior from the MAP's Laplace ball (opt.seed: the same draws whenever
    it runs), with its walkers and Laplace proposal; None when ``stop`` said so at one of
    the sampler's checks."""
    like = post.likelihood
    rng = np.random.default_rng(opt.seed)
    ndim = post.ndim
    n_walkers = opt.walkers or max(24, 2 * ndim + 2)
    n_walkers += n_walkers % 2
    if n_walkers < 2 * ndim:
        raise BayesAmbError(f"option --walkers: value {n_walkers} out of range: must be >= "
                            f"{2 * ndim} (2 x {ndim} sampled dimensions)")
    if opt.moves not in ("laplace", "de"):
        raise BayesAmbError(f"option moves: unknown value {opt.moves!r}; known: laplace, de")
    start = initial_ball(post, x_map, cov, n_walkers, rng)
    laplace = None
    if opt.moves == "laplace" and cov is not None:
        laplace = (x_map[:post.p], np.asarray(cov)[:post.p, :post.p])
        like.remember_rows(4 * n_walkers)     # the noise-only moves reuse the band sums

    def progress(done: int, target: int, tau_max: float) -> None:
        if stop is not None and stop():
            raise Doubted
        if opt.progress is not None:
            opt.progress(done, target, tau_max)

    try:
        run = run_emcee(post, start, rng, n_steps=opt.steps, max_steps=opt.max_steps,
                        laplace=laplace, progress=progress, bands=True)
    except Doubted:
        return None
    finally:
        like.remember_rows(0)
    return run, n_walkers, laplace


def _checked(like: WhittleLikelihood, m: MapResult, names: tuple[str, ...],
             spectrum: LearnedSpectrum | None) -> NoiseCheck | None:
    """The noise check at the MAP; with a learned spectrum that it does not doubt, its
    intervals floored by the record's own scores (noise_check.record_check)."""
    return record_check(like, m.theta, m.log10_sigma, names, spectrum is not None)


def _result(summary: dict[str, Any], names: tuple[str, ...], m: MapResult, eps: np.ndarray,
            like: WhittleLikelihood, **more: Any) -> Identification:
    """The typed result of the summary built above, with what the run keeps beside it."""
    return replace(Identification.from_dict(summary, FILE), names=names, map_result=m,
                   eps=eps, likelihood=like, **more)
