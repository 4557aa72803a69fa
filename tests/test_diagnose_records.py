"""Issue 29: diagnosis across records. An effect named in one record is tested alone in
every other: present where the physics is, absent where it is not."""

import json

import numpy as np
import pytest

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.discrepancy.records import diagnose_records, size_agreement
from bayes_amb.errors import BayesAmbError
from bayes_amb.io.recording import save_recording
from bayes_amb.report.records import write_records_report
from bayes_amb.results.records import RecordsDiagnosis
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, parse_effect, simulate_recording
from tests.helpers import run_cli


@pytest.fixture(scope="module")
def recs():
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, 1e-4), rig)
    kxy = (parse_effect("cross_coupling:kxy=4e4,location=D1"),)
    out = []
    for effects, seed in ((kxy, 1), (kxy, 2), ((), 3)):
        cfg = SimulationConfig(truth="reduced", effects=effects, noise_rms=5e-8,
                               duration=1.0, seed=seed)
        out.append(simulate_recording(rig, ctrl, cfg)[0])
    return out


def test_an_effect_named_in_one_record_is_tested_in_all(recs, tmp_path):
    r = diagnose_records(recs)
    rows = {row.effect: row for row in r.across}
    row = rows["cross_coupling@D1"]
    assert 1 in row.named_in
    assert row.present["1"] and row.present["2"]         # the physics is there
    assert row.present["3"] is False                    # and not in the clean record
    assert not row.in_every_record
    assert row.size.records == [1, 2] and row.size.agree   # one kxy in both
    r.save(tmp_path)
    write_records_report(tmp_path)
    saved = json.loads((tmp_path / "records.json").read_text())
    assert saved["verdicts"][2] == "no mismatch" and (tmp_path / "record_3").is_dir()
    assert len(saved["speeds_rpm"]) == 3
    back = RecordsDiagnosis.load(tmp_path)             # the folder as the typed result
    assert back == r and [d.verdict for d in back.diagnoses] == r.verdicts
    # the report page: each record's fit, the effect across them, what they share
    page = (tmp_path / "records.html").read_text()
    for text in ("Each record", "Effects across the records", "cross_coupling@D1",
                 "What the records share", "k_Ax", "no gain", "data:image/png;base64"):
        assert text in page, text


def test_the_records_report_names_a_folder_without_records(tmp_path):
    from bayes_amb.report.collect import ReportError
    from bayes_amb.report.records import write_records_report
    with pytest.raises(ReportError, match=r"records\.json"):
        write_records_report(tmp_path)
    (tmp_path / "records.json").write_text('{"format": "other/1"}')
    with pytest.raises(BayesAmbError, match="field format: expected "
                                            "'bayes-amb-diagnosis-records/1'"):
        write_records_report(tmp_path)


def test_diagnose_cli_takes_several_records(recs, tmp_path, capsys):
    paths = [str(save_recording(tmp_path / f"r{i}.csv", r)[0]) for i, r in enumerate(recs[1:])]
    code, out, _ = run_cli(["diagnose", *paths, "--effects", "cross_coupling",
                            "--out", str(tmp_path / "d"), "--json", "--no-progress"], capsys)
    assert code == 0
    d = json.loads(out)
    assert d["recordings"] == paths and len(d["verdicts"]) == 2


def _size(q: str, mean: float, half: float) -> dict:
    return {q: {"mean": mean, "hdi90": [mean - half, mean + half]}}


def test_a_1x_size_that_changes_with_speed_points_to_the_other_1x_effect():
    """A runout of fixed amplitude read as unbalance needs u ~ 1 / Omega^2: at 0.65, 0.8
    and 1 x speed the three u disagree and the reading names runout; the same u agrees."""
    speeds = [20475.0, 25200.0, 31500.0]
    scaled = {str(i + 1): _size("u_kgm", 2e-5 / f ** 2, 1e-6)
              for i, f in enumerate((0.65, 0.8, 1.0))}
    out = size_agreement("unbalance@n14", scaled, speeds)
    assert not out["agree"] and "runout" in out["reading"]
    same = {str(i + 1): _size("u_kgm", 2e-5 + 3e-7 * i, 1e-6) for i in range(3)}
    assert size_agreement("unbalance@n14", same, speeds)["agree"]
    kxy = {"1": _size("kxy", 3e4, 2e3), "3": _size("kxy", 6e4, 2e3)}
    out = size_agreement("cross_coupling@D1", kxy, speeds)
    assert out["records"] == [1, 3] and "speed-dependent" in out["reading"]
    assert size_agreement("actuator_lag@A", kxy, speeds) is None
    assert size_agreement("unbalance@n14", {"1": same["1"]}, speeds) is None


