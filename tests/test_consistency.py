"""Cochran's Q across records (inference/consistency.py): calibrated when the records
agree, finds a shift, and the random-effects sd widens by the spread."""

import numpy as np
import pytest

from bayes_amb.inference.consistency import ALPHA, agreement


def test_q_is_calibrated_when_the_records_agree():
    """3 records with unequal sds, 4000 draws: the share of p < 0.05 is 0.05 within 4.5
    binomial sds (and the same for 0.2)."""
    rng = np.random.default_rng(7)
    sds = [0.01, 0.02, 0.04]
    p = []
    for _ in range(4000):
        m = (0.3 + rng.normal(0.0, sds)).tolist()
        p.append(agreement({"k_Ax": m}, {"k_Ax": sds})["parameters"]["k_Ax"]["p"])
    p = np.array(p)
    for level in (0.05, 0.2):
        tol = 4.5 * np.sqrt(level * (1 - level) / p.size)
        assert abs(np.mean(p < level) - level) < tol


def test_a_shifted_record_is_found_and_widens_the_interval():
    out = agreement({"k_Ax": [0.30, 0.31, 0.45], "c_Ax": [0.1, 0.12, 0.11]},
                    {"k_Ax": [0.01, 0.01, 0.01], "c_Ax": [0.02, 0.02, 0.02]})
    assert out["disagree"] == ["k_Ax"]
    k = out["parameters"]["k_Ax"]
    assert k["p_adjusted"] < ALPHA < out["parameters"]["c_Ax"]["p_adjusted"]
    assert k["tau"] == pytest.approx(np.std([0.30, 0.31, 0.45], ddof=1), rel=0.2)
    assert k["random_effects_sd"] > 5 * 0.01 / np.sqrt(3)
    assert "k_Ax" in out["line"] and "--per-record k_Ax" in out["line"]


def test_agreeing_records_keep_the_fixed_effect_combination():
    out = agreement({"k_Ax": [0.30, 0.30]}, {"k_Ax": [0.01, 0.02]})
    k = out["parameters"]["k_Ax"]
    assert k["tau"] == 0.0 and out["disagree"] == []
    assert k["random_effects_sd"] == pytest.approx(1 / np.sqrt(1 / 0.01 ** 2 + 1 / 0.02 ** 2))
    assert "agree" in out["line"]


def test_a_record_without_a_finite_sd_is_left_out():
    out = agreement({"k_Ax": [0.3, 0.9, 0.31]}, {"k_Ax": [0.01, float("nan"), 0.01]})
    assert out["parameters"]["k_Ax"]["dof"] == 1 and out["disagree"] == []
    assert agreement({"k_Ax": [0.3]}, {"k_Ax": [0.01]})["parameters"] == {}
