"""The amplifier's current loop with its rate capped (discrepancy/loop_waveform.py and
current_loop.py): the waveform in its limits and against the continuous lag, and the
screen's decision on foreign records whose amplifier is known."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bayes_amb.discrepancy.loop_waveform import asked_rate, lag_defect, loop_defect
from bayes_amb.discrepancy.nonlinear import slew_defect

DT = 1e-4


@pytest.fixture(scope="module")
def command():
    """A random binary command held over three samples, with a little noise."""
    rng = np.random.default_rng(0)
    return (np.repeat(rng.choice([-0.3, 0.3], (700, 4)), 3, axis=0)
            + 0.01 * rng.standard_normal((2100, 4)))


def test_the_loop_is_the_lag_without_a_cap_and_the_slew_limit_with_an_ideal_loop(command):
    lag = lag_defect(command, 2000.0, DT)
    np.testing.assert_allclose(loop_defect(command, [np.inf], [2000.0], DT)[0], lag,
                               atol=1e-12)
    slew = slew_defect(command, 5000.0, DT)
    np.testing.assert_allclose(loop_defect(command, [5000.0], [np.inf], DT)[0], slew,
                               atol=1e-12)
    # configurations side by side are the same as one at a time
    both = loop_defect(command, [5000.0, 9000.0], [1500.0, 3000.0], DT)
    np.testing.assert_allclose(both[1], loop_defect(command, [9000.0], [3000.0], DT)[0],
                               atol=1e-12)


@pytest.mark.parametrize("first_moment", [True, False])
def test_the_compiled_loop_is_its_numpy_form(command, first_moment):
    """loop_defect's kernel against loop_defect_numpy, capped, uncapped, ideal and both,
    side by side: the same to rounding (the exponential's last bit)."""
    from bayes_amb.discrepancy.loop_waveform import loop_defect_numpy

    rates, bws = [2000.0, 5000.0, np.inf, 9000.0], [1500.0, np.inf, 2000.0, 3000.0]
    got = loop_defect(command, rates, bws, DT, first_moment)
    want = loop_defect_numpy(command, rates, bws, DT, first_moment)
    assert got.shape == want.shape == (4, *command.shape)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-14 * np.abs(want).max())


def test_the_held_lag_has_the_continuous_lags_response_in_the_band():
    """The held samples with the pulse's first moment in place give the plant the lag
    1 / (1 + j f / fb) to 2e-3 up to 500 Hz at 10 kHz (relative, amplitude and phase)."""
    n = 1 << 15
    u = np.zeros((n, 4))
    u[100] = 1.0
    f = np.array([50.0, 200.0, 500.0])
    for fb in (1500.0, 4000.0):
        h = u[:, 0] + lag_defect(u, fb, DT)[:, 0]
        z = np.exp(2j * np.pi * f * DT)
        H = np.array([np.sum(h * zz ** -(np.arange(n) - 100.0)) for zz in z])
        assert np.all(np.abs(H * (1 + 1j * f / fb) - 1) < 2e-3)


def test_the_cap_slows_large_steps_only(command):
    """Below the cap the loop is the lag; a cap below the rate the steps ask makes the
    delivered current fall further behind, and a cap far above it changes nothing."""
    fb = 2000.0
    rate = asked_rate(command, fb, DT)
    lag = lag_defect(command, fb, DT)
    far = loop_defect(command, [100 * rate], [fb], DT)[0]
    np.testing.assert_allclose(far, lag, atol=1e-12)
    capped = loop_defect(command, [0.7 * rate], [fb], DT)[0]
    assert np.mean(np.abs(capped)) > 1.1 * np.mean(np.abs(lag))
    # the means of consecutive samples of a current whose rate is capped differ by at
    # most the cap times a sample
    delivered = command + loop_defect(command, [0.7 * rate], [fb], DT,
                                      first_moment=False)[0]
    assert np.max(np.abs(np.diff(delivered, axis=0))) <= 0.7 * rate * DT * (1 + 1e-9)


@pytest.fixture(scope="module")
def recording():
    from bayes_amb.control.export import export_controller, reference_controller
    from bayes_amb.rig import load_rig
    from bayes_amb.simulate import SimulationConfig, simulate_recording
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, 1e-4), rig)
    cfg = SimulationConfig(truth="reduced", noise_rms=5e-8, duration=0.3, seed=3)
    return simulate_recording(rig, ctrl, cfg)[0]


def test_the_post_lag_port_is_the_plants_input(recording):
    """A current added after the lag reaches eps as r2 does in the model without the lag
    when the lag is fast, and not through the lag when it is slow (loop_model.py)."""
    from bayes_amb.discrepancy.library.bearing_coefficient import BEARING_COEFFICIENTS
    from bayes_amb.discrepancy.linearity import r2_response
    from bayes_amb.discrepancy.loop_model import LAG, post_lag_response
    from bayes_amb.discrepancy.model import ExtendedForwardModel
    lagged = ExtendedForwardModel(recording, BEARING_COEFFICIENTS, (LAG,), None)
    plain = ExtendedForwardModel(recording, BEARING_COEFFICIENTS, (), None)
    d = 0.01 * np.random.default_rng(0).standard_normal((recording.u.shape[0], 4))
    theta = np.zeros(8)
    ref = r2_response(plain, theta, d)
    fast = post_lag_response(lagged, np.r_[theta, 1e-6], d[:, None])       # tau 1 ns
    assert np.max(np.abs(fast - ref)) < 1e-3 * np.max(np.abs(ref))
    slow_tau_ms = 1e3 / (2 * np.pi * 2000.0)
    post = post_lag_response(lagged, np.r_[theta, slow_tau_ms], d[:, None])
    pre = r2_response(lagged, np.r_[theta, slow_tau_ms], d)
    # through the lag the current is filtered: the post-lag port is nearer the plain one
    assert np.max(np.abs(post - ref)) < 0.5 * np.max(np.abs(pre - ref))


def test_a_foreign_capped_loop_is_found_and_modelled(tmp_path):
    """On a foreign record (1 s) whose amplifier's current loop of 1.7 kHz is capped at
    0.91 times the rms rate it asks, the linearity check fails, the loop is modelled (its
    lag exact, loop_model.py) and its rate and bandwidth land within 10 % of the truth
    (the held cap's bias on seven records was up to 5.5 %, LOOP_REL_SD)."""
    from bayes_amb.discrepancy.adequacy import nominal_assessment
    from bayes_amb.discrepancy.library.bearing_coefficient import BEARING_COEFFICIENTS
    from bayes_amb.io.recording import load_recording
    from benchmarks.foreign import draw_case, write_case
    from benchmarks.foreign.benchmark import _controller_file
    rng = np.random.default_rng(25)
    spec = draw_case("amp_voltage_limit", rng, controller_file=str(
        _controller_file(tmp_path, 1e-4)), duration_s=1.0)
    paths = write_case(spec, tmp_path, "amp", rng)
    truth = json.loads(paths["truth"].read_text())["effects"][0]["params"]
    checks, fit, _ = nominal_assessment(load_recording(paths["csv"]), BEARING_COEFFICIENTS)
    lin = next(c for c in checks.checks if c.name == "linearity")
    assert not lin.ok and lin.values["modelled"] == "amp_current_loop"
    est = lin.values["nonlinearity"]["estimate"]
    assert abs(est["all"] / truth["slew_a_per_s"] - 1) < 0.1
    assert abs(est["bandwidth_hz"] / truth["bandwidth_hz"] - 1) < 0.1
    assert [c.key for c in fit.candidates] == ["actuator_lag@both"]
