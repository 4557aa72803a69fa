"""The foreign benchmark's scoring (studies/foreign_benchmark.py): right names, equivalence
classes, wrong names and parameter coverage are counted as stated, and can fail."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np

_SPEC = importlib.util.spec_from_file_location(
    "foreign_benchmark", Path(__file__).parents[1] / "studies" / "foreign_benchmark.py")
fb = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(fb)

THETA = {"k_Ax": 0.1}


def _truth(*effects, kind="x"):
    return {"kind": kind, "truth": "reduced", "n_bending": 0, "theta": THETA,
            "effects": [{"name": n, "params": p} for n, p in effects]}


def _report(*expl, verdict="explained", unexplained=False):
    return {"verdict": verdict, "unexplained": {"present": unexplained},
            "parameters_after": {"k_Ax": {"hdi90": [0.0, 0.2]}},
            "explanations": [{"effect": e, "location": loc, "params": par,
                              "confidence": conf, "kind": "physics",
                              "equivalence_class": [f"{e}@{loc}", *eq]}
                             for e, loc, par, conf, eq in expl]}


def test_the_right_name_with_its_parameter_inside_counts():
    t = _truth(("actuator_gain", {"axis": "Bx", "gain": 0.1}))
    r = fb.score(t, _report(("actuator_gain", "Bx", {"gain": {"hdi90": [0.09, 0.11]}},
                             "confident", [])))
    assert r["all_named"] and not r["wrong"] and r["effect_params_in_hdi"] == [True]
    assert r["coeff_in_hdi"] == 1.0


def test_the_wrong_place_in_the_loop_is_a_confident_wrong_name():
    t = _truth(("actuator_gain", {"axis": "Bx", "gain": 0.1}))
    r = fb.score(t, _report(("sensor_gain", "Bx", {"gain": {"hdi90": [0.09, 0.11]}},
                             "confident", [])))
    assert not r["all_named"] and r["wrong_confident"] == ["sensor_gain@Bx"]


def test_an_equivalent_explanation_names_the_effect():
    t = _truth(("sensor_lag", {"bandwidth_hz": 1000.0, "where": "all"}))
    r = fb.score(t, _report(("actuator_lag", "both", {"bandwidth_hz": {"hdi90": [900, 990]}},
                             "confident", ["sensor_lag@both (same bandwidth)"])))
    assert r["all_named"] and not r["wrong"] and r["effect_params_in_hdi"] == [False]


def test_a_tentative_wrong_name_is_wrong_but_not_confident():
    t = _truth(("pedestal", {"bearing": "A"}))
    r = fb.score(t, _report(("sensor_gain", "Ax", {}, "tentative", []), unexplained=True))
    assert r["wrong"] == ["sensor_gain@Ax"] and not r["wrong_confident"]
    assert not r["in_library"] and r["unexplained"]


def test_the_full_truths_flexibility_is_right_and_anything_else_spurious():
    """Full 320-state truth: the bending pairs and the residual flexibility are its own
    physics (not wrong); pair 1 is required; a gain beside them is spurious."""
    t = {**_truth(), "truth": "full"}
    flex = [("flexible_mode", f"bending pair {k}", {}, "confident", []) for k in (2, 1)]
    res = ("residual_flexibility", "truncated modes", {}, "confident", [])
    r = fb.score(t, _report(*flex, res))
    assert r["all_named"] and not r["wrong"]
    r = fb.score(t, _report(*flex, ("actuator_gain", "Ax", {}, "tentative", [])))
    assert r["all_named"] and r["wrong"] == ["actuator_gain@Ax"]
    r = fb.score(t, _report(flex[0]))
    assert not r["all_named"]                      # pair 1 is not named


def test_a_pair_the_reduced_truth_does_not_have_is_wrong():
    t = {**_truth(), "n_bending": 1}
    r = fb.score(t, _report(("flexible_mode", "bending pair 1", {}, "confident", []),
                            ("flexible_mode", "bending pair 2", {}, "confident", []),
                            ("residual_flexibility", "truncated modes", {}, "confident", [])))
    assert r["all_named"]
    assert r["wrong"] == ["flexible_mode@bending pair 2", "residual_flexibility@truncated modes"]


def _balancing(mean, cov):
    return {"balancing": {"planes": [{"plane": p, "ab_kgm": {"mean": m, "cov": cov}}
                                     for p, m in zip(("D1", "D2"), mean, strict=True)]}}


def test_the_balancing_answer_is_scored_by_its_credible_ellipse():
    cov = [[1e-14, 0.0], [0.0, 1e-14]]                 # sd 1e-7 kg m per component
    r = _balancing([[1e-6, 0.0], [0.0, -2e-6]], cov)
    truth = {"D1": 1e-6 + 1e-7j, "D2": -2.3e-6j}        # 1 sd off, then 3 sd off
    assert fb.balancing_inside(r, truth) == [True, False]
    assert fb.balancing_inside({"balancing": None}, truth) == [False, False]


def test_balancing_truth_finds_the_influence_coefficient_equivalent(controller_file):
    ctrl = controller_file
    axes = ("Ax", "Ay", "Bx", "By")
    t = {"truth": "reduced", "n_bending": 0, "speed_rpm_true": 31400.0, "dt": 1e-4,
         "theta": {**{f"k_{a}": 0.1 for a in axes}, **{f"c_{a}": 0.0 for a in axes}},
         "bearings": {a: {"c_ns_per_m": 50.0} for a in axes},
         "effects": [{"name": "unbalance", "params": {"planes": [
             {"node": "D2", "u_kgm": 2e-5, "phase_rad": 0.5}]}}]}
    eq = fb.balancing_truth(t, ctrl)
    assert abs(eq["D2"] - 2e-5 * np.exp(0.5j)) < 1e-9 * 2e-5 and abs(eq["D1"]) < 1e-12
    t["effects"][0]["params"]["planes"] = [{"node": 20, "u_kgm": 2e-5, "phase_rad": 0.5}]
    eq = fb.balancing_truth(t, ctrl)                   # between the discs: both carry it
    assert abs(eq["D1"]) > 2e-6 and abs(eq["D2"]) > 2e-6


def test_redo_drops_only_the_named_rows(tmp_path):
    rows = [{"name": n} for n in ("a_00", "b_00", "c_00")]
    (tmp_path / "rows.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    fb.drop_rows(tmp_path, {"b_00"})
    assert [json.loads(line)["name"] for line in
            (tmp_path / "rows.jsonl").read_text().splitlines()] == ["a_00", "c_00"]
