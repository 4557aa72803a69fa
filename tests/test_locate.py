"""The location tests keep their false-alarm rate when the noise is coloured (issue 14).

A real rig's sensor noise is coloured; the loop noise model is white at each source. The
cross-correlation and time-window tests then see a coloured residual, whose lags (or
samples) are correlated: the plain statistics have heavier tails than their chi-square /
Bartlett nulls. locate flattens both series by their own smoothed spectra first. Here the
p-values of the flattened tests must be uniform on independent coloured noise, and the
plain ones are shown not to be (so the check can fail).
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from bayes_amb.discrepancy.locate import _windows, _xcorr, flat_series

N, REPS, LAGS, LEVEL = 4000, 150, 25, 0.05


def _draws(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    e = lfilter([1.0], [1.0, -0.9], rng.standard_normal((N, 1)), axis=0)   # AR(1) residual
    x = rng.choice([-1.0, 1.0], size=(N, 1))                                # white excitation
    return e, x


def _rate(flat: bool, test: str) -> float:
    rng = np.random.default_rng(1)
    hits = 0
    for _ in range(REPS):
        e, x = _draws(rng)
        if flat:
            e = flat_series(e)
        if test == "xcorr":
            p = _xcorr(e, flat_series(x) if flat else x, LAGS)[1][0, 0]
        else:
            p = _windows(e, 8, 1e-4)[0][0]
        hits += p < LEVEL
    return hits / REPS


def _bound() -> float:
    """Three binomial standard errors of the rejection rate at LEVEL over REPS draws."""
    return 3.0 * np.sqrt(LEVEL * (1 - LEVEL) / REPS)


def test_flattened_crosscorr_keeps_its_level_on_coloured_noise():
    assert abs(_rate(True, "xcorr") - LEVEL) <= _bound()


def test_flattened_windows_keeps_its_level_on_coloured_noise():
    assert abs(_rate(True, "windows") - LEVEL) <= _bound()


def test_unflattened_tests_do_not_on_the_same_noise():
    """The reason for the flattening: on the same draws the plain tests reject too often."""
    assert _rate(False, "xcorr") > LEVEL + _bound()
    assert _rate(False, "windows") > LEVEL + _bound()


def test_flattening_keeps_a_real_correlation():
    """A residual that is 5 % the excitation (through a short filter) plus coloured noise
    is still found."""
    rng = np.random.default_rng(2)
    e, x = _draws(rng)
    e = e + 0.05 * np.std(e) * lfilter([0.0, 1.0, 0.5], [1.0], x, axis=0)
    assert _xcorr(flat_series(e), flat_series(x), LAGS)[1][0, 0] < 1e-3


def test_running_speed_is_read_from_the_1x_line():
    """A line 0.4 % off the written speed, 0.3 x the noise rms on one channel of a 2 s
    record: the estimate is within 0.01 % (the written speed is 0.4 % off); also when
    the line is aliased (1 kHz sampling of a 525 Hz line)."""
    from bayes_amb.discrepancy.locate import synchronous_speed
    rng = np.random.default_rng(5)
    for dt in (1e-4, 1e-3):
        n = int(2.0 / dt)
        t = np.arange(n) * dt
        f_true = 525.0 * 1.004
        r = rng.standard_normal((n, 4))
        r[:, 2] += 0.3 * np.sqrt(2) * np.cos(2 * np.pi * f_true * t + 1.0)
        est = synchronous_speed(r, dt, 31500.0)
        assert abs(est / (60 * f_true) - 1) < 1e-4, (dt, est)
