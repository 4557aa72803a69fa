"""Issue 27: the classical detection lines of a random-odd multisine as a linearity check.

A linear loop excited by an odd multisine puts the same noise on the left-out odd lines as
on the even ones; an odd nonlinearity puts distortion on the odd ones. Here the tool's own
linear simulation is the linear loop, and a probe's cubic characteristic applied to the
recorded y (3 % at the rms) the odd nonlinearity."""

from dataclasses import replace

import numpy as np
import pytest

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.discrepancy.detection_lines import detection_line_test, odd_design
from bayes_amb.discrepancy.linearity import linearity_check
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, simulate_recording
from bayes_amb.simulate.signals import multisine, odd_multisine


def test_the_odd_multisine_has_odd_lines_and_detection_lines_only():
    rng = np.random.default_rng(0)
    x = odd_multisine(4000, 2, 0.3, rng, 1e-4, (20.0, 1500.0))
    assert np.max(np.abs(x)) == pytest.approx(0.3)
    left, even = odd_design(x)
    assert np.all(left % 2 == 1) and np.all(even % 2 == 0)
    k = np.flatnonzero(np.sum(np.abs(np.fft.rfft(x, axis=0)) ** 2, axis=1) > 1e-8)
    # one odd line of every group of four left out: a quarter of the odd lines in band
    assert left.size == pytest.approx((k.size + left.size) / 4, abs=2)
    assert odd_design(multisine(4000, 2, 0.3, rng, 1e-4)) is None


@pytest.fixture(scope="module")
def linear_record():
    rig = load_rig()
    cfg = SimulationConfig(truth="reduced", excitation="odd-multisine", amplitude=0.3,
                           noise_rms=5e-8, duration=1.0, seed=3)
    rec, _ = simulate_recording(rig, export_controller(reference_controller(rig, cfg.dt), rig),
                                cfg)
    return rec


def test_a_linear_loop_passes_and_a_cubic_probe_fails(linear_record):
    lin = detection_line_test(linear_record)
    assert lin.design and not lin.found
    check = linearity_check(linear_record)
    assert check.ok and "detection lines" in check.line
    y = np.asarray(linear_record.y)
    rms = np.sqrt(np.mean(y ** 2, axis=0))
    bent = replace(linear_record, y=y + 0.03 * y ** 3 / rms ** 2)
    found = detection_line_test(bent)
    assert found.found and all(f["signal"].startswith("y_") for f in found.failing)
    check = linearity_check(bent)
    assert not check.ok and "odd nonlinear distortion" in check.line
