"""Diagnosis end to end: location tests under the null, named effects, the CLI and its file.

Statistical tests use fixed seeds; the null calibration of the coherence F-test uses a
Kolmogorov-Smirnov test on 400 p-values (it fails when the test is miscalibrated).
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from scipy import stats

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.discrepancy import DiagnoseOptions, all_candidates, diagnose
from bayes_amb.discrepancy.library import BEARING_COEFFICIENTS
from bayes_amb.discrepancy.locate import _coherence, holm, merge_spans
from bayes_amb.io.recording import load_recording, save_recording
from bayes_amb.results import Diagnosis
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, parse_effect, simulate_recording
from bayes_amb.uncertainty import get_spec
from tests.helpers import run_cli

NOISE = {"noise_rms": 2e-7, "r1_rms": 1e-7, "r2_rms": 0.02}


@pytest.fixture(scope="module")
def ctrl():
    rig = load_rig()
    return rig, export_controller(reference_controller(rig, 1e-4), rig)


def _rec(ctrl, effects=(), seed=0, duration=0.5):
    rig, c = ctrl
    cfg = SimulationConfig(truth="reduced", params={"k_By": 0.3}, dt=1e-4, duration=duration,
                           effects=tuple(parse_effect(e) for e in effects), seed=seed, **NOISE)
    return simulate_recording(rig, c, cfg)


def test_holm_and_spans():
    p = np.array([0.01, 0.04, 0.03, 0.005])
    assert np.allclose(holm(p), [0.03, 0.06, 0.06, 0.02])
    assert merge_spans([[10, 20], [19, 30], [100, 200]]) == [[10, 30], [100, 200]]


def test_coherence_f_test_is_uniform_under_the_null():
    """Residual independent of the excitation, coloured across bands: p-values uniform."""
    rng = np.random.default_rng(3)
    nf, n_bands = 4000, 100
    X = rng.normal(size=(nf, 4)) + 1j * rng.normal(size=(nf, 4))
    colour = np.repeat(np.geomspace(1, 1e3, n_bands), nf // n_bands)[:, None]
    R = colour * (rng.normal(size=(nf, 4)) + 1j * rng.normal(size=(nf, 4)))
    bands = np.array_split(np.arange(nf), n_bands)
    _, p = _coherence(R, X, bands)
    assert stats.kstest(p.ravel(), "uniform").pvalue > 1e-3
    # and it has power: 10 % of the residual driven by the excitation
    R2 = R + 0.3 * colour * (X @ rng.normal(size=(4, 4)))
    _, p2 = _coherence(R2, X, bands)
    assert np.mean(p2 < 0.01) > 0.9


@pytest.fixture(scope="module")
def control(ctrl):
    rec, truth = _rec(ctrl, seed=11)
    return rec, truth, diagnose(rec, "k_By,c_By")


def test_effect_free_recording_raises_no_alarm(control):
    """One effect-free recording gives a clean report with every check passed. This is a
    regression check of one seed, not the false-alarm rate: that rate is measured on the
    foreign generator's controls (benchmarks/foreign/benchmark.py, README "Diagnosis")."""
    _, _, d = control
    r = d.to_dict()
    assert not r["mismatch"]["detected"]
    assert r["explanations"] == []
    assert r["verdict"] == "no mismatch" and not r["unexplained"]["present"]
    assert r["summary"].startswith("No mismatch")
    assert [(c["check"], c["ok"]) for c in r["checks"]] == [
        ("excitation", True), ("controller", True), ("start", True), ("offsets", True),
        ("linearity", True), ("information", True)]
    assert r["adequacy"]["adequate"] and r["adequacy"]["line"].startswith("model adequate")
    # the model error never narrows a posterior
    assert all(v >= 1 - 1e-9 for v in r["model_error"]["before"]["sd_ratio"].values())
    assert r["record_window"]["at_rest"] and r["record_window"]["start_s"] == 0
    tried = {(c["effect"], c["location"]) for c in r["candidates"]}
    # the six coefficients left out of the fit are tried first, then every physics candidate
    left_out = {("bearing_coefficient", n) for n in BEARING_COEFFICIENTS
                if n not in ("k_By", "c_By")}
    assert tried == {(c.effect, c.location) for c in all_candidates(rig=load_rig())} | left_out


