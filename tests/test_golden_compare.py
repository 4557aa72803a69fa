"""The golden comparison (tests/golden/compare.py) passes rounding and catches results that
really changed: each rule is shown to let through what another CPU does and to fail on a
change of the size that matters on its own scale."""

from __future__ import annotations

import copy
import json

import pytest

from tests.golden.cases import golden_path, read_golden
from tests.golden.compare import LEARNED_FRACTION, SD_FRACTION, differences


def _golden(name: str, what: str) -> dict:
    kind, index = name.rsplit("_", 1)
    return read_golden(golden_path(kind, int(index), what))


def _rounded(x, rel: float = 1e-7):
    """Every float moved by a relative ``rel`` (alternating sign): what rounding does."""
    if isinstance(x, dict):
        return {k: _rounded(v, rel) for k, v in x.items()}
    if isinstance(x, list):
        return [_rounded(v, rel * (-1) ** i) for i, v in enumerate(x)]
    if isinstance(x, float):
        return x * (1 + rel)
    return x


@pytest.mark.parametrize(("name", "what"), [("control_06", "summary"),
                                            ("control_force_07", "summary"),
                                            ("seal_07", "diagnosis"),
                                            ("full_truth_04", "diagnosis")])
def test_rounding_passes(name, what):
    gold = _golden(name, what)
    assert differences(gold, gold) == []
    assert differences(_rounded(gold), gold) == []


def test_a_map_estimate_moved_by_a_tenth_of_its_sd_fails():
    gold = _golden("control_force_07", "summary")       # a fit under a learned spectrum
    assert gold["noise"]["spectrum"]["adopted"] is True
    got = copy.deepcopy(gold)
    par = got["parameters"]["k_By"]
    par["mean"] += 2 * LEARNED_FRACTION * par["sd"]
    diff = differences(got, gold)
    assert len(diff) == 1 and "parameters.k_By.mean" in diff[0]
    got = copy.deepcopy(gold)            # 0.5 sd: 5 sd of two 4000-draw HDI ends' difference
    got["parameters"]["c_Bx"]["hdi90"][0] -= 0.5 * gold["parameters"]["c_Bx"]["sd"]
    assert any("c_Bx.hdi90[0]" in d for d in differences(got, gold))
    got = copy.deepcopy(gold)
    got["parameters"]["c_Bx"]["sd"] *= 1.05
    assert any("c_Bx.sd" in d for d in differences(got, gold))
    # the map block on the same scale: under a learned spectrum a MAP moves by up to 0.018
    # of its sd with the BLAS kernel (probe_angle_01's c_Ay), not by a twentieth
    got = copy.deepcopy(gold)
    got["map"]["c_Ax"] += 0.5 * LEARNED_FRACTION * gold["parameters"]["c_Ax"]["sd"]
    assert differences(got, gold) == []
    got["map"]["c_Ax"] += LEARNED_FRACTION * gold["parameters"]["c_Ax"]["sd"]
    assert any(".map.c_Ax" in d for d in differences(got, gold))


def test_a_fit_without_a_learned_spectrum_is_held_to_a_hundredth_of_its_sd():
    gold = _golden("seal_07", "summary")          # white sources: the spectrum not adopted
    assert gold["noise"]["spectrum"]["adopted"] is False
    got = copy.deepcopy(gold)
    own = got["parameters_model_only"]["k_Ax"]
    own["mean"] += 0.5 * SD_FRACTION * own["sd"]
    assert differences(got, gold) == []
    own["mean"] += SD_FRACTION * own["sd"]
    assert any("parameters_model_only.k_Ax.mean" in d for d in differences(got, gold))
    gold = _golden("seal_07", "diagnosis")
    got = copy.deepcopy(gold)
    after = got["parameters_after"]["c_Ax"]
    after["mean"] += 2 * SD_FRACTION * after["sd"]
    assert any("parameters_after.c_Ax.mean" in d for d in differences(got, gold))


def test_a_sampled_estimate_is_compared_within_its_monte_carlo_error():
    gold = _golden("control_06", "summary")
    name = "k_Ax"
    sd, ess = gold["parameters"][name]["sd"], gold["parameters"][name]["ess_bulk"]
    got = copy.deepcopy(gold)
    got["parameters"][name]["mean"] += sd / ess**0.5         # one Monte Carlo error
    assert differences(got, gold) == []
    got["parameters"][name]["mean"] += 0.5 * sd                # half a posterior sd
    assert any(f"parameters.{name}.mean" in d for d in differences(got, gold))


def test_hdi_ends_are_compared_within_their_cube_root_monte_carlo_error():
    """HDI_MC is what HDI ends of normal draws scatter by (fitstats.hdi, 4000 draws, 400
    sets): within 25 % of 1.1 N^(-1/3) sd; and two independent sets' ends pass the
    comparison in at least 99 % (a 4000-draw end's rule is HDI_Z = 3.3 sd of their
    difference, so about 0.1 % fail by chance; the bound leaves room for 400 sets)."""
    import numpy as np

    from bayes_amb.discrepancy.fitstats import hdi
    from tests.golden.compare import HDI_MC

    rng = np.random.default_rng(3)
    n = 4000
    ends = np.array([hdi(rng.standard_normal(n)) for _ in range(400)])
    assert abs(ends[:, 0].std() / (HDI_MC * n ** (-1 / 3)) - 1) < 0.25
    gold = _golden("control_force_07", "summary")
    block = gold["parameters"]["c_Bx"]
    passed = 0
    for a, b in zip(ends[:200], ends[200:], strict=True):
        got = copy.deepcopy(gold)
        shift = (a - b) * block["sd"]
        got["parameters"]["c_Bx"]["hdi90"] = [block["hdi90"][0] + shift[0],
                                             block["hdi90"][1] + shift[1]]
        passed += not any("c_Bx.hdi90" in d for d in differences(got, gold))
    assert passed >= 198


