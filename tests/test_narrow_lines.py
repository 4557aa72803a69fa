"""The narrowband lines identify leaves out of its likelihood (inference/narrow_lines.py),
on synthetic residual DFTs whose lines are known."""

from __future__ import annotations

import numpy as np
import pytest

from bayes_amb.inference.narrow_lines import LINE_P, find_narrow_lines, local_level

NF = 2000
DF = 0.5


def _noise(rng: np.random.Generator) -> np.ndarray:
    g = rng.standard_normal((NF, 4, 2))
    return (g[..., 0] + 1j * g[..., 1]) * np.sqrt(0.5)


def _case(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return _noise(rng), _noise(rng), (np.arange(NF) + 1) * DF


def test_noise_alone_has_no_line_at_the_test_level():
    """Complex Gaussian residuals with a random excitation: the share of records with any
    line is the test's level, LINE_P (Bonferroni over bins and channels). Over 300 records
    the expected count is 0.3; 4 or more has probability 4e-3 under that level."""
    found = sum(bool(find_narrow_lines(*_case(s)).lines) for s in range(300))
    assert found <= 3


def test_a_line_is_found_on_its_channel_and_left_out():
    """A line 30 times the noise power (15 dB) at 60 Hz on the Ay channel only."""
    R, X, f = _case(1)
    k = round(60.0 / DF) - 1
    R[k, 1] += np.sqrt(30.0)
    out = find_narrow_lines(R, X, f)
    assert np.flatnonzero(out.drop).tolist() == [k]
    (line,) = out.lines
    assert line["f_hz"] == pytest.approx(60.0) and line["channels"] == ["Ay"]
    assert line["bins"] == 1 and 12.0 < line["level_db"] < 18.0
    assert line["synchronous"] is False


def test_a_line_that_leaks_is_one_line_and_a_synchronous_one_says_so():
    """A line between two bins at 50.25 Hz (1x of 3015 rpm), 1e4 times the noise: its
    leaking neighbours are one line, marked synchronous."""
    R, X, f = _case(2)
    n = 2 * NF + 2
    t = np.arange(n) * (1.0 / (n * DF))
    line = np.fft.rfft(np.cos(2 * np.pi * 50.25 * t))[1:NF + 1]
    R[:, 0] += 100.0 * line / np.abs(line).max()
    out = find_narrow_lines(R, X, f, speed_rpm=3015.0)
    assert len(out.lines) == 1 and out.lines[0]["bins"] >= 2
    assert out.lines[0]["f_hz"] == pytest.approx(50.25, abs=DF)
    assert out.lines[0]["synchronous"] is True


def test_a_steep_edge_of_a_coloured_spectrum_is_no_line():
    """Noise whose power steps up by 1e4 at 300 Hz (a band-limited force's edge): each
    side of the edge is level with one of its neighbourhoods."""
    R, X, f = _case(3)
    R[f >= 300.0] *= 100.0
    assert not find_narrow_lines(R, X, f).lines


def test_a_multisine_s_excited_bins_are_never_lines():
    """A multisine excites every seventh bin; the model's misfit puts 1000 times the noise
    there. Those bins are the excitation's, not lines."""
    R, X, f = _case(4)
    excited = np.zeros(NF, dtype=bool)
    excited[::7] = True
    X[~excited] *= 1e-6
    R[excited] *= np.sqrt(1000.0)
    assert not find_narrow_lines(R, X, f).lines


def test_the_lowest_bins_are_no_line():
    """Drift puts 1e4 times the noise into the two lowest bins: no line."""
    R, X, f = _case(5)
    R[:2] *= 100.0
    assert not find_narrow_lines(R, X, f).lines


def test_the_local_level_is_the_larger_side_s_median():
    p = np.ones((300, 1))
    p[150:] = 9.0
    lv = local_level(p)
    assert lv[149, 0] == 9.0 and lv[150, 0] == 9.0 and lv[10, 0] == 1.0
    assert LINE_P < 0.01
