"""Fuzz test of `bayes-amb import`: every broken map or DAQ file is exit 2 and one line.

Each example takes a valid tiny import (40 samples at 1 kHz, CSV or .mat/.mat v7.3/TDMS/HDF5,
positions in V, currents in V through an amplifier gain, excitation in mA) and applies one
mutation that certainly breaks it: a map field removed or given a wrong value, an unknown
key or target, invalid TOML, a source column removed, renamed, non-numeric, non-finite, a
time column that runs backwards or jumps, a shortened channel, a file that is not what its
suffix says. Property: the CLI (in process) exits with status 2, prints nothing on stdout
and exactly one line on stderr, and writes no output. The unmutated base imports (exit 0).
"""

from __future__ import annotations

import contextlib
import copy
import io
import pathlib
import tempfile

import numpy as np
import pytest
from hypothesis import event, given, settings
from hypothesis import strategies as st

from bayes_amb.io import ControllerFile, make_recording
from bayes_amb.io.channel_map import map_to_toml
from bayes_amb.io.daq_export import export_daq, realistic_channel_map
from bayes_amb.io.daq_import import import_recording
from tests.helpers import run_cli

N, DT = 40, 1e-3
SUFFIX = {"csv": ".csv", "mat": ".mat", "mat73": ".mat", "tdms": ".tdms", "hdf5": ".h5"}
_rng = np.random.default_rng(11)
CTRL = ControllerFile(dt=DT, A=np.zeros((0, 0)), B=np.zeros((0, 8)), C=np.zeros((8, 0)),
                      D=np.hstack([np.vstack([-8000.0 * np.eye(4), np.zeros((4, 4))]),
                                   np.vstack([np.eye(4), np.zeros((4, 4))])]), kind="generic")
REC = make_recording(1e-6 * _rng.normal(size=(N, 4)), _rng.normal(size=(N, 4)),
                     {"r2": 0.1 * _rng.normal(size=(N, 4))}, DT, CTRL, speed_rpm=6000.0)


def _base_map(fmt: str) -> dict:
    return realistic_channel_map(fmt, ["r2"], controller="ctrl.json", speed_rpm=6000.0)


CHANNEL_NAMES = list(_base_map("csv")["channels"])
# (table path, field, values that are all invalid there)
FIELD_JUNK = [
    (("time",), "column", [0, "", "nope", True, [1]]),
    (("time",), "sample_rate_hz", [0, -1.0, "x", True, 999.0, float("nan")]),
    (("time",), "decimate", [0, -1, 1.5, "2", True, 11, 13, 2, 10**6]),
    (("time",), "start_s", [-1.0, "a", 1e9, 0.039]),
    (("time",), "stop_s", [0.0, -1.0, 1e-9, "b"]),
    (("recording",), "speed_rpm", [-1.0, "fast", float("nan"), float("inf"), True]),
    (("recording",), "rig", ["nope.toml", 3, ""]),
    (("recording",), "controller", ["nope.json", 3, ""]),
    (("recording",), "notes", [3, True, [1]]),
    (("source",), "format", ["matlab", "", 3, "xlsx"]),
]
CHANNEL_JUNK = {
    "unit": [3, "", "psi", "kV", "V/m", "amps"],
    "sensitivity": [0.0, -1.0, "x", float("inf")],
    "gain": [0.0, -0.5, "x", float("nan")],
    "sign": [0, 2, -2, "-1", True, 0.5],
    "offset": ["x", True, float("nan"), float("inf")],
    "remove_offset": ["yes", 1, 0, 1.0],
    "source": ["nope", "", 3, "AMB1_X_pos_"],
}


def _set_path(m: dict, path: tuple[str, ...], key: str, value) -> None:
    node = m
    for k in path:
        node = node.setdefault(k, {})
    node[key] = value


def m_field(data, m, files):
    path, key, values = data.draw(st.sampled_from(FIELD_JUNK))
    if key == "format":  # a wrong but valid format name for the file also breaks it
        values = [*values, data.draw(st.sampled_from(["csv", "mat", "tdms", "hdf5", "mat73"]
                                                    ).filter(lambda f: f != files["fmt"]))]
    _set_path(m, path, key, data.draw(st.sampled_from(values)))


