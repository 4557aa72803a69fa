"""Rig files: the reference rig and every kind of bad input (unit tests, exact checks)."""

from __future__ import annotations

import copy
import dataclasses
import re
import tomllib
from importlib import resources
from pathlib import Path

import pytest

from bayes_amb.errors import RigError
from bayes_amb.rig import load_rig, rig_from_dict

REFERENCE_TEXT = resources.files("bayes_amb.rig").joinpath("data/reference.toml").read_text()


def reference_dict() -> dict:
    return tomllib.loads(REFERENCE_TEXT)


def test_reference_rig_loads_with_documented_values():
    """Reference: bayes_amb/rig/data/reference.toml (exact values, no tolerance)."""
    rig = load_rig()
    assert rig.name == "reference"
    assert rig.n_nodes == 40
    assert rig.shaft.length == 0.450 and rig.shaft.diameter == 0.090
    assert rig.bearing_nodes == {"A": 8, "B": 33}
    assert rig.sensor_nodes == {"A": 6, "B": 35}
    assert [(d.name, d.node, d.mass) for d in rig.discs] == [("D1", 1, 6.0), ("D2", 40, 5.0)]
    assert (rig.ki, rig.ks, rig.nominal_speed_rpm) == (250.0, 1.0e6, 31500.0)
    assert load_rig("reference") == rig


def test_to_dict_round_trips():
    """Identity: rig_from_dict(rig.to_dict()) reproduces the rig exactly."""
    rig = load_rig()
    again = rig_from_dict(rig.to_dict(), source="reference")
    assert again == rig
    assert dataclasses.replace(again, source="x") != rig


def _set(d: dict, path: str, value):
    """Set (or delete, value=...) a nested key given as 'a.b' or 'discs.0.mass'."""
    *head, last = path.split(".")
    for k in head:
        d = d[int(k)] if k.isdigit() else d[k]
    if value is ...:
        del d[last]
    else:
        d[last] = value


BAD_DICTS = [
    # (path to change, new value or ... to delete, field named in the message)
    ("shaft.length", ..., "shaft.length"),
    ("bearings", ..., "bearings"),
    ("sensors.B", ..., "sensors.B"),
    ("bearings.ki", ..., "bearings.ki"),
    ("shaft.length", 0.0, "shaft.length"),
    ("shaft.length", -0.45, "shaft.length"),
    ("shaft.diameter", 0.0, "shaft.diameter"),
    ("shaft.diameter", -0.09, "shaft.diameter"),
    ("shaft.density", -7810.0, "shaft.density"),
    ("discs.0.mass", 0.0, "discs[0].mass"),
    ("discs.1.mass", -5.0, "discs[1].mass"),
    ("discs.0.ip", -0.01, "discs[0].ip"),
    ("discs.0.node", 41, "discs[0].node"),
    ("discs.1.node", 0, "discs[1].node"),
    ("bearings.A.node", 0, "bearings.A.node"),
    ("sensors.B.node", 99, "sensors.B.node"),
    ("bearings.B.node", 8, "bearings.B.node"),
    ("colour", "red", "colour"),
    ("shaft.colour", "red", "shaft.colour"),
    ("discs.1.radius", 0.1, "discs[1].radius"),
    ("bearings.A.gap", 1e-3, "bearings.A.gap"),
    ("uncertainty.q_ref", 1.0, "uncertainty.q_ref"),
    ("shaft.density", "steel", "shaft.density"),
    ("bearings.ks", "1e6", "bearings.ks"),
    ("shaft.length", float("nan"), "shaft.length"),
    ("bearings.ks", True, "bearings.ks"),
    ("discs.0.mass", False, "discs[0].mass"),
    ("shaft.n_nodes", True, "shaft.n_nodes"),
    ("shaft.n_nodes", 1, "shaft.n_nodes"),
    ("shaft.n_nodes", 40.0, "shaft.n_nodes"),
    ("shaft.poisson", 0.5, "shaft.poisson"),
    ("damping.first_mode_zeta", 1.5, "damping.first_mode_zeta"),
    ("discs.0.node", 1.0, "discs[0].node"),
    ("shaft", [1, 2], "shaft"),
    ("discs", {"name": "D1"}, "discs"),
    ("name", "", "name"),
]


