"""Import of a MATLAB-style controller: state space or transfer functions, continuous or
discrete; it must stabilise the rig, and identification through it covers the truth."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from bayes_amb.control.discrete import ss_freqresp
from bayes_amb.control.pid import PIDSettings, continuous_pid, design_decentralised_pid, pid_gains
from bayes_amb.errors import DataImportError
from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.io import load_controller
from bayes_amb.io.controller_import import import_controller
from bayes_amb.io.daq_export import write_mat
from bayes_amb.rig import CHANNELS, load_rig
from bayes_amb.simulate import SimulationConfig, simulate_recording
from tests.helpers import run_cli

DT = 1e-4


@pytest.fixture(scope="module")
def pid():
    return design_decentralised_pid(load_rig(), DT)


def _matlab_pid_continuous():
    """The PID as a MATLAB user documents it: C(s) with u = -C(s) y (negative feedback)."""
    A, B, C, D = continuous_pid(pid_gains(load_rig(), PIDSettings()))
    return A, B, -C, -D


def test_continuous_state_space_tustin_gives_the_designed_pid(tmp_path, pid):
    A, B, C, D = _matlab_pid_continuous()
    write_mat(tmp_path / "K.mat", {"A": A, "B": B, "C": C, "D": D, "Ts": 0.0})
    imp = import_controller(tmp_path / "K.mat", dt=DT, method="tustin")
    K = imp.controller
    # the same Tustin discretisation of the same realisation as design_decentralised_pid
    for got, want in ((K.A, pid.A), (K.B[:, :4], pid.B), (K.C[:4], pid.C), (K.D[:4, :4], pid.D)):
        assert np.allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    assert K.kind == "generic" and np.array_equal(K.D[:4, 4:], np.eye(4))
    assert not K.has_innovation
    # reference figures (pid.py docstring): spectral radius 0.99819, peaks 3.8-3.9 dB, zone A
    assert imp.spectral_radius == pytest.approx(0.99819, abs=2e-5)
    assert imp.zone == "A" and all(3.6 < v < 4.1 for v in imp.sensitivity_peak_db.values())
    assert "tustin" in imp.discretisation and K.design["feedback"] == "negative"


@pytest.mark.parametrize("v73", [False, True])
def test_discrete_state_space_and_matlab_v73_layout(tmp_path, pid, v73):
    write_mat(tmp_path / "Kd.mat", {"A": pid.A, "B": pid.B, "C": -pid.C, "D": -pid.D,
                                    "Ts": DT}, v73=v73)
    K = import_controller(tmp_path / "Kd.mat").controller
    assert K.dt == DT and np.allclose(K.A, pid.A, rtol=0, atol=1e-15)   # not transposed
    assert np.allclose(K.C[:4], pid.C, rtol=0, atol=1e-12)


def test_transfer_functions_per_axis_match_the_state_space(tmp_path, pid):
    g = pid_gains(load_rig(), PIDSettings())
    tf = {}
    for ch in CHANNELS:   # C(s) = kp + kI/(s + wI) + kd wd s/(s + wd), over a common den
        k = g[ch]
        den = np.polymul([1, k.w_I], [1, k.w_d])
        num = np.polyadd(np.polyadd(k.kp * den, k.kI * np.array([1, k.w_d])),
                         k.kd * k.w_d * np.polymul([1, 0], [1, k.w_I]))
        tf[f"num_{ch}"], tf[f"den_{ch}"] = num, den
    write_mat(tmp_path / "Ktf.mat", {**tf, "Ts": 0.0})
    imp = import_controller(tmp_path / "Ktf.mat", dt=DT, method="tustin")
    z = np.exp(1j * 2 * np.pi * np.array([1.0, 50.0, 500.0, 3000.0]) * DT)
    K = imp.controller
    got = ss_freqresp(K.A, K.B[:, :4], K.C[:4], K.D[:4, :4], z)
    want = ss_freqresp(pid.A, pid.B, pid.C, pid.D, z)
    assert np.max(np.abs(got - want) / np.abs(want).max(axis=(1, 2))[:, None, None]) < 1e-9
    assert imp.form == "transfer functions"


def test_zoh_and_prewarp_are_stated_and_stabilise(tmp_path):
    A, B, C, D = _matlab_pid_continuous()
    write_mat(tmp_path / "K.mat", {"A": A, "B": B, "C": C, "D": D, "Ts": 0.0})
    zoh = import_controller(tmp_path / "K.mat", dt=DT, method="zoh")
    pre = import_controller(tmp_path / "K.mat", dt=DT, prewarp_hz=1000.0)
    assert zoh.spectral_radius < 1 and pre.spectral_radius < 1
    assert zoh.discretisation.startswith("zoh") and "prewarped at 1000 Hz" in pre.discretisation
    # prewarping matches the continuous response exactly at 1 kHz (axis Ax)
    w = 2 * np.pi * 1000.0
    cont = (C @ np.linalg.solve(1j * w * np.eye(A.shape[0]) - A, B) + D)[0, 0]
    Kp = pre.controller
    disc = ss_freqresp(Kp.A, Kp.B[:, :4], Kp.C[:4], Kp.D[:4, :4],
                       np.array([np.exp(1j * w * DT)]))[0, 0, 0]
    assert disc == pytest.approx(-cont, rel=1e-9)


@pytest.mark.parametrize("edit, match", [
    (lambda v: v.update(C=-v["C"], D=-v["D"]), r"does not stabilise rig 'reference' at 31500 "
                                               r"rpm: closed-loop spectral radius .*; least "
                                               r"stable closed-loop pole at \d+ Hz"),
    (lambda v: v.update(Ts=2e-4), r"variable Ts: 0\.0002 s but the sample time is 0\.0001 s"),
    (lambda v: v.update(B=v["B"][:, :3]), r"variable B: expected shape \(8, 4\), got \(8, 3\)"),
    (lambda v: v.pop("Ts"), r"variable Ts: missing"),
    (lambda v: v.update(D=np.full((4, 4), np.nan)), r"variable D: contains NaN or inf"),
])
def test_bad_controllers_are_one_line(tmp_path, capsys, edit, match):
    A, B, C, D = _matlab_pid_continuous()
    v = {"A": A, "B": B, "C": C, "D": D, "Ts": 0.0}
    edit(v)
    write_mat(tmp_path / "K.mat", v)
    code, _, err = run_cli(["import-controller", str(tmp_path / "K.mat"), "--dt", str(DT),
                            "-o", str(tmp_path / "k.json")], capsys)
    assert code == 2 and err.count("\n") == 1 and "K.mat" in err, err
    assert re.search(match, err), err
    assert not (tmp_path / "k.json").exists()


def test_identification_through_the_imported_controller_covers_the_truth(tmp_path, capsys):
    A, B, C, D = _matlab_pid_continuous()
    write_mat(tmp_path / "K.mat", {"A": A, "B": B, "C": C, "D": D, "Ts": 0.0})
    code, out, err = run_cli(["import-controller", str(tmp_path / "K.mat"), "--dt", str(DT),
                              "--method", "tustin", "-o", str(tmp_path / "k.json"), "--json"],
                             capsys)
    assert code == 0, err
    assert json.loads(out)["iso14839_zone"] == "A"
    ctrl = load_controller(tmp_path / "k.json")
    truth = {"k_By": 0.3, "c_By": 0.2}
    rec, _ = simulate_recording(load_rig(), ctrl, SimulationConfig(
        truth="reduced", params=truth, dt=DT, duration=0.4, noise_rms=1e-7, seed=2))
    assert list(rec.excitation) == ["r2"]
    res = identify(rec, "k_By,c_By", options=IdentifyOptions(map_only=True))
    for n, v in truth.items():
        p = res.parameters[n]
        assert p.sd > 0 and abs(p.mean - v) < 3.0 * p.sd, (n, p)
    assert res.excitation_port != "eta"


def test_a_channel_map_can_name_the_matlab_controller(tmp_path, pid):
    from bayes_amb.io.channel_map import map_to_toml
    from bayes_amb.io.daq import file_sha256
    from bayes_amb.io.daq_export import export_daq, realistic_channel_map
    from bayes_amb.io.daq_import import import_recording

    A, B, C, D = _matlab_pid_continuous()
    write_mat(tmp_path / "K.mat", {"A": A, "B": B, "C": C, "D": D, "Ts": 0.0}, v73=True)
    ctrl = import_controller(tmp_path / "K.mat", dt=DT).controller
    rec, _ = simulate_recording(load_rig(), ctrl, SimulationConfig(
        truth="reduced", dt=DT, duration=0.05, seed=1))
    m = realistic_channel_map("hdf5", ["r2"], controller="K.mat", speed_rpm=rec.speed_rpm)
    m["recording"].update(controller_method="tustin", controller_feedback="negative")
    (tmp_path / "map.toml").write_text(map_to_toml(m))
    back = import_recording(export_daq(rec, tmp_path / "daq.h5", m), tmp_path / "map.toml")
    assert np.array_equal(back.controller.D, ctrl.D) and back.controller.kind == "generic"
    imp = back.meta["provenance"]["import"]
    assert imp["controller_sha256"] == file_sha256(tmp_path / "K.mat")
    # the options apply only to a .mat controller
    m["recording"]["controller"] = "ctrl.json"
    (tmp_path / "map.toml").write_text(map_to_toml(m))
    with pytest.raises(DataImportError, match=r"field recording\.controller_method: applies "
                                              r"only to a controller given as a MATLAB"):
        import_recording(tmp_path / "daq.h5", tmp_path / "map.toml")


def test_an_unstable_bending_mode_is_named(tmp_path):
    """Issue 28: a ROSS shaft without material damping (first_mode_zeta 0) let the PID
    destabilise a bending pair, and the refusal gave only the spectral radius. It now names
    the least stable pole and the lightly damped open-loop mode beside it."""
    from bayes_amb.rig import rig_from_dict

    d = load_rig().to_dict()
    d["damping"]["first_mode_zeta"] = 0.0
    rig = rig_from_dict(d, source="undamped")
    A, B, C, D = _matlab_pid_continuous()
    write_mat(tmp_path / "K.mat", {"A": A, "B": B, "C": C, "D": D, "Ts": 0.0})
    with pytest.raises(DataImportError, match=r"spectral radius 1\.00\d+ .*least stable "
                       r"closed-loop pole at 310\d Hz .*next to the open-loop mode at 3095 Hz "
                       r"\(damping ratio .*\): a bending mode the controller destabilises"):
        import_controller(tmp_path / "K.mat", rig, dt=DT)