def m_channel_field(data, m, files):
    target = data.draw(st.sampled_from(CHANNEL_NAMES))
    key = data.draw(st.sampled_from(sorted(CHANNEL_JUNK)))
    value = data.draw(st.sampled_from(CHANNEL_JUNK[key]))
    c = m["channels"][target]
    if key == "unit" and value in ("A", "m"):
        return
    if key == "sensitivity" and target[0] == "u":
        value = 8000.0          # a sensitivity on a current: always wrong
    if key == "gain" and target[0] == "y":
        value = 0.5             # an amplifier gain on a displacement: always wrong
    if key == "remove_offset" and value is True:
        return
    c[key] = value


def m_unit_mismatch(data, m, files):
    target = data.draw(st.sampled_from(CHANNEL_NAMES))
    c = m["channels"][target]
    si = "m" if target[0] == "y" else "A"
    choice = data.draw(st.sampled_from(["other_si", "volt_without_scale", "both_offsets"]))
    if choice == "other_si":
        c["unit"] = "A" if si == "m" else "m"
        c.pop("sensitivity", None)
        c.pop("gain", None)
    elif choice == "volt_without_scale":
        c["unit"] = data.draw(st.sampled_from(["V", "mV"]))
        c.pop("sensitivity", None)
        c.pop("gain", None)
    else:
        c["offset"] = 0.1
        c["remove_offset"] = True


def m_delete(data, m, files):
    what = data.draw(st.sampled_from(["time", "recording", "channels", "controller",
                                      "speed_rpm", "channel", "source_key"]))
    if what in ("time", "recording", "channels"):
        del m[what]
    elif what in ("controller", "speed_rpm"):
        del m["recording"][what]
    elif what == "channel":
        del m["channels"][data.draw(st.sampled_from(CHANNEL_NAMES))]
    else:
        del m["channels"][data.draw(st.sampled_from(CHANNEL_NAMES))]["source"]


def m_unknown(data, m, files):
    where = data.draw(st.sampled_from(["top", "time", "recording", "channel", "target"]))
    key = data.draw(st.sampled_from(["foo", "Unit", "scale", "dt", "rate"]))
    if where == "top":
        m[key] = {"a": 1}
    elif where == "target":
        m["channels"][data.draw(st.sampled_from(["y_Az", "z_Ax", "u_AX", "eps_Ax", "r3_Ax"]))] = {
            "source": "AMB1_X_pos"}
    elif where == "channel":
        m["channels"][data.draw(st.sampled_from(CHANNEL_NAMES))][key] = 1.0
    else:
        m[where][key] = 1.0


def m_toml_text(data, m, files):
    files["toml_suffix"] = data.draw(st.sampled_from(["\n= = =\n", "\n[time\n", "\nx = \n",
                                                      "\n[channels.y_Ax]\nsource = 'a'\n",
                                                      "\n\"unterminated = 1\n"]))


def m_csv_table(data, m, files):
    files["fmt"] = "csv"
    m.update(_base_map("csv"))
    kind = data.draw(st.sampled_from(["drop", "rename", "junk_cell", "time_back",
                                      "time_jump", "short_row", "empty", "header_only",
                                      "not_utf8", "dup_column"]))
    files["csv_edit"] = (kind, data.draw(st.integers(0, 12)), data.draw(st.integers(0, N - 1)),
                         data.draw(st.sampled_from(["nan", "inf", "-inf", "abc", "", "1e999",
                                                    "0x1", "1,5"])))


def m_binary(data, m, files):
    kind = data.draw(st.sampled_from(["garbage", "truncate", "empty", "wrong_suffix"]))
    files["binary_edit"] = (kind, data.draw(st.integers(0, 10**6)))


MUTATIONS = [m_field, m_channel_field, m_unit_mismatch, m_delete, m_unknown, m_toml_text,
             m_csv_table, m_binary]


