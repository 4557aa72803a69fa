"""Every result type shows itself in a notebook (``_repr_html_``): its title, its verdict or
status, its summary table and, where it has one, its key figure; never a wall of JSON."""

from __future__ import annotations

import re

import pytest

from bayes_amb.results import (
    Diagnosis,
    EngineeringAnswers,
    Identification,
    RecordsDiagnosis,
    Study,
)
from tests.golden.cases import golden_path, read_golden
from tests.test_results import _answers


def _shown(obj) -> str:
    html = obj._repr_html_()
    assert html.startswith("<style>") and html.endswith("</div>")
    assert '"format"' not in html and "{'" not in html          # no JSON or dict dump
    assert html.count("<table>") == html.count("</table>") >= 1
    return html


def test_a_diagnosis_shows_its_verdict_effects_coefficients_and_figure():
    d = Diagnosis.from_dict(read_golden(golden_path("seal", 7, "diagnosis")))
    html = _shown(d)
    assert f"verdict: {d.verdict}" in html and d.verdict.endswith("explained")
    assert "cross-coupled stiffness" in html and "k_Ax" in html
    assert 'src="data:image/png;base64,' in html                  # the coefficients figure
    cells = re.findall(r"<td>([^<]*)</td>", html)
    assert any(re.fullmatch(r"-?[\d.e+]+ \[-?[\d.e+]+, -?[\d.e+]+\]", c) for c in cells)


def test_an_identification_shows_its_table_and_no_figure_without_draws():
    res = Identification.from_dict(read_golden(golden_path("seal", 7, "summary")))
    html = _shown(res)
    assert "MAP with Laplace approximation; converged: True" in html
    assert all(f"<td>{n}</td>" in html for n in res.parameters)
    assert "<img" not in html                                       # MAP only: no draws


def test_answers_a_study_and_several_records_show_themselves():
    html = _shown(EngineeringAnswers.from_dict(_answers()))
    assert "rigid 1: frequency" in html and "<img" in html
    study = Study.from_dict({"format": "bayes-amb-study/1", "package_version": "0",
                             "study": {"study": {"name": "noise", "description": "a sweep"}},
                             "cells": [{"noise_rms": 1e-7}, {"noise_rms": 1e-6}],
                             "seeds": {"base": 1}, "n_rows": 4, "failures": 0,
                             "conclusions": ["sd grows with the noise"]})
    html = _shown(study)
    assert "Study &#x27;noise&#x27;" in html and "noise_rms=1e-06" in html
    assert "sd grows with the noise" in html
    recs = RecordsDiagnosis.from_dict({
        "format": "bayes-amb-diagnosis-records/1", "recordings": ["a.csv", "b.csv"],
        "speeds_rpm": [3000.0, 6000.0], "verdicts": ["explained", "no mismatch"],
        "across": [{"effect": "unbalance@D1", "named_in": [1],
                    "log_bayes_factor": {"1": 12.0, "2": 0.5},
                    "present": {"1": True, "2": False}, "in_every_record": False,
                    "size": None}]})
    html = _shown(recs)
    assert "<td>no mismatch</td>" in html and "unbalance@D1" in html


@pytest.mark.parametrize("cls", [Diagnosis, Identification, EngineeringAnswers, Study,
                                 RecordsDiagnosis])
def test_every_result_type_has_its_own_view(cls):
    assert "_repr_html_" in vars(cls)