def _mid_operation(rec, cut: int, y_offset, u_offset):
    """The same loop recorded from sample ``cut`` on, with sensor and current offsets."""
    t = np.asarray(rec.t)[cut:]
    return dataclasses.replace(
        rec, t=t - t[0], y=np.asarray(rec.y)[cut:] + np.asarray(y_offset),
        u=np.asarray(rec.u)[cut:] + np.asarray(u_offset),
        excitation={k: np.asarray(v)[cut:] for k, v in rec.excitation.items()})


def test_record_habits_are_nuisance_not_physics(ctrl):
    """A record cut from a running loop (non-zero plant and controller state) with sensor
    offsets of 20-50 um (seen by the controller, so u has them too): the checks find both,
    the start-up is kept out of the comparison, and no physics is named."""
    rig, c = ctrl
    cfg = SimulationConfig(truth="reduced", params={"k_By": 0.3}, dt=1e-4, duration=0.8,
                           seed=21, **NOISE)
    rec, _ = simulate_recording(rig, c, cfg)
    y_off = np.array([2e-5, -3e-5, 5e-5, 1e-5])
    # the controller's steady-state answer to the offsets: its DC gain from y to u
    A, B, C, D = (np.asarray(m) for m in (c.A, c.B, c.C, c.D))
    dc = C[:4] @ np.linalg.solve(np.eye(A.shape[0]) - A, B[:, :4]) + D[:4, :4]
    habit = _mid_operation(rec, 3000, y_off, dc @ y_off)
    r = diagnose(habit).to_dict()
    checks = {ch["check"]: ch for ch in r["checks"]}
    assert checks["controller"]["ok"]
    assert not checks["start"]["at_rest"]
    assert any(s.startswith("y_Bx offset +50") for s in checks["offsets"]["removed"])
    assert 0 < r["record_window"]["start_s"] <= 0.2 * 0.5
    assert r["explanations"] == [] and not r["unexplained"]["present"]
    # the eight coefficients are fitted by default; k_By = 0.3 is recovered
    kb = r["parameters_before"]["k_By"]
    assert len(r["parameters_before"]) == 8
    assert kb["hdi90"][0] - 2 * kb["sd"] < 0.3 < kb["hdi90"][1] + 2 * kb["sd"]


def test_a_controller_that_is_not_the_documented_one_fails_a_check(ctrl):
    """The loop ran with the documented controller, but the sidecar's has a state-feedback
    gain 1 % larger: the check fails and no physics is named."""
    rec, _ = _rec(ctrl, seed=22, duration=0.3)
    k = rec.controller
    Cm = np.array(k.C)
    Cm[:4] *= 1.01
    wrong = dataclasses.replace(rec, controller=dataclasses.replace(k, C=Cm))
    r = diagnose(wrong, "k_By,c_By").to_dict()
    checks = {ch["check"]: ch for ch in r["checks"]}
    assert not checks["controller"]["ok"] and "FAILED" in checks["controller"]["line"]
    assert r["verdict"] == "data check failed" and r["explanations"] == []
    assert r["summary"].startswith("The data failed a check")
    # and the right controller passes the same check on the same data
    ok = diagnose(rec, "k_By,c_By", options=DiagnoseOptions(max_effects=0)).to_dict()
    assert {ch["check"]: ch["ok"] for ch in ok["checks"]}["controller"]


def test_a_left_out_coefficient_is_named_before_physics(ctrl):
    """k_Ax off by 0.4 while only k_By, c_By are fitted: the left-out coefficient is the
    explanation, with its size, and no physics is named."""
    rig, c = ctrl
    cfg = SimulationConfig(truth="reduced", params={"k_By": 0.3, "k_Ax": 0.4}, dt=1e-4,
                           duration=0.5, seed=23, **NOISE)
    rec, _ = simulate_recording(rig, c, cfg)
    r = diagnose(rec, "k_By,c_By", options=DiagnoseOptions(max_effects=1)).to_dict()
    assert [(e["effect"], e["location"], e["kind"]) for e in r["explanations"]] == [
        ("bearing_coefficient", "k_Ax", "model")]
    v = r["explanations"][0]["params"]["value"]
    true = 0.4 * get_spec("k_Ax").physical_scale(rig)
    lo, hi = v["hdi90"]
    sd = (hi - lo) / (2 * 1.645)
    assert abs(v["mean"] - true) < 4 * sd


