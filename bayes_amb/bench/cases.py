"""The benchmarks: each fast path timed side by side with its baseline in the same process.

Every benchmark returns a small frozen dataclass (bayes_amb.bench.results) with both
timings and their ratio (``speedup`` = baseline time / our time). Times are medians over
repeats after one warm-up call. Each benchmark first checks that the two sides compute the
same thing and raises BenchmarkError if they do not, so that the ratio compares like with
like. ``quick=True`` shrinks each benchmark to a smoke test of a few seconds.

Run them with ``bayes-amb bench`` or ``benchmarks/run_all.py`` (see benchmarks/README.md).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import control
import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

from bayes_amb.bench.baselines import (
    closed_loop_ss,
    median_time,
    naive_eval_us,
    naive_log_likelihood,
)
from bayes_amb.bench.recordings import PARAMS_8, TRUE_8, make_recording
from bayes_amb.bench.results import (
    BenchmarkError,
    LikelihoodBench,
    MapBench,
    MapRun,
    ParamRecovery,
    PosteriorBench,
    Result,
    SamplerSide,
    SimulateBench,
)
from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.estimate import LogPosterior, find_map
from bayes_amb.inference.forward import ForwardModel
from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.inference.offline import dual_youla_eps
from bayes_amb.inference.priors import PriorSet
from bayes_amb.inference.whittle import WhittleLikelihood
from bayes_amb.io.recording import Recording
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, build_truth, simulate_recording
from bayes_amb.threads import limited_threads

log = logging.getLogger(__name__)

CHECK_RTOL = 1e-9  # largest relative difference allowed between the two sides
LIKELIHOOD_TARGET_US = 50.0   # issue 16: one evaluation, 8 parameters, 5000 x 4, batch 32


def _posterior(rec: Recording, names: tuple[str, ...]
               ) -> tuple[ForwardModel, NDArray, LogPosterior]:
    fm = ForwardModel(rec, names)
    eps = dual_youla_eps(fm.parts, np.asarray(rec.y), np.asarray(rec.u))
    return fm, eps, LogPosterior(WhittleLikelihood(fm, eps), PriorSet.build(names))


def _ball(theta: NDArray, n: int, rng: np.random.Generator, spread: float = 1e-3) -> NDArray:
    """n points [theta, log10 sigma] scattered by spread around theta (walkers near it)."""
    sig = np.tile([np.log10(2e-8), -10.0, np.log10(0.05)], (n, 1))
    return np.hstack([theta + spread * rng.standard_normal((n, theta.size)), sig])


def bench_likelihood(quick: bool = False, batch: int = 32) -> LikelihoodBench:
    """Fast log posterior against the naive likelihood: 8 parameters, 5000 samples x 4.

    The record: reduced truth at TRUE_8, 0.5 s at dt = 1e-4 s, noise_rms 2e-8 m, r2_rms
    0.05 A. Fast side: ``LogPosterior(WhittleLikelihood(...), PriorSet.build(...))`` on
    batches of ``batch`` parameter vectors near the truth (emcee passes half the ensemble
    as one batch); per-evaluation time = batch time / batch. Baseline:
    :func:`~bayes_amb.bench.baselines.naive_log_likelihood`, one vector per call. Before
    timing, the DFT of the forced_response residual at the truth (through the likelihood's
    prewhitening FIR) is checked against the fast path's residual DFT (relative difference
    below CHECK_RTOL). The default path is also timed against the paths it replaced
    (``BAYES_AMB_KERNEL=lapack``: LAPACK's modal form and the first compiled kernel;
    ``numpy``: before any kernel), interleaved call by call in wall and CPU time, and all
    must give the same log posterior to CHECK_RTOL.

    Parameters
    ----------
    quick : bool
        Fewer repeats (3 instead of 15 batches and 9 naive evaluations).
    batch : int
        Parameter vectors per fast call.

    Returns
    -------
    LikelihoodBench
    """
    rec = make_recording("reduced", TRUE_8, 1e-4, 0.5, noise_rms=2e-8, r2_rms=0.05)
    fm, eps, post = _posterior(rec, PARAMS_8)
    theta = np.array([TRUE_8[n] for n in PARAMS_8])
    like = post.likelihood
    r_time = naive_log_likelihood(fm, eps, _ball(theta, 1, np.random.default_rng(0), 0.0)[0])[1]
    # the likelihood sees the residual through its prewhitening FIR (1 when there is none)
    ref = np.fft.rfft(lfilter(like.prefilter, [1.0], r_time, axis=0), axis=0)[like.k]
    fast = like.residual_dft(theta[None])[0][0] * like.scale
    err = float(np.max(np.abs(fast - ref)) / np.max(np.abs(ref)))
    if not err < CHECK_RTOL:
        raise BenchmarkError(f"likelihood benchmark: the DFT residual differs from the "
                             f"forced_response residual by {err:.2e}; expected < {CHECK_RTOL}")
    points = _ball(theta, batch, np.random.default_rng(0))
    repeats = 3 if quick else 15
    paths = _kernel_side_by_side(post, points, repeats)
    fast_us = paths["numba"]["wall_us"]
    base_us = naive_eval_us(fm, eps, points, 3 if quick else 9)
    cpu = {k: v["cpu_us"] for k, v in paths.items()}
    return LikelihoodBench(likelihood_us=fast_us, baseline_us=base_us,
                           speedup=base_us / fast_us, n_params=len(PARAMS_8),
                           n_samples=rec.n_samples, batch=batch, repeats=repeats,
                           residual_rel_err=err, numpy_path_us=paths["numpy"]["wall_us"],
                           kernel_speedup=paths["numpy"]["wall_us"] / fast_us,
                           kernel_rel_err=paths["numba"]["rel_err"],
                           previous_path_us=paths["lapack"]["wall_us"],
                           previous_speedup=paths["lapack"]["wall_us"] / fast_us,
                           previous_rel_err=paths["lapack"]["rel_err"], cpu_us=cpu,
                           cpu_previous_speedup=cpu["lapack"] / cpu["numba"],
                           target_us=LIKELIHOOD_TARGET_US)


def _kernel_side_by_side(post: LogPosterior, points: NDArray, repeats: int
                         ) -> dict[str, dict[str, float]]:
    """Per-evaluation time (us) of the posterior on each likelihood path, interleaved call by
    call after a warm-up of each (the order rotates every round; the likelihood's remembered
    last batch is forgotten before every call): ``numba`` (the default: everything compiled),
    ``lapack`` (the path before it: the modal form by LAPACK's eig, then the first compiled
    kernel) and ``numpy`` (the path before any kernel), see ``BAYES_AMB_KERNEL``. Per path:
    the median wall time (``wall_us``) and CPU time (``cpu_us``, ``time.process_time``) of
    one evaluation, and the largest relative difference of its log posteriors from the numpy
    path's (``rel_err``; BenchmarkError above CHECK_RTOL)."""
    from bayes_amb.inference.kernels import KERNEL_MODES, Engine

    forward = post.likelihood.forward
    chosen = forward.engine
    wall: dict[str, list[float]] = {k: [] for k in KERNEL_MODES}
    cpu: dict[str, list[float]] = {k: [] for k in KERNEL_MODES}
    values = {}
    try:
        for r in range(repeats + 1):
            shift = r % len(KERNEL_MODES)
            for kind in KERNEL_MODES[shift:] + KERNEL_MODES[:shift]:
                forward.engine = Engine(kind)
                post.likelihood._last_sums = None    # no remembered batch: a real evaluation
                c0, t0 = time.process_time(), time.perf_counter()
                values[kind] = post(points)
                t1, c1 = time.perf_counter(), time.process_time()
                if r:
                    wall[kind].append(t1 - t0)
                    cpu[kind].append(c1 - c0)
    finally:
        forward.engine = chosen
    n = points.shape[0]
    out = {}
    for kind in KERNEL_MODES:
        rel = float(np.max(np.abs(values[kind] - values["numpy"]) / np.abs(values["numpy"])))
        if not rel < CHECK_RTOL:
            raise BenchmarkError(f"likelihood benchmark: the {kind} path's log posterior "
                                 f"differs from the numpy path's by {rel:.2e}; expected < "
                                 f"{CHECK_RTOL}")
        out[kind] = {"wall_us": 1e6 * float(np.median(wall[kind])) / n,
                     "cpu_us": 1e6 * float(np.median(cpu[kind])) / n, "rel_err": rel}
    return out


