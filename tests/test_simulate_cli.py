"""`bayes-amb simulate`: the paper's and a realistic case as one command each, a PID controller
file, byte-for-byte reproducibility, and one-line user errors (exit status 2).

Nothing here is timed: these are behaviour tests, not benchmarks.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.signal as sps

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.control.pid import design_decentralised_pid
from bayes_amb.io.recording import load_recording, load_truth
from bayes_amb.rig import CHANNELS, load_rig
from tests.helpers import run_cli

CONSOLE = Path(sys.executable).with_name("bayes-amb")
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}


def test_paper_case_is_one_command(tmp_path, capsys):
    """The paper's case (reduced truth, k_By = 0.5, 1 kHz, 0.5 s): 500 samples, the observer
    controller's eta group, SI units; the true theta only through load_truth."""
    out_csv = tmp_path / "paper.csv"
    code, out, err = run_cli(["simulate", "--truth", "reduced", "--set", "k_By=0.5", "--dt",
                              "1e-3", "--duration", "0.5", "-o", str(out_csv)], capsys)
    assert (code, err) == (0, "")
    assert "500 samples at dt = 0.001 s" in out
    rec = load_recording(out_csv)
    assert rec.n_samples == 500 and rec.dt == 1e-3
    assert rec.controller.kind == "observer" and list(rec.excitation) == ["eta"]
    assert set(np.unique(rec.excitation["eta"])) == {-0.5, 0.5}     # default 0.5 A binary
    assert "truth" not in rec.meta
    assert np.all(np.std(rec.y, axis=0) > 1e-7)                     # micrometres, not zero
    truth = load_truth(out_csv)
    assert truth["plant"] == "reduced" and truth["params"] == {"k_By": 0.5}
    assert truth["dt"] == 1e-3 and truth["effects"] == []


