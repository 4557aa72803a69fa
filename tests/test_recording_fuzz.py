"""Fuzz test of load_recording: malformed input gives a Recording or a RecordingError, nothing else.

Each example mutates a valid small recording (12 rows, eta and r2 excitation, a truth entry)
with one to three random mutations of the CSV table, the CSV text, the sidecar dict or the
sidecar text. Property: load_recording either raises RecordingError (and leaves the files
unchanged) or returns a Recording whose invariants hold. When exactly one mutation was applied
and that mutation certainly breaks the format, the load must fail.
"""

from __future__ import annotations

import copy
import csv
import io
import json
import math
import pathlib
import tempfile

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from bayes_amb.errors import RecordingError
from bayes_amb.io import Recording, load_controller, load_recording, save_recording
from bayes_amb.rig import CHANNELS
from tests.test_controller_file import controller_dict

DT = 2.5e-4
N_ROWS = 12


def _base() -> dict:
    """A valid recording as editable pieces: header, rows of strings, sidecar dict."""
    rng = np.random.default_rng(3)
    exc = {"eta": 0.1 * rng.normal(size=(N_ROWS, 4)), "r2": 0.1 * rng.normal(size=(N_ROWS, 4))}
    with tempfile.TemporaryDirectory() as d:
        csv_p, json_p = save_recording(
            pathlib.Path(d) / "base.csv", y=1e-6 * rng.normal(size=(N_ROWS, 4)),
            u=rng.normal(size=(N_ROWS, 4)), excitation=exc, dt=DT, speed_rpm=9000.0,
            controller=load_controller(controller_dict(dt=DT)), truth={"k_A": 1.1e5})
        rows = list(csv.reader(io.StringIO(csv_p.read_text())))
        side = json.loads(json_p.read_text())
    return {"header": rows[0], "rows": rows[1:], "side": side, "side_text": None,
            "csv_text": None, "csv_missing": False}


BASE = _base()
JUNK_CELLS = ["", " ", "abc", "nan", "NaN", "inf", "-inf", "Infinity", "1e999", "0x10", "1,5",
              "--1", "1e", ".", "+", "None", "true", "\t", '"', "1.0.0", "\u00a0", "١٢"]
JUNK_VALUES = [None, True, False, 0, 1, -3.5, 1e300, "x", "", [], {}, [1, 2], {"a": 1},
               [[1.0, 2.0]], "reference", "bayes-amb-recording/1"]
NAMES = ["t", "y_Ax", "u_By", "eta_Ax", "r2_Bx", "r1_Ay", "foo", "", " T", "Y_AX", "eta_Az",
         "r2_", "t "]
# nested sidecar entries whose replacement by any JUNK_VALUE breaks the recording
NESTED = ["controller.A", "controller.B", "controller.C", "controller.D", "controller.dt",
          "controller.inputs", "controller.kind", "controller.format", "excitation.columns",
          "excitation.injected_at", "units.y", "units.t"]


def _finite_number(s: str) -> bool:
    try:
        return math.isfinite(float(s))
    except ValueError:
        return False


def _col(state, data) -> int | None:
    width = len(state["header"])
    return data.draw(st.integers(0, width - 1)) if width else None


def m_delete_column(state, data) -> bool:
    j = _col(state, data)
    if j is None:
        return False
    del state["header"][j]
    for row in state["rows"]:
        if j < len(row):
            del row[j]
    return True


def m_duplicate_column(state, data) -> bool:
    j = _col(state, data)
    if j is None:
        return False
    state["header"].append(state["header"][j])
    for row in state["rows"]:
        row.append(row[j] if j < len(row) else "0")
    return True


def m_rename_column(state, data) -> bool:
    j = _col(state, data)
    if j is None:
        return False
    new = data.draw(st.sampled_from(NAMES))
    old, state["header"][j] = state["header"][j], new
    return new.strip() != old.strip()


def m_add_column(state, data) -> bool:
    state["header"].append(data.draw(st.sampled_from(NAMES)))
    for row in state["rows"]:
        row.append("0.0")
    return True