@pytest.mark.parametrize(("path", "value", "field"), BAD_DICTS,
                         ids=[f"{p}={v!r}" for p, v, _ in BAD_DICTS])
def test_bad_rig_dict_raises_naming_the_field(path, value, field):
    """Each bad rig dict raises RigError whose message names the source and the field."""
    data = copy.deepcopy(reference_dict())
    _set(data, path, value)
    with pytest.raises(RigError, match=rf"rig file bad\.toml: field {re.escape(field)}:"):
        rig_from_dict(data, source="bad.toml")


def test_rig_error_is_a_value_error():
    with pytest.raises(ValueError, match=r"shaft\.length"):
        rig_from_dict({**reference_dict(), "shaft": {**reference_dict()["shaft"],
                                                     "length": -1.0}})


BAD_FILES = [
    # (text replacement in the reference file, field named in the message)
    (("length = 0.450", "length = -0.450"), "shaft.length"),
    (("mass = 6.0", "mass = 0"), "discs[0].mass"),
    (("node = 40", "node = 41"), "discs[1].node"),
    (("ks = 1.0e6", "ks = true"), "bearings.ks"),
    (("[bearings]", "[bearings]\nbias = 1.0"), "bearings.bias"),
    (("[shaft]", "[shaft\n"), "<toml>"),
    (("density = 7810.0", "density = "), "<toml>"),
]


@pytest.mark.parametrize(("change", "field"), BAD_FILES, ids=[f for _, f in BAD_FILES])
def test_bad_rig_file_raises_naming_file_and_field(tmp_path: Path, change, field):
    """A bad TOML file raises RigError naming the file path and the field."""
    old, new = change
    assert old in REFERENCE_TEXT
    path = tmp_path / "my_rig.toml"
    path.write_text(REFERENCE_TEXT.replace(old, new, 1), encoding="utf-8")
    with pytest.raises(RigError, match=rf"{re.escape(str(path))}: field {re.escape(field)}"):
        load_rig(path)


def test_invalid_toml_says_so(tmp_path: Path):
    path = tmp_path / "broken.toml"
    path.write_text("[shaft\nlength = ", encoding="utf-8")
    with pytest.raises(RigError, match=r"broken\.toml: field <toml>: not valid TOML"):
        load_rig(path)


def test_non_utf8_file_is_a_rig_error(tmp_path: Path):
    path = tmp_path / "latin1.toml"
    path.write_bytes(b'name = "r\xe9f"\n')
    with pytest.raises(RigError, match="not valid TOML"):
        load_rig(path)


def test_missing_file(tmp_path: Path):
    path = tmp_path / "nowhere.toml"
    with pytest.raises(RigError, match=r"nowhere\.toml: field <file>: not found"):
        load_rig(path)


def test_directory_is_not_a_rig_file(tmp_path: Path):
    with pytest.raises(RigError, match="not found"):
        load_rig(tmp_path)


def test_valid_file_round_trip(tmp_path: Path):
    """The unchanged reference text loaded from disk gives the reference rig (bar source)."""
    path = tmp_path / "copy.toml"
    path.write_text(REFERENCE_TEXT, encoding="utf-8")
    rig = load_rig(path)
    assert rig.source == str(path)
    assert dataclasses.replace(rig, source="reference") == load_rig()


SEAL = {"name": "seal", "node": 20, "kxx": 2e5, "kxy": 5e4, "kyx": -5e4, "kyy": 2e5,
        "cxx": 150.0, "cyy": 150.0, "mxx": 0.1, "myy": 0.1}


