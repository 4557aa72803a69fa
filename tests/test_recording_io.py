"""Unit tests of the recording format (bayes_amb.io.recording) and of atomic writes."""

from __future__ import annotations

import csv
import io
import json
import os
import pathlib

import numpy as np
import pytest

from bayes_amb.errors import RecordingError
from bayes_amb.io import (
    Recording,
    atomic_path,
    load_controller,
    load_recording,
    load_truth,
    make_recording,
    save_recording,
    write_text_atomic,
)
from bayes_amb.rig import load_rig, rig_from_dict
from tests.test_controller_file import controller_dict

DT = 1e-4
N = 20
TRUTH = {"theta": {"k_A": 1.25e5, "c_B": 310.0}, "seed": 7}


def arrays(groups=("eta",), n=N, seed=1):
    rng = np.random.default_rng(seed)
    y = 1e-6 * rng.normal(size=(n, 4))
    u = rng.normal(size=(n, 4))
    exc = {g: (1e-6 if g == "r1" else 0.1) * rng.normal(size=(n, 4)) for g in groups}
    return y, u, exc


def write_valid(path, groups=("eta",), truth=TRUTH, **kw):
    y, u, exc = arrays(groups)
    ctrl = load_controller(controller_dict(dt=DT))
    return save_recording(path, y=y, u=u, excitation=exc, dt=DT, controller=ctrl,
                          speed_rpm=12000.0, notes="bench run 3", truth=truth, **kw)


def snapshot(*paths):
    return [(p.read_bytes(), p.stat().st_mtime_ns) if p.exists() else None for p in paths]


# ------------------------------------------------------------------ round trip
@pytest.mark.parametrize("groups", [("eta",), ("r2",), ("r1",), ("eta", "r2", "r1")])
def test_round_trip_identical_arrays_and_bytes(tmp_path, groups):
    csv_a, json_a = write_valid(tmp_path / "a.csv", groups)
    rec = load_recording(csv_a)
    y, u, exc = arrays(groups)
    assert np.array_equal(rec.y, y) and np.array_equal(rec.u, u)
    assert set(rec.excitation) == set(groups)
    for g in groups:
        assert np.array_equal(rec.excitation[g], exc[g])
    assert np.array_equal(rec.t, DT * np.arange(N))
    assert rec.dt == DT and rec.speed_rpm == 12000.0 and rec.notes == "bench run 3"
    assert rec.rig.name == "reference" and rec.controller.A.shape == (2, 2)
    assert rec.source == str(csv_a) and rec.n_samples == N
    # the same data twice give the same bytes, and so does re-saving the loaded recording
    csv_b, json_b = write_valid(tmp_path / "b.csv", groups)
    csv_c, json_c = save_recording(tmp_path / "c.csv", rec, truth=TRUTH)
    for other_csv, other_json in ((csv_b, json_b), (csv_c, json_c)):
        assert other_csv.read_bytes() == csv_a.read_bytes()
        assert other_json.read_bytes() == json_a.read_bytes()


def test_embedded_rig_and_provenance_round_trip(tmp_path):
    rig_dict = load_rig().to_dict()
    rig_dict["name"] = "bench-2"
    rig_dict["bearings"]["ks"] = 1.5e5
    rig = rig_from_dict(rig_dict, source="bench-2.toml")
    csv_p, json_p = write_valid(tmp_path / "r.csv", rig=rig, provenance={"by": "test"})
    rec = load_recording(csv_p)
    assert rec.rig.name == "bench-2" and rec.rig.ks == 1.5e5
    assert rec.meta["rig"] == rig_dict and rec.meta["provenance"] == {"by": "test"}
    csv_2, json_2 = save_recording(tmp_path / "r2.json", rec, truth=TRUTH)
    assert json_2.read_bytes() == json_p.read_bytes()
    assert csv_2.read_bytes() == csv_p.read_bytes()


