"""One convention for u: the recorded u is the plant current and includes an injected r2.

u = K_u([y + r1; eta]) + r2 for every controller kind (io/recording.py). The simulator writes
it (``port="r2"`` with the reference observer controller, and a designed PID whose eta port
is that same sum), the data check recomputes it (checks.recompute_u), and the identification
model assumes it (loop_model: port r2 enters the plant and the recorded u). The check must
still catch a firmware that is not its documents: a 1 % gain change and an added notch.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import signal

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.control.pid import design_decentralised_pid
from bayes_amb.discrepancy.checks import check_controller, recompute_u
from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.io.controller_file import ControllerFile
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, simulate_recording

DT = 1e-4
NOISE = {"noise_rms": 2e-7, "r1_rms": 1e-7, "r2_rms": 0.02}


@pytest.fixture(scope="module")
def rig():
    return load_rig()


@pytest.fixture(scope="module")
def controllers(rig):
    return {"observer": export_controller(reference_controller(rig, DT), rig),
            "pid": export_controller(design_decentralised_pid(rig, DT), rig)}


def _record(rig, ctrl, port=None, seed=5, duration=0.3, noise=None):
    cfg = SimulationConfig(truth="reduced", params={"k_By": 0.3}, dt=DT, duration=duration,
                           seed=seed, port=port, **(NOISE if noise is None else noise))
    return simulate_recording(rig, ctrl, cfg)[0]


def _with_notch(ctrl: ControllerFile, f0_hz: float = 300.0, q: float = 3.0
                ) -> ControllerFile:
    """The same controller with a notch filter in series with each u output (eps rows
    unchanged): a firmware whose documents do not mention the notch."""
    b, a = signal.iirnotch(f0_hz, q, fs=1 / ctrl.dt)
    an, bn, cn, dn = signal.tf2ss(b, a)
    eye = np.eye(4)
    An, Bn, Cn, Dn = (np.kron(eye, m) for m in (an, bn, cn, dn))
    A, B, C, D = (np.asarray(m, dtype=float) for m in (ctrl.A, ctrl.B, ctrl.C, ctrl.D))
    nk, nn = A.shape[0], An.shape[0]
    A2 = np.block([[A, np.zeros((nk, nn))], [Bn @ C[:4], An]])
    B2 = np.vstack([B, Bn @ D[:4]])
    C2 = np.block([[Dn @ C[:4], Cn], [C[4:], np.zeros((4, nn))]])
    D2 = np.vstack([Dn @ D[:4], D[4:]])
    return dataclasses.replace(ctrl, A=A2, B=B2, C=C2, D=D2)


def _gain_plus_1pct(ctrl: ControllerFile) -> ControllerFile:
    C, D = np.array(ctrl.C, dtype=float), np.array(ctrl.D, dtype=float)
    C[:4] *= 1.01
    D[:4, :4] *= 1.01
    return dataclasses.replace(ctrl, C=C, D=D)


def _controller_ok(rec) -> bool:
    return check_controller(rec, np.zeros(0))[0].ok


@pytest.mark.parametrize("kind,port", [("observer", "r2"), ("observer", "eta"),
                                       ("pid", "r2")])
def test_recorded_u_is_the_documented_controller_plus_r2(rig, controllers, kind, port):
    """Honest data pass, for every controller kind and port; u includes r2 exactly (the
    unrecorded r1 is left out here: the controller's answer to it is not in the record)."""
    rec = _record(rig, controllers[kind], port, noise={"noise_rms": 2e-7, "r2_rms": 0.02})
    assert list(rec.excitation) == [port]
    d = np.asarray(rec.u) - recompute_u(rec)
    assert np.sqrt(np.mean(d**2)) < 1e-9 * np.sqrt(np.mean(np.asarray(rec.u) ** 2))
    assert _controller_ok(rec)
    if port == "r2":     # without adding r2 the recomputed u is off by the excitation
        d0 = np.asarray(rec.u) - recompute_u(dataclasses.replace(
            rec, excitation={"r1": 0 * rec.excitation["r2"]}))
        assert np.allclose(d0, rec.excitation["r2"], atol=1e-9)


@pytest.mark.parametrize("kind", ["observer", "pid"])
@pytest.mark.parametrize("firmware", [_gain_plus_1pct, _with_notch])
def test_a_firmware_that_is_not_its_documents_fails(rig, controllers, kind, firmware):
    """The loop ran with a changed firmware (1 % more gain, or an undocumented 300 Hz
    notch); the sidecar documents the original controller: the check fails."""
    documented = controllers[kind]
    rec = _record(rig, firmware(documented), "r2", seed=7)
    rec = dataclasses.replace(rec, controller=documented)
    assert not _controller_ok(rec)


def test_port_eta_needs_an_observer_controller(rig, controllers):
    cfg = SimulationConfig(truth="reduced", dt=DT, duration=0.01, port="eta")
    with pytest.raises(BayesAmbError, match="option --port: eta needs an observer"):
        simulate_recording(rig, controllers["pid"], cfg)
    with pytest.raises(BayesAmbError, match="option --port: value 'u'"):
        SimulationConfig(port="u").validate()


def test_identification_with_r2_on_the_observer_controller(rig, controllers):
    """The reference observer controller excited at r2 (the generic loop path of
    ForwardModel): k_By = 0.3 is recovered within 4 Laplace sd."""
    rec = _record(rig, controllers["observer"], "r2", seed=11, duration=0.5)
    res = identify(rec, "k_By,c_By", options=IdentifyOptions(map_only=True))
    k = res.parameters["k_By"]
    assert 0 < k.sd < 0.1
    assert abs(k.mean - 0.3) < 4 * k.sd