@pytest.mark.parametrize("effect,name,key,true,loc", [
    ("unbalance:u_kgm=2e-6,disc=D2,phase_deg=40", "unbalance", "u_kgm", 2e-6, "D2"),
    ("actuator_lag:bandwidth_hz=2500", "actuator_lag", "bandwidth_hz", 2500.0, "both"),
])
def test_concealed_effect_is_named_with_its_parameter(ctrl, effect, name, key, true, loc):
    rec, _ = _rec(ctrl, [effect], seed=12)
    clean, _ = _rec(ctrl, [], seed=12)
    quiet = simulate_recording(ctrl[0], ctrl[1], SimulationConfig(
        truth="reduced", params={"k_By": 0.3}, dt=1e-4, duration=0.5, seed=12))[0]
    eff_rms = np.sqrt(np.mean((np.asarray(rec.y) - np.asarray(clean.y)) ** 2, axis=0))
    noise_rms = np.sqrt(np.mean((np.asarray(clean.y) - np.asarray(quiet.y)) ** 2, axis=0))
    assert np.all(eff_rms < noise_rms)                 # concealed in the raw signals
    d = diagnose(rec, "k_By,c_By")
    r = d.to_dict()
    assert d.effects == [name]
    e = r["explanations"][0]
    assert e["location"] == loc and e["score"] > 3
    lo, hi = e["params"][key]["hdi90"]
    sd = (hi - lo) / (2 * 1.645)                       # Laplace: HDI90 = mean -+ 1.645 sd
    assert abs(e["params"][key]["mean"] - true) < 3 * sd   # fails 0.3 % of seeds if calibrated
    assert r["fit"]["log_likelihood_gain"] > 3
    if name != "unbalance":
        assert r["balancing"] is None
        return
    # the balancing answer: the truth in both correction planes (nothing at D1) inside the
    # 99.9 % credible ellipse of (a, b) (chi-square, 2 dof: fails 0.1 % of seeds)
    planes = {p["plane"]: p for p in r["balancing"]["planes"]}
    for plane, u in (("D1", 0j), ("D2", true * np.exp(1j * np.deg2rad(40)))):
        ab = planes[plane]["ab_kgm"]
        dev = np.array([u.real, u.imag]) - ab["mean"]
        assert dev @ np.linalg.solve(ab["cov"], dev) < -2 * np.log(1e-3), plane
    assert planes["D2"]["nonzero"]
    assert r["mismatch"]["detected"] and r["mismatch"]["bands_hz"]


def test_cli_diagnose_writes_the_documented_file(ctrl, tmp_path, capsys):
    rec, truth = _rec(ctrl, ["sensor_gain:gain=0.05,channel=Bx"], seed=13, duration=0.3)
    csv_path, _ = save_recording(tmp_path / "rec.csv", rec, truth=truth)
    out = tmp_path / "diag"
    code, stdout, _ = run_cli(["diagnose", str(csv_path), "--effects",
                               "sensor_gain,time_delay", "--out", str(out), "--json"], capsys)
    assert code == 0
    r = json.loads(stdout)
    assert r == json.loads((out / "diagnosis.json").read_text())
    assert set(r["mismatch"]) >= {"detected", "channels", "bands_hz", "time_s", "evidence"}
    for e in r["explanations"]:
        assert set(e) >= {"effect", "location", "params", "score"}
        for v in e["params"].values():
            assert set(v) >= {"mean", "hdi90", "unit"}
    assert {c["effect"] for c in r["candidates"]} == {"sensor_gain", "time_delay"}
    for k in ("before", "after"):
        assert set(r["fit"][k]) == {"nrmse", "whiteness_p"}
        assert set(r["fit"][k]["nrmse"]) == {"Ax", "Ay", "Bx", "By"}
    assert set(r["parameters_before"]) == set(r["parameters_after"]) == set(BEARING_COEFFICIENTS)
    assert [e["effect"] for e in r["explanations"]] == ["sensor_gain"]
    assert (out / "residuals.nc").is_file() and (out / "models" / "nominal.nc").is_file()
    loaded = Diagnosis.load(out)                  # the CLI's folder as the typed result
    assert loaded.effects == ["sensor_gain"] and loaded.to_dict() == r
    assert "psd_after" in loaded.residuals and "step1_sensor_gain" in loaded.models
    assert loaded.plot("location") is not None
    # the stored truth never reaches the diagnosis: the same numbers without it
    side = json.loads(csv_path.with_suffix(".json").read_text())
    side.pop("truth")
    csv_path.with_suffix(".json").write_text(json.dumps(side))
    d2 = diagnose(load_recording(csv_path), options=DiagnoseOptions(
        candidates=tuple(c for c in all_candidates()
                         if c.effect in ("sensor_gain", "time_delay"))))
    assert d2.to_dict()["explanations"][0]["params"] == r["explanations"][0]["params"]