def test_truth_is_kept_apart(tmp_path):
    csv_p, json_p = write_valid(tmp_path / "r.csv")
    rec = load_recording(csv_p)
    assert "truth" not in rec.meta
    assert "1.25e5" not in repr(rec.meta) and "125000" not in repr(rec.meta)
    assert load_truth(csv_p) == TRUTH
    assert json.loads(json_p.read_text())["truth"] == TRUTH
    csv_q, _ = write_valid(tmp_path / "q.csv", truth=None)
    assert load_truth(csv_q) is None
    fields = {f: getattr(rec, f) for f in ("t", "y", "u", "excitation", "dt", "speed_rpm",
                                           "rig", "controller")}
    with pytest.raises(RecordingError, match="field meta: must not contain 'truth'"):
        Recording(**fields, meta={"truth": TRUTH})


def test_arrays_read_only_and_loading_never_writes(tmp_path):
    csv_p, json_p = write_valid(tmp_path / "r.csv")
    os.utime(csv_p, ns=(1_000_000_000, 1_000_000_000))
    os.utime(json_p, ns=(1_000_000_000, 1_000_000_000))
    before = snapshot(csv_p, json_p)
    rec = load_recording(csv_p)
    load_recording(json_p)
    load_truth(csv_p)
    assert snapshot(csv_p, json_p) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.csv", "r.json"]
    with pytest.raises(ValueError, match="read-only"):
        rec.y[0, 0] = 1.0


def test_hand_written_recording_loads(tmp_path):
    """What a rig engineer writes: own column order, 9 significant digits, minimal sidecar."""
    y, u, exc = arrays(("r2",))
    header = ["t", *(f"r2_{c}" for c in ("Ax", "Ay", "Bx", "By")),
              *(f"{g}_{c}" for g in ("u", "y") for c in ("Ax", "Ay", "Bx", "By"))]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\r\n")
    w.writerow(header)
    for k in range(N):
        w.writerow([f"{k * 0.0001:.6f}", *(f"{v:.9g}" for v in (*exc["r2"][k], *u[k], *y[k]))])
    (tmp_path / "run.csv").write_text(buf.getvalue() + "\r\n", newline="")
    ctrl = controller_dict(n=0)
    ctrl["kind"] = "generic"
    side = {"format": "bayes-amb-recording/1", "dt": 0.0001, "speed_rpm": 0, "rig": "reference",
            "controller": ctrl, "excitation": {"columns": ["r2"],
                                               "injected_at": {"r2": "plant_input"}},
            "units": {"t": "s", "y": "m", "u": "A", "r2": "A"}}
    (tmp_path / "run.json").write_text(json.dumps(side))
    rec = load_recording(tmp_path / "run.csv")
    assert np.allclose(rec.y, y, rtol=1e-8) and np.allclose(rec.excitation["r2"], exc["r2"],
                                                            rtol=1e-8)
    assert rec.notes == "" and rec.controller.kind == "generic" and rec.speed_rpm == 0.0


# ------------------------------------------------------------------ malformations
def _csv_rows(p):
    with open(p, newline="") as f:
        return list(csv.reader(f))


def _write_rows(p, rows):
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(rows)
    p.write_text(buf.getvalue())


def side_edit(fn):
    def mutate(csv_p, json_p):
        d = json.loads(json_p.read_text())
        fn(d)
        json_p.write_text(json.dumps(d))
    return mutate


def rows_edit(fn):
    def mutate(csv_p, json_p):
        rows = _csv_rows(csv_p)
        fn(rows)
        _write_rows(csv_p, rows)
    return mutate


def text(which, fn):
    def mutate(csv_p, json_p):
        p = csv_p if which == "csv" else json_p
        p.write_text(fn(p.read_text()))
    return mutate


def _drop_col(rows, j):
    for r in rows:
        del r[j]


def _set(d, path, value):
    *head, last = path.split(".")
    for k in head:
        d = d[k]
    d[last] = value


