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
    assert nominal.map["c_By"] == pytest.approx(-0.8, abs=1e-3)
    cands = tuple(c for c in all_candidates()
                  if (c.effect, c.location) in {("actuator_lag", "both"),
                                                ("time_delay", "controller")})
    d = diagnose(rec, "k_By,c_By", options=DiagnoseOptions(max_effects=1, candidates=cands))
    assert d.effects == ["actuator_lag"]
    bw = d.explanations[0].params["bandwidth_hz"].mean
    assert bw == pytest.approx(1500.0, rel=0.05)
    after = d.parameters_after
    for n, v in truth.items():       # with the lag modelled, both are covered (3 sd)
        assert abs(after[n].mean - v) < 3 * after[n].sd, (n, after[n])
    assert np.isfinite(d.fit.log_likelihood_gain)
    assert d.fit.log_likelihood_gain > 3


def _short_rig(n_nodes=25):
    """A rig with fewer shaft nodes than the reference rig's n27 (the ROSS rotor of issue 28:
    25 nodes, bearings at 5 and 21)."""
    from bayes_amb.rig import rig_from_dict

    d = load_rig("small_rotor").to_dict()
    d["shaft"]["n_nodes"] = n_nodes
    d["discs"][0]["node"], d["discs"][1]["node"] = 2, n_nodes - 1
    d["bearings"]["A"]["node"], d["bearings"]["B"]["node"] = 5, n_nodes - 4
    d["sensors"]["A"]["node"], d["sensors"]["B"]["node"] = 4, n_nodes - 3
    return rig_from_dict(d, source="short")


def test_default_candidates_sit_on_the_rig():
    """The default unbalance nodes were the reference rig's n14, n20, n27: on a 25-node rig
    diagnose stopped after its nominal fit with 'node n27 out of range'. They are now the
    rig's own quarter-span nodes between the bearings."""
    from bayes_amb.rig import node_label

    rig = _short_rig()
    nodes = [node_label(c.location) for c in all_candidates(rig=rig)]
    nodes = [n for n in nodes if n is not None]
    assert sorted(set(nodes)) == [9, 13, 17]          # unbalance: the quarter-span nodes
    assert [c.location for c in all_candidates(["cross_coupling"], rig=rig)][-1] == "n13"
    assert all(rig.bearing_nodes["A"] < n < rig.bearing_nodes["B"] for n in nodes)


def test_a_candidate_off_the_rig_is_refused_before_fitting(rig_ctrl):
    from bayes_amb.discrepancy.library import make_candidate
    from bayes_amb.errors import BayesAmbError

    rig, ctrl = rig_ctrl
    rec, _ = simulate_recording(rig, export_controller(ctrl, rig), SimulationConfig(
        truth="reduced", dt=DT, duration=0.02, seed=1))
    with pytest.raises(BayesAmbError, match=r"candidate unbalance@n40: rig 'small_rotor' .* "
                                            r"has nodes n1 \.\. n36"):
        diagnose(rec, "k_By", options=DiagnoseOptions(
            candidates=(make_candidate("unbalance@n40"),)))
