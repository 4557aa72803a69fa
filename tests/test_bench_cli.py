"""`bayes-amb bench --quick`: it runs, prints every key, and its side-by-side checks hold.

No timing assertions: speed is measured in benchmarks, never asserted in tests. What is
asserted here can fail: each benchmark's two sides must compute the same thing (residual
DFT against forced_response, simulated displacements against forced_response), and both
MAP searches must find the paper's k_By = 0.5 from noise-free data.
"""

from __future__ import annotations

import contextlib
import io
import json
import math

import pytest

from bayes_amb.cli.bench_cmd import format_text
from bayes_amb.cli.main import main

KEYS = {
    "likelihood": {"likelihood_us", "baseline_us", "speedup", "n_params", "n_samples",
                   "batch", "repeats", "residual_rel_err", "numpy_path_us",
                   "kernel_speedup", "kernel_rel_err", "previous_path_us",
                   "previous_speedup", "previous_rel_err", "cpu_us",
                   "cpu_previous_speedup", "target_us"},
    "posterior": {"posterior_s", "wall_s", "ess_per_s", "converged", "max_r_hat", "min_ess",
                  "n_tau", "likelihood_evals", "baseline_eval_us",
                  "baseline_posterior_s_estimated", "speedup_estimated", "parameters",
                  "cpu_s", "de", "cpu_speedup", "wall_speedup", "target_s"},
    "simulate": {"simulate_s", "baseline_s", "speedup", "n_states", "n_samples",
                 "requirement_s", "max_rel_diff"},
    "map": {"lbfgs", "nelder_mead", "speedup", "eval_ratio"},
}
TIMES = {"likelihood": ("likelihood_us", "baseline_us", "numpy_path_us", "previous_path_us"),
         "posterior": ("posterior_s", "wall_s", "baseline_posterior_s_estimated"),
         "simulate": ("simulate_s", "baseline_s")}