BAD = [
    ("no sidecar", lambda c, j: j.unlink(), r"sidecar .*r\.json: field <file>: not found"),
    ("no csv", lambda c, j: c.unlink(), r"recording .*r\.csv: field <file>: not found"),
    ("format missing", side_edit(lambda d: d.pop("format")),
     r"field format: expected 'bayes-amb-recording/1', missing"),
    ("format version", side_edit(lambda d: _set(d, "format", "bayes-amb-recording/2")),
     r"field format: expected 'bayes-amb-recording/1', got 'bayes-amb-recording/2'"),
    ("unknown key", side_edit(lambda d: _set(d, "comment", "x")), r"field comment: unknown key"),
    ("missing controller", side_edit(lambda d: d.pop("controller")),
     r"field controller: missing"),
    ("missing units", side_edit(lambda d: d.pop("units")), r"field units: missing"),
    ("truncated json", text("json", lambda s: s[:40]), r"field <json>: not valid JSON"),
    ("NaN in json", text("json", lambda s: s.replace('"speed_rpm": 12000.0', '"speed_rpm": NaN')),
     r"field <json>: not valid JSON \(non-finite number NaN"),
    ("json list", text("json", lambda s: "[" + s + "]"),
     r"field <top>: expected a JSON object, got list"),
    ("dt zero", side_edit(lambda d: _set(d, "dt", 0)),
     r"field dt: expected a positive sample time in s, got 0"),
    ("dt negative", side_edit(lambda d: _set(d, "dt", -1e-4)), r"field dt: .* got -0.0001"),
    ("dt string", side_edit(lambda d: _set(d, "dt", "1e-4")), r"field dt: .* got '1e-4'"),
    ("speed negative", side_edit(lambda d: _set(d, "speed_rpm", -1)),
     r"field speed_rpm: expected a number >= 0, got -1"),
    ("speed string", side_edit(lambda d: _set(d, "speed_rpm", "fast")),
     r"field speed_rpm: .* got 'fast'"),
    ("speed bool", side_edit(lambda d: _set(d, "speed_rpm", True)),
     r"field speed_rpm: .* got True"),
    ("unknown rig", side_edit(lambda d: _set(d, "rig", "turbo9")),
     r"field rig: unknown rig 'turbo9' \(shipped: \['reference'\]"),
    ("bad rig dict", side_edit(lambda d: _set(d, "rig", {"name": "x", "shaft": 1})),
     r"field rig: rig file .*r\.json#rig: field shaft: expected a table"),
    ("controller B 7 columns", side_edit(lambda d: [r.pop() for r in d["controller"]["B"]]),
     r"sidecar .*r\.json: field controller\.B: expected 8 columns \(one per input\), got 7"),
    ("controller C 3 states", side_edit(lambda d: [r.append(0) for r in d["controller"]["C"]]),
     r"field controller\.C: expected 2 columns"),
    ("controller not object", side_edit(lambda d: _set(d, "controller", "k.json")),
     r"field controller\.<top>: expected a JSON object"),
    ("controller dt", side_edit(lambda d: _set(d, "controller.dt", 2e-4)),
     r"field controller\.dt: controller sample time 0.0002 s differs from the recording dt"),
    ("excitation lists r2", side_edit(lambda d: _set(d, "excitation", {
        "columns": ["r2"], "injected_at": {"r2": "plant_input"}}) or _set(
        d, "units", {"t": "s", "y": "m", "u": "A", "r2": "A"})),
     r"field excitation\.columns: the sidecar lists \['r2'\] but the CSV has excitation "
     r"groups \['eta'\]"),
    ("excitation empty", side_edit(lambda d: _set(d, "excitation.columns", [])),
     r"field excitation\.columns: expected distinct groups"),
    ("excitation unknown group", side_edit(lambda d: _set(d, "excitation.columns", ["r3"])),
     r"field excitation\.columns: .* got \['r3'\]"),
    ("injected_at wrong", side_edit(lambda d: _set(d, "excitation.injected_at.eta", "sensor")),
     r"field excitation\.injected_at: expected \{'eta': 'youla_port'\}"),
    ("units mm", side_edit(lambda d: _set(d, "units.y", "mm")),
     r"field units: expected .*\(SI only\), got .*'mm'"),
    ("notes not string", side_edit(lambda d: _set(d, "notes", 3)),
     r"field notes: expected a string, got 3"),
    ("truth not object", side_edit(lambda d: _set(d, "truth", [1])),
     r"field truth: expected an object, got \[1\]"),
    ("missing column", rows_edit(lambda rows: _drop_col(rows, 3)), r"column y_Bx: missing$"),
    ("missing t", rows_edit(lambda rows: _drop_col(rows, 0)), r"column t: missing$"),
    ("extra column", rows_edit(lambda rows: [r.append("0") for r in rows] and rows[0].__setitem__(
        -1, "temp")), r"column 'temp' \(column 14\): unknown column"),
    ("duplicated column", rows_edit(lambda rows: [r.append(r[5]) for r in rows]),
     r"column u_Ax: duplicated \(columns 6, 14\)"),
    ("incomplete group", rows_edit(lambda rows: _drop_col(rows, 12)),
     r"column eta_By: missing \(excitation group eta needs all 4 channels\)"),
    ("junk cell", rows_edit(lambda rows: rows[3].__setitem__(2, "abc")),
     r"column y_Ay: row 3 \(line 4\): not a number: 'abc'"),
    ("empty cell", rows_edit(lambda rows: rows[7].__setitem__(9, "")),
     r"column eta_Ax: row 7 \(line 8\): not a number: ''"),
    ("decimal comma", rows_edit(lambda rows: rows[1].__setitem__(6, '1,5')),
     r"column u_Ay: row 1 \(line 2\): not a number"),
    ("nan cell", rows_edit(lambda rows: rows[5].__setitem__(7, "nan")),
     r"column u_Bx: row 5 \(line 6\): not finite \(nan\)"),
    ("inf cell", rows_edit(lambda rows: rows[20].__setitem__(1, "-inf")),
     r"column y_Ax: row 20 \(line 21\): not finite \(-inf\)"),
    ("short row", rows_edit(lambda rows: rows[4].pop()),
     r"row 4 \(line 5\): expected 13 cells, got 12"),
    ("blank line inside", text("csv", lambda s: s.replace("\n", "\n\n", 3)),
     r"row 1 \(line 2\): expected 13 cells, got 0"),
    ("empty file", text("csv", lambda s: ""), r"field <file>: empty file"),
    ("header only", text("csv", lambda s: s.splitlines()[0] + "\n"),
     r"field <rows>: expected at least 2 data rows, got 0"),
    ("one row", text("csv", lambda s: "\n".join(s.splitlines()[:2])),
     r"field <rows>: expected at least 2 data rows, got 1"),
    ("t swapped", rows_edit(lambda rows: rows.__setitem__(slice(4, 6), rows[5:3:-1])),
     r"column t: not strictly increasing at row 5 \(line 6\)"),
    ("t repeated", rows_edit(lambda rows: rows[9].__setitem__(0, rows[8][0])),
     r"column t: not strictly increasing at row 9"),
    ("t jitter", rows_edit(lambda rows: rows[12].__setitem__(0, repr(float(rows[12][0]) + 2e-9))),
     r"column t: non-uniform \(usual step .*\) at row 12 \(line 13\)"),
    ("t gap", rows_edit(lambda rows: rows.pop(10)), r"column t: non-uniform .* at row 10"),
    ("dt disagrees", side_edit(lambda d: _set(d, "dt", 2e-4) or _set(d, "controller.dt", 2e-4)),
     r"recording .*r\.csv: field dt: dt = 0.0002 s but column t has step .* s$"),
    ("not utf8", lambda c, j: c.write_bytes(c.read_bytes().replace(b"t,", b"\xff,", 1)),
     r"field <file>: not UTF-8"),
]


