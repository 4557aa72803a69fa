"""Typed results (bayes_amb/results): the blocks' rules (required keys, omitted keys, keys
a block does not name, nulls), the one-line errors of a bad result file, and the answers'
round trip. The diagnoses and identifications of real runs: tests/test_golden.py."""

from __future__ import annotations

import json

import pytest

from bayes_amb.errors import BayesAmbError, ResultError
from bayes_amb.io.nonfinite import result_json_text
from bayes_amb.results import CandidateScore, Diagnosis, EngineeringAnswers, Identification
from tests.helpers import diagnosis_json


def test_a_row_keeps_its_nulls_and_the_keys_it_does_not_name():
    row = {"effect": "time_delay", "location": "controller", "round": "revisit",
           "screen_gain": None, "log_bayes_factor": 3.5, "fingerprint": "a delay"}
    c = CandidateScore.from_dict(row)
    assert c.screen_gain is None and c.screen is None and c.extra == {"fingerprint": "a delay"}
    assert c.to_dict() == row                       # null kept, absent keys not invented
    assert c.key == "time_delay@controller"


def test_a_missing_required_key_is_named_with_its_path():
    bad = diagnosis_json()
    del bad["explanations"][0]["score"]
    with pytest.raises(BayesAmbError, match=r"diagnosis.json.explanations\[0\]: required key "
                                            r"'score' missing"):
        Diagnosis.from_dict(bad)
    bad = diagnosis_json()
    bad["candidates"] = {"not": "a list"}
    with pytest.raises(BayesAmbError, match=r"candidates: expected a JSON array"):
        Diagnosis.from_dict(bad)


def test_load_refuses_a_missing_folder_or_another_format(tmp_path):
    with pytest.raises(ResultError, match=r"diagnosis\.json: not found"):
        Diagnosis.load(tmp_path)
    (tmp_path / "diagnosis.json").write_text(json.dumps({**diagnosis_json(),
                                                         "format": "other/1"}))
    with pytest.raises(ResultError, match=r"field format: expected 'bayes-amb-diagnosis/1', "
                                          r"got 'other/1'"):
        Diagnosis.load(tmp_path)
    (tmp_path / "summary.json").write_text("{not json")
    with pytest.raises(ResultError, match=r"summary\.json: not valid JSON"):
        Identification.load(tmp_path)


def test_a_saved_diagnosis_loads_back_to_the_same_object(tmp_path):
    d = Diagnosis.from_dict(diagnosis_json())
    d.save(tmp_path)
    back = Diagnosis.load(tmp_path)
    assert back == d and back.residuals is None and back.models == {}
    assert (tmp_path / "diagnosis.json").read_text() == result_json_text(back.to_dict())
    assert back.explanations[0].params["bandwidth_hz"].hdi90 == [2400, 2600]
    assert back.summary().startswith("verdict: explained\n")
    with pytest.raises(BayesAmbError, match="has no residuals"):
        back.plot("location")
    assert back.plot("parameters") is not None


def _answers() -> dict:
    q = {"unit": "Hz", "group": "modes", "value": 100.0, "interval90": [95.0, 106.0],
         "nominal": 101.0, "n_valid": 60}
    return {"format": "bayes-amb-engineering/2", "model": "full", "speeds_rpm": [31500.0],
            "running_speed_rpm": 31500.0, "n_draws": 60, "n_edge_points": 4,
            "interval": "equal-tailed", "notes": [],
            "quantities": {"rigid 1: frequency": q,
                           "rigid 1: log dec": {**q, "unit": "-", "value": 0.5,
                                                "interval90": [0.4, 0.6], "nominal": 0.5}}}


def test_answers_round_trip_and_plot(tmp_path):
    a = EngineeringAnswers.from_dict(_answers())
    assert a.quantities["rigid 1: frequency"].interval90 == [95.0, 106.0]
    assert a.save(tmp_path) == tmp_path / "answers.json"
    assert EngineeringAnswers.load(tmp_path) == a
    assert "rigid 1: log dec" in a.summary()
    assert len(a.plot().axes[0].get_yticklabels()) == 2
    with pytest.raises(BayesAmbError, match="known groups modes"):
        a.plot("bearings")


def test_the_schema_document_is_the_codes():
    """docs/results.md is written from the blocks; a field added without regenerating it
    fails here (python -m bayes_amb.results.schema > docs/results.md)."""
    from pathlib import Path

    from bayes_amb.results.schema import markdown
    doc = Path(__file__).resolve().parents[1] / "docs" / "results.md"
    assert doc.read_text() == markdown()


def test_a_node_refits_rows_go_into_its_round_in_the_report():
    """A diagnosis that moved a force node by node has rows of round "1 node"; the report's
    candidate table and figure crashed on them before the typed results (int("1 node"), a
    sort of int and str)."""
    from bayes_amb.plots.discrepancy import plot_candidates
    from bayes_amb.report.discrepancy import _candidate_table
    rows = [{"effect": "cross_coupling", "location": "n20", "round": 1, "screen_gain": 40.0,
             "log_bayes_factor": 30.0},
            {"effect": "cross_coupling", "location": "n22", "round": "1 node",
             "screen_gain": None, "log_bayes_factor": 33.0},
            {"effect": "sensor_gain", "location": "Ax", "round": 2, "screen_gain": 1.0}]
    d = Diagnosis.from_dict({**diagnosis_json(), "candidates": rows})
    table = _candidate_table(d.candidates)
    assert table.header[2:] == ["round 1: gain (nats)", "round 1: log BF",
                                "round 2: gain (nats)", "round 2: log BF"]
    assert [r[:2] for r in table.rows] == [["cross_coupling", "n20"],
                                           ["cross_coupling", "n22"], ["sensor_gain", "Ax"]]
    assert len([ax for ax in plot_candidates(d).axes if ax.get_visible()]) == 2