def m_corrupt_cell(state, data) -> bool:
    if not state["rows"] or not state["header"]:
        return False
    i = data.draw(st.integers(0, len(state["rows"]) - 1))
    j = data.draw(st.integers(0, len(state["header"]) - 1))
    value = data.draw(st.sampled_from(JUNK_CELLS) | st.text(
        st.characters(blacklist_categories=("Cs",)), max_size=6))
    row = state["rows"][i]
    if j >= len(row):
        return False
    row[j] = value
    return not _finite_number(value)


def m_drop_rows(state, data) -> bool:
    n = len(state["rows"])
    if n == 0:
        return False
    start = data.draw(st.integers(0, n - 1))
    count = data.draw(st.integers(1, n - start))
    del state["rows"][start:start + count]
    return len(state["rows"]) < 2 or (start > 0 and start + count < n)


def m_shuffle_rows(state, data) -> bool:
    perm = data.draw(st.permutations(range(len(state["rows"]))))
    state["rows"] = [state["rows"][k] for k in perm]
    return list(perm) != sorted(perm)


def m_perturb_t(state, data) -> bool:
    if "t" not in state["header"] or not state["rows"]:
        return False
    j = state["header"].index("t")
    i = data.draw(st.integers(0, len(state["rows"]) - 1))
    factor = data.draw(st.sampled_from([1e-9, 1e-3, -1e-3, 0.5, -0.5, 2.0, -1.0, 1e6]))
    try:
        state["rows"][i][j] = repr(float(state["rows"][i][j]) + factor * DT)
    except (ValueError, IndexError):
        return False
    return abs(factor) >= 1e-4


def m_sidecar_dt(state, data) -> bool:
    if state["side"] is None:
        return False
    value = data.draw(st.sampled_from([0, 0.0, -DT, 2 * DT, DT * (1 + 1e-4), DT * (1 + 1e-9),
                                       str(DT), None, True, [], {}, float("nan")]))
    state["side"]["dt"] = value
    return not (isinstance(value, float) and abs(value - DT) <= 1e-7 * DT)


def m_break_json(state, data) -> bool:
    if state["side"] is None:
        return False
    text = json.dumps(state["side"])
    state["side_text"] = text[: data.draw(st.integers(0, len(text) - 1))]
    return True


def m_delete_key(state, data) -> bool:
    if not state["side"]:
        return False
    key = data.draw(st.sampled_from(sorted(state["side"])))
    del state["side"][key]
    return key not in ("notes", "provenance", "truth")


def m_wrong_type(state, data) -> bool:
    if state["side"] is None:
        return False
    key = data.draw(st.sampled_from(["format", "dt", "speed_rpm", "rig", "controller",
                                     "excitation", "units", "notes", "provenance", "truth",
                                     "bogus"]))
    value = data.draw(st.sampled_from(JUNK_VALUES))
    state["side"][key] = copy.deepcopy(value)
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    harmless = ((key == "speed_rpm" and number and value >= 0)
                or (key == "notes" and isinstance(value, str))
                or (key in ("provenance", "truth") and isinstance(value, dict))
                or (key == "rig" and value == "reference")
                or (key == "format" and value == "bayes-amb-recording/1"))
    return not harmless


def m_nested_type(state, data) -> bool:
    side = state["side"]
    path = data.draw(st.sampled_from(NESTED))
    outer, inner = path.split(".")
    if side is None or not isinstance(side.get(outer), dict):
        return False
    side[outer][inner] = copy.deepcopy(data.draw(st.sampled_from(JUNK_VALUES)))
    return True


def m_delete_file(state, data) -> bool:
    if data.draw(st.booleans()):
        state["side"], state["side_text"] = None, None
    else:
        state["csv_missing"] = True
    return True


