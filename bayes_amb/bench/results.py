"""Result objects of the benchmarks: small frozen dataclasses holding the numbers.

Times are in seconds (``*_s``) or microseconds (``*_us``). ``speedup`` is always the
baseline's time divided by ours: above 1 we are faster, below 1 the baseline is.
"""

from __future__ import annotations

import os
import platform
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np


class BenchmarkError(RuntimeError):
    """The two sides of a benchmark disagree, so their timings must not be compared."""


class Result:
    """Base of the benchmark results."""

    def to_dict(self) -> dict[str, Any]:
        """Plain dict of the numbers (nested results become dicts, tuples lists)."""
        return asdict(self)  # type: ignore[call-overload]


@dataclass(frozen=True)
class LikelihoodBench(Result):
    """Cost of one log-posterior evaluation, fast path against the naive baseline.

    Attributes
    ----------
    likelihood_us, baseline_us : float
        Median time of one evaluation, in us: fast (batch time / batch) and naive
        (forced_response + iid Gaussian log-likelihood).
    speedup : float
        baseline_us / likelihood_us.
    n_params, n_samples, batch, repeats : int
        Parameters, samples per channel (4 channels), vectors per fast call, timed calls.
    residual_rel_err : float
        Largest relative difference between the two residual DFTs at the truth.
    numpy_path_us : float
        The same evaluation on the numpy path (``BAYES_AMB_KERNEL=numpy``, the path before
        the compiled kernel), timed interleaved with likelihood_us.
    kernel_speedup : float
        numpy_path_us / likelihood_us.
    kernel_rel_err : float
        Largest relative difference between the default path's log posteriors and the numpy
        path's.
    previous_path_us : float
        The same evaluation on the path before the compiled modal form
        (``BAYES_AMB_KERNEL=lapack``: ``np.linalg.eig``, numpy ZOH and modal state, the first
        compiled band-sum kernel), timed interleaved with the others.
    previous_speedup : float
        previous_path_us / likelihood_us.
    previous_rel_err : float
        Largest relative difference between its log posteriors and the numpy path's.
    cpu_us : dict
        Median CPU time (``time.process_time``) of one evaluation per path: "numba" (the
        default), "lapack", "numpy"; the comparable figure on a shared machine.
    cpu_previous_speedup : float
        cpu_us["lapack"] / cpu_us["numba"].
    target_us : float
        The issue-16 target for likelihood_us.
    """

    likelihood_us: float
    baseline_us: float
    speedup: float
    n_params: int
    n_samples: int
    batch: int
    repeats: int
    residual_rel_err: float
    numpy_path_us: float
    kernel_speedup: float
    kernel_rel_err: float
    previous_path_us: float
    previous_speedup: float
    previous_rel_err: float
    cpu_us: dict[str, float]
    cpu_previous_speedup: float
    target_us: float


@dataclass(frozen=True)
class ParamRecovery(Result):
    """Posterior of one parameter, in theta units (bias = mean - true)."""

    name: str
    true: float
    mean: float
    sd: float
    bias: float
    r_hat: float
    ess_bulk: float


@dataclass(frozen=True)
class SamplerSide(Result):
    """One ``identify`` run of the posterior benchmark with the given sampler moves.

    Attributes
    ----------
    moves : str
        IdentifyOptions.moves ("laplace": the default; "de": differential evolution
        alone, the sampler before issue 16).
    cpu_s, wall_s, posterior_s : float
        CPU time (time.process_time) and wall time of the whole call, and the sampler's
        wall time, in s.
    steps, likelihood_evals : int
    n_tau, max_r_hat, min_ess : float
    converged : bool
    parameters : tuple of ParamRecovery
    """

    moves: str
    cpu_s: float
    wall_s: float
    posterior_s: float
    steps: int
    likelihood_evals: int
    n_tau: float
    max_r_hat: float
    min_ess: float
    converged: bool
    parameters: tuple[ParamRecovery, ...]


