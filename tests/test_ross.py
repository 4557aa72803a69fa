"""ROSS rotor -> rig file (optional extra): the two models have the same eigenvalues.

Skipped unless ross-rotordynamics is installed (pip install 'bayes-amb[ross]').
"""

from __future__ import annotations

import contextlib
import io
import warnings

import numpy as np
import pytest

from bayes_amb.errors import RigError
from bayes_amb.rig import load_rig, rig_difference
from bayes_amb.rotor import full_model
from tests.helpers import run_cli

with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()), \
        warnings.catch_warnings():
    warnings.simplefilter("ignore")
    rs = pytest.importorskip("ross")

KP = 8000.0   # a proportional bearing law i = -KP y (A/m), the same on both sides


def _rotor(odl=(0.06,) * 35, sensor_nodes=(4, 28), beta=0.0, **shaft_kw):
    steel = rs.Material(name="steel_bayes_amb_test", rho=7850.0, E=205e9, Poisson=0.29)
    kw = {"shear_effects": False, "rotary_inertia": True, "gyroscopic": True, **shaft_kw}
    shaft = [rs.ShaftElement(L=0.01, idl=0.0, odl=d, material=steel, beta=beta, **kw)
             for d in odl]
    discs = [rs.DiskElement(n=0, m=3.2, Id=0.0035, Ip=0.0020),
             rs.DiskElement(n=35, m=1.1, Id=0.0008, Ip=0.0012)]
    amb = [rs.MagneticBearingElement(n=n, g0=6e-4, i0=2.0, ag=1e-4, nw=431, kp_pid=KP,
                                     sensor_node=s) for n, s in zip((4, 28), sensor_nodes,
                                                                    strict=True)]
    return rs.Rotor(shaft, discs, amb)


def test_converted_rig_has_the_ross_eigenvalues(tmp_path, capsys):
    rotor = _rotor()
    rotor.save(tmp_path / "rotor.toml")
    code, out, err = run_cli(["rig", "from-ross", str(tmp_path / "rotor.toml"), "--speed-rpm",
                              "24000", "--zeta", "0", "-o", str(tmp_path / "rig.toml")], capsys)
    assert code == 0, err
    # a saved rotor comes back with plain BearingElements; the PID note survives that
    assert "the ROSS bearings' controller (kp_pid" in out, out
    rig = load_rig(tmp_path / "rig.toml")
    assert (rig.n_nodes, rig.bearing_nodes, rig.sensor_nodes) == (36, {"A": 5, "B": 29},
                                                                  {"A": 5, "B": 29})
    assert rig.ks == pytest.approx(-rotor.bearing_elements[0].ks, rel=1e-12)
    assert [d.node for d in rig.discs] == [1, 36]
    for w in (0.0, 2000.0):   # rad/s; ROSS closes each bearing as k_eq = ks + ki KP
        fm = full_model(rig, w * 60 / (2 * np.pi))
        ours = np.sort(np.abs(np.linalg.eigvals(fm.A - KP * fm.B @ fm.C).imag))
        ours = ours[ours > 1.0][:12:2]                      # the 6 lowest lateral pairs
        theirs = np.abs(rotor.run_modal(speed=w, num_modes=40).evalues.imag)
        for v in ours:   # each lateral frequency of ours is one of ROSS's (ROSS adds axial
            assert np.min(np.abs(theirs - v)) / v < 1e-6     # and torsional modes)


def test_what_a_rig_cannot_hold_is_one_line(tmp_path, capsys):
    from bayes_amb.rig.ross import rig_from_ross

    rotor = _rotor(odl=(0.06,) * 35)
    rotor.shaft_elements[10].shear_effects = True
    with pytest.raises(RigError, match=r"shaft element 10: shear_effects=True differs from "
                                       r"element 0's False"):
        rig_from_ross(rotor, nominal_speed_rpm=1.0)
    code, _, err = run_cli(["rig", "from-ross", str(tmp_path / "none.toml"), "-o",
                            str(tmp_path / "rig.toml")], capsys)
    assert code == 2 and err.count("\n") == 1 and "none.toml: field <file>: not found" in err