def m_csv_text(state, data) -> bool:
    """Harmless (BOM, trailing blank lines, CRLF, spaces) or harmful (blank line inside)."""
    kind = data.draw(st.sampled_from(["bom", "trailing", "crlf", "blank_inside", "empty"]))
    state["csv_text"] = kind
    return kind in ("blank_inside", "empty")


MUTATIONS = [m_delete_column, m_duplicate_column, m_rename_column, m_add_column,
             m_corrupt_cell, m_corrupt_cell, m_drop_rows, m_shuffle_rows, m_perturb_t,
             m_sidecar_dt, m_break_json, m_delete_key, m_wrong_type, m_nested_type,
             m_delete_file, m_csv_text]


def _write(state, directory: pathlib.Path) -> tuple[pathlib.Path, pathlib.Path]:
    csv_p, json_p = directory / "rec.csv", directory / "rec.json"
    if not state["csv_missing"]:
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow(state["header"])
        writer.writerows(state["rows"])
        text = buf.getvalue()
        kind = state["csv_text"]
        if kind == "bom":
            text = "\ufeff" + text
        elif kind == "trailing":
            text += "\n\n  \n"
        elif kind == "crlf":
            text = text.replace("\n", "\r\n")
        elif kind == "blank_inside":
            text = text.replace("\n", "\n\n", 2)
        elif kind == "empty":
            text = ""
        csv_p.write_text(text, encoding="utf-8", newline="")
    if state["side_text"] is not None:
        json_p.write_text(state["side_text"], encoding="utf-8")
    elif state["side"] is not None:
        json_p.write_text(json.dumps(state["side"], allow_nan=True), encoding="utf-8")
    return csv_p, json_p


def _check_invariants(rec: Recording) -> None:
    n = rec.t.shape[0]
    assert n >= 2 and rec.t.shape == (n,)
    assert rec.y.shape == (n, len(CHANNELS)) and rec.u.shape == (n, len(CHANNELS))
    assert rec.excitation and set(rec.excitation) <= {"eta", "r2", "r1"}
    for arr in (rec.t, rec.y, rec.u, *rec.excitation.values()):
        assert np.all(np.isfinite(arr)) and not arr.flags.writeable
    for arr in rec.excitation.values():
        assert arr.shape == (n, len(CHANNELS))
    assert rec.dt > 0 and math.isfinite(rec.dt) and rec.speed_rpm >= 0
    steps = np.diff(rec.t)
    assert np.all(np.abs(steps - rec.dt) <= 2e-6 * rec.dt)
    assert abs(rec.controller.dt - rec.dt) <= 1e-6 * rec.dt
    assert "truth" not in rec.meta


@settings(max_examples=300, deadline=None, derandomize=True, database=None)
@given(data=st.data())
def test_malformed_recordings_give_recording_or_recording_error(data):
    state = copy.deepcopy(BASE)
    n_mutations = data.draw(st.sampled_from([1, 1, 2, 3]), label="n_mutations")
    certain = []
    for _ in range(n_mutations):
        mutate = data.draw(st.sampled_from(MUTATIONS), label="mutation")
        certain.append(mutate(state, data))
    with tempfile.TemporaryDirectory() as d:
        csv_p, json_p = _write(state, pathlib.Path(d))
        before = [p.read_bytes() if p.exists() else None for p in (csv_p, json_p)]
        try:
            rec = load_recording(csv_p)
        except RecordingError as exc:
            assert "\n" not in str(exc)
            rec = None
        assert [p.read_bytes() if p.exists() else None for p in (csv_p, json_p)] == before
    if rec is None:
        return
    assert not (n_mutations == 1 and certain[0]), "a certainly broken recording was accepted"
    _check_invariants(rec)


def test_unmutated_base_loads():
    """The fuzz base itself is valid (otherwise the property above is vacuous)."""
    with tempfile.TemporaryDirectory() as d:
        rec = load_recording(_write(copy.deepcopy(BASE), pathlib.Path(d))[0])
    _check_invariants(rec)
    assert set(rec.excitation) == {"eta", "r2"} and rec.n_samples == N_ROWS
