"""The example rig of docs/your_rig.md (small_rotor) runs simulate -> identify -> diagnose."""

from __future__ import annotations

import numpy as np
import pytest

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.control.robustness import full_plant_discrete, loop_spectral_radius
from bayes_amb.discrepancy import DiagnoseOptions, all_candidates, diagnose
from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.io import load_recording, save_recording
from bayes_amb.rig import load_rig
from bayes_amb.rotor import full_model
from bayes_amb.simulate import SimulationConfig, parse_effect, simulate_recording

DT = 1e-4


@pytest.fixture(scope="module")
def rig_ctrl():
    rig = load_rig("small_rotor")
    return rig, reference_controller(rig, DT)


def test_example_rig_differs_from_the_reference_and_is_stabilised(rig_ctrl):
    rig, ctrl = rig_ctrl
    ref = load_rig()
    assert (rig.n_nodes, rig.shaft.diameter, rig.ks, rig.nominal_speed_rpm) != (
        ref.n_nodes, ref.shaft.diameter, ref.ks, ref.nominal_speed_rpm)
    assert [d.mass for d in rig.discs] != [d.mass for d in ref.discs]
    for speed in (0.0, rig.nominal_speed_rpm):   # the full FE plant, bending modes included
        fm = full_model(rig, speed)
        Ap, Bp = full_plant_discrete(fm.A, fm.B, DT)
        assert loop_spectral_radius(Ap, Bp, fm.C, ctrl.controller_matrices()) < 0.999


def test_simulate_identify_diagnose_end_to_end(rig_ctrl, tmp_path):
    rig, ctrl = rig_ctrl
    truth = {"k_By": 0.3, "c_By": 0.2}
    rec, t = simulate_recording(rig, export_controller(ctrl, rig), SimulationConfig(
        truth="reduced", params=truth, dt=DT, duration=0.5, noise_rms=2e-7, r2_rms=0.02,
        effects=(parse_effect("actuator_lag:bandwidth_hz=1500"),), seed=3))
    save_recording(tmp_path / "small.csv", rec, truth=t)
    rec = load_recording(tmp_path / "small.csv")        # the rig travels embedded
    assert rec.rig.name == "small_rotor" and rec.rig.n_nodes == 36
    # the nominal model leaves the lag out: damping is driven to its prior bound
    nominal = identify(rec, "k_By,c_By", options=IdentifyOptions(map_only=True))
    assert nominal.summary["map"]["c_By"] == pytest.approx(-0.8, abs=1e-3)
    cands = tuple(c for c in all_candidates()
                  if (c.effect, c.location) in {("actuator_lag", "both"),
                                                ("time_delay", "controller")})
    d = diagnose(rec, "k_By,c_By", options=DiagnoseOptions(max_effects=1, candidates=cands))
    assert d.effects == ["actuator_lag"]
    bw = d.report["explanations"][0]["params"]["bandwidth_hz"]["mean"]
    assert bw == pytest.approx(1500.0, rel=0.05)
    after = d.report["parameters_after"]
    for n, v in truth.items():       # with the lag modelled, both are covered (3 sd)
        assert abs(after[n]["mean"] - v) < 3 * after[n]["sd"], (n, after[n])
    assert np.isfinite(d.report["fit"]["log_likelihood_gain"])
    assert d.report["fit"]["log_likelihood_gain"] > 3