def _bench_json(*args: str) -> dict:
    """`bayes-amb bench --quick --json ARGS`: its JSON (the command must succeed)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["bench", "--quick", "--json", *args])
    assert code == 0, err.getvalue()
    return json.loads(out.getvalue())


@pytest.fixture(scope="module")
def bench_json():
    """`bayes-amb bench --quick --json`, run once for the module."""
    return _bench_json()


def test_json_has_every_benchmark_and_key(bench_json):
    assert bench_json["quick"] is True
    assert bench_json["environment"]["cpu_count"] >= 1
    for name, keys in KEYS.items():
        missing = keys - set(bench_json[name])
        assert not missing, f"{name}: missing {sorted(missing)}"
        for k in TIMES.get(name, ()):
            v = bench_json[name][k]
            assert math.isfinite(v) and v > 0, f"{name}.{k} = {v}"
    for run in ("lbfgs", "nelder_mead"):
        assert {"wall_s", "n_evals", "theta", "log_post"} <= set(bench_json["map"][run])


def test_sides_compute_the_same_thing(bench_json):
    # the time-domain forced_response residual and the fast DFT residual (rounding only)
    assert bench_json["likelihood"]["residual_rel_err"] < 1e-9
    # the three likelihood paths give the same log posterior (issue 16's exactness)
    assert bench_json["likelihood"]["kernel_rel_err"] < 1e-9
    assert bench_json["likelihood"]["previous_rel_err"] < 1e-9
    assert set(bench_json["likelihood"]["cpu_us"]) == {"numba", "lapack", "numpy"}
    # simulate_recording against forced_response on the explicit closed loop
    assert bench_json["simulate"]["max_rel_diff"] < 1e-9
    assert bench_json["simulate"]["n_states"] == 320
    assert bench_json["likelihood"]["n_samples"] == 5000


def test_map_methods_recover_the_paper_value(bench_json):
    # noise-free reduced truth with k_By = 0.5: both searches must land on it
    for run in ("lbfgs", "nelder_mead"):
        assert bench_json["map"][run]["theta"] == pytest.approx(0.5, abs=1e-6)


def test_posterior_quick_reports_each_parameter(bench_json):
    post = bench_json["posterior"]
    assert post["fixed_steps"] is True
    names = [p["name"] for p in post["parameters"]]
    assert names == ["k_By", "c_By"]
    for p in post["parameters"]:
        assert p["bias"] == pytest.approx(p["mean"] - p["true"])
        assert p["sd"] > 0
    # the side-by-side run with the sampler before issue 16, on the same recording
    de = post["de"]
    assert de["moves"] == "de" and de["steps"] == post["steps"]
    assert [p["name"] for p in de["parameters"]] == names
    assert de["cpu_s"] > 0 and post["cpu_s"] > 0


def test_text_table_names_every_benchmark(bench_json):
    text = format_text(bench_json)
    for name in KEYS:
        assert any(line.startswith(name) for line in text.splitlines()), name
    assert "speedup" in text and "estimated" in text


def test_text_output_of_cli(capsys):
    assert main(["bench", "--quick", "--only", "simulate"]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[0].startswith("bayes-amb bench --quick")
    rows = [ln.split()[0] for ln in out.splitlines() if ln.split()[:1] and ln.split()[0] in KEYS]
    assert rows == ["simulate"]          # table row of the one benchmark run, no other


@pytest.mark.parametrize("only", ["nope", "likelihood,nope", ","])
def test_unknown_benchmark_is_a_one_line_error(only, capsys):
    assert main(["bench", "--quick", "--only", only]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.count("\n") == 1
    assert "option --only" in err and "known: likelihood, posterior, simulate, map" in err


def test_text_table_shows_missing_diagnostics_as_dash(bench_json):
    # a too-short chain can give no finite R-hat or ESS (None in the JSON)
    data = json.loads(json.dumps(bench_json))
    data["posterior"]["max_r_hat"] = None
    data["posterior"]["parameters"][0]["r_hat"] = None
    line = next(ln for ln in format_text(data).splitlines() if ln.startswith("posterior:"))
    assert "max R-hat -," in line


def test_study_throughput_row(bench_json):
    """The opt-in study benchmark is not in the default set; its row reads per 1000."""
    assert "study" not in bench_json
    data = dict(bench_json, study={"n_replicates": 1000, "wall_s": 480.0, "workers": 2,
                                   "s_per_1000": 480.0})
    row = next(ln for ln in format_text(data).splitlines() if ln.startswith("study"))
    assert "1000 replicates in 480 s" in row and "8.0 min/1000" in row


def test_diagnose_benchmark_names_the_hidden_lag():
    """`bench --only diagnose --quick`: the diagnosis it times names the lag it hides (the
    benchmark raises BenchmarkError otherwise); its row and detail line are printed."""
    doc = _bench_json("--only", "diagnose")
    d = doc["diagnose"]
    assert "actuator_lag" in d["effects"] and d["n_samples"] == 5000
    assert math.isfinite(d["cpu_s"]) and d["cpu_s"] > 0 and d["target_median_s"] == 20
    assert d["full_screen_cpu_s"] > 0 and d["speedup"] == pytest.approx(
        d["full_screen_cpu_s"] / d["cpu_s"])
    assert 0 < d["screens_cpu_s"] < d["cpu_s"] and d["screens_rise"] == pytest.approx(
        d["screens_cpu_s"] / (d["cpu_s"] - d["screens_cpu_s"]))
    text = format_text(doc)
    assert "diagnose" in text and "actuator_lag" in text and "full screens" in text
    assert "nonlinear screens" in text and "target <= 15 %" in text


def test_cpu_in_counts_the_wrapped_calls_and_restores_them():
    """The diagnose benchmark's timer (diagnose_case.cpu_in) sums the CPU time of calls of
    the named functions only while its block runs, and puts the functions back."""
    import bayes_amb.discrepancy.adequacy as adequacy
    from bayes_amb.bench.diagnose_case import SCREENS, cpu_in

    original = adequacy.take_in_clipping
    with cpu_in(SCREENS[:1]) as spent:
        assert adequacy.take_in_clipping is not original
        assert spent[0] == 0.0
    assert adequacy.take_in_clipping is original
    import numpy as np

    import bayes_amb.control.discrete as discrete
    with cpu_in((("bayes_amb.control.discrete", "spectral_radius"),)) as spent:
        discrete.spectral_radius(np.random.default_rng(0).standard_normal((300, 300)))
        inside = spent[0]
        np.linalg.eigvals(np.random.default_rng(1).standard_normal((300, 300)))
    assert inside > 0 and spent[0] == inside       # the wrapped call, not the eigvals after
    with pytest.raises(RuntimeError), cpu_in(SCREENS[:1]):
        raise RuntimeError("a failed diagnosis")
    assert adequacy.take_in_clipping is original


def test_transient_benchmark_fits_the_start_by_default():
    """`bench --only transient --quick`: on its record, which starts mid-operation, the
    default fits the transient, and that narrows the intervals; the row and detail print."""
    doc = _bench_json("--only", "transient")
    t = doc["transient"]
    assert t["fitted_by_default"] is True
    assert t["cost"] == pytest.approx(t["fitted_s"] / t["noise_s"])
    assert set(t["sd_ratio"]) == {"k_By", "c_By"} and max(t["sd_ratio"].values()) < 1
    text = format_text(doc)
    assert "start transient fitted" in text and "sd fitted / as noise" in text


def test_answers_benchmark_gives_the_same_answers_on_both_sides():
    """`bench --only answers` (quick): one thread and the pool give the same engineering
    answers on both rigs, and each side's time is a real time."""
    from bayes_amb.bench.answers_case import bench_answers

    r = bench_answers(quick=True)
    for row in (r.reference, r.test_rig):
        assert row.identical, row.rig
        assert row.serial_s > 0 and row.pool_s > 0 and row.pool_threads >= 1
        assert row.speedup == pytest.approx(row.serial_s / row.pool_s)
