"""The amplifier's current loop with its rate capped (discrepancy/loop_waveform.py and
current_loop.py): the waveform in its limits and against the continuous lag, and the
screen's decision on foreign records whose amplifier is known."""

from __future__ import annotations

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
