"""The bending pairs a recording's model keeps (inference/model_band.py): the paper's 8-state
model where the control band holds no bending mode, the rigid-body modes and pair 1 on
ROSS's real test rig with its own controllers, whose loop gain reaches one above half the
first bending frequency."""

from __future__ import annotations

import numpy as np
import pytest

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.discrepancy.library import all_candidates
from bayes_amb.discrepancy.library.flexible_mode import past_kept
from bayes_amb.inference.forward import ForwardModel
from bayes_amb.inference.model_band import (
    MAX_PAIRS,
    choose_model,
    control_band_hz,
    feedback_part,
)
from bayes_amb.io.controller_file import shipped_controller
from bayes_amb.reduction import reduce_pseudo_modal
from bayes_amb.rig import load_rig
from bayes_amb.rotor import full_model
from bayes_amb.simulate import SimulationConfig, simulate_recording

# ROSS's own two controllers of the test rig, shipped (controller_from_ross(..., dt=1e-4,
# speed_rpm=3000, scale={"A": 1/0.0062, "B": 1/0.0046}); tests/test_ross.py checks that
# import), so that this runs without ROSS


def _k(ctrl):
    return feedback_part(ctrl.A, ctrl.B, ctrl.C, ctrl.D)


def test_the_reference_rig_keeps_the_papers_8_state_model_bit_for_bit():
    rig = load_rig()
    full = full_model(rig, 31500.0)
    ctrl = export_controller(reference_controller(rig, 1e-4), rig)
    red, band = choose_model(full, _k(ctrl), 1e-4)
    assert band.n_bending == 0 and not band.capped and red.n_states == 8
    assert band.validity_hz == pytest.approx(513.6, abs=0.5)
    assert 150.0 < band.control_hz < band.validity_hz
    ref = reduce_pseudo_modal(full)
    assert np.array_equal(red.A, ref.A) and np.array_equal(red.C, ref.C)


def test_the_real_test_rig_keeps_its_first_bending_pair():
    rig, ctrl = load_rig("ross_test_rig"), shipped_controller("ross_test_rig")
    full = full_model(rig, 3000.0)
    red, band = choose_model(full, _k(ctrl), 1e-4)
    # the rigid-body model is valid to 51 Hz, the loop's gain reaches one near 105 Hz
    rigid = reduce_pseudo_modal(full)
    assert control_band_hz(rigid, _k(ctrl), 1e-4) > 2 * 50.8
    assert band.n_bending == 1 and red.n_states == 12 and not band.capped
    assert band.bending_hz == pytest.approx((101.6, 102.9), abs=0.1)
    assert band.control_hz <= band.validity_hz == pytest.approx(193.2, abs=0.5)
    assert "bending pair 1 (101.6/102.9 Hz)" in band.line()


def test_no_loop_gain_keeps_the_rigid_body_model_and_an_endless_one_is_capped():
    rig, ctrl = load_rig("ross_test_rig"), shipped_controller("ross_test_rig")
    full = full_model(rig, 3000.0)
    A, B, C, D = _k(ctrl)
    _, none = choose_model(full, (A, B, 0 * C, 0 * D), 1e-4)
    assert none.n_bending == 0 and none.control_hz == 0.0
    _, loud = choose_model(full, (A, B, 1e6 * C, 1e6 * D), 1e-4)
    assert loud.capped and loud.n_bending == MAX_PAIRS
    assert "stops short of the control band" in loud.line()


def test_the_forward_model_and_the_diagnosis_candidates_follow_the_kept_pairs():
    rig, ctrl = load_rig("ross_test_rig"), shipped_controller("ross_test_rig")
    rec, _ = simulate_recording(rig, ctrl, SimulationConfig(duration=0.05, dt=1e-4, seed=1,
                                                            amplitude=0.1))
    fwd = ForwardModel(rec, ("k_Ax", "k_By"))
    assert fwd.reduced.n_states == 12 and fwd.band.n_bending == 1
    assert fwd.validity_band_hz() == pytest.approx(fwd.band.validity_hz)
    assert ForwardModel(rec, ("k_Ax",), n_bending=0).reduced.n_states == 8
    flex = [c.location for c in past_kept(all_candidates(rig=rig), fwd.band.n_bending)
            if c.effect == "flexible_mode"]
    assert flex == ["bending pair 2", "bending pair 3", "bending pair 4"]