POSTERIOR_TARGET_S = 15.0   # issue 16: the 8-parameter converged posterior, whole call


def _identify_side(rec: Recording, names: tuple[str, ...], truth: dict[str, float],
                   moves: str, steps: int | None) -> tuple[SamplerSide, dict]:
    """identify with the given sampler moves, timed in CPU and wall time."""
    c0, w0 = time.process_time(), time.perf_counter()
    # the quick smoke test's 0.2 s of the full truth is not adequate for the model, which
    # identify then does not sample: its adequacy test is left out there
    res = identify(rec, names, options=IdentifyOptions(steps=steps, moves=moves,
                                                       adequacy=steps is None))
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    pars = tuple(ParamRecovery(name=n, true=truth[n], mean=v.mean, sd=v.sd,
                               bias=v.mean - truth[n], r_hat=v.r_hat, ess_bulk=v.ess_bulk)
                 for n, v in res.parameters.items())
    samp = res.sampler
    side = SamplerSide(moves=moves, cpu_s=cpu, wall_s=wall, posterior_s=samp.wall_s,
                       steps=samp.steps, likelihood_evals=samp.likelihood_evals,
                       n_tau=samp.n_tau, max_r_hat=max(p.r_hat for p in pars),
                       min_ess=min(p.ess_bulk for p in pars), converged=res.converged,
                       parameters=pars)
    return side, res.to_dict()