def _edit_csv(path: pathlib.Path, edit) -> None:
    kind, j, i, junk = edit
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    rows = [r.split(",") for r in lines[1:]]
    j = j % len(header)
    if kind == "drop":
        header.pop(j)
        for r in rows:
            r.pop(j)
    elif kind == "rename":
        header[j] = header[j] + "_old"
    elif kind == "junk_cell":
        rows[i][j] = junk
    elif kind == "dup_column":
        header[(j + 1) % len(header)] = header[j]
    elif kind in ("time_back", "time_jump"):
        t = header.index("time")
        i = max(i, 1)
        rows[i][t] = repr(float(rows[i][t]) + (-2 * DT if kind == "time_back" else 0.5 * DT))
    elif kind == "short_row":
        rows[i] = rows[i][: max(1, j % len(rows[i]))]
    if kind == "empty":
        path.write_text("")
    elif kind == "header_only":
        path.write_text(",".join(header) + "\n")
    elif kind == "not_utf8":
        path.write_bytes(b"time,\xff\xfe\x00AMB\n\x80\x81")
    else:
        path.write_text("\n".join(",".join(r) for r in [header, *rows]) + "\n")


def _edit_binary(path: pathlib.Path, edit) -> pathlib.Path:
    kind, seed = edit
    raw = path.read_bytes()
    if kind == "garbage":
        path.write_bytes(np.random.default_rng(seed).bytes(64 + seed % 512))
    elif kind == "truncate":
        path.write_bytes(raw[: seed % max(1, len(raw) // 2)])
    elif kind == "empty":
        path.write_bytes(b"")
    else:  # a CSV file named like a binary one
        path.write_text("time,AMB1_X_pos\n0,1\n")
    return path


def _run(fmt: str, m: dict, files: dict, capsys) -> tuple[int, str, str, pathlib.Path]:
    with tempfile.TemporaryDirectory() as d:
        d = pathlib.Path(d)
        CTRL.save(d / "ctrl.json")
        src = export_daq(REC, d / f"daq{SUFFIX[fmt]}", _base_map(fmt))
        if "csv_edit" in files:
            _edit_csv(src, files["csv_edit"])
        if "binary_edit" in files:
            _edit_binary(src, files["binary_edit"])
        (d / "map.toml").write_text(map_to_toml(m) + files.get("toml_suffix", ""))
        out = d / "out.csv"
        code, stdout, err = run_cli(["import", str(src), "--map", str(d / "map.toml"),
                                     "-o", str(out)], capsys)
        return code, stdout, err, out.exists()


@pytest.mark.parametrize("fmt", list(SUFFIX))
def test_the_unmutated_base_imports(fmt, capsys):
    code, out, err, written = _run(fmt, _base_map(fmt), {"fmt": fmt}, capsys)
    assert code == 0 and written and out.startswith("wrote "), err
    d = pathlib.Path(tempfile.mkdtemp())
    CTRL.save(d / "ctrl.json")
    (d / "map.toml").write_text(map_to_toml(_base_map(fmt)))
    back = import_recording(export_daq(REC, d / f"daq{SUFFIX[fmt]}", _base_map(fmt)),
                            d / "map.toml")
    assert np.abs(back.u - REC.u).max() < 1e-14 and np.abs(back.y - REC.y).max() < 1e-20


@settings(max_examples=320, deadline=None, derandomize=True)
@given(data=st.data())
def test_every_broken_import_is_exit_2_and_one_line(data):
    fmt = data.draw(st.sampled_from(list(SUFFIX)))
    files = {"fmt": fmt}
    m = copy.deepcopy(_base_map(fmt))
    mutation = data.draw(st.sampled_from(MUTATIONS))
    if mutation is m_binary and fmt == "csv":
        fmt = files["fmt"] = data.draw(st.sampled_from(["mat", "mat73", "tdms", "hdf5"]))
        m = copy.deepcopy(_base_map(fmt))
    mutation(data, m, files)
    fmt = files["fmt"]

    class _Cap:  # capsys cannot be used with hypothesis' repeated examples
        def readouterr(self):
            return _cap_out.getvalue(), _cap_err.getvalue()

    _cap_out, _cap_err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(_cap_out), contextlib.redirect_stderr(_cap_err):
        code, out, err, written = _run(fmt, m, files, _Cap())
    note = f"{mutation.__name__} {fmt} {files}"
    event(mutation.__name__)
    assert code == 2, f"{note}: exit {code}, stderr {err!r}"
    assert out == "" and not written, note
    assert err.count("\n") == 1 and err.startswith("bayes-amb import: error: "), (note, err)
