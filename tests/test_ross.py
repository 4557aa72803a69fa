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
from bayes_amb.rig import load_rig
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

    with pytest.raises(RigError, match=r"shaft element 10: outer diameter \(left\) 0\.07 "
                                       r"differs from element 0's 0\.06"):
        rig_from_ross(_rotor(odl=(0.06,) * 10 + (0.07,) * 25), nominal_speed_rpm=1.0)
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
    ({"alpha": 0.5}, r"shaft element 0: mass-proportional damping alpha 0\.5 has no rig "),
    ({"rotary_inertia": False}, r"shaft element 0: rotary_inertia=False; a rig always"),
    ({"axial_force": 100.0}, r"shaft element 0: axial force 100\.0 has no rig equivalent"),
])
def test_what_ross_holds_and_a_rig_cannot_is_refused(kw, match):
    from bayes_amb.rig.ross import rig_from_ross

    with pytest.raises(RigError, match=match):
        rig_from_ross(_rotor(**kw), nominal_speed_rpm=1.0)
