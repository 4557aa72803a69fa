"""Identity tests of the physics library against the foreign generator (benchmarks/foreign).

Every candidate, at the true values of its physical parameters, reproduces the foreign
generator's noise-free recording of its effect sample by sample: eps computed from the
recorded y and u by the tool's offline filter equals the extended model's prediction
S(theta, phi) x (plus its 1x lines), with all eight bearing coefficients off nominal. The
generator was written apart from the library (continuous-time state augmentations, exact
piecewise integration of delays, a continuous oscillator for the lines), so agreement is an
independent check. The library never imports benchmarks.foreign; this test may.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from bayes_amb.discrepancy.library import (
    Actuator2nd,
    ActuatorGain,
    ActuatorLag,
    CrossCoupling,
    FlexibleMode,
    ResidualFlexibility,
    Runout,
    SensorDelay,
    SensorGain,
    SensorLag,
    TimeDelay,
    Unbalance,
)
from bayes_amb.discrepancy.model import ExtendedForwardModel
from bayes_amb.inference.offline import dual_youla_eps
from bayes_amb.io import load_recording
from bayes_amb.rig import load_rig
from benchmarks.foreign import CaseSpec, Effect, Habits, write_case
from tests.helpers import C_NSM, K_THETA

NAMES = ("k_Ax", "k_Ay", "k_Bx", "k_By", "c_Ax", "c_Ay", "c_Bx", "c_By")
TOL = 1e-6


def _tau_ms(hz: float) -> float:
    return 1e3 / (2 * np.pi * hz)


def _line(amp: float, phase: float, unit: float) -> list[float]:
    return [amp * np.cos(phase) / unit, amp * np.sin(phase) / unit]


_LAG_A = Effect("actuator_lag", {"bandwidth_hz": 800.0, "where": "A"})
_DELAY = Effect("actuator_delay", {"delay_s": 1.37e-4})
CASES = {
    # id: (foreign effects, candidates, their parameters phi in order)
    "actuator_lag@A": ((_LAG_A,), (ActuatorLag("actuator_lag", "A"),), [_tau_ms(800)]),
    "actuator_lag@both": ((Effect("actuator_lag", {"bandwidth_hz": 1500.0, "where": "all"}),),
                          (ActuatorLag("actuator_lag", "both"),), [_tau_ms(1500)]),
    "actuator_2nd@both": ((Effect("actuator_2nd", {"natural_hz": 1500.0, "zeta": 0.5,
                                                   "where": "all"}),),
                          (Actuator2nd("actuator_2nd", "both"),), [_tau_ms(1500), 0.5]),
    "actuator_2nd@B": ((Effect("actuator_2nd", {"natural_hz": 900.0, "zeta": 1.3,
                                                "where": "B"}),),
                       (Actuator2nd("actuator_2nd", "B"),), [_tau_ms(900), 1.3]),
    "sensor_lag@B": ((Effect("sensor_lag", {"bandwidth_hz": 2000.0, "where": "B"}),),
                     (SensorLag("sensor_lag", "B"),), [_tau_ms(2000)]),
    "sensor_lag@both": ((Effect("sensor_lag", {"bandwidth_hz": 1200.0, "where": "all"}),),
                        (SensorLag("sensor_lag", "both"),), [_tau_ms(1200)]),
    "time_delay (actuator_delay)": ((Effect("actuator_delay", {"delay_s": 0.37e-4}),),
                                    (TimeDelay("time_delay", "controller"),), [0.037]),
    "time_delay, 1.37 samples": ((_DELAY,), (TimeDelay("time_delay", "controller"),),
                                 [0.137]),
    "sensor_delay": ((Effect("sensor_delay", {"delay_s": 0.62e-4}),),
                     (SensorDelay("sensor_delay", "sensors"),), [0.062]),
    "actuator_gain@Ay": ((Effect("actuator_gain", {"axis": "Ay", "gain": 0.05}),),
                         (ActuatorGain("actuator_gain", "Ay"),), [0.05]),
    "sensor_gain@By": ((Effect("sensor_gain", {"channel": "By", "gain": -0.04}),),
                       (SensorGain("sensor_gain", "By"),), [-0.04]),
    "cross_coupling@D1": ((Effect("cross_coupling", {"where": "D1", "kxy_nm": 4e4}),),
                          (CrossCoupling("cross_coupling", "D1"),), None),
    "cross_coupling@n12": ((Effect("cross_coupling", {"where": 12, "kxy_nm": 6e4}),),
                           (CrossCoupling("cross_coupling", "n12"),), None),
    "unbalance@D2": ((Effect("unbalance", {"planes": [{"node": "D2", "u_kgm": 2e-5,
                                                       "phase_rad": 0.7}]}),),
                     (Unbalance("unbalance", "D2"),), _line(2e-5, 0.7, 1e-5)),
    "unbalance@n20": ((Effect("unbalance", {"planes": [{"node": 20, "u_kgm": 3e-5,
                                                        "phase_rad": -2.0}]}),),
                      (Unbalance("unbalance", "n20"),), _line(3e-5, -2.0, 1e-5)),
    "runout@Bx": ((Effect("runout", {"channel": "Bx", "amplitude_m": 2e-7,
                                     "phase_rad": 0.4}),),
                  (Runout("runout", "Bx"),), _line(2e-7, 0.4, 1e-7)),
    # several effects and several instances of one effect
    "actuator_lag + time_delay": ((_LAG_A, _DELAY), (ActuatorLag("actuator_lag", "A"),
                                                     TimeDelay("time_delay", "controller")),
                                  [_tau_ms(800), 0.137]),
    "sensor_gain@Ax + sensor_gain@By": (
        (Effect("sensor_gain", {"channel": "Ax", "gain": 0.03}),
         Effect("sensor_gain", {"channel": "By", "gain": -0.05})),
        (SensorGain("sensor_gain", "Ax"), SensorGain("sensor_gain", "By")), [0.03, -0.05]),
    "unbalance in two planes": (
        (Effect("unbalance", {"planes": [{"node": "D1", "u_kgm": 1e-5, "phase_rad": 0.2},
                                         {"node": 27, "u_kgm": 2e-5, "phase_rad": 2.5}]}),),
        (Unbalance("unbalance", "D1"), Unbalance("unbalance", "n27")),
        _line(1e-5, 0.2, 1e-5) + _line(2e-5, 2.5, 1e-5)),
    "actuator_gain + sensor_lag + runout": (
        (Effect("actuator_gain", {"axis": "Bx", "gain": -0.08}),
         Effect("sensor_lag", {"bandwidth_hz": 2500.0, "where": "A"}),
         Effect("runout", {"channel": "By", "amplitude_m": 1e-7, "phase_rad": 1.0})),
        (ActuatorGain("actuator_gain", "Bx"), SensorLag("sensor_lag", "A"),
         Runout("runout", "By")), [-0.08, _tau_ms(2500), *_line(1e-7, 1.0, 1e-7)]),
}


def _record(controller_file, tmp_path, effects, duration=0.2):
    spec = CaseSpec(k_theta=K_THETA, c_nsm=C_NSM, habits=Habits(noise_rms_m=0.0),
                    effects=tuple(effects), duration_s=duration,
                    controller_file=controller_file)
    paths = write_case(spec, tmp_path, "case", np.random.default_rng(3), conceal_effects=False)
    return load_recording(paths["csv"]), spec.theta(load_rig().c_ref)


def _prediction(fwd: ExtendedForwardModel, P: np.ndarray) -> np.ndarray:
    pred = fwd.simulate(P)
    for c, basis in zip(fwd.line_candidates, fwd.line_responses(P), strict=True):
        pred = pred + basis @ P[0, fwd.slices[fwd.candidates.index(c)]]
    return pred


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b ** 2)))


@pytest.mark.parametrize("case", list(CASES))
def test_candidate_reproduces_the_foreign_generator(controller_file, tmp_path, case):
    effects, cands, phi = CASES[case]
    rec, theta = _record(controller_file, tmp_path, effects)
    fwd = ExtendedForwardModel(rec, NAMES, cands)
    if phi is None:                                    # kxy in units of k_ref
        phi = [effects[0].params["kxy_nm"] / rec.rig.k_ref]
    P = np.array([[*(theta[n] for n in NAMES), *phi]])
    eps = dual_youla_eps(fwd.parts, np.asarray(rec.y), np.asarray(rec.u))
    rel = _rel(_prediction(fwd, P), eps)
    without = _rel(_prediction(fwd, np.concatenate([P[:, :8], fwd.null[None, 8:]], axis=1)),
                   eps)
    assert without > 1e-3, f"{case}: the effect does not show ({without:.1e})"
    assert rel < TOL, f"{case}: relative rms difference {rel:.2e}"


def _flexible(*pairs: int) -> tuple[FlexibleMode, ...]:
    return tuple(FlexibleMode("flexible_mode", f"bending pair {k}", pair=k) for k in pairs)


def _errors(rec, theta, variants) -> list[float]:
    """Relative rms error of S(theta, phi) x against the recording's eps, per candidate set
    (each at its null, the residual scale set to 1: the FE prediction)."""
    out = []
    for cands in variants:
        fwd = ExtendedForwardModel(rec, NAMES, cands)
        P = np.array([[*(theta[n] for n in NAMES), *fwd.null[8:]]])
        for i, c in enumerate(fwd.candidates):
            if isinstance(c, ResidualFlexibility):
                P[0, fwd.slices[i]] = 1.0
        eps = dual_youla_eps(fwd.parts, np.asarray(rec.y), np.asarray(rec.u))
        out.append(_rel(_prediction(fwd, P), eps))
    return out


@pytest.mark.parametrize("n_pairs", [2, 3])
def test_bending_pairs_reproduce_a_foreign_truth_with_those_pairs(controller_file, tmp_path,
                                                                   n_pairs):
    """The foreign generator truncates its own eigen-decomposition of the FE state space
    to the rigid-body modes and n bending pairs; flexible_mode at pairs 1..n (FE values)
    reproduces it (measured 3e-11 with two pairs); one pair fewer does not."""
    spec = CaseSpec(truth="reduced", n_bending=n_pairs, k_theta=K_THETA, c_nsm=C_NSM,
                    habits=Habits(noise_rms_m=0.0), duration_s=0.2,
                    controller_file=controller_file)
    paths = write_case(spec, tmp_path, "case", np.random.default_rng(3), conceal_effects=False)
    rec = load_recording(paths["csv"])
    every, fewer = _errors(rec, spec.theta(load_rig().c_ref),
                           [_flexible(*range(1, n_pairs + 1)), _flexible(*range(1, n_pairs))])
    assert fewer > 1e-3 and every < TOL, (every, fewer)


@pytest.mark.parametrize("n_pairs", [0, 1, 2, 3])
def test_residual_flexibility_reproduces_a_foreign_static_correction(controller_file,
                                                                     tmp_path, n_pairs):
    """The foreign generator's reduced truth with its own static correction (mode
    acceleration: the left-out modes follow the force quasi-statically, residual = full
    static compliance - the kept modes', sampled with the current in force just before the
    sampling instant). flexible_mode at pairs 1..n plus residual_flexibility at its FE value
    reproduces it sample by sample; without the residual it does not (there the residual
    is almost all of eps with 0 and 1 kept pairs: 0.999 and 0.79 without it).

    Both sides sum the static compliance over the left-out modes. As (full static) -
    (kept static) each side lost ~2e-4 of it to the full A's conditioning (~7e14) and
    they agreed only to 3-4e-6 with 0 and 1 kept pairs; now 1.5e-10, 1.4e-10, 2.5e-11 and
    2.2e-11 with 0-3 kept pairs (measured)."""
    spec = CaseSpec(truth="reduced", n_bending=n_pairs, static_correction=True,
                    k_theta=K_THETA, c_nsm=C_NSM, habits=Habits(noise_rms_m=0.0),
                    duration_s=0.2, controller_file=controller_file)
    paths = write_case(spec, tmp_path, "case", np.random.default_rng(3), conceal_effects=False)
    rec = load_recording(paths["csv"])
    res = (ResidualFlexibility("residual_flexibility", "truncated modes"),)
    pairs = _flexible(*range(1, n_pairs + 1))
    without, with_res = _errors(rec, spec.theta(load_rig().c_ref), [pairs, pairs + res])
    assert without > 1e-2 and with_res < TOL, (without, with_res)


def test_residual_flexibility_is_the_static_part_of_the_truncated_modes(controller_file,
                                                                        tmp_path):
    """Against the foreign generator's full 320-state truth. With 8 bending pairs kept the
    rest are above 20 kHz and settle within a sample: the residual flexibility candidate
    (at its FE value) then takes the error from 4.9e-4 to 4.0e-5 (measured). With the three
    pairs the diagnosis tries (modes 4-5 at 7-12 kHz are dynamic, not static) it still
    removes part of it (1.31 % to 0.99 %): an approximation there, and said so."""
    spec = CaseSpec(truth="full", k_theta=K_THETA, c_nsm=C_NSM,
                    habits=Habits(noise_rms_m=0.0), duration_s=0.2,
                    controller_file=controller_file)
    paths = write_case(spec, tmp_path, "case", np.random.default_rng(3), conceal_effects=False)
    rec = load_recording(paths["csv"])
    res = (ResidualFlexibility("residual_flexibility", "truncated modes"),)
    eight, eight_r, three, three_r = _errors(
        rec, spec.theta(load_rig().c_ref),
        [_flexible(*range(1, 9)), _flexible(*range(1, 9)) + res,
         _flexible(1, 2, 3), _flexible(1, 2, 3) + res])
    assert eight_r < 1e-4 and eight_r < eight / 5, (eight, eight_r)
    assert three_r < 0.85 * three, (three, three_r)


def test_the_library_does_not_import_the_foreign_generator():
    lib = Path(__file__).parent.parent / "bayes_amb" / "discrepancy" / "library"
    for f in sorted(lib.glob("*.py")):
        for node in ast.walk(ast.parse(f.read_text())):
            mods = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                    [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            assert not any(m.startswith("tests") for m in mods), f"{f.name} imports {mods}"
