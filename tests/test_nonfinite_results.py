"""Fuzz: non-finite numbers anywhere in a result never crash a writer or a report.

A diagnosis of a full-order record with a 45 us control delay crashed at the end with
"ValueError: Out of range float values are not JSON compliant: -inf". Here a real
identification summary and diagnosis report get nan, +inf or -inf injected at random
float leaves (fixed seed, 60 cases each); every writer (summary.json, diagnosis.json,
--json output) and the command texts must run, as must the report (collected back from the
files, sections with figures and HTML; every 6th case); the files must be strict JSON and
the values must come back.
"""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from bayes_amb.cli.common import emit
from bayes_amb.cli.diagnose_cmd import format_report
from bayes_amb.cli.identify_cmd import format_summary
from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.discrepancy import DiagnoseOptions, all_candidates, diagnose
from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.io.atomic import parse_json_text, write_text_atomic
from bayes_amb.io.nonfinite import restore_non_finite, result_json_text, split_non_finite
from bayes_amb.report.collect import collect_run
from bayes_amb.report.render import build_sections, render_html
from bayes_amb.report.sections import ReportOptions
from bayes_amb.results import Diagnosis, Identification
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, parse_effect, simulate_recording

N_CASES = 60
BAD = (math.nan, math.inf, -math.inf)


@pytest.fixture(scope="module")
def results():
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, 1e-4), rig)
    cfg = SimulationConfig(truth="reduced", params={"k_By": 0.3}, dt=1e-4, duration=0.3,
                           effects=(parse_effect("actuator_lag:bandwidth_hz=800"),), seed=4,
                           noise_rms=2e-7, r2_rms=0.02)
    rec, _ = simulate_recording(rig, ctrl, cfg)
    summary = identify(rec, "k_By,c_By", options=IdentifyOptions(map_only=True)).to_dict()
    opts = DiagnoseOptions(max_effects=1, candidates=all_candidates(("actuator_lag",
                                                                      "time_delay")))
    report = diagnose(rec, "k_By,c_By", options=opts).to_dict()
    return json.loads(json.dumps(summary)), json.loads(json.dumps(report))


def _leaves(obj, path=()):
    """Paths of every float leaf (integers - counts, indices, rounds - are finite by type)."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _leaves(v, (*path, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _leaves(v, (*path, i))
    elif isinstance(obj, float):
        yield path


def _inject(obj, rng):
    """A copy with 1-5 float leaves set to nan/inf/-inf; the paths and values set."""
    out = copy.deepcopy(obj)
    leaves = list(_leaves(out))
    picks = rng.choice(len(leaves), size=min(len(leaves), int(rng.integers(1, 6))),
                       replace=False)
    done = []
    for j in picks:
        *head, last = leaves[j]
        node = out
        for p in head:
            node = node[p]
        node[last] = float(rng.choice(BAD))
        done.append((leaves[j], node[last]))
    return out, done


def _get(obj, path):
    for p in path:
        obj = obj[p]
    return obj


def _same(a, b):
    return (math.isnan(a) and math.isnan(b)) or a == b


def test_results_have_numbers_to_break(results):
    summary, report = results
    assert len(list(_leaves(summary))) > 20 and len(list(_leaves(report))) > 100
    assert split_non_finite(report)[1] == {}


def test_non_finite_results_never_crash(results, tmp_path, capsys):
    summary0, report0 = results
    rng = np.random.default_rng(2028)
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    for case in range(N_CASES):
        summary, s_done = _inject(summary0, rng)
        report, r_done = _inject(report0, rng)
        for obj, done, name in ((summary, s_done, "summary.json"),
                                (report, r_done, "diagnosis.json")):
            text = result_json_text(obj)
            back = restore_non_finite(parse_json_text(text))     # strict JSON
            for path, value in done:
                assert _same(_get(back, path), value), (case, name, path)
            write_text_atomic(run_dir / name, text)
        # the command texts and --json output
        format_summary(Identification.from_dict(summary))
        format_report(Diagnosis.from_dict(report))
        emit(report, "", as_json=True)
        out = capsys.readouterr().out
        parse_json_text(out)
        if case % 6:
            continue
        # the report, read back from the files (the recording is not found: noted); every
        # 6th case, as its figures take about a second
        run = collect_run(run_dir)
        assert run.recording is None and run.diagnosis is not None
        sections, meta = build_sections(run, ["bayes-amb", "report"], ReportOptions())
        assert "<html" in render_html(sections, meta)