def bench_posterior(quick: bool = False) -> PosteriorBench:
    """``identify`` of 8 parameters from 1 s at 10 kHz of the full (320-state) truth.

    True theta TRUE_8, sensor noise 2e-7 m, r1 1e-7 m, r2 0.02 A, seed 2; the sampler runs
    to 50 tau (its own stopping rule). Side by side in the same process: the same call with
    the sampler before issue 16 (``IdentifyOptions(moves="de")``, differential evolution
    alone), run first. The naive baseline is an estimate, not a run: the posterior's
    likelihood evaluations times the naive per-evaluation cost
    (:func:`~bayes_amb.bench.baselines.naive_eval_us`, measured on this record).

    Parameters
    ----------
    quick : bool
        Smoke test: k_By and c_By from 0.2 s, 100 fixed steps (not converged).

    Returns
    -------
    PosteriorBench
    """
    names = ("k_By", "c_By") if quick else PARAMS_8
    truth = {n: TRUE_8[n] for n in names}
    rec = make_recording("full", truth, 1e-4, 0.2 if quick else 1.0, seed=2,
                         noise_rms=2e-7, r1_rms=1e-7, r2_rms=0.02)
    steps = 100 if quick else None
    de, _ = _identify_side(rec, names, truth, "de", steps)
    ours, s = _identify_side(rec, names, truth, "laplace", steps)
    pars = ours.parameters
    fm, eps, _ = _posterior(rec, names)
    theta = np.array([truth[n] for n in names])
    eval_us = naive_eval_us(fm, eps, _ball(theta, 8, np.random.default_rng(1)),
                            2 if quick else 7)
    samp = s["sampler"]
    est = samp["likelihood_evals"] * eval_us * 1e-6
    return PosteriorBench(
        n_params=len(names), n_samples=rec.n_samples, posterior_s=samp["wall_s"],
        wall_s=s["wall_s"], ess_per_s=ours.min_ess / samp["wall_s"], converged=s["converged"],
        max_r_hat=ours.max_r_hat, min_ess=ours.min_ess, n_tau=samp["n_tau"],
        steps=samp["steps"], walkers=samp["walkers"], fixed_steps=quick,
        likelihood_evals=samp["likelihood_evals"], baseline_eval_us=eval_us,
        baseline_posterior_s_estimated=est, speedup_estimated=est / s["wall_s"],
        parameters=pars, cpu_s=ours.cpu_s, de=de, cpu_speedup=de.cpu_s / ours.cpu_s,
        wall_speedup=de.wall_s / ours.wall_s, target_s=POSTERIOR_TARGET_S)


