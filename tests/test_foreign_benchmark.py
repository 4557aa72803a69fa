"""The foreign benchmark's scoring (benchmarks/foreign/benchmark.py): right names, equivalence
classes, wrong names and parameter coverage are counted as stated, and can fail."""

from __future__ import annotations

import json

import numpy as np

from benchmarks.foreign import benchmark as fb

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


# ------------------------------------------------ bearing-coefficient coverage (issue 27)
AXES = ("Ax", "Ay", "Bx", "By")
TRUE8 = {**{f"k_{a}": 0.1 for a in AXES}, **{f"c_{a}": 0.2 for a in AXES}}


def _params(lo, hi, **override):
    """hdi90 [lo, hi] for every coefficient, [lo, hi] pairs in override per name."""
    return {n: {"hdi90": list(override.get(n, (lo, hi)))} for n in TRUE8}


def test_an_interval_without_the_truth_counts_outside_with_its_width():
    cov = fb.coefficient_coverage(TRUE8, _params(0.05, 0.25, k_Bx=(0.11, 0.13),
                                                 c_Ay=(0.2, 0.2)))
    assert set(cov) == set(TRUE8)
    assert not cov["k_Bx"]["inside"] and abs(cov["k_Bx"]["width"] - 0.02) < 1e-15
    assert cov["c_Ay"]["inside"]                         # closed interval: an end counts
    assert sum(v["inside"] for v in cov.values()) == 7
    assert fb.coefficient_coverage(TRUE8, {"kxy_D1": {"hdi90": [0, 1]}}) == {}
    nan = fb.coefficient_coverage(TRUE8, _params(float("nan"), float("nan")))
    assert all(not v["inside"] and v["width"] is None for v in nan.values())


def test_only_a_failed_check_named_linearity_catches_a_nonlinearity():
    def rep(*checks):
        return {"checks": [{"check": n, "ok": ok} for n, ok in checks]}
    assert fb.linearity_failed(rep(("linearity", False), ("offsets", True)))
    assert not fb.linearity_failed(rep(("linearity", True)))
    assert not fb.linearity_failed(rep(("stationarity", False)))
    assert not fb.linearity_failed({})


def test_families_of_the_coverage_table():
    assert [fb.family(k) for k in ("held_out", "pair", "pair:sensor_lag+runout",
                                   "control_force", "seal", "actuator_lag")] == \
        ["pedestal", "pair", "pair", "control_force", "seal", "actuator_lag"]


def test_old_kinds_keep_their_seeds():
    before = ("control", "actuator_lag", "actuator_delay", "sensor_delay", "sensor_gain",
              "cross_coupling", "unbalance", "actuator_2nd", "sensor_lag",
              "actuator_gain", "runout", "pair", "held_out", "full_truth")
    assert fb.DEFAULT_KINDS[:len(before)] == before
    assert [fb.kind_number(k) for k in before] == list(range(len(before)))
    assert fb.kind_number("pair:a+b") == fb.kind_number("pair:a+b") != fb.kind_number("pair")


def test_the_coverage_table_counts_from_the_saved_files(tmp_path):
    (tmp_path / "recordings").mkdir()
    (tmp_path / "diagnoses").mkdir()
    (tmp_path / "identify").mkdir()
    recs = {  # name: (kind, effects, diagnosis interval, linearity check, identify)
        "control_00": ("control", [], _params(0.0, 0.3), None, None),
        "control_01": ("control", [], _params(0.0, 0.3, k_Ax=(0.2, 0.3)), None,
                       {"parameters": _params(0.09, 0.25, c_By=(0.0, 0.1))}),
        "current_limit_00": ("current_limit", [{"name": "current_limit", "params": {}}],
                             _params(0.0, 0.3), ("linearity", False),
                             {"parameters": _params(0.0, 1.0),
                              "adequacy": {"adequate": False}}),
        "current_limit_01": ("current_limit", [{"name": "current_limit", "params": {}}],
                             _params(0.3, 0.5), ("linearity", True), None),
    }
    for name, (kind, eff, par, check, ident) in recs.items():
        (tmp_path / "recordings" / f"{name}.truth.json").write_text(json.dumps(
            {"kind": kind, "theta": TRUE8, "effects": eff,
             "draws": {"clipped_share": 0.03} if eff else {}}))
        rep = {"verdict": "no mismatch" if kind == "control" else "unexplained",
               "parameters_after": par,
               "checks": [{"check": check[0], "ok": check[1]}] if check else []}
        (tmp_path / "diagnoses" / f"{name}.json").write_text(json.dumps(rep))
        if ident:
            (tmp_path / "identify" / f"{name}.json").write_text(json.dumps(ident))
    out = fb.coverage(tmp_path, list(recs))
    c, n = out["families"]["control"], out["families"]["current_limit"]
    assert c["recordings"] == 2 and c["k_inside"] == [7, 8] and c["c_inside"] == [8, 8]
    assert abs(c["k_width_mean"] - (7 * 0.3 + 0.1) / 8) < 1e-12
    assert c["verdicts"] == {"no mismatch": 2} and c["linearity_failed"] == [0, 2]
    assert c["identify"]["recordings"] == 1 and c["identify"]["k_inside"] == [4, 4]
    assert c["identify"]["c_inside"] == [3, 4] and c["identify"]["adequacy_reported"] == 0
    assert n["linearity_failed"] == [1, 2] and n["nonlinear"] == 2
    assert n["k_inside"] == [4, 8] and n["c_inside"] == [4, 8]
    assert n["identify"]["inadequate"] == 1 and n["identify"]["adequacy_reported"] == 1
    md = (tmp_path / "coverage.md").read_text()
    assert "| current_limit | 2 | 4/8 | 4/8 |" in md
    assert json.loads((tmp_path / "coverage.json").read_text())["families"].keys() == \
        {"control", "current_limit"}


