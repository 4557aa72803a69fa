"""A rig engineer's own rotor, controller and DAQ file, end to end through the CLI.

As README.md and docs/your_rig.md describe it, with nothing from the reference rig: a rig
file written here (0.5 m x 50 mm shaft, 26 nodes, overhung discs at nodes 2 and 25,
bearings at nodes 6 and 20, probes outboard at 5 and 21, 18000 rpm; 208 states), a
continuous decentralised PID saved by scipy.io.savemat as MATLAB would (u = -C(s) y),
imported with `import-controller`; records simulated with the excitation added to the coil
current (`--port r2`, so u_* includes it), written as a .mat DAQ file in volts (8 V/mm
probes with offsets, the Ay probe inverted, currents at 0.5 A/V with offsets, excitation in
mA), imported through a channel map that names the rig file and the MATLAB controller;
then `identify` (all eight bearing coefficients, MAP + Laplace: `--map-only`, to stay
fast), `diagnose`, `answers` and `report`, each with `--rig`.

The effect-free record passes every data check (the controller check included: r2 is in
u and in the documented controller's output) and names no physics; a second record with a
hidden 600 Hz actuator lag has it named.
"""

from __future__ import annotations

import json

import pytest
import scipy.io

from bayes_amb.control.pid import PIDSettings, continuous_pid, pid_gains
from bayes_amb.discrepancy.library import BEARING_COEFFICIENTS
from bayes_amb.io.channel_map import map_to_toml
from bayes_amb.io.daq_export import export_daq, realistic_channel_map
from bayes_amb.io.recording import load_recording
from bayes_amb.rig import load_rig
from bayes_amb.rotor import full_model
from tests.helpers import run_cli

RIG_TOML = """\
name = "e2e_rotor"
description = "a test rotor unlike the reference and small_rotor"
[shaft]
youngs_modulus = 2.0e11
density = 7900.0
poisson = 0.3
diameter = 0.05
length = 0.5
n_nodes = 26
[[discs]]
name = "D1"
node = 2
mass = 2.0
ip = 0.004
id = 0.0025
[[discs]]
name = "D2"
node = 25
mass = 1.2
ip = 0.0018
id = 0.0011
[bearings]
ki = 90.0
ks = 2.5e5
A = { node = 6 }
B = { node = 20 }
[sensors]
A = { node = 5 }
B = { node = 21 }
[damping]
first_mode_zeta = 0.004
[operation]
nominal_speed_rpm = 18000.0
[uncertainty]
c_ref = 800.0
k_ref = 5.0e4
"""
DT = 1e-4
PARAMS = ",".join(BEARING_COEFFICIENTS)


def _ok(argv, capsys):
    code, out, err = run_cli(argv, capsys)
    assert code == 0, (argv[0], err)
    return out


@pytest.fixture(scope="module")
def own(tmp_path_factory):
    d = tmp_path_factory.mktemp("own_rig")
    (d / "my_rig.toml").write_text(RIG_TOML)
    rig = load_rig(d / "my_rig.toml")
    A, B, C, D = continuous_pid(pid_gains(rig, PIDSettings()))
    scipy.io.savemat(d / "K.mat", {"A": A, "B": B, "C": -C, "D": -D, "Ts": 0.0})
    return d, rig


def _record(d, capsys, name, seed, effect=None):
    """simulate -> .mat DAQ file in volts -> channel map -> import; the imported CSV."""
    sim = d / f"sim_{name}.csv"
    argv = ["simulate", "--rig", str(d / "my_rig.toml"), "--controller", str(d / "ctrl.json"),
            "--port", "r2", "--truth", "reduced", "--set", "k_By=0.3", "--set", "c_Ax=0.2",
            "--noise-rms", "1e-7", "--r2-rms", "0.01", "--dt", str(DT), "--duration", "0.5",
            "--seed", str(seed), "-o", str(sim)]
    _ok(argv + (["--effect", effect] if effect else []), capsys)
    rec = load_recording(sim)
    assert list(rec.excitation) == ["r2"]
    m = realistic_channel_map("mat", ["r2"], controller="K.mat", speed_rpm=rec.speed_rpm,
                              rig="my_rig.toml")
    m["recording"].update(controller_method="tustin", controller_feedback="negative")
    (d / f"{name}.toml").write_text(map_to_toml(m))
    export_daq(rec, d / f"{name}.mat", m)
    out = d / f"{name}.csv"
    _ok(["import", str(d / f"{name}.mat"), "--map", str(d / f"{name}.toml"), "-o", str(out)],
        capsys)
    return out


def _diagnose(d, capsys, rec, run):
    _ok(["identify", str(rec), "--params", PARAMS, "--map-only", "--rig",
         str(d / "my_rig.toml"), "--out", str(run), "--json"], capsys)
    out = _ok(["diagnose", str(rec), "--params", PARAMS, "--effects",
               "actuator_lag,time_delay", "--max-effects", "1", "--rig",
               str(d / "my_rig.toml"), "--out", str(run), "--json"], capsys)
    return json.loads(out)


def test_own_rig_controller_and_daq_file_end_to_end(own, capsys):
    d, rig = own
    assert full_model(rig).n_states == 208
    out = _ok(["import-controller", str(d / "K.mat"), "--rig", str(d / "my_rig.toml"),
               "--dt", str(DT), "--method", "tustin", "-o", str(d / "ctrl.json"), "--json"],
              capsys)
    assert json.loads(out)["iso14839_zone"] in ("A", "B")

    # an effect-free record: every data check passes, no physics is named
    clean = _record(d, capsys, "clean", seed=3)
    rec = load_recording(clean)
    assert rec.rig.name == "e2e_rotor" and rec.controller.kind == "generic"
    rep = _diagnose(d, capsys, clean, d / "run_clean")
    checks = {c["check"]: c for c in rep["checks"]}
    assert all(c["ok"] for c in checks.values()), [c["line"] for c in checks.values()]
    assert "r2 on Ax,Ay,Bx,By" in checks["excitation"]["line"]
    assert rep["explanations"] == []
    summary = json.loads((d / "run_clean" / "summary.json").read_text())
    assert summary["parameters_estimated"] == list(BEARING_COEFFICIENTS)
    k = summary["parameters"]["k_By"]
    assert abs(k["mean"] - 0.3) < 4 * k["sd"], k

    # a hidden actuator lag is named
    lag = _record(d, capsys, "lag", seed=4, effect="actuator_lag:bandwidth_hz=600")
    rep = _diagnose(d, capsys, lag, d / "run_lag")
    assert not [c for c in rep["checks"] if not c["ok"]]
    assert [e["effect"] for e in rep["explanations"]] == ["actuator_lag"]

    # the engineering answers and the report of that run, with the rig checked
    out = _ok(["answers", str(d / "run_lag"), "--draws", "8", "--model", "reduced", "--rig",
               str(d / "my_rig.toml"), "--json"], capsys)
    assert json.loads(out)["quantities"]
    out = _ok(["report", str(d / "run_lag"), "--no-pdf", "--rig", str(d / "my_rig.toml"),
               "--json"], capsys)
    html = (d / "run_lag" / "report.html").read_text()
    assert "208-state FE plant of rig &#39;e2e_rotor&#39;" in html
    assert "320-state" not in html