@pytest.mark.parametrize(("mutate", "match"), [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_malformed_recording_raises_one_line(tmp_path, mutate, match):
    csv_p, json_p = write_valid(tmp_path / "r.csv")
    mutate(csv_p, json_p)
    before = snapshot(csv_p, json_p)
    with pytest.raises(RecordingError, match=match) as info:
        load_recording(csv_p)
    msg = str(info.value)
    assert "\n" not in msg and (("r.csv" in msg) or ("r.json" in msg))
    assert snapshot(csv_p, json_p) == before


def test_wrong_suffix(tmp_path):
    with pytest.raises(RecordingError, match=r"expected NAME\.csv .*got suffix '\.txt'"):
        load_recording(tmp_path / "r.txt")


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"y": np.zeros((N, 3))}, r"field y: expected shape \(20, 4\), got \(20, 3\)"),
    ({"excitation": {}}, r"field excitation: expected one or more of"),
    ({"excitation": {"r3": np.zeros((N, 4))}}, r"field excitation: .* got \['r3'\]"),
    ({"dt": -1.0}, r"field dt"),
    ({"speed_rpm": np.nan}, r"field speed_rpm"),
    ({"u": np.full((N, 4), np.inf)}, r"column u_Ax: row 1 \(line 2\): not finite"),
    ({"t": np.arange(N) * DT * 1.5}, r"field dt: dt = 0.0001 s but column t has step"),
])
def test_make_recording_validates(kwargs, match):
    y, u, exc = arrays()
    args = {"y": y, "u": u, "excitation": exc, "dt": DT,
            "controller": load_controller(controller_dict(dt=DT)), **kwargs}
    with pytest.raises(RecordingError, match=r"^recording <memory>: " + match):
        make_recording(**args)


