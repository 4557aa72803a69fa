"""Issue 29: diagnosis across records. An effect named in one record is tested alone in
every other: present where the physics is, absent where it is not."""

import json

import pytest

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.discrepancy.records import diagnose_records
from bayes_amb.io.recording import save_recording
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
    rows = {row["effect"]: row for row in r.across}
    row = rows["cross_coupling@D1"]
    assert 1 in row["named_in"]
    assert row["present"]["1"] and row["present"]["2"]   # the physics is there
    assert row["present"]["3"] is False                 # and not in the clean record
    assert not row["in_every_record"]
    r.save(tmp_path)
    saved = json.loads((tmp_path / "records.json").read_text())
    assert saved["verdicts"][2] == "no mismatch" and (tmp_path / "record_3").is_dir()


def test_diagnose_cli_takes_several_records(recs, tmp_path, capsys):
    paths = [str(save_recording(tmp_path / f"r{i}.csv", r)[0]) for i, r in enumerate(recs[1:])]
    code, out, _ = run_cli(["diagnose", *paths, "--effects", "cross_coupling",
                            "--out", str(tmp_path / "d"), "--json", "--no-progress"], capsys)
    assert code == 0
    d = json.loads(out)
    assert d["recordings"] == paths and len(d["verdicts"]) == 2
