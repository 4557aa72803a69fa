"""Import of DAQ files through a channel map: round trips, identification, one-line errors."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import scipy.signal as sig

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.errors import DataImportError
from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.io import load_recording, save_recording
from bayes_amb.io.channel_map import map_to_toml
from bayes_amb.io.daq import file_sha256
from bayes_amb.io.daq_export import export_daq, realistic_channel_map
from bayes_amb.io.daq_import import import_recording
from bayes_amb.io.recording import make_recording
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, simulate_recording
from tests.helpers import run_cli

SUFFIX = {"mat": ".mat", "mat73": ".mat", "tdms": ".tdms", "hdf5": ".h5", "csv": ".csv"}
FORMATS = tuple(SUFFIX)
DT = 1e-3


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """A 1 s, 1 kHz simulated recording (reduced truth, k_By = 0.3, c_By = 0.2, noise)."""
    d = tmp_path_factory.mktemp("daq")
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, DT), rig)
    ctrl.save(d / "ctrl.json")
    rec, _ = simulate_recording(rig, ctrl, SimulationConfig(
        truth="reduced", params={"k_By": 0.3, "c_By": 0.2}, dt=DT, duration=1.0,
        noise_rms=2e-7, seed=4))
    save_recording(d / "canonical.csv", rec)
    return d, load_recording(d / "canonical.csv")


def _export(case, fmt: str, **kw) -> tuple[Path, Path]:
    d, rec = case
    m = realistic_channel_map(fmt, list(rec.excitation), controller="ctrl.json",
                              speed_rpm=rec.speed_rpm, dt=rec.dt, **kw)
    map_path = d / f"{fmt}.toml"
    map_path.write_text(map_to_toml(m))
    return export_daq(rec, d / f"rec_{fmt}{SUFFIX[fmt]}", m), map_path


def _rel(a, b) -> float:
    """Largest per-channel max|a - b| / max|b|."""
    a, b = np.asarray(a), np.asarray(b)
    return float(np.max(np.max(np.abs(a - b), axis=0) / np.max(np.abs(b), axis=0)))


@pytest.mark.parametrize("fmt", FORMATS)
def test_round_trip_changes_nothing_beyond_the_stated_scaling(case, fmt):
    d, _rec = case
    src, map_path = _export(case, fmt)
    # the file holds volts, offsets and an inverted Ay probe, not SI
    raw = load_recording(d / "canonical.csv")
    back = import_recording(src, map_path)
    for a, b in ((back.y, raw.y), (back.u, raw.u), (back.excitation["eta"], raw.excitation["eta"])):
        assert _rel(a, b) < 1e-13        # offsets up to 0.12 V on signals of ~10 mV
    assert np.abs(back.t - raw.t).max() < 1e-15 and back.dt == pytest.approx(DT, rel=1e-12)
    imp = back.meta["provenance"]["import"]
    assert imp["source_sha256"] == file_sha256(src) and imp["map_sha256"] == file_sha256(map_path)
    assert imp["mapping"]["channels"]["y_Ay"]["sign"] == -1 and imp["source_format"] == fmt
    # saved with the existing writer, the provenance survives a load
    save_recording(d / f"imported_{fmt}.csv", back)
    again = load_recording(d / f"imported_{fmt}.csv")
    assert again.meta["provenance"]["import"]["source_sha256"] == imp["source_sha256"]
    assert np.array_equal(again.y, back.y)


def test_the_file_really_holds_volts(case):
    _d, rec = case
    src, _ = _export(case, "csv")
    header = src.read_text().splitlines()[0].split(",")
    col = np.loadtxt(src, delimiter=",", skiprows=1)[:, header.index("AMB1_Y_pos")]
    assert np.allclose(col, -0.05 - 8000.0 * rec.y[:, 1], rtol=0, atol=1e-15)


def test_decimation_trimming_and_offset_removal(case):
    d, rec = case
    m = realistic_channel_map("hdf5", ["eta"], controller="ctrl2.json", speed_rpm=rec.speed_rpm)
    src = export_daq(rec, d / "dec.h5", m)
    ctrl2 = export_controller(reference_controller(load_rig(), 2 * DT), load_rig())
    ctrl2.save(d / "ctrl2.json")
    m["time"].update({"decimate": 2, "start_s": 0.1, "stop_s": 0.9})
    m["channels"]["y_Bx"] = {**m["channels"]["y_Bx"], "remove_offset": True}
    del m["channels"]["y_Bx"]["offset"]
    (d / "dec.toml").write_text(map_to_toml(m))
    back = import_recording(src, d / "dec.toml")
    i0, i1 = 100, 900
    for got, full in ((back.y, rec.y), (back.u, rec.u), (back.excitation["eta"],
                                                          rec.excitation["eta"])):
        seg = np.array(full[i0:i1])
        if full is rec.y:   # y_Bx: its mean over the trimmed record is removed, in SI
            seg[:, 2] -= seg[:, 2].mean()
        want = sig.decimate(seg, 2, n=8, ftype="iir", zero_phase=True, axis=0)
        assert _rel(got, want) < 1e-12
    assert back.dt == pytest.approx(2 * DT) and back.t[0] == pytest.approx(0.1)
    assert back.n_samples == 400
    assert back.meta["provenance"]["import"]["offsets_removed_si"]["y_Bx"] == pytest.approx(
        float(np.mean(rec.y[i0:i1, 2])) + 0.03 / 8000.0, rel=1e-9)


@pytest.fixture(scope="module")
def reference_posterior(case):
    """MAP + Laplace of k_By, c_By from the canonical CSV."""
    return identify(case[1], "k_By,c_By", options=IdentifyOptions(map_only=True)
                    ).parameters


@pytest.mark.parametrize("fmt", ("mat", "mat73", "tdms", "hdf5"))
def test_identification_is_the_same_as_from_the_canonical_csv(case, reference_posterior, fmt):
    _d, _rec = case
    opt = IdentifyOptions(map_only=True)
    ref = reference_posterior
    src, map_path = _export(case, fmt)
    got = identify(import_recording(src, map_path), "k_By,c_By",
                   options=opt).parameters
    for n in ("k_By", "c_By"):
        assert np.isfinite(ref[n].sd) and ref[n].sd > 0
        assert abs(got[n].mean - ref[n].mean) < 0.1 * ref[n].sd
        assert got[n].sd == pytest.approx(ref[n].sd, rel=0.01)
    # and the posterior is about the truth (k_By 0.3, c_By 0.2): within 4 sd
    assert abs(got["k_By"].mean - 0.3) < 4 * got["k_By"].sd


def test_cli_import_writes_the_canonical_recording(case, capsys):
    d, rec = case
    src, map_path = _export(case, "tdms")
    code, out, err = run_cli(["import", str(src), "--map", str(map_path), "-o",
                              str(d / "cli.csv"), "--json"], capsys)
    assert code == 0, err
    res = json.loads(out)
    assert res["samples"] == rec.n_samples and res["source_format"] == "tdms"
    back = load_recording(d / "cli.csv")
    assert _rel(back.y, rec.y) < 1e-13
    assert json.loads((d / "cli.json").read_text())["provenance"]["import"]["map"] == str(map_path)


def _broken(case, fmt, edit_map=None, edit_cols=None):
    d, rec = case
    m = realistic_channel_map(fmt, ["eta"], controller="ctrl.json", speed_rpm=rec.speed_rpm)
    if edit_map:
        edit_map(m)
    src = d / f"bad{SUFFIX[fmt]}"
    export_daq(rec, src, realistic_channel_map(fmt, ["eta"], controller="ctrl.json",
                                               speed_rpm=rec.speed_rpm))
    if edit_cols:
        header, *rows = src.read_text().splitlines()
        names = header.split(",")
        table = np.array([[float(v) for v in r.split(",")] for r in rows])
        header, table = edit_cols(names, table)
        src.write_text("\n".join([",".join(header), *(",".join(map(repr, r)) for r in
                                                      table.tolist())]) + "\n")
    (d / "bad.toml").write_text(map_to_toml(m))
    return src, d / "bad.toml"


def _set(path, value):
    def edit(m):
        node = m
        for k in path[:-1]:
            node = node[k]
        node[path[-1]] = value
    return edit


def _nan_cell(names, table):
    table = table.copy()
    table[17, names.index("I_ref_2")] = np.nan
    return names, table


def _rename(names, table):
    return [("AMB_2_Y_pos" if n == "AMB2_Y_pos" else n) for n in names], table


@pytest.mark.parametrize("edit_map, edit_cols, expected", [
    (None, _rename, r"bad\.csv: channel 'AMB2_Y_pos': not found"),
    (None, _nan_cell, r"bad\.csv: channel 'I_ref_2': sample 17 is not finite \(nan\)"),
    (_set(["time", "sample_rate_hz"], 1010.0), None,
     r"bad\.csv: channel 'time' \(time\): sample_rate_hz = 1010\.0 disagrees"),
    (_set(["channels", "y_Ax", "unit"], "A"), None,
     r"bad\.toml: channel y_Ax: unit 'A' cannot be converted to m"),
    (_set(["channels", "u_Bx", "unit"], "psi"), None,
     r"bad\.toml: channel u_Bx: unit 'psi' cannot be converted to A"),
    (_set(["channels", "y_By", "sensitivity"], -8000.0), None,
     r"bad\.toml: channel y_By: field sensitivity: expected a positive number, got -8000\.0"),
    (_set(["time", "stop_s"], 0.001), None, r"bad\.csv: time: 1 samples remain"),
    (_set(["time", "decimate"], 11), None, r"time\.decimate: 11 has a prime factor above 10"),
    (_set(["recording", "controller"], "nope.json"), None,
     r"bad\.toml: field recording\.controller: .*nope\.json.*not found"),
])
def test_mismatch_is_one_line_naming_file_channel_and_value(case, capsys, edit_map, edit_cols,
                                                            expected):
    src, map_path = _broken(case, "csv", edit_map, edit_cols)
    code, out, err = run_cli(["import", str(src), "--map", str(map_path), "-o",
                              str(src.parent / "never.csv")], capsys)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith("bayes-amb import: error: "), err
    assert re.search(expected, err), err
    assert not (src.parent / "never.csv").exists()


@pytest.mark.parametrize("fmt", ("mat", "mat73", "tdms", "hdf5"))
def test_lengths_that_differ_are_named(case, fmt):
    d, rec = case
    m = realistic_channel_map(fmt, ["eta"], controller="ctrl.json", speed_rpm=rec.speed_rpm)
    cut = make_recording(rec.y[:-1], rec.u[:-1], {"eta": rec.excitation["eta"][:-1]}, DT,
                         rec.controller, speed_rpm=rec.speed_rpm)
    path = export_daq(cut, d / f"len{SUFFIX[fmt]}", m)
    _replace_channel(path, m["channels"]["y_Ax"]["source"], np.zeros(1000), fmt)
    m["time"] = {"sample_rate_hz": 1000.0}
    with pytest.raises(DataImportError, match=r"len\.(mat|tdms|h5): channel '[^']*AMB1_Y_pos'"
                                              r": 999 samples, but channel '[^']*AMB1_X_pos' "
                                              r"\(y_Ax\) has 1000"):
        import_recording(path, m, controller=rec.controller)


def _replace_channel(path, name, values, fmt):
    """Overwrite one channel of a written DAQ file with other values (another length)."""
    import h5py
    import scipy.io
    from nptdms import ChannelObject, TdmsFile, TdmsWriter

    if fmt == "mat":
        data = {k: v for k, v in scipy.io.loadmat(path).items() if not k.startswith("__")}
        data[name] = values.reshape(-1, 1)
        scipy.io.savemat(path, data)
    elif fmt == "tdms":
        f = TdmsFile.read(path)
        chans = [ChannelObject("AMB", c.name, values if f"AMB/{c.name}" == name else c[:])
                 for c in f["AMB"].channels()]
        with TdmsWriter(str(path)) as w:
            w.write_segment(chans)
    else:
        with h5py.File(path, "r+") as f:
            del f[name]
            f.create_dataset(name, data=values.reshape(1, -1) if fmt == "mat73" else values)


def test_tdms_time_base_from_wf_increment_and_mat_struct_paths(case):
    import scipy.io

    d, rec = case
    m = realistic_channel_map("tdms", ["eta"], controller="ctrl.json", speed_rpm=rec.speed_rpm)
    src = export_daq(rec, d / "inc.tdms", m)
    m["time"] = {}                       # no time column, no sample rate: wf_increment
    back = import_recording(src, m, controller=rec.controller)
    assert back.dt == DT and _rel(back.y, rec.y) < 1e-13
    assert back.meta["provenance"]["import"]["sample_time_read_s"] == DT
    # dSPACE-style: the channels inside a struct, addressed as data.NAME
    m5 = realistic_channel_map("mat", ["eta"], controller="ctrl.json", speed_rpm=rec.speed_rpm)
    flat = d / "flat.mat"
    export_daq(rec, flat, m5)
    raw = {k: v for k, v in scipy.io.loadmat(flat).items() if not k.startswith("__")}
    scipy.io.savemat(d / "struct.mat", {"data": raw})
    for c in m5["channels"].values():
        c["source"] = "data." + c["source"]
    m5["time"]["column"] = "data.time"
    back5 = import_recording(d / "struct.mat", m5, controller=rec.controller)
    assert _rel(back5.u, rec.u) < 1e-13
    with pytest.raises(DataImportError, match=r"struct\.mat: channel 'data\.nope': not found"):
        m5["channels"]["u_Ax"]["source"] = "data.nope"
        import_recording(d / "struct.mat", m5, controller=rec.controller)