def test_part_is_a_record_cut_from_the_longer_one():
    y, u, exc = arrays(("eta", "r2"))
    rec = make_recording(y=y, u=u, excitation=exc, dt=DT,
                         controller=load_controller(controller_dict(dt=DT)))
    cut = rec.part(slice(5, None))
    assert cut.n_samples == N - 5 and cut.t[0] == 0.0
    np.testing.assert_allclose(cut.t, rec.t[5:] - rec.t[5])
    np.testing.assert_array_equal(cut.y, rec.y[5:])
    np.testing.assert_array_equal(cut.u, rec.u[5:])
    assert set(cut.excitation) == {"eta", "r2"}
    np.testing.assert_array_equal(cut.excitation["r2"], rec.excitation["r2"][5:])
    assert cut.controller is rec.controller and cut.dt == rec.dt


# ------------------------------------------------------------------ atomic writes
def test_atomic_path_leaves_no_partial_file(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("old content")
    with pytest.raises(RuntimeError, match="writer failed"):
        with atomic_path(target) as tmp:
            tmp.write_text("half of the new con")
            raise RuntimeError("writer failed")
    assert target.read_text() == "old content"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]
    new = tmp_path / "new.txt"
    with pytest.raises(RuntimeError):
        with atomic_path(new) as tmp:
            tmp.write_text("partial")
            raise RuntimeError("writer failed")
    assert not new.exists() and [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_atomic_write_modes(tmp_path):
    p = tmp_path / "m.txt"
    write_text_atomic(p, "a\n")
    umask = os.umask(0)
    os.umask(umask)
    assert p.stat().st_mode & 0o777 == 0o666 & ~umask
    p.chmod(0o600)
    write_text_atomic(p, "b\n")
    assert p.read_bytes() == b"b\n" and p.stat().st_mode & 0o777 == 0o600


def test_save_recording_failing_mid_way_keeps_old_pair(tmp_path, monkeypatch):
    csv_p, json_p = write_valid(tmp_path / "r.csv")
    before = snapshot(csv_p, json_p)
    calls = []
    real = pathlib.Path.write_bytes

    def flaky(self, data):
        calls.append(self)
        if len(calls) == 2:  # the sidecar: write half of it, then fail
            real(self, data[: len(data) // 2])
            raise OSError("disk full")
        return real(self, data)

    monkeypatch.setattr(pathlib.Path, "write_bytes", flaky)
    with pytest.raises(OSError, match="disk full"):
        write_valid(tmp_path / "r.csv", groups=("r2",))
    monkeypatch.undo()
    assert snapshot(csv_p, json_p) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.csv", "r.json"]
    load_recording(csv_p)


def test_save_recording_unserialisable_truth_writes_nothing(tmp_path):
    with pytest.raises(RecordingError, match=r"sidecar .*r\.json: not writable as JSON"):
        write_valid(tmp_path / "r.csv", truth={"k": np.nan})
    assert list(tmp_path.iterdir()) == []