def test_shaft_damping_beta_is_carried(tmp_path, capsys):
    """ROSS's stiffness-proportional shaft damping (beta) becomes first_mode_zeta = beta w1/2
    and gives the same damped eigenvalues (real parts too); before, it was dropped for a
    default zeta of 0.005."""
    from bayes_amb.rig.ross import rig_from_ross
    from bayes_amb.rotor.assembly import first_free_free_bending, shaft_matrices

    beta = 1e-6                                       # s; zeta about 0.007
    rotor = _rotor(beta=beta)
    rotor.save(tmp_path / "rotor.toml")
    code, _, err = run_cli(["rig", "from-ross", str(tmp_path / "rotor.toml"),
                            "--speed-rpm", "24000", "-o", str(tmp_path / "rig.toml")], capsys)
    assert code == 0, err
    rig = load_rig(tmp_path / "rig.toml")
    M, K, _ = shaft_matrices(rig)
    assert rig.first_mode_zeta == pytest.approx(0.5 * beta * first_free_free_bending(M, K),
                                                rel=1e-12)
    assert 0.003 < rig.first_mode_zeta < 0.02
    fm = full_model(rig, 0.0)
    ours = np.linalg.eigvals(fm.A - KP * fm.B @ fm.C)
    ours = ours[ours.imag > 1.0]
    ours = ours[np.argsort(ours.imag)][:12]
    theirs = np.asarray(rotor.run_modal(speed=0.0, num_modes=60).evalues)
    for v in ours:                       # damped: real parts agree as well as frequencies
        assert np.min(np.abs(theirs - v)) / abs(v) < 1e-6, v
    assert np.min(ours.real) < -1.0     # and there is damping to compare
    # an explicit --zeta replaces it, and says so
    conv = rig_from_ross(rotor, nominal_speed_rpm=1.0, first_mode_zeta=0.01)
    assert conv.rig.first_mode_zeta == 0.01
    assert any("replaces the ROSS shaft's damping (beta 1e-06 s" in n for n in conv.notes)


@pytest.mark.parametrize("kw, match", [
    ({"rotary_inertia": False}, r"shaft element 0: rotary_inertia=False; a rig always"),
    ({"axial_force": 100.0}, r"shaft element 0: axial force 100\.0 has no rig equivalent"),
])
def test_what_ross_holds_and_a_rig_cannot_is_refused(kw, match):
    from bayes_amb.rig.ross import rig_from_ross

    with pytest.raises(RigError, match=match):
        rig_from_ross(_rotor(**kw), nominal_speed_rpm=1.0)


EXAMPLES = ("rotor_example_amb_simple", "rotor_example_amb_general_controllers",
            "rotor_example_amb_complex_controllers")


def _ross_open_loop(rotor, speed_rpm: float) -> np.ndarray:
    """Eigenvalues of ROSS's own matrices of the bare rotor (Rotor.M, K, C, G of the shaft and
    discs; lateral DOFs), each magnet's ROSS ks added at its node: the open-loop plant."""
    with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bare = rs.Rotor(rotor.shaft_elements, rotor.disk_elements)
        M, K, C, G = bare.M(0), bare.K(0), bare.C(0), bare.G()
    lat = [i for i in range(M.shape[0]) if i % 6 in (0, 1, 3, 4)]
    M, K, C, G = (X[np.ix_(lat, lat)] for X in (M, K, C, G))
    for b in rotor.bearing_elements:
        for ax in (0, 1):
            K[4 * b.n + ax, 4 * b.n + ax] += b.ks
    n, Mi, w = M.shape[0], np.linalg.inv(M), speed_rpm * 2 * np.pi / 60
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-Mi @ K, -Mi @ (C + w * G)]])
    return np.linalg.eigvals(A)