def bench_simulate(quick: bool = False) -> SimulateBench:
    """``simulate_recording`` with the full 320-state truth, 0.5 s at 10 kHz.

    Baseline: ``control.forced_response`` on the same closed loop assembled explicitly
    (:func:`~bayes_amb.bench.baselines.closed_loop_ss`) from the given excitation; the truth
    plant, ZOH and assembly are timed on both sides. The two displacement records must
    agree to CHECK_RTOL. Requirement: simulate_s below 2 s.

    Parameters
    ----------
    quick : bool
        0.1 s instead of 0.5 s, 2 repeats instead of 7.

    Returns
    -------
    SimulateBench
    """
    dt, duration = 1e-4, 0.1 if quick else 0.5
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, dt), rig)
    cfg = SimulationConfig(truth="full", dt=dt, duration=duration)
    rec, truth = simulate_recording(rig, ctrl, cfg)
    eta = np.asarray(rec.excitation["eta"])
    n_states = build_truth(rig, truth["speed_rpm"], "full").n_states

    def baseline() -> NDArray:
        tp = build_truth(rig, truth["speed_rpm"], "full")
        sys = closed_loop_ss(tp.A, tp.B, tp.C, ctrl, dt)
        return np.asarray(control.forced_response(sys, U=eta.T).outputs).T

    y = np.asarray(rec.y)
    diff = float(np.max(np.abs(baseline()[:, :4] - y)) / np.max(np.abs(y)))
    if not diff < CHECK_RTOL:
        raise BenchmarkError(f"simulate benchmark: the forced_response y differs from the "
                             f"simulate_recording y by {diff:.2e}; expected < {CHECK_RTOL}")
    repeats = 2 if quick else 7
    ours = median_time(lambda: simulate_recording(rig, ctrl, cfg), repeats)
    base = median_time(baseline, repeats)
    return SimulateBench(simulate_s=ours, baseline_s=base, speedup=base / ours,
                         n_states=n_states, n_samples=rec.n_samples, requirement_s=2.0,
                         max_rel_diff=diff)


def bench_map(quick: bool = False) -> MapBench:
    """MAP of the paper's case: L-BFGS-B against Nelder-Mead (the paper's fminsearch).

    Reduced truth, k_By = 0.5, dt = 1e-3 s, 0.5 s, no noise; k_By estimated. Each search
    runs ``find_map`` on a fresh posterior; the wall time is the median over repeats.

    Parameters
    ----------
    quick : bool
        0.2 s instead of 0.5 s, one search per method instead of three.

    Returns
    -------
    MapBench
    """
    rec = make_recording("reduced", {"k_By": 0.5}, 1e-3, 0.2 if quick else 0.5)
    runs = {}
    for method in ("lbfgs", "nelder-mead"):
        walls = []
        for _ in range(1 if quick else 3):
            post = _posterior(rec, ("k_By",))[2]
            t0 = time.perf_counter()
            m = find_map(post, method)
            walls.append(time.perf_counter() - t0)
        runs[method] = MapRun(method=method, wall_s=float(np.median(walls)),
                              n_evals=m.n_evals, theta=float(m.theta[0]),
                              abs_error=abs(float(m.theta[0]) - 0.5), log_post=m.log_post)
    lb, nm = runs["lbfgs"], runs["nelder-mead"]
    return MapBench(lbfgs=lb, nelder_mead=nm, speedup=nm.wall_s / lb.wall_s,
                    eval_ratio=nm.n_evals / lb.n_evals)


