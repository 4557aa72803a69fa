"""Nonparametric frequency response (excitation as instrument) against the model.

A noise-free closed loop (reduced truth, k_By = 0.3, dt = 1e-3 s) is excited by a periodic
multisine in four records whose channel signs follow a 4 x 4 Hadamard matrix, so that the
four excitation vectors at every excited bin are independent. After the transient, whole
periods with a rectangular window have no leakage: on the excited bins the joint
input-output estimate must equal the sampled plant C (zI - Ad)^-1 Bd to round-off.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from bayes_amb.control.discrete import zoh
from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.engineering import Draws, frequency_responses, joint_io_frf
from bayes_amb.errors import BayesAmbError
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, simulate_recording
from bayes_amb.simulate.loop import simulate_loop
from bayes_amb.simulate.signals import multisine
from bayes_amb.simulate.truth import build_truth

DT = 1e-3
PERIOD = 500          # samples: 2 Hz lines
N_PERIODS = 6         # the first 3 are dropped as transient


@pytest.fixture(scope="module")
def setup():
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, DT), rig)
    truth = build_truth(rig, rig.nominal_speed_rpm, "reduced", {"k_By": 0.3})
    return rig, ctrl, truth


def test_instrumented_frf_equals_the_model_on_excited_bins(setup):
    _rig, ctrl, truth = setup
    s = multisine(PERIOD, 4, 0.5, np.random.default_rng(1), DT, (4.0, 400.0), n_lines=60)
    H = sla.hadamard(4).astype(float)
    records = []
    for b in range(4):
        eta = np.tile(s * H[b][None], (N_PERIODS, 1))
        sig = simulate_loop(truth, (ctrl.A, ctrl.B, ctrl.C, ctrl.D), DT, eta)
        assert not sig.unstable
        records.append((eta, sig.u, sig.y))
    est = joint_io_frf(records, DT, PERIOD, window="boxcar", overlap=0.0, skip=3 * PERIOD)
    assert est.n_segments == 4 * (N_PERIODS - 3)
    spec = np.abs(np.fft.rfft(s, axis=0))[1:PERIOD // 2 + 1]
    excited = np.all(spec > 1e-6 * spec.max(), axis=1)
    assert excited.sum() >= 40
    Ad, Bd = zoh(truth.A, truth.B, DT)
    z = np.exp(2j * np.pi * est.freq_hz[excited] * DT)
    G = np.stack([truth.C @ np.linalg.solve(zk * np.eye(Ad.shape[0]) - Ad, Bd) for zk in z])
    err = np.abs(est.G[excited] - G).max() / np.abs(G).max()
    assert err < 1e-6, err        # measured 2.6e-15
    # noise-free: the excitation explains all of y on the excited bins
    assert np.all(est.coherence[excited] > 1 - 1e-9)


def test_frequency_responses_with_noise_stay_inside_a_sane_band(setup):
    """Realistic use on a noisy random-binary recording: the measured plant magnitude lies
    within a factor 1.5 of the model at the true theta where the coherence is high, and
    the posterior band of a single draw collapses onto that draw."""
    rig, ctrl, _ = setup
    rec, _ = simulate_recording(rig, ctrl, SimulationConfig(
        truth="reduced", params={"k_By": 0.3}, dt=DT, duration=2.0, noise_rms=1e-7, seed=4))
    r = frequency_responses(Draws(("k_By",), [[0.3]]), rec, model="reduced", nperseg=256)
    np.testing.assert_array_equal(r.plant_band[0], r.plant_band[2])
    good = (r.coherence > 0.9) & (r.freq_hz[:, None] < 300)
    assert good.sum() > 50
    ratio = r.plant_measured[good] / r.plant_band[1][good]
    assert np.all((ratio > 1 / 1.5) & (ratio < 1.5)), (ratio.min(), ratio.max())
    assert np.all(r.compliance_band[1] > 0)


def test_bad_segment_length_is_rejected():
    x = np.zeros((100, 4))
    with pytest.raises(BayesAmbError, match="nperseg"):
        joint_io_frf([(x, x, x)], DT, 4)
    with pytest.raises(BayesAmbError, match="longer than every record"):
        joint_io_frf([(x, x, x)], DT, 512)


def test_response_snr_is_infinite_without_noise_and_follows_the_noise_level(setup):
    """Noise-free data: y is all excitation response (the rest is round-off). With sensor
    noise, the rest is the noise as the loop shapes it, y_noisy - y_clean (same seed, same
    excitation; the loop is linear), and the noise-driven part is not the bare sensor
    noise: the loop amplifies it (|S| > 1 near crossover)."""
    from bayes_amb.engineering.snr import excitation_response, response_snr_db

    rig, ctrl, _ = setup
    cfg = SimulationConfig(truth="reduced", params={"k_By": 0.3}, dt=DT, duration=4.0,
                           seed=7)
    clean, _ = simulate_recording(rig, ctrl, cfg)
    # round-off: the controller file's copy of the nominal model equals this process's
    # reduction to ~1e-10 when they were made with other BLAS thread counts (a rotated
    # basis, forward.state_transform), i.e. an SNR floor near 190 dB
    assert np.all(response_snr_db(clean, {"k_By": 0.3}, "reduced") > 170)
    sigma = 2e-7
    noisy, _ = simulate_recording(rig, ctrl, SimulationConfig(
        truth="reduced", params={"k_By": 0.3}, dt=DT, duration=4.0, seed=7,
        noise_rms=sigma))
    p_x = np.mean(excitation_response(clean, {"k_By": 0.3}, "reduced") ** 2, axis=0)
    rest = np.mean((noisy.y - clean.y) ** 2, axis=0)
    snr = response_snr_db(noisy, {"k_By": 0.3}, "reduced")
    np.testing.assert_allclose(snr, 10 * np.log10(p_x / rest), atol=1e-6)
    assert np.all(rest > sigma**2)


def test_the_pool_of_threads_gives_the_serial_bands_to_the_bit(setup, monkeypatch):
    """The draws run in a pool of threads (threads.pool_threads): one thread and two give
    the same bands to the bit."""
    rig, ctrl, _ = setup
    rec, _ = simulate_recording(rig, ctrl, SimulationConfig(
        truth="reduced", params={"k_By": 0.3}, dt=DT, duration=0.5, noise_rms=1e-7, seed=5))
    draws = Draws(("k_By", "c_By"), [[0.3, 0.0], [0.25, 0.1], [0.35, -0.1], [0.3, 0.05]])
    got = {}
    for n in ("1", "2"):
        monkeypatch.setenv("BAYES_AMB_POOL", n)
        r = frequency_responses(draws, rec, model="reduced", nperseg=128)
        got[n] = (r.plant_band, r.compliance_band, r.plant_nominal)
    for a, b in zip(got["1"], got["2"], strict=True):
        np.testing.assert_array_equal(a, b)
