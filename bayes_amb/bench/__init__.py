"""Benchmarks: speed measured as ratios against a baseline run side by side.

Each benchmark times a fast path of bayes_amb and a plain baseline in the same process and
returns both with their ratio (see ``benchmarks/README.md``). Speed is never asserted in
tests; run ``bayes-amb bench`` or ``benchmarks/run_all.py``.
"""

from bayes_amb.bench.baselines import (
    closed_loop_ss,
    median_time,
    naive_eval_us,
    naive_log_likelihood,
)
from bayes_amb.bench.cases import (
    BENCHMARKS,
    DEFAULT_BENCHMARKS,
    bench_cli,
    bench_diagnose,
    bench_likelihood,
    bench_map,
    bench_posterior,
    bench_simulate,
    make_recording,
    run_benchmarks,
)
from bayes_amb.bench.results import (
    BenchmarkError,
    DiagnoseBench,
    LikelihoodBench,
    MapBench,
    MapRun,
    ParamRecovery,
    PosteriorBench,
    Result,
    SamplerSide,
    SimulateBench,
    environment,
    report,
)

__all__ = ["BENCHMARKS", "DEFAULT_BENCHMARKS", "BenchmarkError", "DiagnoseBench",
           "LikelihoodBench", "MapBench", "MapRun", "ParamRecovery", "PosteriorBench", "Result",
           "SamplerSide", "SimulateBench", "bench_cli", "bench_diagnose", "bench_likelihood",
           "bench_map", "bench_posterior", "bench_simulate", "closed_loop_ss", "environment",
           "make_recording", "median_time", "naive_eval_us", "naive_log_likelihood",
           "report", "run_benchmarks"]