def _screened(gains: dict[str, float]) -> object:
    """A record's diagnosis as joint_search reads it: no failed check, nothing accepted,
    its last round's screens with these gains."""
    from types import SimpleNamespace

    from bayes_amb.results import CandidateScore
    rows = [CandidateScore(effect=k.split("@")[0], location=k.split("@")[1], round=1,
                           screen_gain=g) for k, g in gains.items()]
    return SimpleNamespace(checks_failed=False, candidates=rows,
                           selection=SimpleNamespace(accepted=[]))


@pytest.mark.parametrize(("lbf", "named"), [(2.0, True), (0.5, False)])
def test_the_records_together_name_what_none_names_alone(monkeypatch, lbf, named):
    """Three records each screen a weak cross-coupling at D1 (gain 2.5, below what one
    record accepts) and a sensor gain (0.5). The summed screens point to D1 only; fitted in
    each record with log BF 2 (each below the threshold 3) the joint log BF 6 minus log K
    (K = 2 candidates) passes: named together, present in no record alone. With log BF 0.5
    each it does not. An effect a record named already is not searched again."""
    from bayes_amb.discrepancy import records
    from bayes_amb.discrepancy.diagnose import DiagnoseOptions
    fitted = []

    def tested(d, key, priors, seed, force=False, parent="nominal"):
        fitted.append((key, force, parent))
        return lbf, None, True

    monkeypatch.setattr(records, "_tested_in", tested)
    diags = [_screened({"cross_coupling@D1": 2.5, "sensor_gain@Ax": 0.5})] * 3
    rows = records.joint_search(diags, set(), None, DiagnoseOptions(), [2e4, 2.5e4, 3e4])
    assert [r["effect"] for r in rows] == ["cross_coupling@D1"]
    assert fitted == [("cross_coupling@D1", True, "final")] * 3
    row = rows[0]
    assert row["joint_log_bayes_factor"] == pytest.approx(3 * lbf)
    assert row["joint_log_posterior_odds"] == pytest.approx(3 * lbf - np.log(2))
    assert row["named_jointly"] is named and not any(row["present"].values())
    assert records.joint_search(diags, {"cross_coupling@A"}, None, DiagnoseOptions(),
                                [2e4, 2.5e4, 3e4]) == []


def test_the_joint_search_discounts_the_occam_factor_its_records_show(monkeypatch):
    """A sensor gain screened at 3 nats in each record sums to 9, enough before its Occam
    factor; the records' own refined sensor gain (screen 6, log BF 1) shows that factor to
    be 5 nats per record, so nothing is pointed to and nothing fitted."""
    from bayes_amb.discrepancy import records
    from bayes_amb.discrepancy.diagnose import DiagnoseOptions
    from bayes_amb.results import CandidateScore
    monkeypatch.setattr(records, "_tested_in", lambda *a, **k: pytest.fail("fitted"))
    d = _screened({"sensor_gain@Ax": 3.0, "actuator_gain@By": 0.5})
    d.candidates.append(CandidateScore(effect="sensor_gain", location="Bx", round=1,
                                       screen_gain=6.0, log_bayes_factor=1.0))
    assert records.joint_search([d] * 3, set(), None, DiagnoseOptions(),
                                [2e4, 2.5e4, 3e4]) == []


def test_the_records_prefer_the_place_they_favour_together():
    """A foreign group (records_weak, cross_coupling_01): a cross-coupling at A named in the
    two faster records, at D1 in the slowest, where the two places are 0.2 nats apart; over
    the three records A leads by 36 nats, so the records prefer A. An unbalance's node is
    not physics and is left alone; an effect named at one place only gets nothing."""
    from bayes_amb.discrepancy.records import prefer_locations

    def row(key, named_in, lbfs):
        return {"effect": key, "named_in": named_in, "present": {},
                "log_bayes_factor": dict(zip(("1", "2", "3"), lbfs, strict=True))}
    across = [row("cross_coupling@A", [1, 2], [32.3, 225.0, 7.1]),
              row("cross_coupling@D1", [3], [26.7, 194.1, 7.3]),
              row("unbalance@n14", [1], [20.0, 30.0, 40.0]),
              row("unbalance@D2", [2], [25.0, 35.0, 45.0]),
              row("runout@Ax", [1], [9.0, None, 4.0])]
    prefer_locations(across)
    a, d1, n14, d2, runout = across
    assert a["preferred_location"] == d1["preferred_location"] == "cross_coupling@A"
    assert "weaker_by" not in a and d1["weaker_by"] == pytest.approx(36.3)
    assert not {"preferred_location", "weaker_by"} & (set(n14) | set(d2) | set(runout))