def test_a_seals_cross_coupling_is_right_only_at_its_node():
    """A gas seal's cross-coupled stiffness is the library's kxy at the seal's node; the
    same name at a bearing is wrong, and so is any other physics."""
    seal = {"node": 22, "k_direct_nm": 2e5, "k_cross_nm": 3e5, "c_direct_nsm": 200.0,
            "c_cross_nsm": 20.0}
    t = _truth(("seal", seal), kind="seal")
    right = fb.score(t, _report(("cross_coupling", "n22", {"kxy": {"hdi90": [2.8e5, 3.2e5]}},
                                 "confident", [])))
    assert right["all_named"] and not right["wrong"]
    assert right["effect_params_in_hdi"] == [True]
    wrong = fb.score(t, _report(("cross_coupling", "B", {"kxy": {"hdi90": [2.8e5, 3.2e5]}},
                                 "confident", [])))
    assert wrong["wrong_confident"] == ["cross_coupling@B"] and not wrong["all_named"]
    at_disc = fb.score(_truth(("seal", {**seal, "node": "D1"}), kind="seal"),
                       _report(("cross_coupling", "D1", {"kxy": {"hdi90": [1e5, 2e5]}},
                                "confident", [])))
    assert at_disc["all_named"] and at_disc["effect_params_in_hdi"] == [False]
    # the default scan node between the bearings (n20 on the reference rig) names a seal
    # between them; its direct terms are scored from diagnosis.json's direct_terms
    scan = _report(("cross_coupling", "n20", {"kxy": {"hdi90": [2.8e5, 3.2e5]}},
                    "confident", []))
    scan["direct_terms"] = [{"effect": "direct_terms", "location": "n20",
                             "params": {"K": {"hdi90": [1.5e5, 2.5e5]},
                                        "C": {"hdi90": [250.0, 300.0]}}}]
    at_scan = fb.score(t, scan)
    assert at_scan["all_named"] and not at_scan["wrong"]
    assert at_scan["effect_params_in_hdi"] == [True, True, False]
    off = fb.score(_truth(("seal", {**seal, "node": 5}), kind="seal"), scan)
    assert off["wrong_confident"] == ["cross_coupling@n20"]


def test_a_node_range_names_every_node_in_it():
    """A force moved along the shaft reports the nodes that fit as well (node_range): a
    seal at node 23 named at n24 with range n22-n26 is right; the same name with a range
    n24-n25, or none, is wrong."""
    seal = {"node": 23, "k_direct_nm": 2e5, "k_cross_nm": 3e5, "c_direct_nsm": 200.0,
            "c_cross_nsm": 20.0}
    t = _truth(("seal", seal), kind="seal")

    def named(rng):
        r = _report(("cross_coupling", "n24", {"kxy": {"hdi90": [2.8e5, 3.2e5]}},
                     "confident", []))
        if rng:
            r["explanations"][0]["node_range"] = rng
        return fb.score(t, r)

    assert named(["n22", "n26"])["all_named"] and not named(["n22", "n26"])["wrong"]
    assert named(["n24", "n25"])["wrong_confident"] == ["cross_coupling@n24"]
    assert named(None)["wrong_confident"] == ["cross_coupling@n24"]
