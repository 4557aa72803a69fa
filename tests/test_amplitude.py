"""Issue 27: a residual that grows with the amplitude is a failed linearity check.

The tool's own linear simulation is the linear loop; a probe's cubic characteristic of 1 %
at the rms applied to the recorded y is the smooth nonlinearity (the odd multisine's
detection lines miss it at that size)."""

from dataclasses import replace

import numpy as np
import pytest

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.discrepancy.adequacy import nominal_assessment
from bayes_amb.discrepancy.library.bearing_coefficient import BEARING_COEFFICIENTS
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, simulate_recording


@pytest.fixture(scope="module")
def record():
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, 1e-4), rig)
    cfg = SimulationConfig(truth="reduced", noise_rms=5e-8, duration=2.0, seed=2)
    return simulate_recording(rig, ctrl, cfg)[0]


def _linearity(rec):
    checks, _, _ = nominal_assessment(rec, BEARING_COEFFICIENTS)
    return next(c for c in checks.checks if c.name == "linearity")


def test_linear_record_passes_and_a_cubic_probe_fails(record):
    lin = _linearity(record)
    assert lin.ok and "does not grow with the amplitude" in lin.line
    assert min(lin.values["amplitude_p"].values()) > 1e-3
    y = np.asarray(record.y)
    rms = np.sqrt(np.mean(y ** 2, axis=0))
    bent = _linearity(replace(record, y=y + 0.01 * y ** 3 / rms ** 2))
    assert not bent.ok and "grows with the predicted response's amplitude" in bent.line
    assert bent.values["amplitude_dependence"]


def test_a_record_that_starts_mid_operation_compares_aligned_blocks(record):
    """A record cut mid-operation is compared after its start-up window (record_window):
    the residual's blocks and the predicted response's are the same samples. A linear
    record passes; the cubic probe is found (with the response's blocks shifted by the
    start-up, the check compared each residual block with most of the next block's
    response: blind to the cubic, and a foreign linear control failed at p 9e-6)."""
    cut = 3057
    t = np.asarray(record.t).ravel()[cut:]
    mid = replace(record, t=t - t[0], y=np.asarray(record.y)[cut:], u=np.asarray(record.u)[cut:],
                  excitation={k: np.asarray(v)[cut:] for k, v in record.excitation.items()})
    lin = _linearity(mid)
    assert lin.ok and min(lin.values["amplitude_p"].values()) > 1e-3
    y = np.asarray(mid.y)
    rms = np.sqrt(np.mean(y ** 2, axis=0))
    bent = _linearity(replace(mid, y=y + 0.01 * y ** 3 / rms ** 2))
    assert bent.values["amplitude_dependence"], bent.values["amplitude_p"]
