"""The foreign benchmark's scoring (studies/foreign_benchmark.py): right names, equivalence
classes, wrong names and parameter coverage are counted as stated, and can fail."""

from __future__ import annotations

import importlib.util
from pathlib import Path

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