@pytest.mark.parametrize(("entry", "field"), [
    ({**SEAL, "kxx": "stiff"}, "supports[0].kxx"),
    ({**SEAL, "cxy": float("inf")}, "supports[0].cxy"),
    ({**SEAL, "node": 41}, "supports[0].node"),
    ({**SEAL, "kzz": 1.0}, "supports[0].kzz"),
    ({k: v for k, v in SEAL.items() if k != "node"}, "supports[0].node"),
    ({**SEAL, "name": ""}, "supports[0].name"),
])
def test_a_bad_support_is_one_line_naming_its_field(entry, field):
    data = {**reference_dict(), "supports": [entry]}
    with pytest.raises(RigError, match=rf"rig file bad\.toml: field {re.escape(field)}:"):
        rig_from_dict(data, source="bad.toml")


def test_a_support_enters_the_plant_at_its_node_and_round_trips():
    """A seal's stiffness, damping and added mass are added at its node's x and y DOFs
    (cross-coupled terms where they belong), nothing else changes, and the rig file form
    reads back to the same rig."""
    import numpy as np

    from bayes_amb.rotor.assembly import assemble, dof_index

    rig = rig_from_dict({**reference_dict(), "supports": [SEAL]}, source="seal.toml")
    assert rig_from_dict(rig.to_dict(), source="seal.toml") == rig
    base, seal = assemble(load_rig()), assemble(rig)
    x, y = dof_index(20, "x"), dof_index(20, "y")
    xy = np.ix_([x, y], [x, y])
    assert np.allclose((seal.K_shaft - base.K_shaft)[xy], [[2e5, 5e4], [-5e4, 2e5]],
                       rtol=1e-12)
    assert np.allclose((seal.C - base.C)[xy], [[150.0, 0.0], [0.0, 150.0]], rtol=1e-12)
    assert np.allclose((seal.M - base.M)[xy], [[0.1, 0.0], [0.0, 0.1]], rtol=1e-12)
    for a, b in ((seal.K_shaft, base.K_shaft), (seal.C, base.C), (seal.M, base.M)):
        d = a - b
        d[xy] = 0.0
        assert not d.any()
    assert np.array_equal(seal.K_bearing, base.K_bearing) and seal.beta == base.beta


def test_modal_damping_gives_every_free_free_bending_mode_its_ratio():
    """[damping] modal_zeta: each flexible mode of the non-rotating shaft with its discs
    (no bearings) has exactly that damping ratio, the rigid-body modes none; it excludes
    first_mode_zeta and reads back from the rig's dict."""
    import numpy as np

    from bayes_amb.rotor.assembly import assemble

    data = {**reference_dict(), "damping": {"modal_zeta": 0.012}}
    rig = rig_from_dict(data, source="modal.toml")
    assert (rig.modal_zeta, rig.first_mode_zeta) == (0.012, 0.0)
    assert rig_from_dict(rig.to_dict(), source="modal.toml") == rig
    m = assemble(rig)
    n = m.n_q
    A = np.block([[np.zeros((n, n)), np.eye(n)],
                  [-np.linalg.solve(m.M, m.K_shaft), -np.linalg.solve(m.M, m.C)]])
    lam = np.linalg.eigvals(A)
    flexible = lam[np.abs(lam) > 1.0]
    assert flexible.size == 2 * n - 8                  # 4 rigid modes x 2 per plane pair
    assert np.allclose(-flexible.real / np.abs(flexible), 0.012, atol=1e-6)
    with pytest.raises(RigError, match=r"field damping\.modal_zeta: give first_mode_zeta "):
        rig_from_dict({**reference_dict(), "damping": {"modal_zeta": 0.01,
                                                       "first_mode_zeta": 0.005}}, "x.toml")
    with pytest.raises(RigError, match=r"field damping\.modal_zeta: expected a value below"):
        rig_from_dict({**reference_dict(), "damping": {"modal_zeta": 1.5}}, "x.toml")
