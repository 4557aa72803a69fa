"""Study throughput: how many replicates per second the study runner turns over.

The workload is the paper's single-parameter case (reduced truth, k_By = 0.5, 1 kHz,
0.5 s records) identified by MAP + Laplace, as a sensor-noise sweep of ~10 levels with
equal replicates per level, run through :func:`bayes_amb.studies.run_study` into a
temporary folder (process pool start-up included). Unlike the other benchmarks there is
no baseline: the number is replicates per second on this machine, and
:func:`replicate_cost` splits one replicate into its stages to show where the time goes.

Nothing here is run by the test suite at full size (1000 replicates take minutes).
With ``workers > 1`` call it under ``if __name__ == "__main__":`` (forkserver pool).
"""

from __future__ import annotations

import statistics
import tempfile
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from bayes_amb.bench.results import BenchmarkError, Result
from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.inference.estimate import LogPosterior, find_map, laplace_covariance
from bayes_amb.inference.forward import ForwardModel
from bayes_amb.inference.offline import dual_youla_eps
from bayes_amb.inference.priors import PriorSet
from bayes_amb.inference.whittle import WhittleLikelihood
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, simulate_recording
from bayes_amb.studies import run_study, study_from_dict

NOISE_LEVELS: tuple[float, ...] = (0.0, 1e-8, 3e-8, 1e-7, 3e-7, 1e-6, 3e-6, 1e-5, 2e-5, 3e-5)
"""Sensor noise RMS levels of the sweep, in m (0 to past failure, as studies/noise.toml)."""


@dataclass(frozen=True)
class StudyThroughputBench(Result):
    """Throughput of run_study on the MAP + Laplace noise sweep.

    Attributes
    ----------
    n_replicates, n_levels, workers : int
        Replicates run (n_levels x replicates per level), noise levels, pool processes.
    wall_s : float
        Wall time of run_study, in s (pool start-up included, tables not written).
    replicates_per_s : float
        n_replicates / wall_s.
    s_per_1000 : float
        Projected wall time of 1000 replicates, in s.
    replicate_wall_s_median : float
        Median wall time of one replicate inside its worker, in s.
    failures, converged : int
        Replicates that raised, and that converged (MAP success and a Laplace covariance).
    """

    n_replicates: int
    n_levels: int
    workers: int
    wall_s: float
    replicates_per_s: float
    s_per_1000: float
    replicate_wall_s_median: float
    failures: int
    converged: int


@dataclass(frozen=True)
class ReplicateCost(Result):
    """Median cost of the stages of one replicate, in s.

    Attributes
    ----------
    simulate_s : float
        simulate_recording (reference controller cached, as in a study worker).
    setup_s : float
        ForwardModel, dual-Youla eps and the Whittle likelihood.
    map_s : float
        find_map (MAP of theta and the noise intensities).
    laplace_s : float
        laplace_covariance at the MAP.
    total_s : float
        Sum of the four.
    cpu_total_s : float
        Median CPU time of this process for the four stages, in s (near total_s on an idle
        machine; much lower than total_s when other processes share the cores).
    n : int
        Replicates timed (noise levels cycled).
    """

    simulate_s: float
    setup_s: float
    map_s: float
    laplace_s: float
    total_s: float
    cpu_total_s: float
    n: int


def throughput_study(n_replicates: int, seed: int = 7) -> dict[str, Any]:
    """The study dict of the sweep: min(10, n) noise levels x (n // levels) replicates."""
    if n_replicates < 1:
        raise BenchmarkError(f"n_replicates must be >= 1, got {n_replicates}")
    n_levels = min(len(NOISE_LEVELS), n_replicates)
    return {"study": {"name": "throughput", "seed": seed,
                      "replicates": n_replicates // n_levels, "inference": "laplace"},
            "truth": {"plant": "reduced", "params": {"k_By": 0.5}},
            "simulation": {"dt": 1e-3, "duration": 0.5, "amplitude": 0.5},
            "estimate": {"params": ["k_By"]},
            "factors": {"noise_rms": list(NOISE_LEVELS[:n_levels])}}


def bench_study_throughput(n_replicates: int = 1000, workers: int = 2) -> StudyThroughputBench:
    """Run the MAP + Laplace noise sweep through run_study and time it.

    Parameters
    ----------
    n_replicates : int
        Replicates in all (rounded down to a multiple of the number of noise levels).
    workers : int
        Processes of the local pool (1: in this process).

    Returns
    -------
    StudyThroughputBench
    """
    spec = study_from_dict(throughput_study(n_replicates), "<bench throughput>")
    with tempfile.TemporaryDirectory(prefix="bayes-amb-throughput-") as out:
        t0 = time.perf_counter()
        rows = run_study(spec, out, workers=workers)
        wall = time.perf_counter() - t0
    n = len(rows)
    if n != spec.n_replicates_total:
        raise BenchmarkError(f"throughput study: expected {spec.n_replicates_total} rows, "
                             f"got {n}")
    return StudyThroughputBench(
        n_replicates=n, n_levels=len(spec.cells), workers=workers, wall_s=wall,
        replicates_per_s=n / wall, s_per_1000=1000 * wall / n,
        replicate_wall_s_median=statistics.median(r["wall_s"] for r in rows),
        failures=sum(bool(r["error"]) for r in rows),
        converged=sum(bool(r["converged"]) for r in rows))


def replicate_cost(n: int = 5, seed: int = 1) -> ReplicateCost:
    """Time the stages of n replicates of the sweep (the steps of identify with map_only)."""
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, 1e-3), rig)
    stages: dict[str, list[float]] = {"simulate": [], "setup": [], "map": [], "laplace": []}
    cpu = []
    for i in range(n):
        cfg = SimulationConfig(params={"k_By": 0.5}, truth="reduced", dt=1e-3, duration=0.5,
                               amplitude=0.5, noise_rms=NOISE_LEVELS[i % len(NOISE_LEVELS)],
                               seed=seed + i)
        c0, t0 = time.process_time(), time.perf_counter()
        rec, _ = simulate_recording(rig, ctrl, cfg)
        t1 = time.perf_counter()
        forward = ForwardModel(rec, ("k_By",))
        eps = dual_youla_eps(forward.parts, np.asarray(rec.y), np.asarray(rec.u))
        post = LogPosterior(WhittleLikelihood(forward, eps), PriorSet.build(("k_By",), None))
        t2 = time.perf_counter()
        m = find_map(post)
        t3 = time.perf_counter()
        laplace_covariance(post, np.concatenate([m.theta, m.log10_sigma]))
        t4 = time.perf_counter()
        cpu.append(time.process_time() - c0)
        for k, dt in zip(stages, (t1 - t0, t2 - t1, t3 - t2, t4 - t3), strict=True):
            stages[k].append(dt)
    med = {k: statistics.median(v) for k, v in stages.items()}
    return ReplicateCost(simulate_s=med["simulate"], setup_s=med["setup"], map_s=med["map"],
                         laplace_s=med["laplace"], total_s=sum(med.values()),
                         cpu_total_s=statistics.median(cpu), n=n)
