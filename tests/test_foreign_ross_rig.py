"""The foreign generator on ROSS's model of the real AMB test rig (benchmarks/foreign/
ross_plant.py, ross_rig.py): ROSS's open-loop eigenvalues, its controllers stabilising the
rotor once scaled, records the product loads, a truth it never reads, and no product stage
imported. Skipped without ROSS (the optional extra bayes-amb[ross])."""

from __future__ import annotations

import ast
import contextlib
import io
import json
import subprocess
import sys
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

FOREIGN = Path(__file__).resolve().parents[1] / "benchmarks" / "foreign"
MODULES = ("ross_plant.py", "ross_rig.py")
FORBIDDEN = ("simulate", "discrepancy", "reduction", "uncertainty", "inference", "control",
             "io")


@pytest.fixture(scope="module")
def world():
    pytest.importorskip("ross")
    from benchmarks.foreign import ross_rig
    with ross_rig.one_thread():
        yield ross_rig.world()


@pytest.fixture(scope="module")
def ross_rotor(world):
    from ross.bearings.magnetic.amb_models import rotor_example_amb_complex_controllers
    with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return rotor_example_amb_complex_controllers()


def _rigid_and_bending(poles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The unstable poles (upper half plane) and the first four bending modes."""
    lam = poles[np.argsort(np.abs(poles), kind="stable")]
    unstable = lam[:8][(lam[:8].real > 0) & (lam[:8].imag >= 0)]
    return unstable[np.argsort(unstable.real)], lam[8:][lam[8:].imag > 0][:4]


def test_the_generator_imports_no_product_stage():
    for name in MODULES:
        tree = ast.parse((FOREIGN / name).read_text())
        mods = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
        mods |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        for m in mods:
            if m.startswith("bayes_amb"):
                assert m == "bayes_amb.rig", f"{name} imports {m}"
    code = ("import sys, benchmarks.foreign.ross_rig; print(','.join(m for m in sys.modules "
            "if m.startswith('bayes_amb') or m == 'ross'))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True, cwd=FOREIGN.parent.parent).stdout.strip().split(",")
    bad = [m for m in loaded if any(m.startswith(f"bayes_amb.{s}") for s in FORBIDDEN)]
    assert not bad, f"importing the ROSS rig generator loads {bad}"
    assert "ross" not in loaded                    # ROSS is read on first use only


def test_magnets_and_nodes_are_rosss_and_the_rig_files(world):
    from bayes_amb.rig.rig import magnet_constants
    rr, rig = world.rr, world.rig
    for b in "AB":
        m = rr.magnets[b]
        ki, ks = magnet_constants(m["g0"], m["i0"], m["ag"], m["nw"], m["alpha"])
        assert rr.ki[b] == pytest.approx(ki, rel=1e-12) == rig.magnets[b].ki
        assert rr.ks[b] == pytest.approx(ks, rel=1e-12) == pytest.approx(rig.magnets[b].ks)
        assert rr.ks[b] > 0 and rr.bearing_nodes[b] == rig.bearing_nodes[b]
        assert rr.sensor_nodes[b] == rig.sensor_nodes[b]
    assert (rr.bearing_nodes, rr.n_q) == ({"A": 13, "B": 44}, 4 * 53)
    assert rig.disc("D1").node == 29 and 29 in rr.disc_nodes


def test_open_loop_eigenvalues_are_rosss(world, ross_rotor):
    """The generator's plant (its own state space from ROSS's bare-rotor matrices, the
    magnets' ks applied by it) against ROSS's own assembly of the open loop: the rotor with
    a BearingElement of ROSS's (negative) ks at each magnet's node, eigenvalues of its M, K,
    C, G (lateral DOFs): the 4 unstable poles and the first four bending modes within 0.1 %
    (they agree to 1e-7)."""
    import ross as rs

    from benchmarks.foreign import ross_plant as rp
    with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        negs = [rs.BearingElement(n=b.n, kxx=b.ks, kyy=b.ks, cxx=0.0, cyy=0.0)
                for b in ross_rotor.bearing_elements]
        ol = rs.Rotor(ross_rotor.shaft_elements, ross_rotor.disk_elements,
                      bearing_elements=negs)
        M, K, C, G = ol.M(0), ol.K(0), ol.C(0), ol.G()
    lat = [i for i in range(M.shape[0]) if i % 6 in (0, 1, 3, 4)]
    M, K, C, G = (X[np.ix_(lat, lat)] for X in (M, K, C, G))
    n, w = M.shape[0], rp.SPEED_RPM * np.pi / 30
    Mi = np.linalg.inv(M)
    theirs = np.linalg.eigvals(np.block([[np.zeros((n, n)), np.eye(n)],
                                         [-Mi @ K, -Mi @ (C + w * G)]]))
    ours = np.linalg.eigvals(rp.build(world.rr, rp.SPEED_RPM, {}, {}).A)
    (u_o, b_o), (u_t, b_t) = _rigid_and_bending(ours), _rigid_and_bending(theirs)
    assert len(u_o) == len(u_t) == 2 and np.all(u_o.real > 200)
    assert np.max(np.abs(u_o - u_t) / np.abs(u_t)) < 1e-3
    assert np.max(np.abs(b_o - b_t) / np.abs(b_t)) < 1e-3
    assert np.max(np.abs(b_o - b_t) / np.abs(b_t)) < 1e-7
    assert b_o.imag / (2 * np.pi) == pytest.approx([101.5, 102.8, 383.2, 409.8], abs=0.1)
    # the full FE model: every bending mode is in it (ROSS's Rayleigh beta = 1e-4 s makes
    # those above about 1.5 kHz overdamped), up to the element's own far above 100 kHz
    assert ours.size == 2 * n and np.abs(ours).max() / (2 * np.pi) > 1e5


def test_controllers_are_rosss_and_stabilise_only_when_scaled(world, ross_rotor):
    """The cascade realisation has ROSS's C(s); the scaled controllers stabilise the rotor
    (Tustin: spectral radius 0.9926 at 3000 rpm and 10 kHz; ZOH too), the unscaled ones
    do not (1.025)."""
    import control as ct

    from benchmarks.foreign import ross_plant as rp
    from benchmarks.foreign.loop import closed_loop, read_controller
    for name, b in zip("AB", sorted(ross_rotor.bearing_elements, key=lambda e: e.n),
                       strict=True):
        A, B, C, D = rp.cascade(*world.rr.controllers[name])
        tf = b.get_analog_controller()
        for f in (1.0, 50.0, 400.0, 2000.0):
            s = 2j * np.pi * f
            mine = (C @ np.linalg.solve(s * np.eye(A.shape[0]) - A, B) + D)[0, 0]
            assert mine == pytest.approx(complex(ct.evalfr(tf, s)), rel=1e-9)
    plant = rp.build(world.rr, rp.SPEED_RPM, {}, {})
    rho = {}
    for key, method, scale in (("tustin", "tustin", None), ("zoh", "zoh", None),
                               ("unscaled", "tustin", {"A": 1.0, "B": 1.0})):
        cf = rp.controller_file(world.rr, world.rig, 1e-4, method, scale)
        rho[key] = np.abs(np.linalg.eigvals(closed_loop(plant, read_controller(cf)).Acl)).max()
    assert rho["tustin"] == pytest.approx(0.9926, abs=1e-4)
    assert rho["zoh"] < 1.0 and rho["unscaled"] > 1.02


def test_records_load_and_the_truth_is_not_read(world, tmp_path):
    from bayes_amb.io.recording import load_recording
    from benchmarks.foreign import ross_rig
    for i, kind in enumerate(ross_rig.FAMILIES):
        rng = np.random.default_rng([7, i])
        case = ross_rig.draw_rig_case(kind, rng, duration_s=0.1, w=world)
        paths = ross_rig.write_case(case, tmp_path, kind, rng, world)
        rec = load_recording(paths["csv"])
        assert rec.y.shape == (1000, 4) and list(rec.excitation) == ["r2"]
        assert "truth" not in rec.meta and rec.controller.kind == "generic"
        side = json.loads(paths["json"].read_text())
        truth = side.pop("truth")
        assert set(truth["theta"]) == {f"{g}_{a}" for g in "kc" for a in ross_rig.AXES}
        assert [e["name"] for e in truth["effects"]] == ([] if kind == "control" else [kind])
        assert truth["held_out"] == ([kind] if kind in ross_rig.HELD_OUT else [])
        assert truth["draws"]["spectral_radius"] < 1
        assert np.all(np.abs(rec.excitation["r2"]) == case.habits.eta_amplitude_a)
        if kind == "unbalance":
            assert max(truth["draws"]["unbalance_line_m"]) > 2.9 * truth["noise_rms_m"]
        paths["json"].write_text(json.dumps(side))            # the truth deleted
        again = load_recording(paths["csv"])
        for a, b in ((rec.y, again.y), (rec.u, again.u), (rec.excitation["r2"],
                                                          again.excitation["r2"]),
                     (rec.controller.A, again.controller.A)):
            assert np.array_equal(a, b)
        assert rec.meta == again.meta


def test_u_is_the_controller_on_the_recorded_y_plus_r2(world):
    """u = K(y) + r2 exactly, with K the controller file the sidecar carries (run from rest:
    no burn-in), all habits but the burn-in on."""
    from benchmarks.foreign import ross_rig
    from benchmarks.foreign.loop import read_controller
    rng = np.random.default_rng(3)
    case = ross_rig.draw_rig_case("actuator_lag", rng, duration_s=0.05, w=world)
    case = replace(case, habits=replace(case.habits, burn_in_s=0.0))
    sim = ross_rig.simulate_case(case, rng, world)
    k = read_controller(world.controller(case))
    x, u = np.zeros(k.Ak.shape[0]), []
    for y in sim["y"]:
        u.append(k.Cu @ x + k.Duy @ y)
        x = k.Ak @ x + k.By @ y
    assert np.allclose(np.array(u) + sim["r2"], sim["u"], rtol=0, atol=1e-9)
    assert np.abs(sim["u"] - sim["r2"]).max() > 1e-3