def test_realistic_case_is_one_command_console_script(tmp_path):
    """Full FE truth at 10 kHz with sensor noise, r1, r2 and an 800 Hz actuator lag, through
    the installed console script: runs, 3000 samples load, truth records every setting."""
    out_csv = tmp_path / "real.csv"
    proc = subprocess.run([str(CONSOLE), "simulate", "--truth", "full", "--dt", "1e-4",
                           "--duration", "0.3", "--noise-rms", "2e-7", "--r1-rms", "1e-7",
                           "--r2-rms", "0.02", "--effect", "actuator_lag:bandwidth_hz=800",
                           "-o", str(out_csv), "--json"],
                          capture_output=True, text=True, env=ENV, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    d = json.loads(proc.stdout)
    assert d["samples"] == 3000 and d["truth"] == "full"
    rec = load_recording(out_csv)
    assert rec.n_samples == 3000 and rec.dt == 1e-4
    truth = load_truth(out_csv)
    assert truth["plant"] == "full"
    assert (truth["noise_rms"], truth["r1_rms"], truth["r2_rms"]) == (2e-7, 1e-7, 0.02)
    assert truth["effects"] == [{"effect": "actuator_lag", "bandwidth_hz": 800.0,
                                 "bearing": "both"}]
    # white sensor noise of 2e-7 m RMS is in y: RMS of the sample-to-sample difference of y
    # > 0.8 sqrt(2) 2e-7 = 2.3e-7 m (measured 3.1e-7 m; 1.4e-7 m with --noise-rms 0)
    dy = np.diff(np.asarray(rec.y), axis=0)
    assert np.all(np.sqrt(np.mean(dy**2, axis=0)) > 0.8 * np.sqrt(2) * 2e-7)


def test_pid_controller_file(tmp_path, capsys):
    """An exported decentralised PID passed with --controller: the excitation is the r2
    group (added to the current), and the recorded u - r2 is the PID's K y (dlsim on the
    controller, relative 1e-9)."""
    rig = load_rig()
    pid = design_decentralised_pid(rig, 1e-4)
    path = tmp_path / "pid.json"
    export_controller(pid, rig).save(path)
    out_csv = tmp_path / "pid_run.csv"
    code, _, err = run_cli(["simulate", "--controller", str(path), "--truth", "full",
                            "--duration", "0.1", "-o", str(out_csv)], capsys)
    assert (code, err) == (0, "")
    header = out_csv.read_text().splitlines()[0].split(",")
    assert header[9:] == [f"r2_{c}" for c in CHANNELS]
    rec = load_recording(out_csv)
    assert rec.controller.kind == "generic" and list(rec.excitation) == ["r2"]
    r2 = np.asarray(rec.excitation["r2"])
    _, Ky, _ = sps.dlsim((*pid.controller_matrices(), 1e-4), np.asarray(rec.y))
    fb = np.asarray(rec.u) - r2
    assert np.max(np.abs(fb - Ky)) < 1e-9 * np.max(np.abs(Ky))
    assert np.max(np.abs(Ky)) > 1e-2                        # the feedback is not negligible


def test_same_seed_same_bytes_cli(tmp_path, capsys):
    """Same command and seed -> byte-identical NAME.csv and NAME.json; --seed 2 differs."""
    base = ["simulate", "--truth", "reduced", "--set", "k_Ay=-0.2", "--dt", "1e-3",
            "--duration", "0.1", "--noise-rms", "1e-7", "--r2-rms", "0.01", "--r2-band-hz",
            "100", "--effect", "unbalance", "--excitation", "multisine"]
    for tag, seed in (("a", "1"), ("b", "1"), ("c", "2")):
        (tmp_path / tag).mkdir()
        code, _, err = run_cli([*base, "--seed", seed, "-o", str(tmp_path / tag / "r.csv")],
                               capsys)
        assert (code, err) == (0, "")

    def read(tag: str) -> tuple[bytes, bytes]:
        return ((tmp_path / tag / "r.csv").read_bytes(), (tmp_path / tag / "r.json").read_bytes())

    assert read("a") == read("b")
    assert read("a")[0] != read("c")[0] and read("a")[1] != read("c")[1]


@pytest.fixture(scope="module")
def controller_1e4(tmp_path_factory):
    """The reference controller exported at dt = 1e-4 s (used with --dt 1e-3)."""
    rig = load_rig()
    path = tmp_path_factory.mktemp("ctl") / "k_1e4.json"
    export_controller(reference_controller(rig, 1e-4), rig).save(path)
    return path


BAD = [
    (["--set", "k_Bz=0.5"], "unknown parameter name 'k_Bz'"),
    (["--set", "k_By=abc"], "option --set: k_By: value 'abc' is not a number"),
    (["--set", "k_By=2"], r"option --set: k_By: value 2 out of range: must be in -0\.95\.\.0\.95$"),
    (["--effect", "wobble"], "unknown effect 'wobble'"),
    (["--effect", "actuator_lag:bw=3"], "effect actuator_lag: unknown parameter 'bw'"),
    (["--effect", "time_delay:delay_s=1"], "delay_s: value 1 out of range"),
    (["--controller", "{missing}"], "controller file .*nope.json.*not found"),
    (["--controller", "{ctl}"], "field dt: 0.0001 s does not match the simulation dt 0.001 s"),
    (["--noise-rms=-1e-7"], "argument --noise-rms: value -1e-07 out of range: must be >= 0 m$"),
    (["--noise-rms", "-1e-7"], "argument --noise-rms: value -1e-07 out of range: must be >= 0 m$"),
    (["--dt", "-1e-3"], "argument --dt: value -0.001 out of range: must be > 0 and <= 0.01 s$"),
    (["--duration", "0"], "argument --duration: value 0 out of range: must be > 0 and <= 600 s$"),
    (["--duration", "1e-3"], "option --duration: 0.001 s is shorter than 2 samples of --dt"),
    (["--amplitude", "0"], "argument --amplitude: value 0 out of range: must be > 0 A$"),
    (["--amplitude", "nan"], "argument --amplitude: value 'nan' is not a finite number$"),
    (["--seed", "-1"], "argument --seed: value -1 out of range: must be in 0..4294967295$"),
    (["--speed-rpm", "1e5"], "option --speed-rpm: value 100000 out of range: must be in "
     "0..63000 rpm$"),
    (["-o", "{missing_dir}/x.csv"], "error: {missing_dir}/x.csv: No such file or directory$"),
    (["--excitation", "prbs", "--band", "10,20"],
     "option --band: only the multisine and random-binary excitations have a band"),
    (["--excitation", "multisine", "--band", "20,10"],
     r"option --band: value 20,10 out of range: must be 0 < LO < HI <= 500 Hz \(Nyquist\)$"),
    (["--excitation", "multisine", "--band", "10"], "option --band: expected LO,HI in Hz"),
]


@pytest.mark.parametrize(("extra", "match"), BAD)
def test_bad_input_one_line_exit_2(extra, match, tmp_path, capsys, controller_1e4):
    import re

    missing_dir = tmp_path / "no_such_dir"
    extra = [e.format(missing=tmp_path / "nope.json", ctl=controller_1e4,
                      missing_dir=missing_dir) for e in extra]
    match = match.format(missing_dir=re.escape(str(missing_dir)))
    out_csv = tmp_path / "x.csv"
    code, out, err = run_cli(["simulate", "--truth", "reduced", "--dt", "1e-3",
                              "--duration", "0.05", "-o", str(out_csv), *extra], capsys)
    assert code == 2 and out == ""
    assert err.endswith("\n") and err.count("\n") == 1
    assert err.startswith("bayes-amb simulate: error: ")
    assert re.search(match, err.rstrip("\n")), err
    assert ".tmp" not in err                    # the user's path, not the atomic temp file
    assert not out_csv.exists() and not out_csv.with_suffix(".json").exists()


def test_bad_input_console_script(tmp_path):
    """Through the installed console script: exit status 2, one stderr line, no traceback."""
    proc = subprocess.run([str(CONSOLE), "simulate", "--truth", "reduced", "--dt", "1e-3",
                           "--effect", "actuator_lag:bandwidth_hz=fast",
                           "-o", str(tmp_path / "x.csv")],
                          capture_output=True, text=True, env=ENV, timeout=60)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr == ("bayes-amb simulate: error: effect actuator_lag: parameter "
                           "bandwidth_hz: expected a number, got 'fast'\n")
