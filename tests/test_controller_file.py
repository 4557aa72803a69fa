"""Unit tests of the controller file format (bayes_amb.io.controller_file)."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from bayes_amb.errors import ControllerError
from bayes_amb.io import (
    CONTROLLER_FORMAT,
    CONTROLLER_INPUTS,
    CONTROLLER_OUTPUTS,
    ControllerFile,
    check_fits_rig,
    load_controller,
)
from bayes_amb.rig import load_rig


def controller_dict(n: int = 2, seed: int = 0, dt: float = 1e-4) -> dict:
    """A valid observer-form controller dict: n states, A Schur-stable (spectral radius 0.6)."""
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(n, n))
    if n:
        a *= 0.6 / max(abs(np.linalg.eigvals(a)))
    return {
        "format": CONTROLLER_FORMAT, "kind": "observer", "dt": dt,
        "inputs": list(CONTROLLER_INPUTS), "outputs": list(CONTROLLER_OUTPUTS),
        "A": a.tolist(), "B": rng.normal(size=(n, 8)).tolist(),
        "C": rng.normal(size=(8, n)).tolist() if n else [[] for _ in range(8)],
        "D": rng.normal(size=(8, 8)).tolist(), "rig": "reference",
        "design": {"method": "test", "poles": [0.5, 0.6]},
    }


def test_round_trip_dict_file_and_bytes(tmp_path):
    d = controller_dict()
    k = load_controller(d)
    assert k.to_dict() == d
    k.save(tmp_path / "a.json")
    k2 = load_controller(tmp_path / "a.json")
    for name in "ABCD":
        assert np.array_equal(getattr(k, name), getattr(k2, name))
    assert k2.dt == k.dt and k2.design == d["design"] and k2.kind == "observer"
    k2.save(tmp_path / "b.json")
    assert (tmp_path / "a.json").read_bytes() == (tmp_path / "b.json").read_bytes()
    assert k2.source == str(tmp_path / "a.json")


def test_zero_states_and_generic_pid_without_innovation():
    d = controller_dict(n=0)
    d["kind"] = "generic"
    # decentralised proportional controller u = -kp y; eps rows all zero
    dmat = np.zeros((8, 8))
    dmat[:4, :4] = -2.0e3 * np.eye(4)
    d["D"] = dmat.tolist()
    k = load_controller(d)
    assert k.n_states == 0 and k.B.shape == (0, 8) and k.C.shape == (8, 0)
    assert not k.has_innovation
    check_fits_rig(k)
    assert load_controller(controller_dict()).has_innovation


def test_embedded_rig_dict_accepted():
    d = controller_dict()
    d["rig"] = load_rig().to_dict()
    assert load_controller(d).rig["name"] == "reference"


def test_arrays_are_read_only():
    k = load_controller(controller_dict())
    with pytest.raises(ValueError, match="read-only"):
        k.A[0, 0] = 1.0


def _set(path: str, value):
    def mutate(d: dict) -> None:
        keys = path.split(".")
        target = d
        for key in keys[:-1]:
            target = target[key]
        target[keys[-1]] = value
    return mutate


def _delete(key: str):
    def mutate(d: dict) -> None:
        del d[key]
    return mutate


BAD = [
    (_delete("format"), r"field format: missing"),
    (_set("format", "bayes-amb-controller/2"), r"field format: unsupported format "
                                               r"'bayes-amb-controller/2'"),
    (_set("bogus", 1), r"field bogus: unknown key"),
    (_delete("A"), r"field A: missing"),
    (_delete("kind"), r"field kind: missing"),
    (_delete("rig"), r"field rig: missing"),
    (_set("dt", 0.0), r"field dt: expected a positive sample time in s, got 0.0"),
    (_set("dt", -1e-4), r"field dt: .* got -0.0001"),
    (_set("dt", "1e-4"), r"field dt: .* got '1e-4'"),
    (_set("dt", True), r"field dt: .* got True"),
    ((lambda d: [r.pop() for r in d["B"]]), r"field B: expected 8 columns \(one per "
                                                 r"input\), got 7"),
    ((lambda d: d["B"].append([0.0] * 8)), r"field B: expected 2 rows \(one per state\), "
                                                r"got 3"),
    ((lambda d: d["C"].pop()), r"field C: expected 8 rows \(one per output\), got 7"),
    ((lambda d: d["C"][3].append(1.0)), r"field C: expected 2 columns"),
    ((lambda d: d["D"][5].pop()), r"field D: expected 8 columns"),
    ((lambda d: [r.append(0.0) for r in d["A"]]), r"field A: expected a square matrix"),
    ((lambda d: d["A"][1].append(0.0)), r"field A: row 1 has 3 entries, row 0 has 2"),
    (_set("A", "eye(2)"), r"field A: expected a list of rows, got 'eye\(2\)'"),
    ((lambda d: d["B"].__setitem__(1, 3.0)), r"field B\[1\]: expected a list of numbers"),
    ((lambda d: d["A"][0].__setitem__(1, "x")), r"field A\[0\]\[1\]: expected a finite "
                                                     r"number, got 'x'"),
    ((lambda d: d["D"][2].__setitem__(3, math.nan)), r"field D\[2\]\[3\]: .* got nan"),
    ((lambda d: d["C"][7].__setitem__(0, math.inf)), r"field C\[7\]\[0\]: .* got inf"),
    ((lambda d: d["B"][0].__setitem__(0, None)), r"field B\[0\]\[0\]: .* got None"),
    ((lambda d: d["B"][0].__setitem__(0, False)), r"field B\[0\]\[0\]: .* got False"),
    ((lambda d: d["inputs"].reverse()), r"field inputs: expected \['y_Ax'"),
    ((lambda d: d["outputs"].pop()), r"field outputs: expected"),
    (_set("inputs", "y,eta"), r"field inputs: expected"),
    (_set("kind", "lqg"), r"field kind: expected one of \['observer', 'generic'\], got 'lqg'"),
    (_set("design", [1, 2]), r"field design: expected a JSON object, got \[1, 2\]"),
    (_set("rig", ""), r"field rig: expected a rig name or a rig object, got ''"),
    (_set("rig", 3), r"field rig: expected a rig name or a rig object, got 3"),
    (_set("rig", {"name": "x"}), r"field rig: rig file .*: field shaft: missing"),
]


@pytest.mark.parametrize(("mutate", "match"), BAD, ids=[m for _, m in BAD])
def test_malformed_controller_dict_raises(mutate, match):
    d = controller_dict()
    mutate(d)
    with pytest.raises(ControllerError, match=r"^controller file <dict>: " + match) as info:
        load_controller(d)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(("mutate", "match"), BAD[:8], ids=[m for _, m in BAD[:8]])
def test_malformed_controller_file_names_the_file(tmp_path, mutate, match):
    d = controller_dict()
    mutate(d)
    p = tmp_path / "ctl.json"
    p.write_text(json.dumps(d))
    before = (p.read_bytes(), p.stat().st_mtime_ns)
    with pytest.raises(ControllerError, match=r"^controller file .*ctl\.json: " + match):
        load_controller(p)
    assert (p.read_bytes(), p.stat().st_mtime_ns) == before


@pytest.mark.parametrize(("text", "match"), [
    ("", r"field <json>: not valid JSON"),
    ('{"format": "bayes-amb-controller/1", "dt": NaN}', r"field <json>: not valid JSON "
                                                        r"\(non-finite number NaN"),
    ('{"dt": 1e999}', r"field <json>: not valid JSON \(number 1e999 overflows"),
    ("[1, 2]", r"field <top>: expected a JSON object, got list"),
    ('{"format": ', r"field <json>: not valid JSON"),
])
def test_bad_json_text(tmp_path, text, match):
    p = tmp_path / "ctl.json"
    p.write_text(text)
    with pytest.raises(ControllerError, match=r"^controller file .*ctl\.json: " + match):
        load_controller(p)


def test_missing_and_non_utf8_file(tmp_path):
    with pytest.raises(ControllerError, match=r"nope\.json: field <file>: not found"):
        load_controller(tmp_path / "nope.json")
    p = tmp_path / "ctl.json"
    p.write_bytes(b'{"format": "\xff"}')
    with pytest.raises(ControllerError, match=r"field <json>: not UTF-8"):
        load_controller(p)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"A": np.zeros((2, 3))}, r"field A: expected shape \(2, 2\), got \(2, 3\)"),
    ({"B": np.zeros((2, 7))}, r"field B: expected shape \(2, 8\), got \(2, 7\)"),
    ({"D": np.full((8, 8), np.nan)}, r"field D: contains NaN or inf"),
    ({"D": np.zeros(8)}, r"field D: expected a 2-D real array"),
    ({"dt": 0.0}, r"field dt: expected a positive finite sample time"),
    ({"kind": "pid"}, r"field kind"),
    ({"inputs": ("y_Ax",)}, r"field inputs"),
    ({"rig": None}, r"field rig"),
    ({"design": "x"}, r"field design"),
])
def test_direct_construction_is_validated(kwargs, match):
    base = {"dt": 1e-4, "A": np.zeros((2, 2)), "B": np.zeros((2, 8)), "C": np.zeros((8, 2)),
            "D": np.zeros((8, 8))}
    with pytest.raises(ControllerError, match=r"^controller <memory>: " + match):
        ControllerFile(**{**base, **kwargs})


def test_check_fits_rig_rejects_other_channel_counts():
    k = load_controller(controller_dict())
    check_fits_rig(k, 4, 4)
    with pytest.raises(ControllerError, match=r"does not fit a rig with 4 inputs and 3 outputs: "
                                              r"it has 4 y inputs \(expected 3\)"):
        check_fits_rig(k, n_inputs=4, n_outputs=3)
    with pytest.raises(ControllerError, match=r"it has 4 eta inputs \(expected 2\)"):
        check_fits_rig(k, n_inputs=2, n_outputs=4)


def test_save_refuses_non_json_design_and_leaves_no_file(tmp_path):
    d = copy.deepcopy(controller_dict())
    k = load_controller(d)
    bad = ControllerFile(dt=k.dt, A=k.A, B=k.B, C=k.C, D=k.D, design={"x": math.nan})
    with pytest.raises(ControllerError, match=r"field design: cannot be written as JSON"):
        bad.save(tmp_path / "k.json")
    assert list(tmp_path.iterdir()) == []