@pytest.mark.parametrize("argv,needle", [
    (["--effects", "warp_drive"], "option --effects"),
    (["--max-effects", "-1"], "--max-effects: value -1 out of range: must be >= 0"),
    (["--params", "k_Zz"], "unknown parameter name"),
    (["--planes", "D1,Q"], "option --planes: rig reference: no plane 'Q'"),
    (["--planes", "D1"], "option --planes: rig reference: balancing needs two correction"),
    (["--planes", "D1,n1"], "are at the same axial position"),
])
def test_cli_diagnose_bad_input(ctrl, tmp_path, capsys, argv, needle):
    rec, truth = _rec(ctrl, seed=1, duration=0.05)
    csv_path, _ = save_recording(tmp_path / "r.csv", rec, truth=truth)
    code, _, err = run_cli(["diagnose", str(csv_path), "--out", str(tmp_path / "o"), *argv],
                           capsys)
    assert code == 2 and needle in err and len(err.strip().splitlines()) == 1


def test_sampled_posteriors_are_saved_as_emcee_draws(ctrl, tmp_path):
    import xarray as xr

    rec, _ = _rec(ctrl, ["sensor_gain:gain=0.05,channel=Ay"], seed=14, duration=0.1)
    d = diagnose(rec, "k_By", options=DiagnoseOptions(
        candidates=tuple(c for c in all_candidates() if c.effect == "sensor_gain"),
        sample=True, steps=60))
    out = d.save(tmp_path / "diag")
    assert d.to_dict()["inference"] == "emcee"
    for f in (out / "models").glob("*.nc"):
        ds = xr.load_dataset(f)
        assert ds.attrs["inference"] == "emcee" and ds.sizes["draw"] > 100
        assert np.all(np.isfinite(ds["k_By"].values))


def test_the_running_speeds_line_has_a_band_of_its_own_width(control):
    """The diagnosis' likelihood widens the band of the 1x bin to LINE_BAND_BINS where the
    record's bands are narrower there (a line alone in a band of one or two bins is taken
    for that band's noise); elsewhere the bands stay, and identify's likelihood keeps
    its own."""
    from dataclasses import replace as _replace

    from bayes_amb.discrepancy.fitting import build
    from bayes_amb.discrepancy.likelihood import LINE_BAND_BINS
    from bayes_amb.inference.forward import ForwardModel
    from bayes_amb.inference.offline import dual_youla_eps
    from bayes_amb.inference.whittle import WhittleLikelihood, band_edges

    rec = _replace(control[0], speed_rpm=3000.0)             # 1x at 50 Hz: bands of 1 bin
    eps = dual_youla_eps(ForwardModel(rec, BEARING_COEFFICIENTS).parts, rec.y, rec.u)
    fwd, like, _ = build(rec, BEARING_COEFFICIENTS, eps)
    plain = band_edges(like.k.size, 192)
    c = int(np.argmin(np.abs(like.k / (like.n * fwd.dt) - 50.0)))
    band = int(np.searchsorted(like.starts, c, side="right") - 1)
    assert like.counts[band] >= LINE_BAND_BINS and like.starts[band] <= c - 8
    assert like.counts.sum() == like.k.size and np.all(like.counts > 0)
    below = plain < like.starts[band]
    assert np.array_equal(like.starts[like.starts < like.starts[band]], plain[below])
    assert np.array_equal(like.starts[band + 1:], plain[plain > c + 8])
    own = WhittleLikelihood(ForwardModel(rec, BEARING_COEFFICIENTS), eps)
    assert np.array_equal(own.starts, band_edges(own.k.size, 256))
