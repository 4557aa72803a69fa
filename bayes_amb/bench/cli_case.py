"""A README command as the user runs it, with and without ``OPENBLAS_NUM_THREADS=1``.

Issue 16: the benchmarks used to be run with ``OPENBLAS_NUM_THREADS=1`` while a user who
copies the README's commands does not set it, and on a loaded 2-core machine the paper's
case was up to 6x slower without it. The tool now limits the BLAS/OpenMP threads itself
(:mod:`bayes_amb.threads`). This benchmark runs the paper's case of the README,

    bayes-amb simulate --truth reduced --set k_By=0.5 --dt 1e-3 --duration 0.5 -o paper.csv
    bayes-amb identify paper.csv --params k_By --out DIR

(the ``identify`` step is timed, start-up included; one untimed ``--map-only`` run first
fills the compiled kernels' cache) in a fresh subprocess per run, in three environments,
interleaved run by run so that a change of machine load hits all three:

* ``default``: the user's environment with every thread variable *removed*
  (OPENBLAS_NUM_THREADS, OMP_NUM_THREADS, ..., BAYES_AMB_THREADS): what a new user gets;
* ``variable``: the same plus ``OPENBLAS_NUM_THREADS=1``, the old recipe;
* ``unprotected``: the default environment with ``BAYES_AMB_THREADS=0`` (the tool leaves
  the BLAS libraries alone): the behaviour before issue 16.

``ratio`` = median(default) / median(variable) (target <= 1.2) and ``unprotected_ratio`` =
median(unprotected) / median(variable), what the protection saves.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from bayes_amb.bench.results import BenchmarkError, Result
from bayes_amb.threads import BLAS_ENV_VARS, ENV_VAR

SIMULATE_ARGS = ("simulate", "--truth", "reduced", "--set", "k_By=0.5", "--dt", "1e-3",
                 "--duration", "0.5", "-o", "paper.csv")
IDENTIFY_ARGS = ("identify", "paper.csv", "--params", "k_By", "--no-progress")
VARIANTS = ("default", "variable", "unprotected")
TARGET_RATIO = 1.2


@dataclass(frozen=True)
class CliBench(Result):
    """Wall time of one README command in a subprocess, per thread environment.

    Attributes
    ----------
    command : str
        The timed command line.
    repeats : int
        Runs per environment (interleaved).
    default_s, variable_s, unprotected_s : float
        Median wall time, in s, of the runs without any thread variable, with
        OPENBLAS_NUM_THREADS=1, and with BAYES_AMB_THREADS=0 (no protection).
    ratio : float
        default_s / variable_s (target <= TARGET_RATIO).
    unprotected_ratio : float
        unprotected_s / variable_s.
    runs_s : dict
        Every run's wall time per environment, in order.
    """

    command: str
    repeats: int
    default_s: float
    variable_s: float
    unprotected_s: float
    ratio: float
    unprotected_ratio: float
    target_ratio: float
    runs_s: dict[str, list[float]]


def child_env(variant: str, base: dict[str, str] | None = None) -> dict[str, str]:
    """The environment of a timed run: base (default os.environ) without any thread
    variable, plus what the variant adds.

    Examples
    --------
    >>> env = child_env("variable", {"OMP_NUM_THREADS": "1", "PATH": "/bin"})
    >>> sorted(env.items())
    [('OPENBLAS_NUM_THREADS', '1'), ('PATH', '/bin')]
    """
    if variant not in VARIANTS:
        raise ValueError(f"unknown variant {variant!r}; expected one of {VARIANTS}")
    env = {k: v for k, v in (os.environ if base is None else base).items()
           if k not in (*BLAS_ENV_VARS, ENV_VAR)}
    if variant == "variable":
        env["OPENBLAS_NUM_THREADS"] = "1"
    elif variant == "unprotected":
        env[ENV_VAR] = "0"
    return env


def _run(args: tuple[str, ...], cwd: Path, env: dict[str, str]) -> float:
    """Wall time of `bayes-amb ARGS` in a fresh interpreter; BenchmarkError if it fails."""
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "bayes_amb.cli.main", *args], cwd=cwd,
                          env=env, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        raise BenchmarkError(f"cli benchmark: `bayes-amb {' '.join(args)}` failed with status "
                             f"{done.returncode}: {done.stderr.strip()[-300:]}")
    return wall


def bench_cli(quick: bool = False) -> CliBench:
    """The paper's case of the README through the CLI, with and without the variable.

    Parameters
    ----------
    quick : bool
        One run per environment and ``--map-only`` (smoke test; not representative).

    Returns
    -------
    CliBench
    """
    repeats = 1 if quick else 3
    args = (*IDENTIFY_ARGS, *(("--map-only",) if quick else ()))
    runs: dict[str, list[float]] = {v: [] for v in VARIANTS}
    with tempfile.TemporaryDirectory(prefix="bayes-amb-bench-cli-") as tmp:
        cwd = Path(tmp)
        _run(SIMULATE_ARGS, cwd, child_env("default"))
        # untimed: fills the compiled kernels' on-disk cache, so no timed run compiles
        _run((*IDENTIFY_ARGS, "--map-only", "--out", "warm_up"), cwd, child_env("default"))
        for r in range(repeats):
            order = VARIANTS if r % 2 == 0 else VARIANTS[::-1]
            for v in order:
                runs[v].append(_run((*args, "--out", f"run_{v}_{r}"), cwd, child_env(v)))
    med = {v: statistics.median(t) for v, t in runs.items()}
    return CliBench(command="bayes-amb " + " ".join((*args, "--out", "DIR")), repeats=repeats,
                    default_s=med["default"], variable_s=med["variable"],
                    unprotected_s=med["unprotected"],
                    ratio=med["default"] / med["variable"],
                    unprotected_ratio=med["unprotected"] / med["variable"],
                    target_ratio=TARGET_RATIO, runs_s=runs)