def _rigid_and_bending(poles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    lam = poles[np.argsort(np.abs(poles), kind="stable")]
    return np.sort(lam[:8][lam[:8].real > 0].real), lam[8:][lam[8:].imag > 0][:4]


@pytest.mark.parametrize("example", EXAMPLES)
def test_rosss_amb_examples_convert_with_rosss_eigenvalues(example, tmp_path, capsys):
    """All three AMB rotors ROSS ships convert, live (the notebook path) and saved (the CLI
    path), and the open-loop plant has ROSS's unstable poles and first four bending modes
    within 0.1 % (they agree to 1e-7)."""
    amb_models = pytest.importorskip("ross.bearings.magnetic.amb_models")

    from bayes_amb.rig.ross import rig_from_ross

    with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rotor = getattr(amb_models, example)()
        rotor.save(tmp_path / "rotor.toml")
    live = rig_from_ross(rotor, nominal_speed_rpm=3000.0).rig
    code, out, err = run_cli(["rig", "from-ross", str(tmp_path / "rotor.toml"), "--speed-rpm",
                              "3000", "-o", str(tmp_path / "rig.toml")], capsys)
    assert code == 0, err
    assert err == "" and out.startswith("wrote ")     # no raw library warnings
    saved = load_rig(tmp_path / "rig.toml")
    assert rig_difference(saved, live) is None         # ROSS's save rounds Poisson to 1e-16
    ross_unstable, ross_bending = _rigid_and_bending(_ross_open_loop(rotor, 3000.0))
    unstable, bending = _rigid_and_bending(full_model(saved, 3000.0).poles)
    assert unstable == pytest.approx(ross_unstable, rel=1e-3)
    assert np.max(np.abs(bending - ross_bending) / np.abs(ross_bending)) < 1e-3
    assert np.max(np.abs(bending - ross_bending) / np.abs(ross_bending)) < 1e-7


def test_rosss_real_rig_controllers_are_imported_and_checked():
    """The real test rig's own controllers, each bearing its own transfer function: as ROSS
    writes them they do not hold the rotor up once ks destabilises (a gain written twice),
    and the refusal says why ROSS may show them stable; with the doubled factor removed they
    stabilise the full plant (spectral radius 0.9926 at 3000 rpm and 10 kHz)."""
    amb_models = pytest.importorskip("ross.bearings.magnetic.amb_models")

    from bayes_amb.errors import DataImportError
    from bayes_amb.io.ross_controller import controller_from_ross

    with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rotor = amb_models.rotor_example_amb_complex_controllers()
    rig = load_rig("ross_test_rig")
    with pytest.raises(DataImportError, match=r"spectral radius 1\.02\d+ .*at the magnets' "
                       r"unstable rigid-body poles.*ROSS's time-domain simulation adds the "
                       r"magnet's ks as a restoring spring") as e:
        controller_from_ross(rotor, rig, dt=1e-4, speed_rpm=3000.0)
    assert "\n" not in str(e.value)
    imp = controller_from_ross(rotor, rig, dt=1e-4, speed_rpm=3000.0,
                               scale={"A": 1 / 0.0062, "B": 1 / 0.0046})
    assert imp.spectral_radius == pytest.approx(0.9926, abs=1e-4)
    assert imp.controller.n_states > 8 and imp.zone in "ABCD"
    assert imp.controller.design["ross_scale"] == {"A": 1 / 0.0062, "B": 1 / 0.0046}
    # the shipped copy (bayes_amb/rig/data) is this import: the same frequency response
    from bayes_amb.control.discrete import ss_freqresp
    from bayes_amb.io.controller_file import shipped_controller

    z = np.exp(2j * np.pi * np.array([1.0, 50.0, 102.0, 400.0, 2000.0]) * 1e-4)
    got, ship = (ss_freqresp(k.A, k.B, k.C, k.D, z) for k in (imp.controller,
                                                             shipped_controller(rig.name)))
    assert np.allclose(got, ship, rtol=1e-8, atol=1e-8 * np.abs(ship).max())


def test_a_saved_rotors_pid_controllers_import_from_the_cli(tmp_path, capsys):
    amb_models = pytest.importorskip("ross.bearings.magnetic.amb_models")

    with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        amb_models.rotor_example_amb_simple().save(tmp_path / "simple.toml")
        amb_models.rotor_example_amb_complex_controllers().save(tmp_path / "complex.toml")
    assert run_cli(["rig", "from-ross", str(tmp_path / "simple.toml"), "--speed-rpm", "3000",
                    "-o", str(tmp_path / "rig.toml")], capsys)[0] == 0
    code, out, err = run_cli(["import-controller", "--from-ross", str(tmp_path / "simple.toml"),
                              "--rig", str(tmp_path / "rig.toml"), "--dt", "1e-4", "-o",
                              str(tmp_path / "c.json")], capsys)
    assert code == 0 and err == "", err
    assert "from ROSS bearing controllers (negative feedback)" in out
    assert "marginal" in out                  # its integrator gain is 0.2: |z| = 1 - 2e-10
    code, _, err = run_cli(["import-controller", "--from-ross", str(tmp_path / "complex.toml"),
                            "--rig", "ross_test_rig", "--dt", "1e-4", "-o",
                            str(tmp_path / "c2.json")], capsys)
    assert code == 2 and err.count("\n") == 1
    assert "bearing A (ROSS node 12): no controller" in err and "only as kxx and cxx" in err


def test_an_imported_transfer_function_is_realised_well_scaled():
    """tf2ss's companion form of the real rig's 14th-order lead-lag and notch chain had
    entries from 1e-5 to 1e25 and an eigenvector condition of 3e18; balanced, the same
    controller (the same spectral radius) has a condition below 1e5, and the loop's noise
    filters of a model that keeps bending pairs can be evaluated."""
    amb_models = pytest.importorskip("ross.bearings.magnetic.amb_models")
    from bayes_amb.io.ross_controller import controller_from_ross

    with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rotor = amb_models.rotor_example_amb_complex_controllers()
    imp = controller_from_ross(rotor, load_rig("ross_test_rig"), dt=1e-4, speed_rpm=3000.0,
                               scale={"A": 1 / 0.0062, "B": 1 / 0.0046})
    A = imp.controller.A
    assert np.linalg.cond(np.linalg.eig(A)[1]) < 1e5
    assert np.abs(A).max() < 10 and np.abs(imp.controller.C).max() < 1e10
    assert imp.spectral_radius == pytest.approx(0.99258514, abs=1e-7)


def test_fluid_film_bearings_and_seals_come_in_as_fixed_supports(tmp_path, capsys):
    """A ROSS rotor with a cross-coupled fluid-film bearing and a seal with added mass besides
    its two magnets converts (live and saved), each as a [[supports]] entry with ROSS's
    coefficients at the nominal speed, and the closed loop has ROSS's eigenvalues, damped
    and gyroscopic, at that speed."""
    from bayes_amb.rig.ross import rig_from_ross

    rotor = _rotor()
    extra = [rs.BearingElement(n=17, kxx=4e6, kyy=5e6, kxy=1.5e6, kyx=-1.2e6, cxx=900.0,
                               cyy=1100.0, cxy=60.0, cyx=-40.0, tag="journal"),
             rs.SealElement(n=33, kxx=3e5, kyy=3e5, kxy=2e5, kyx=-2e5, cxx=250.0,
                            cyy=250.0, mxx=0.05, myy=0.05, tag="seal")]
    with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rotor = rs.Rotor(rotor.shaft_elements, rotor.disk_elements,
                         [*rotor.bearing_elements, *extra])
        rotor.save(tmp_path / "rotor.toml")
    rpm = 12000.0
    conv = rig_from_ross(rotor, nominal_speed_rpm=rpm, first_mode_zeta=0.0)
    assert [(s.name, s.node) for s in conv.rig.supports] == [("S1", 18), ("S2", 34)]
    assert conv.rig.supports[0].matrix("k").tolist() == [[4e6, 1.5e6], [-1.2e6, 5e6]]
    assert conv.rig.supports[1].matrix("m").tolist() == [[0.05, 0.0], [0.0, 0.05]]
    assert any("-> support S2" in n and "held fixed" in n for n in conv.notes)
    code, _, err = run_cli(["rig", "from-ross", str(tmp_path / "rotor.toml"), "--speed-rpm",
                            str(rpm), "--zeta", "0", "-o", str(tmp_path / "rig.toml")], capsys)
    assert code == 0, err
    rig = load_rig(tmp_path / "rig.toml")
    assert rig_difference(rig, conv.rig) is None
    w = rpm * 2 * np.pi / 60
    fm = full_model(rig, rpm)
    ours = np.linalg.eigvals(fm.A - KP * fm.B @ fm.C)
    ours = ours[ours.imag > 1.0]
    ours = ours[np.argsort(np.abs(ours))][:12]
    with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        theirs = np.asarray(rotor.run_modal(speed=w, num_modes=60).evalues)
    err = np.array([np.min(np.abs(theirs - v)) / abs(v) for v in ours])   # real parts too
    # the rigid-body modes to 1e-9; above, both eigen-solvers on a cross-coupled (not
    # symmetric) stiffness agree to 1e-7 - 2e-6 (to 2e-8 on the rotor without them)
    assert np.max(err[:4]) < 1e-8 and np.max(err) < 1e-5, err
    without = full_model(rig_from_ross(_rotor(), nominal_speed_rpm=rpm,
                                       first_mode_zeta=0.0).rig, rpm)
    lam0 = np.linalg.eigvals(without.A - KP * without.B @ without.C)
    lam0 = lam0[lam0.imag > 1.0]
    moved = np.abs(np.sort(np.abs(lam0))[:4] - np.sort(np.abs(ours))[:4])
    assert np.min(moved) > 10.0                  # rad/s: the supports move the rigid modes


def test_a_support_linked_to_a_pedestal_is_refused():
    from bayes_amb.rig.ross import rig_from_ross

    rotor = _rotor()
    with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rotor = rs.Rotor(rotor.shaft_elements, rotor.disk_elements,
                         [*rotor.bearing_elements, rs.BearingElement(n=17, kxx=1e6,
                                                                     cxx=100.0)])
    journal = next(b for b in rotor.bearing_elements if b.n == 17)
    journal.n_link = 36                       # as ROSS has it, with a pedestal node beyond
    with pytest.raises(RigError, match=r"node 17: n_link 36: a support linked to another"):
        rig_from_ross(rotor, nominal_speed_rpm=1.0)