def bench_cli(quick: bool = False) -> Result:
    """The README's paper case through the CLI in subprocesses, with and without
    OPENBLAS_NUM_THREADS=1 (bayes_amb.bench.cli_case)."""
    from bayes_amb.bench.cli_case import bench_cli as run

    return run(quick)


def bench_study(quick: bool = False) -> Result:
    """Study throughput (bayes_amb.bench.study_case): the 1000-replicate MAP + Laplace
    noise sweep of the paper's case through run_study on 2 workers (quick: 20)."""
    from bayes_amb.bench.study_case import bench_study_throughput

    return bench_study_throughput(20 if quick else 1000, workers=2)


def bench_diagnose(quick: bool = False) -> Result:
    """One diagnosis of a 2 s, 10 kHz recording with a hidden lag, default options
    (bayes_amb.bench.diagnose_case; quick: 0.5 s)."""
    from bayes_amb.bench.diagnose_case import bench_diagnose as run

    return run(quick)


def bench_plan(quick: bool = False) -> Result:
    """The plan of the eight coefficients against the study it replaces
    (bayes_amb.bench.plan_case)."""
    from bayes_amb.bench.plan_case import bench_plan as run

    return run(quick)


def bench_transient(quick: bool = False) -> Result:
    """identify on a record that starts mid-operation, its start transient fitted (the
    default there) against taken as noise (bayes_amb.bench.transient_case)."""
    from bayes_amb.bench.transient_case import bench_transient as run

    return run(quick)


def bench_rigs(quick: bool = False) -> Result:
    """ROSS's real test rig against the reference rig: model, likelihood, identify and
    diagnose on the same case (bayes_amb.bench.rig_case)."""
    from bayes_amb.bench.rig_case import bench_rigs as run

    return run(quick)


def bench_answers(quick: bool = False) -> Result:
    """The engineering answers with one thread against the pool of threads, on both rigs
    (bayes_amb.bench.answers_case)."""
    from bayes_amb.bench.answers_case import bench_answers as run

    return run(quick)


BENCHMARKS: dict[str, Callable[..., Result]] = {
    "likelihood": bench_likelihood, "posterior": bench_posterior,
    "simulate": bench_simulate, "map": bench_map, "diagnose": bench_diagnose,
    "cli": bench_cli, "study": bench_study, "plan": bench_plan,
    "transient": bench_transient, "rigs": bench_rigs, "answers": bench_answers}

DEFAULT_BENCHMARKS = ("likelihood", "posterior", "simulate", "map")
"""What ``bayes-amb bench`` runs without --only (the diagnosis, the CLI runs and the study
sweep are asked for with --only diagnose, --only cli, --only study)."""


@limited_threads
def run_benchmarks(names: list[str] | tuple[str, ...] | None = None, quick: bool = False
                   ) -> dict[str, Result]:
    """Run the named benchmarks in BENCHMARKS order, BLAS threads limited as the CLI does
    (bayes_amb.threads).

    Parameters
    ----------
    names : sequence of str, optional
        Names from BENCHMARKS (default: DEFAULT_BENCHMARKS).
    quick : bool
        Passed to each benchmark.

    Returns
    -------
    dict
        Benchmark name -> result dataclass.

    Raises
    ------
    BayesAmbError
        For an unknown benchmark name.
    """
    names = list(DEFAULT_BENCHMARKS) if not names else list(names)
    unknown = [n for n in names if n not in BENCHMARKS]
    if unknown:
        raise BayesAmbError(f"option --only: unknown benchmark {unknown[0]!r}; known: "
                            f"{', '.join(BENCHMARKS)}")
    out = {}
    for n in BENCHMARKS:
        if n in names:
            log.info("benchmark %s%s", n, " (quick)" if quick else "")
            out[n] = BENCHMARKS[n](quick=quick)
    return out