@dataclass(frozen=True)
class PosteriorBench(Result):
    """A full ``identify`` run and the estimated cost of the same run done naively.

    Attributes
    ----------
    posterior_s, wall_s : float
        Sampler wall time and total identify wall time (MAP, sampling, summary), in s.
    ess_per_s : float
        Smallest bulk ESS over the parameters / posterior_s.
    converged, max_r_hat, min_ess, n_tau : bool, float, float, float
        Diagnostics of the run (n_tau: chain length in autocorrelation times).
    steps, walkers, fixed_steps : int, int, bool
        Sampler settings (fixed_steps: quick mode, not run to 50 tau).
    likelihood_evals : int
        Log-posterior evaluations of the whole run (MAP included).
    baseline_eval_us : float
        Naive cost of one evaluation on this record, in us.
    baseline_posterior_s_estimated : float
        likelihood_evals x baseline_eval_us, in s: an estimate, not a timed run.
    speedup_estimated : float
        baseline_posterior_s_estimated / wall_s.
    parameters : tuple of ParamRecovery
    cpu_s : float
        CPU time (time.process_time) of the identify call, in s.
    de : SamplerSide
        The same identification with the sampler before issue 16 (IdentifyOptions(moves=
        "de")), run in the same process right before ours.
    cpu_speedup, wall_speedup : float
        de.cpu_s / cpu_s and de.wall_s / wall_s.
    target_s : float
        Issue 16's target for wall_s.
    """

    n_params: int
    n_samples: int
    posterior_s: float
    wall_s: float
    ess_per_s: float
    converged: bool
    max_r_hat: float
    min_ess: float
    n_tau: float
    steps: int
    walkers: int
    fixed_steps: bool
    likelihood_evals: int
    baseline_eval_us: float
    baseline_posterior_s_estimated: float
    speedup_estimated: float
    parameters: tuple[ParamRecovery, ...]
    cpu_s: float
    de: SamplerSide
    cpu_speedup: float
    wall_speedup: float
    target_s: float


@dataclass(frozen=True)
class SimulateBench(Result):
    """Closed-loop simulation of the full truth against forced_response.

    Attributes
    ----------
    simulate_s, baseline_s : float
        Median wall time of simulate_recording and of the forced_response baseline, in s.
    speedup : float
        baseline_s / simulate_s.
    n_states, n_samples : int
        Truth-plant states and samples simulated.
    requirement_s : float
        The time simulate_s must stay under, in s.
    max_rel_diff : float
        Largest relative difference between the displacements of the two.
    """

    simulate_s: float
    baseline_s: float
    speedup: float
    n_states: int
    n_samples: int
    requirement_s: float
    max_rel_diff: float


@dataclass(frozen=True)
class MapRun(Result):
    """One MAP search: median wall time (s), log-posterior evaluations, estimate of theta,
    its absolute error and the log posterior reached."""

    method: str
    wall_s: float
    n_evals: int
    theta: float
    abs_error: float
    log_post: float


@dataclass(frozen=True)
class MapBench(Result):
    """MAP by L-BFGS-B against Nelder-Mead (the paper's fminsearch); speedup is the wall
    time ratio nelder_mead / lbfgs, eval_ratio the ratio of evaluations."""

    lbfgs: MapRun
    nelder_mead: MapRun
    speedup: float
    eval_ratio: float


@dataclass(frozen=True)
class DiagnoseBench(Result):
    """One diagnosis with default options (bayes_amb.bench.diagnose_case): CPU and wall
    time (s), the issue's target for the median CPU time, the record (s, samples), what it
    found (effects named, verdict), and side by side the CPU time of the same diagnosis
    with every candidate screened fully (no pre-screening) and the ratio; the CPU time of
    the nonlinearity screens within the default run and the rise it makes over the rest
    (screens / (cpu - screens)), with its target."""

    cpu_s: float
    wall_s: float
    target_median_s: float
    duration_s: float
    n_samples: int
    effects: tuple[str, ...]
    verdict: str
    full_screen_cpu_s: float
    speedup: float
    screens_cpu_s: float
    screens_rise: float
    target_screens_rise: float


def environment() -> dict[str, Any]:
    """What the timings depend on: versions, CPU count and BLAS thread settings.

    Returns
    -------
    dict
        Versions of bayes_amb, Python, numpy, scipy and python-control, the machine, the
        CPU count and OPENBLAS_NUM_THREADS / OMP_NUM_THREADS / BAYES_AMB_THREADS (None
        when unset).
    """
    import control
    import scipy

    from bayes_amb import __version__
    return {"bayes_amb": __version__, "python": platform.python_version(),
            "numpy": np.__version__, "scipy": scipy.__version__, "control": control.__version__,
            "machine": platform.machine(), "cpu_count": os.cpu_count(),
            "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS"),
            "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS"),
            "BAYES_AMB_THREADS": os.environ.get("BAYES_AMB_THREADS")}


def _finite_or_none(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _finite_or_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite_or_none(v) for v in obj]
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def report(results: dict[str, Result], quick: bool) -> dict[str, Any]:
    """The JSON document of a benchmark run (what ``bayes-amb bench --json`` prints).

    Parameters
    ----------
    results : dict
        Benchmark name -> result, as returned by ``run_benchmarks``.
    quick : bool
        Whether the smoke-test sizes were used.

    Returns
    -------
    dict
        ``quick``, ``environment`` (:func:`environment`) and one dict per benchmark under
        its name; non-finite numbers (e.g. R-hat of a too-short chain) become None.
    """
    out: dict[str, Any] = {"quick": bool(quick), "environment": environment()}
    out.update({name: r.to_dict() for name, r in results.items()})
    return _finite_or_none(out)
