"""Study layer (issue 8): spec validation, per-replicate seeds, resumable JSONL, process pool
against Dask, output tables and the SBC verdict.

Every study here is tiny: the paper's single-parameter case (reduced truth, k_By = 0.5,
1 kHz, 0.25 s records, MAP + Laplace), 3 noise levels x 2 replicates, about 1 s per
replicate. Nothing is timed.
"""

from __future__ import annotations

import copy
import csv
import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import scipy.stats as st

import bayes_amb
from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.priors import parse_prior
from bayes_amb.io.nonfinite import result_json_text
from bayes_amb.plots.studies import study_figures
from bayes_amb.results.study import Study
from bayes_amb.studies import (
    StudyError,
    finalise,
    load_study,
    read_rows,
    replicate_seeds,
    run_replicate,
    run_study,
    sbc_statistics,
    study_from_dict,
)
from bayes_amb.studies.binomial import binomial_band, binomial_interval
from bayes_amb.studies.replicate import N_RANK_DRAWS, replicate_id

STUDIES = Path(__file__).resolve().parents[1] / "studies"
CONSOLE = Path(sys.executable).with_name("bayes-amb")
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
NOISE = [0.0, 1e-7, 1e-6]

TINY = {"study": {"name": "tiny", "seed": 5, "replicates": 2, "inference": "laplace"},
        "truth": {"plant": "reduced", "params": {"k_By": 0.5}},
        "simulation": {"dt": 1e-3, "duration": 0.25, "amplitude": 0.5},
        "estimate": {"params": ["k_By"]},
        "factors": {"noise_rms": NOISE}}


def tiny(**study) -> dict:
    """The tiny study dict with [study] entries replaced."""
    d = copy.deepcopy(TINY)
    d["study"].update(study)
    return d


def to_toml(d: dict) -> str:
    """Enough TOML for the study dicts of this file (tables of scalars, lists, inline
    tables of scalars)."""
    def val(v):
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {val(x)}" for k, x in v.items()) + " }"
        if isinstance(v, list):
            return "[" + ", ".join(val(x) for x in v) + "]"
        return json.dumps(v) if not isinstance(v, float) else repr(v)
    return "".join(f"[{t}]\n" + "".join(f"{k} = {val(v)}\n" for k, v in tab.items()) + "\n"
                   for t, tab in d.items())


def canon(rows: list[dict]) -> list[str]:
    """Rows as canonical JSON, sorted by id, without the wall-clock time (the only entry
    allowed to differ between runs)."""
    return [json.dumps({k: v for k, v in r.items() if k != "wall_s"}, sort_keys=True,
                       default=lambda o: o.item()) for r in sorted(rows, key=lambda r: r["id"])]


def csv_without_wall(path: Path) -> list[dict]:
    with path.open(newline="", encoding="utf-8") as fh:
        return [{k: v for k, v in r.items() if k != "wall_s"} for r in csv.DictReader(fh)]


def jsonl_lines(path: Path) -> list[str]:
    return path.read_text(encoding="utf-8").splitlines()


@pytest.fixture(scope="module")
def finished(tmp_path_factory) -> tuple[object, Path, list[dict]]:
    """The tiny study run to completion in-process (workers=1), finalised, with figures."""
    out = tmp_path_factory.mktemp("tiny")
    spec = study_from_dict(tiny(), "tiny.toml")
    rows = run_study(spec, out, workers=1)
    study = finalise(spec, rows, out)
    study_figures(spec, out, study)
    return spec, out, rows


# --- shipped studies and validation -------------------------------------------------------

@pytest.mark.parametrize("path", sorted(STUDIES.glob("*.toml")), ids=lambda p: p.stem)
def test_shipped_studies_load(path):
    spec = load_study(path)
    assert spec.name == path.stem
    assert len(spec.cells) >= 1 and spec.n_replicates_total >= len(spec.cells)
    assert spec.estimate
    if spec.draw_from_prior:
        assert set(spec.priors) >= set(spec.estimate)


def test_shipped_sbc_study_draws_from_prior():
    spec = load_study(STUDIES / "sbc.toml")
    assert spec.draw_from_prior
    assert spec.replicates * len(spec.cells) >= 200


