"""`bayes-amb model` and `bayes-amb params`: output contents and one-line user errors."""

from __future__ import annotations

import itertools
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bayes_amb.cli.main import main
from bayes_amb.rig.rig import CHANNELS
from bayes_amb.uncertainty import PARAMETERS
from tests.helpers import run_cli


@pytest.fixture(scope="module")
def model_json():
    """JSON of `bayes-amb model --json` (run once; capsys is function-scoped)."""
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["model", "--json"]) == 0
    return json.loads(out.getvalue())


def test_model_json_keys_and_values(model_json):
    """Reference rig at its nominal 31500 rpm: 40 nodes, 320 states, 4 x 4 channels, 4 RHP
    poles (as [re, im], re > 0), >= 4 ascending bending frequencies, 8 reduced states with
    8 poles, reduction error < 1 dB (measured 0.046 dB)."""
    d = model_json
    for key in ("n_nodes", "n_states", "n_inputs", "n_outputs", "speed_rpm", "unstable_poles",
                "bending_hz", "reduced_states", "reduced_poles", "reduction_error_db"):
        assert key in d, key
    assert (d["n_nodes"], d["n_states"]) == (40, 320)
    assert d["n_inputs"] == d["n_outputs"] == len(CHANNELS) == 4
    assert d["speed_rpm"] == 31500.0
    assert len(d["unstable_poles"]) == 4
    assert all(len(p) == 2 and p[0] > 0 for p in d["unstable_poles"])
    bh = d["bending_hz"]
    assert len(bh) >= 4 and all(b > a for a, b in itertools.pairwise(bh))
    assert d["reduced_states"] == 8 and len(d["reduced_poles"]) == 8
    assert sorted(p[0] > 0 for p in d["reduced_poles"]).count(True) == 4
    assert 0.0 <= d["reduction_error_db"] < 1.0


def test_model_text_summary(capsys):
    code, out, err = run_cli(["model", "--speed-rpm", "15000"], capsys)
    assert code == 0 and err == ""
    assert "Rig 'reference' at 15000 rpm" in out
    assert "320 states" in out and "4 poles in the right half-plane" in out
    assert "reduced model : 8 states" in out


def test_model_speed_option_reaches_the_model(capsys):
    code, out, _ = run_cli(["model", "--json", "--speed-rpm", "0"], capsys)
    assert code == 0
    d = json.loads(out)
    assert d["speed_rpm"] == 0.0 and len(d["unstable_poles"]) == 4


def test_params_json_lists_all_names(capsys):
    code, out, err = run_cli(["params", "--json"], capsys)
    assert code == 0 and err == ""
    rows = json.loads(out)["parameters"]
    assert [r["name"] for r in rows] == list(PARAMETERS)
    assert len(rows) == 12
    units = {r["name"]: r["unit"] for r in rows}
    assert units["k_By"] == "N/m" and units["c_Ax"] == "N s/m" and units["kxy_D1"] == "N/m"


def test_params_text(capsys):
    code, out, _ = run_cli(["params"], capsys)
    assert code == 0
    assert all(name in out for name in PARAMETERS)


MALFORMED = "[shaft\nlength = 0.45\n"


@pytest.mark.parametrize(("argv", "must_contain"), [
    (["model", "--rig", "{tmp}/missing.toml"], ["missing.toml", "not found"]),
    (["model", "--rig", "{tmp}/malformed.toml"], ["malformed.toml", "not valid TOML"]),
    (["model", "--rig", "{tmp}/negative.toml"], ["negative.toml", "shaft.length"]),
    (["params", "--rig", "{tmp}/missing.toml"], ["missing.toml", "not found"]),
    (["model", "--colour", "red"], ["unrecognized arguments: --colour"]),
    (["model", "--speed-rpm", "-5"], ["--speed-rpm", "-5"]),
    (["model", "--speed-rpm", "1e9"], ["--speed-rpm", "out of range: must be in 0..63000 rpm"]),
    (["model", "--speed-rpm", "-1e3"], ["--speed-rpm", "value -1000 out of range"]),
    (["model", "--speed-rpm", "nan"], ["--speed-rpm", "'nan' is not a finite number"]),
    (["model", "--speed-rpm", "fast"], ["--speed-rpm", "'fast' is not a number"]),
    (["frobnicate"], ["invalid choice", "frobnicate"]),
])
def test_user_errors_give_one_line_and_status_2(tmp_path: Path, capsys, argv, must_contain):
    """Bad input exits with status 2 and exactly one line on stderr naming the problem."""
    (tmp_path / "malformed.toml").write_text(MALFORMED, encoding="utf-8")
    from importlib import resources
    ref = resources.files("bayes_amb.rig").joinpath("data/reference.toml").read_text()
    (tmp_path / "negative.toml").write_text(ref.replace("length = 0.450", "length = -1.0"),
                                            encoding="utf-8")
    argv = [a.format(tmp=tmp_path) for a in argv]
    code, out, err = run_cli(argv, capsys)
    assert code == 2
    assert out == ""
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("bayes-amb")
    for text in must_contain:
        assert text in lines[0], lines[0]
    assert "Traceback" not in err


def console_script() -> Path:
    exe = Path(sys.executable).parent / "bayes-amb"
    found = exe if exe.is_file() else shutil.which("bayes-amb")
    if found is None:
        pytest.skip("console script bayes-amb is not installed next to this Python")
    return Path(found)


def test_console_script_runs(tmp_path: Path):
    """The installed `bayes-amb` script: `params --json` succeeds, a missing rig file
    exits 2 with one line and no traceback."""
    exe = console_script()
    ok = subprocess.run([str(exe), "params", "--json"], capture_output=True, text=True,
                        timeout=120, check=False)
    assert ok.returncode == 0, ok.stderr
    assert len(json.loads(ok.stdout)["parameters"]) == 12
    bad = subprocess.run([str(exe), "model", "--rig", str(tmp_path / "none.toml")],
                         capture_output=True, text=True, timeout=120, check=False)
    assert bad.returncode == 2
    assert "Traceback" not in bad.stderr
    assert len(bad.stderr.splitlines()) == 1 and "none.toml" in bad.stderr