def test_a_sampler_count_moves_by_its_ceiling_not_by_more():
    """burn is ceil(2 tau): a step either way is rounding, three steps are a changed chain."""
    gold = _golden("control_06", "summary")
    got = copy.deepcopy(gold)
    got["sampler"]["burn"] = gold["sampler"]["burn"] - 1
    assert differences(got, gold) == []
    got["sampler"]["burn"] = gold["sampler"]["burn"] + 3
    assert any("sampler.burn" in d for d in differences(got, gold))
    got = copy.deepcopy(gold)
    got["sampler"]["steps"] = gold["sampler"]["steps"] + 50     # a count that is not ceiled
    assert any("sampler.steps" in d for d in differences(got, gold))


def test_words_names_and_verdicts_are_exact():
    gold = _golden("seal_07", "diagnosis")
    flip = {"confident": "tentative"}
    for change in (lambda d: d.update(verdict="unexplained"),
                   lambda d: d["explanations"][0].update(effect="unbalance"),
                   lambda d: d["explanations"][0].update(
                       confidence=flip.get(d["explanations"][0]["confidence"], "confident")),
                   lambda d: d["adequacy"].update(adequate=True),
                   lambda d: d["adequacy"]["channels"].pop(),
                   lambda d: d["candidates"].pop(3)):
        got = copy.deepcopy(gold)
        change(got)
        assert differences(got, gold), change


def test_candidates_tie_in_any_order_but_not_in_their_evidence():
    gold = _golden("seal_07", "diagnosis")
    got = copy.deepcopy(gold)
    got["candidates"].reverse()
    assert differences(got, gold) == []
    scored = next(c for c in got["candidates"] if isinstance(c.get("log_bayes_factor"), float))
    scored["log_bayes_factor"] += 1.0
    assert any("log_bayes_factor" in d for d in differences(got, gold))


def test_p_values_on_the_decision_scale():
    def with_p(p):
        return {"mismatch": {"evidence": {"p_adjusted_min": p}}}
    assert differences(with_p(1e-20), with_p(1e-12)) == []         # decisive either way
    assert differences(with_p(0.0102), with_p(0.0100)) == []
    assert differences(with_p(0.02), with_p(0.01))                  # across alpha
    assert differences(with_p(1e-4), with_p(1e-9))


def test_a_check_on_rounding_compares_no_p_value():
    def check(diff, p):
        return {"checks": [{"check": "controller", "relative_difference": diff, "p_adjusted": p}]}
    assert differences(check(1.2e-14, 0.03), check(1.5e-14, 0.07)) == []
    assert differences(check(1.2e-3, 0.03), check(1.5e-14, 0.07))


def test_a_doubted_models_intervals_are_compared_within_a_twentieth_of_their_sd():
    gold = _golden("actuator_gain_00", "summary")
    assert "parameters_model_only" in gold and not gold["adequacy"]["adequate"]
    got = copy.deepcopy(gold)                 # the sd too, relative: 1.4 % on another build
    got["parameters"]["k_Ax"]["sd"] *= 1.03
    assert differences(got, gold) == []
    got["parameters"]["k_Ax"]["sd"] *= 1.03
    assert any("parameters.k_Ax.sd" in d for d in differences(got, gold))
    gold = _golden("probe_angle_01", "summary")
    assert "parameters_model_only" in gold and not gold["adequacy"]["adequate"]
    got = copy.deepcopy(gold)
    par = got["parameters"]["c_Ay"]
    par["mean"] += 0.03 * par["sd"]
    assert differences(got, gold) == []
    par["mean"] += 0.05 * par["sd"]
    assert any("parameters.c_Ay.mean" in d for d in differences(got, gold))
    got = copy.deepcopy(gold)       # the model's own intervals: its MAP's learned spectrum
    own = got["parameters_model_only"]["c_Ay"]
    own["mean"] += 0.03 * own["sd"]
    assert differences(got, gold) == []
    own["mean"] += 0.04 * own["sd"]
    assert any("parameters_model_only.c_Ay.mean" in d for d in differences(got, gold))


def test_a_learned_spectrums_gains_within_0_4_decibel():
    def spectrum(gain):
        return {"noise": {"spectrum": {"gain_db": {"r1": {"By": [gain, 1.0]}}}}}
    assert differences(spectrum(4.98), spectrum(5.10)) == []      # rounding, a flat source
    assert differences(spectrum(0.73), spectrum(0.72)) == []
    assert differences(spectrum(4.90), spectrum(5.10)) == []      # -8.28 against -8.48
    assert differences(spectrum(4.60), spectrum(5.10))            # a change of the spectrum


def test_a_golden_file_is_plain_json():
    gold = _golden("control_06", "summary")
    assert json.loads(json.dumps(gold)) == gold