def _set(path: str, value):
    def mutate(d):
        *head, last = path.split(".")
        t = d
        for k in head:
            t = t.setdefault(k, {})
        t[last] = value
    return mutate


BAD = [
    ("unknown table", _set("solver.x", 1), "solver"),
    ("unknown factor", _set("factors.bogus", [1, 2]), "factors.bogus"),
    ("empty factor", _set("factors.noise_rms", []), "factors.noise_rms"),
    ("bad inference", _set("study.inference", "nuts"), "study.inference"),
    ("zero replicates", _set("study.replicates", 0), "study.replicates"),
    ("negative seed", _set("study.seed", -1), "study.seed"),
    ("bad plant", _set("truth.plant", "half"), "truth.plant"),
    ("unknown true param", _set("truth.params", {"k_Zz": 0.1}), "truth.params.k_Zz"),
    ("non-numeric truth", _set("truth.params", {"k_By": "big"}), "truth.params.k_By"),
    ("unknown estimate", _set("estimate.params", ["k_By", "k_Zz"]), "estimate.params"),
    ("unknown sim key", _set("simulation.fs", 1000), "simulation.fs"),
    ("malformed prior", _set("estimate.priors", {"k_By": "normal(0.2"}),
     "estimate.priors.k_By"),
    ("prior of unknown param", _set("estimate.priors", {"k_Zz": "normal(0, 1)"}),
     "estimate.priors.k_Zz"),
    ("draw without priors", _set("truth.draw_from_prior", True), "estimate.priors"),
    ("negative noise cell", _set("factors.noise_rms", [1e-7, -1e-7]), "factors (cell 1"),
    ("unknown effect", _set("truth.effects", ["warp_drive:speed=9"]), "truth.effects[0]"),
]


