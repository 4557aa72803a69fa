"""Thread control (issue 16): BLAS pools single-threaded by default, with an override."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np  # (also loads the BLAS library whose pools are checked)
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from bayes_amb.cli.main import _global_words, main
from bayes_amb.errors import BayesAmbError
from bayes_amb.threads import (
    BLAS_ENV_VARS,
    ENV_VAR,
    configure_process,
    configured_threads,
    limited_threads,
    parse_threads,
)


@pytest.fixture
def clean_env(monkeypatch):
    for var in (ENV_VAR, *BLAS_ENV_VARS):
        monkeypatch.delenv(var, raising=False)
    saved = threadpool_limits(limits=None)     # configure_process limits pools for good
    yield monkeypatch
    saved.restore_original_limits()


def _blas_threads() -> set[int]:
    return {d["num_threads"] for d in threadpool_info() if d["user_api"] == "blas"}


def test_default_fills_only_unset_variables(clean_env):
    clean_env.setenv("OMP_NUM_THREADS", "3")
    assert configure_process() == 1
    assert os.environ["OPENBLAS_NUM_THREADS"] == "1"
    assert os.environ["MKL_NUM_THREADS"] == "1"
    assert os.environ["OMP_NUM_THREADS"] == "3"       # the user's own setting is kept
    assert ENV_VAR not in os.environ


def test_explicit_count_overrides_and_is_inherited(clean_env):
    clean_env.setenv("OPENBLAS_NUM_THREADS", "7")
    assert configure_process(2) == 2
    assert os.environ[ENV_VAR] == "2"
    assert all(os.environ[v] == "2" for v in BLAS_ENV_VARS)
    # a worker process started now (a study's pool) sees the same limit
    code = ("import json, numpy; from threadpoolctl import threadpool_info; "
            "print(json.dumps([d['num_threads'] for d in threadpool_info() "
            "if d['user_api'] == 'blas']))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env=dict(os.environ)).stdout
    assert set(json.loads(out)) == {2}


def test_zero_leaves_the_libraries_alone(clean_env):
    assert configure_process(0) == 0
    assert all(v not in os.environ for v in BLAS_ENV_VARS)
    assert configured_threads() == 0


@pytest.mark.parametrize("value", ["-1", "two", "1.5", ""])
def test_bad_counts_are_rejected(value):
    with pytest.raises(BayesAmbError, match="expected a thread count >= 0"):
        parse_threads(value, "option --threads")


def test_bad_environment_value_names_the_variable(clean_env):
    clean_env.setenv(ENV_VAR, "many")
    with pytest.raises(BayesAmbError, match=f"{ENV_VAR}: expected a thread count"):
        configured_threads()


def test_decorated_entry_points_run_single_threaded_and_restore(clean_env):
    @limited_threads
    def inner() -> set[int]:
        return _blas_threads()

    with threadpool_limits(limits=2, user_api="blas"):
        assert inner() == {1}
        assert _blas_threads() == {2}
        clean_env.setenv(ENV_VAR, "0")
        assert inner() == {2}


@pytest.mark.parametrize(("argv", "value"), [
    (["--threads", "3", "identify", "x.csv"], "3"),
    (["-v", "--threads=0", "bench"], "0"),
    (["identify", "x.csv", "--threads", "3"], None),     # after the command: not global
    (["params"], None),
])
def test_threads_option_is_read_before_parsing(argv, value):
    assert _global_words(argv)[0] == value


def test_cli_rejects_a_bad_thread_count_in_one_line(clean_env, capsys):
    assert main(["--threads", "lots", "params"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "option --threads" in err


@pytest.mark.parametrize("variant", ["default", "variable", "unprotected"])
def test_cli_benchmark_environments_differ_only_in_the_thread_variables(variant):
    from bayes_amb.bench.cli_case import child_env

    base = {"PATH": "/bin", "PYTHONPATH": "/src", "OPENBLAS_NUM_THREADS": "4",
            "OMP_NUM_THREADS": "2", ENV_VAR: "3"}
    env = child_env(variant, base)
    added = {"default": {}, "variable": {"OPENBLAS_NUM_THREADS": "1"},
             "unprotected": {ENV_VAR: "0"}}[variant]
    assert env == {"PATH": "/bin", "PYTHONPATH": "/src", **added}


def test_the_cli_module_does_not_load_numpy_before_the_thread_limit():
    """OpenBLAS reads its thread variables when it is loaded: main() sets them, so importing
    the CLI entry point must not load numpy (and with it BLAS) first."""
    code = "import sys, bayes_amb.cli.main; print('numpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("env,blas,expected", [
    ({"BAYES_AMB_POOL": "3"}, "1", 3),
    ({"BAYES_AMB_POOL": "0"}, "1", 1),
    ({}, "0", 1),                 # BLAS keeps its own threads: no pool on top of them
    ({}, "2", 1),
])
def test_pool_threads(monkeypatch, env, blas, expected):
    from bayes_amb.threads import pool_threads

    monkeypatch.delenv("BAYES_AMB_POOL", raising=False)
    monkeypatch.setenv("BAYES_AMB_THREADS", blas)
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    assert pool_threads() == expected


def test_pool_threads_follows_the_cpus_and_refuses_a_bad_count(monkeypatch):
    from bayes_amb.threads import MAX_POOL, pool_threads

    monkeypatch.delenv("BAYES_AMB_POOL", raising=False)
    monkeypatch.setenv("BAYES_AMB_THREADS", "1")
    assert pool_threads() == min(len(os.sched_getaffinity(0)), MAX_POOL)
    monkeypatch.setenv("BAYES_AMB_POOL", "many")
    with pytest.raises(BayesAmbError, match="BAYES_AMB_POOL"):
        pool_threads()


def test_over_rows_covers_the_batch_once_in_threads_and_raises_their_errors(monkeypatch):
    import threading

    from bayes_amb.threads import over_rows

    monkeypatch.setenv("BAYES_AMB_THREADS", "1")
    monkeypatch.setenv("BAYES_AMB_POOL", "3")
    seen, ranges, names = [], [], set()

    def record(lo, hi):
        seen.extend(range(lo, hi))
        ranges.append((lo, hi))
        names.add(threading.current_thread().name)

    over_rows(record, 7)
    assert sorted(seen) == list(range(7)) and len(ranges) == 3    # one range per thread
    assert "MainThread" in names and len(names) >= 2              # the caller and the pool
    seen.clear()
    over_rows(record, 1)                                          # below min_rows: in place
    assert seen == [0]

    def fail(lo, hi):
        if lo > 0:
            raise ValueError(f"row {lo}")

    with pytest.raises(ValueError, match="row"):
        over_rows(fail, 4)
    monkeypatch.setenv("BAYES_AMB_POOL", "1")                     # no pool: one call
    calls = []
    over_rows(lambda lo, hi: calls.append((lo, hi)), 9)
    assert calls == [(0, 9)]


def test_the_likelihood_kernels_give_the_same_rows_in_threads_bit_for_bit(monkeypatch):
    """The compiled modal form, the state after the record, the residual DFT and the band
    sums (both kernels of each) computed with the batch split across threads equal the
    single-threaded results exactly: every row is computed alone."""
    from bayes_amb.inference import kernels, residual_rows, walker_kernels
    from bayes_amb.inference.eigen import final_state, modal_batch

    rng = np.random.default_rng(3)
    nb, ns, nf = 29, 10, 300
    A = rng.standard_normal((nb, ns, ns))
    A *= 0.9 / np.max(np.abs(np.linalg.eigvals(A)), axis=1)[:, None, None]
    B, C = rng.standard_normal((nb, ns, 4)), rng.standard_normal((nb, 4, ns))
    x = rng.standard_normal((500, 4))
    X = rng.standard_normal((nf, 4)) + 1j * rng.standard_normal((nf, 4))
    E = rng.standard_normal((nf, 4)) + 1j * rng.standard_normal((nf, 4))
    z = np.exp(1j * np.linspace(0.01, 3.1, nf))
    starts, counts = np.arange(0, nf, 30), np.full(nf // 30, 30)

    def run():
        lam, Bm, Cm, ok = modal_batch(A, B, C)
        xi = final_state(lam, Bm, x, 1e-13)
        args = (lam, Bm, Cm, xi, X, z, E, 2.0)
        return (lam, Bm, Cm, ok, xi, kernels.residual_dft(*args),
                residual_rows.residual_dft_lanes(*args),
                kernels.residual_band_sums(*args, starts, counts),
                walker_kernels.residual_band_sums_lanes(*args, starts, counts))

    monkeypatch.setenv("BAYES_AMB_THREADS", "1")
    monkeypatch.setenv("BAYES_AMB_POOL", "1")
    alone = run()
    assert alone[3].all() and alone[6] is not None
    monkeypatch.setenv("BAYES_AMB_POOL", "2")
    for a, b in zip(alone, run(), strict=True):
        assert np.array_equal(a, b)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the test forks on Linux")
def test_identifys_forked_adequacy_test_keeps_its_rows_in_one_thread(monkeypatch):
    """The adequacy test runs in a forked process beside identify's fit (pending.py): each
    takes a core, so the process's own batches stay in one thread (with two each, identify
    on ROSS's test rig took 12 % longer)."""
    from bayes_amb.inference import pending

    monkeypatch.setenv("BAYES_AMB_POOL", "2")
    monkeypatch.setattr(pending, "_assessed", lambda *a: os.environ.get("BAYES_AMB_POOL"))
    run = pending.PendingAdequacy(None, (), None, 0)       # type: ignore[arg-type]
    try:
        assert run._proc is not None                       # forked here
        run._done(wait=True)
        assert run._out == ("ok", "1")
    finally:
        run.close()
    assert os.environ["BAYES_AMB_POOL"] == "2"            # the caller's own is untouched