@pytest.mark.parametrize(("mutate", "field"), [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_study_raises_naming_the_field(mutate, field, tmp_path):
    d = tiny()
    mutate(d)
    with pytest.raises(StudyError, match=re.escape(f"field {field}")):
        study_from_dict(d)
    p = tmp_path / "bad.toml"                       # the same through the TOML file
    p.write_text(to_toml(d), encoding="utf-8")
    with pytest.raises(BayesAmbError, match=re.escape(f"field {field}")):
        load_study(p)


def test_missing_and_malformed_files(tmp_path):
    with pytest.raises(StudyError, match="field <file>"):
        load_study(tmp_path / "nope.toml")
    (tmp_path / "broken.toml").write_text("[study\nname = 1\n", encoding="utf-8")
    with pytest.raises(StudyError, match="field <toml>"):
        load_study(tmp_path / "broken.toml")


def test_toml_round_trip_and_cells(tmp_path):
    """The TOML writer of this file gives the same spec as the dict; cells are the product
    of the factors in order."""
    p = tmp_path / "tiny.toml"
    p.write_text(to_toml(tiny()), encoding="utf-8")
    spec = load_study(p)
    assert spec.to_dict() == study_from_dict(tiny()).to_dict()
    assert spec.cells == [{"noise_rms": v} for v in NOISE]
    d = tiny()
    d["factors"]["true.k_By"] = [0.3, 0.5]
    assert study_from_dict(d).cells == [{"noise_rms": n, "true.k_By": k}
                                        for n in NOISE for k in (0.3, 0.5)]


# --- seeds --------------------------------------------------------------------------------

def test_replicate_seeds_deterministic_and_distinct():
    spec = study_from_dict(tiny(replicates=20))
    grid = [(c, r) for c in range(len(spec.cells)) for r in range(spec.replicates)]
    seeds = [replicate_seeds(spec, c, r) for c, r in grid]
    assert seeds == [replicate_seeds(study_from_dict(tiny(replicates=20)), c, r)
                     for c, r in grid]
    flat = [s for triple in seeds for s in triple]
    assert len(set(flat)) == len(flat)              # 180 distinct 32-bit seeds
    other = study_from_dict(tiny(replicates=20, seed=6))
    assert all(replicate_seeds(other, c, r) != s for (c, r), s in zip(grid, seeds, strict=True))
    # the seeds of a replicate do not depend on how many replicates the study has
    assert replicate_seeds(study_from_dict(tiny(replicates=2)), 1, 1) == seeds[21]


def test_single_replicate_rerun_matches_full_run(finished):
    _, _, rows = finished
    assert len(rows) == 6
    by_id = {r["id"]: r for r in rows}
    alone = run_replicate(study_from_dict(tiny(), "tiny.toml"), 2, 1)
    assert alone["error"] == ""
    assert canon([alone]) == canon([by_id[replicate_id(2, 1)]])
    # and the replicates are really different datasets
    assert len({r["k_By_mean"] for r in rows}) == len(rows)


# --- resumability ----------------------------------------------------------------------

def _wait_for_lines(path: Path, n: int, proc: subprocess.Popen, timeout: float) -> None:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if path.is_file() and len(jsonl_lines(path)) >= n:
            return
        if proc.poll() is not None:
            pytest.fail(f"study exited early ({proc.returncode}): {proc.stderr.read()}")
        time.sleep(0.05)
    proc.kill()
    pytest.fail(f"fewer than {n} results after {timeout} s")


def test_killed_study_resumes_to_the_uninterrupted_result(tmp_path):
    toml = tmp_path / "resume.toml"
    toml.write_text(to_toml(tiny(name="resume", replicates=3)), encoding="utf-8")
    killed, clean = tmp_path / "killed", tmp_path / "clean"
    cmd = [str(CONSOLE), "study", str(toml), "--workers", "1", "--json"]
    proc = subprocess.Popen([*cmd, "--out", str(killed), "--no-figures"], env=ENV,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _wait_for_lines(killed / "results.jsonl", 2, proc, timeout=300)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    proc.stdout.close()
    proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL
    before = jsonl_lines(killed / "results.jsonl")
    assert 2 <= len(before) < 9, "killed too late to test resuming"
    assert [json.loads(x)["id"] for x in before]        # every line is intact JSON

    done = subprocess.run([*cmd, "--out", str(killed)], env=ENV, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    after = jsonl_lines(killed / "results.jsonl")
    assert after[:len(before)] == before                # rows before the kill untouched
    ids = [json.loads(x)["id"] for x in after]
    assert sorted(ids) == sorted({replicate_id(c, r) for c in range(3) for r in range(3)})
    assert json.loads(done.stdout)["rows"] == 9
    pngs = sorted((killed / "figures").glob("*.png"))
    assert [p.name for p in pngs] == ["noise_rms_k_By.png"]
    assert pngs[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    ref = subprocess.run([str(CONSOLE), "study", str(toml), "--workers", "2", "--json",
                          "--out", str(clean), "--no-figures"], env=ENV, capture_output=True,
                         text=True, timeout=600)
    assert ref.returncode == 0, ref.stderr
    assert not (clean / "figures").exists()
    assert canon(read_rows(killed / "results.jsonl")) == canon(read_rows(clean /
                                                                          "results.jsonl"))
    # and so do the final tables
    assert (killed / "summary.csv").read_text() == (clean / "summary.csv").read_text()
    assert csv_without_wall(killed / "results.csv") == csv_without_wall(clean / "results.csv")


def test_torn_last_line_is_ignored_and_rerun(finished, tmp_path):
    spec, src, rows = finished
    out = tmp_path / "torn"
    shutil.copytree(src, out)
    lines = jsonl_lines(out / "results.jsonl")
    torn_id = json.loads(lines[-1])["id"]
    (out / "results.jsonl").write_text("\n".join(lines[:-1]) + "\n" +
                                       lines[-1][:len(lines[-1]) // 2], encoding="utf-8")
    assert len(read_rows(out / "results.jsonl")) == 5
    again = run_study(spec, out, workers=1)
    assert len(again) == 6 and [r["id"] for r in again] == sorted(r["id"] for r in rows)
    assert canon(again) == canon(rows)
    fixed = jsonl_lines(out / "results.jsonl")      # the file itself is whole again
    assert [json.loads(x)["id"] for x in fixed][-1] == torn_id
    assert len(fixed) == 6


def test_other_study_in_same_folder_is_refused(finished, tmp_path):
    _, src, _ = finished
    out = tmp_path / "reuse"
    shutil.copytree(src, out)
    results = (out / "results.jsonl").read_bytes()
    with pytest.raises(StudyError, match=re.escape("field study.json")):
        run_study(study_from_dict(tiny(seed=6), "tiny.toml"), out, workers=1)
    toml = tmp_path / "other.toml"
    toml.write_text(to_toml(tiny(replicates=3)), encoding="utf-8")
    res = subprocess.run([str(CONSOLE), "study", str(toml), "--out", str(out), "--workers",
                          "1", "--no-figures"], env=ENV, capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and "different study definition" in res.stderr
    assert "Traceback" not in res.stderr
    assert (out / "results.jsonl").read_bytes() == results


# --- process pool against Dask ------------------------------------------------------------

def test_dask_and_process_pool_match_serial(finished, tmp_path):
    spec, _, serial = finished
    pool = run_study(spec, tmp_path / "pool", workers=2)
    dask = run_study(spec, tmp_path / "dask", dask_local=2)
    assert len(pool) == len(dask) == 6
    assert canon(pool) == canon(serial)
    assert canon(dask) == canon(serial)


# --- outputs ------------------------------------------------------------------------------

def test_results_csv_one_row_per_replicate(finished):
    _, out, rows = finished
    with (out / "results.csv").open(newline="") as fh:
        table = list(csv.DictReader(fh))
    assert sorted(r["id"] for r in table) == sorted(r["id"] for r in rows)
    for col in ("true_k_By", "k_By_mean", "k_By_sd", "k_By_hdi_lo", "k_By_hdi_hi",
                "k_By_covered", "k_By_rhat", "k_By_ess", "wall_s", "f_noise_rms"):
        assert col in table[0], col
    by_id = {r["id"]: r for r in rows}
    for t in table:
        r = by_id[t["id"]]
        assert float(t["k_By_mean"]) == r["k_By_mean"]
        assert float(t["f_noise_rms"]) == NOISE[r["cell"]]
        assert float(t["k_By_hdi_lo"]) <= float(t["k_By_mean"]) <= float(t["k_By_hdi_hi"])
        assert t["k_By_covered"] == str(r["k_By_hdi_lo"] <= 0.5 <= r["k_By_hdi_hi"])


def test_summary_csv_recomputed_from_rows(finished):
    _, out, rows = finished
    with (out / "summary.csv").open(newline="") as fh:
        summ = list(csv.DictReader(fh))
    assert [int(s["cell"]) for s in summ] == [0, 1, 2]
    for s in summ:
        rs = [r for r in rows if r["cell"] == int(s["cell"])]
        err = np.array([r["k_By_mean"] - r["true_k_By"] for r in rs])
        k = sum(r["k_By_covered"] for r in rs)
        assert float(s["f_noise_rms"]) == NOISE[int(s["cell"])] and s["param"] == "k_By"
        assert float(s["bias"]) == pytest.approx(err.mean(), rel=1e-12, abs=1e-15)
        assert float(s["rmse"]) == pytest.approx(np.sqrt(np.mean(err**2)), rel=1e-12)
        assert float(s["mean_width90"]) == pytest.approx(
            np.mean([r["k_By_hdi_hi"] - r["k_By_hdi_lo"] for r in rs]), rel=1e-12)
        assert float(s["coverage90"]) == k / len(rs)
        assert (float(s["coverage90_lo"]), float(s["coverage90_hi"])) == pytest.approx(
            binomial_interval(k, len(rs)))
        assert float(s["frac_converged"]) == np.mean([r["converged"] for r in rs])
    # the posterior widens with the noise (5 times per decade or more, by 1/sqrt(SNR))
    widths = [float(s["mean_width90"]) for s in summ]
    assert widths[0] < widths[1] / 5 < widths[2] / 25


def test_netcdf_and_manifest(finished):
    import xarray as xr

    spec, out, rows = finished
    with xr.open_dataset(out / "results.nc", engine="h5netcdf") as ds:
        assert ds.sizes["replicate"] == len(rows)
        by_id = {r["id"]: r["k_By_mean"] for r in rows}
        np.testing.assert_array_equal(ds["k_By_mean"].values,
                                      [by_id[str(i)] for i in ds["id"].values])
    m = json.loads((out / "study.json").read_text(encoding="utf-8"))
    assert m["package_version"] == bayes_amb.__version__
    assert m["study"] == json.loads(json.dumps(spec.to_dict()))
    assert m["seeds"] == {replicate_id(c, r): replicate_seeds(spec, c, r)[0]
                          for c in range(3) for r in range(2)}
    assert m["n_rows"] == 6 and m["failures"] == 0
    assert m["conclusions"] and all(isinstance(s, str) and s.endswith(".") and "k_By" in s
                                    for s in m["conclusions"])
    pngs = sorted((out / "figures").glob("*.png"))
    assert [p.name for p in pngs] == ["noise_rms_k_By.png"] and pngs[0].stat().st_size > 10_000


def _strict(text: str):
    """json.loads that refuses NaN/Infinity tokens (what any other JSON reader does)."""
    def refuse(token):
        raise ValueError(f"invalid JSON token {token}")
    return json.loads(text, parse_constant=refuse)


def test_non_finite_numbers_make_valid_json(finished, tmp_path):
    """Issue 28: json.dumps wrote NaN/Infinity tokens into results.jsonl and study.json (a
    failed replicate's sd, an undefined coverage). They are now null with a "non_finite"
    list, every file parses as strict JSON, and read_rows gives the floats back."""
    from bayes_amb.studies.runner import append_row

    spec, out, rows = finished
    bad = [dict(r) for r in rows]
    bad[0]["k_By_sd"] = float("nan")
    bad[1]["k_By_mean"] = np.float64("inf")
    bad[2]["k_By_hdi_lo"] = -math.inf
    shutil.copy(out / "study.json", tmp_path / "study.json")
    for r in bad:
        append_row(tmp_path / "results.jsonl", r)
    lines = jsonl_lines(tmp_path / "results.jsonl")
    parsed = [_strict(line) for line in lines]
    assert parsed[0]["k_By_sd"] is None and parsed[0]["non_finite"] == {"/k_By_sd": "nan"}
    back = read_rows(tmp_path / "results.jsonl")
    assert math.isnan(back[0]["k_By_sd"]) and back[1]["k_By_mean"] == math.inf
    assert back[2]["k_By_hdi_lo"] == -math.inf and "non_finite" not in back[0]
    assert canon(back[3:]) == canon(rows[3:])
    m = finalise(spec, back, tmp_path)
    text = (tmp_path / "study.json").read_text(encoding="utf-8")
    assert _strict(text)["n_rows"] == 6 and m.n_rows == 6
    loaded = Study.load(tmp_path)
    assert loaded == m and len(loaded.rows) == 6 and loaded.finished
    assert result_json_text(loaded.to_dict()) == text       # study.json, byte for byte
    _strict((out / "study.json").read_text(encoding="utf-8"))


# --- binomial intervals and SBC statistics ------------------------------------------------

@pytest.mark.parametrize(("k", "n"), [(0, 10), (3, 10), (10, 10), (45, 50), (180, 200)])
def test_binomial_interval_is_clopper_pearson(k, n):
    ci = st.binomtest(k, n).proportion_ci(confidence_level=0.95, method="exact")
    assert binomial_interval(k, n) == pytest.approx((ci.low, ci.high), rel=1e-9, abs=1e-12)
    if k == 0:                          # closed form: upper limit 1 - (alpha/2)^(1/n)
        assert binomial_interval(k, n)[1] == pytest.approx(1 - 0.025 ** (1 / n))


@pytest.mark.parametrize(("n", "p"), [(200, 0.5), (200, 0.9), (37, 0.1), (1000, 0.9)])
def test_binomial_band_is_central_99_percent(n, p):
    lo, hi = binomial_band(n, p)
    assert (lo * n, hi * n) == pytest.approx(st.binom.interval(0.99, n, p))
    kl, kh = round(lo * n), round(hi * n)
    assert st.binom.cdf(kh, n, p) - st.binom.cdf(kl - 1, n, p) >= 0.99
    assert st.binom.cdf(kl - 1, n, p) <= 0.005 and st.binom.sf(kh, n, p) <= 0.005


def _sbc_rows(q: np.ndarray) -> list[dict]:
    return [{"id": replicate_id(0, i), "cell": 0, "error": "", "k_By_q": float(x),
             "k_By_rank": int(min(math.floor(x * (N_RANK_DRAWS + 1)), N_RANK_DRAWS))}
            for i, x in enumerate(q)]


def test_sbc_statistics_uniform_ranks_are_calibrated():
    spec = study_from_dict(tiny())
    q = np.random.default_rng(8).uniform(size=400)
    s = sbc_statistics(spec, _sbc_rows(q))["k_By"]
    assert s["n"] == 400 and sum(s["rank_hist"]) == 400 and len(s["rank_hist"]) == 10
    assert s["coverage90"] == pytest.approx(np.mean((q > 0.05) & (q < 0.95)))
    assert s["calibrated"] is True


@pytest.mark.parametrize("shape", ["extremes", "middle", "shifted"])
def test_sbc_statistics_miscalibrated_ranks_fail(shape):
    """Overconfident posteriors pile ranks at the ends, underconfident ones in the middle,
    biased ones to one side; each must be flagged."""
    spec = study_from_dict(tiny())
    rng = np.random.default_rng(9)
    q = {"extremes": rng.beta(0.4, 0.4, 400), "middle": rng.beta(3, 3, 400),
         "shifted": rng.beta(1.6, 1, 400)}[shape]
    s = sbc_statistics(spec, _sbc_rows(q))["k_By"]
    assert s["calibrated"] is False
    assert s["uniformity_p"] < 0.01


# --- throughput benchmark case (tiny; the 1000-replicate run is never part of the suite) --

def test_throughput_study_shape():
    from bayes_amb.bench.study_case import NOISE_LEVELS, throughput_study

    spec = study_from_dict(throughput_study(1000))
    assert spec.n_replicates_total == 1000 and len(spec.cells) == len(NOISE_LEVELS) == 10
    assert spec.inference == "laplace" and spec.estimate == ("k_By",)
    assert spec.true_params == {"k_By": 0.5} and spec.plant == "reduced"
    assert spec.simulation["dt"] == 1e-3 and spec.simulation["duration"] == 0.5
    assert study_from_dict(throughput_study(3)).n_replicates_total == 3


def test_bench_study_throughput_counts_what_it_ran():
    from bayes_amb.bench.study_case import bench_study_throughput

    b = bench_study_throughput(n_replicates=2, workers=1)
    assert (b.n_replicates, b.n_levels, b.workers, b.failures) == (2, 2, 1, 0)
    assert b.converged == 2
    assert b.replicates_per_s == pytest.approx(2 / b.wall_s)
    assert b.s_per_1000 == pytest.approx(500 * b.wall_s)
    assert 0 < b.replicate_wall_s_median <= b.wall_s


def test_shipped_sbc_priors_stay_inside_the_simulator_range():
    """The SBC datasets are drawn from the estimation priors; a prior with mass outside the
    range the simulator accepts (|theta| <= 0.95) would lose datasets (or, if redrawn, make
    the data prior differ from the posterior's)."""
    spec = load_study(STUDIES / "sbc.toml")
    for n in spec.estimate:
        lo, hi = parse_prior(spec.priors[n], n).support
        assert -0.95 <= lo and hi <= 0.95, (n, spec.priors[n])


def test_sbc_figures_render_and_mark_what_fails(tmp_path):
    """Rank histograms and the coverage figure from sbc_statistics; an overconfident
    parameter (ranks at the ends) is drawn in the failure colour in both."""
    from matplotlib.colors import to_rgba

    from bayes_amb.plots.studies import plot_sbc_coverage, plot_sbc_ranks
    from bayes_amb.plots.style import save_figure, style_context
    spec = study_from_dict(tiny())
    rng = np.random.default_rng(10)
    sbc = {"k_By": sbc_statistics(spec, _sbc_rows(rng.uniform(size=400)))["k_By"],
           "c_By": sbc_statistics(spec, _sbc_rows(rng.beta(0.4, 0.4, 400)))["k_By"]}
    assert sbc["k_By"]["calibrated"] and not sbc["c_By"]["coverage90_ok"]
    with style_context():
        cov = plot_sbc_coverage(sbc)
        ranks = plot_sbc_ranks(sbc)
        failed = [line for ax in cov.axes for line in ax.get_lines()
                  if line.get_marker() == "X"]
        assert failed and all(line.get_xdata().tolist() == [1] for line in failed)
        bars = list(ranks.axes[1].containers[0])
        assert bars and all(b.get_facecolor() == to_rgba("C3") for b in bars)
        paths = [save_figure(cov, tmp_path / "cov.png"), save_figure(ranks, tmp_path / "r.png")]
    assert all(p.stat().st_size > 10_000 for p in paths)
