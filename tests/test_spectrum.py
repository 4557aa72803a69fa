"""The noise spectrum learned from a record (inference/spectrum.py): its algebra, and what it
learns on a record whose actuator-side force is band-limited. Its calibration on the
foreign generator is in docs/identify.md ("Coloured noise")."""

import numpy as np
import pytest

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.inference.spectrum import (
    MIN_KNOT_BINS,
    _Objective,
    colour_transform,
    hat_basis,
    knot_frequencies,
)
from bayes_amb.planning import Design, Noise
from bayes_amb.planning.plan import BEARING_COEFFICIENTS, design_recording
from bayes_amb.rig import load_rig


def test_the_colour_transform_folds_a_colour_into_a_spectrum():
    """T Phi T^H = L C L^H for L the Cholesky factor of Phi, on random Hermitian positive
    definite stacks; the identity colour leaves Phi alone."""
    rng = np.random.default_rng(1)
    A = rng.standard_normal((5, 4, 4)) + 1j * rng.standard_normal((5, 4, 4))
    Phi = A @ np.conj(np.swapaxes(A, 1, 2)) + 4 * np.eye(4)
    B = rng.standard_normal((5, 4, 4)) + 1j * rng.standard_normal((5, 4, 4))
    C = B @ np.conj(np.swapaxes(B, 1, 2)) / 4 + np.eye(4)
    T = colour_transform(Phi, C)
    L = np.linalg.cholesky(Phi)
    assert np.allclose(T @ Phi @ np.conj(np.swapaxes(T, 1, 2)),
                       L @ C @ np.conj(np.swapaxes(L, 1, 2)))
    assert np.allclose(colour_transform(Phi, np.broadcast_to(np.eye(4), C.shape)),
                       np.eye(4))


def test_knots_are_spaced_in_log_frequency_but_never_closer_than_their_bins():
    f = np.arange(1, 1029) * 0.5                      # a 2 s record's bins up to 514 Hz
    k = knot_frequencies(f, 0.5)
    assert k[0] == f[0] and k[-1] == f[-1]
    assert np.all(np.diff(k) >= MIN_KNOT_BINS * 0.5 - 1e-9)
    ratio = np.diff(np.log(k))
    assert ratio[-1] < 2 * ratio[len(ratio) // 2]      # evenly in log f above the floor
    B = hat_basis(np.log(f), np.log(k))
    assert np.allclose(B.sum(axis=1), 1.0) and np.all(B >= 0)


@pytest.mark.parametrize("compiled", [True, False])
def test_the_objectives_gradient_is_its_derivative(compiled):
    """The penalised -log L of the knot values and its analytic gradient agree with central
    differences (relative 1e-5) on random filters and band sums, compiled
    (hermitian_kernels.spectrum_terms) and in numpy, and the two agree to rounding."""
    rng = np.random.default_rng(2)
    nb, K = 12, 4
    h = rng.standard_normal((3, 4, nb, 4)) + 1j * rng.standard_normal((3, 4, nb, 4))
    G = h[..., :, None] * np.conj(h[..., None, :])
    R = rng.standard_normal((nb, 6, 4)) + 1j * rng.standard_normal((nb, 6, 4))
    Pb = np.einsum("bkc,bkd->bcd", R, np.conj(R))
    B = hat_basis(np.linspace(0, 1, nb), np.linspace(0, 1, K))
    obj = _Objective(G, Pb, np.full(nb, 6.0), 1, B, compiled)
    obj.centre = rng.standard_normal((12, K)) * 0.1
    a = rng.standard_normal(12 * K) * 0.3
    val, grad = obj(a)
    other = _Objective(G, Pb, np.full(nb, 6.0), 1, B, not compiled)
    other.centre = obj.centre
    val2, grad2 = other(a)
    assert abs(val - val2) <= 1e-10 * abs(val)
    assert np.allclose(grad, grad2, rtol=1e-9, atol=1e-10 * np.abs(grad).max())
    num = np.empty_like(a)
    for j in range(a.size):
        e = np.zeros_like(a)
        e[j] = 1e-6
        num[j] = (obj(a + e)[0] - obj(a - e)[0]) / 2e-6
    assert np.allclose(grad, num, rtol=1e-5, atol=1e-6 * abs(val))


def _low_pass_record():
    """1 s at 10 kHz, random binary 1 A, 20 nm sensor noise, r2 0.01 A below 60 Hz."""
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, 1e-4), rig)
    rec, _ = design_recording(rig, ctrl, Design(duration=1.0, amplitude=1.0),
                              Noise(noise_rms=2e-8, r2_rms=0.01, r2_band_hz=60.0), seed=3)
    return rec


@pytest.fixture(scope="module")
def low_pass_identification():
    return identify(_low_pass_record(), BEARING_COEFFICIENTS,
                    options=IdentifyOptions(map_only=True, adequacy=False))


@pytest.fixture(scope="module")
def line_record():
    """The low-pass force record with a 150 Hz line added to the Ax probe (100 nm, five
    times the sensor noise's rms, above the force's band, on the measurement after the
    fact)."""
    from dataclasses import replace

    rec = _low_pass_record()
    y = np.array(rec.y, dtype=float)
    t = np.arange(y.shape[0]) * rec.dt
    y[:, 0] += 1e-7 * np.cos(2 * np.pi * 150.0 * t + 0.3)
    return replace(rec, y=y)


def test_a_low_pass_force_is_learned_where_it_is(low_pass_identification):
    """r2 below 60 Hz (4th-order Butterworth): the spectrum is adopted (its likelihood ratio
    far past the test), and the learned r2 gain is at least 10 dB higher below 40 Hz than
    above 200 Hz on every channel (measured 15-16 dB: the filter falls 24 dB per octave,
    but above 200 Hz the sensor noise masks r2, and its gain there is the smoothness
    prior's continuation, which costs the likelihood nothing)."""
    sp = low_pass_identification.noise.spectrum
    assert sp is not None and sp.adopted and sp.lr_statistic > 5 * sp.dof
    f = np.array(sp.knot_hz)
    for ch, gains in sp.gain_db["r2"].items():
        g = np.array(gains)
        assert g[f < 40].mean() - g[f > 200].mean() > 10, ch


def test_a_mains_line_is_left_out_and_reported_with_its_frequency(low_pass_identification,
                                                                  line_record):
    """The 150 Hz line on Ax (line_record): its bin is left out of the likelihood before
    the fit and reported as a line at 150 Hz on Ax, not synchronous, and no other line; the
    record without it has none. With leave_out_lines=False the learned spectrum takes it as
    noise instead, as before."""
    res = identify(line_record, BEARING_COEFFICIENTS,
                   options=IdentifyOptions(map_only=True, adequacy=False))
    out = res.noise.lines_left_out
    assert out is not None and len(out) == 1, out
    assert out[0].f_hz == pytest.approx(150.0, abs=1.0) and "Ax" in out[0].channels
    assert not out[0].synchronous and out[0].bins <= 3
    like = res.likelihood
    f = like.k / (like.n * like.forward.dt)
    assert np.min(np.abs(f - 150.0)) > 0.5 and like.counts.sum() == like.k.size
    assert "left out of the likelihood" in res.summary() and "150 Hz" in res.summary()
    from bayes_amb.cli.identify_cmd import format_summary
    assert "lines left out of the likelihood (1 bins): 150 Hz" in format_summary(res)
    assert res.noise.spectrum is None or not res.noise.spectrum.lines
    assert low_pass_identification.noise.lines_left_out is None
    kept = identify(line_record, BEARING_COEFFICIENTS,
                    options=IdentifyOptions(map_only=True, adequacy=False,
                                            leave_out_lines=False))
    assert kept.noise.lines_left_out is None
    assert kept.noise.spectrum.lines is not None and len(kept.noise.spectrum.lines) == 1
    assert "lines taken as noise: 150 Hz" in kept.noise.spectrum.line


def test_identifys_adequacy_fit_leaves_the_line_out_and_the_diagnosis_keeps_it(line_record):
    """The same 150 Hz line on Ax: identify's adequacy test (nominal_assessment with
    learn) fits without its bin, as identify's likelihood has it, with each band's prior
    weight following its bin count; the diagnosis' nominal fit keeps it (its band spectra
    absorb a mains line, and a line at the running speed is physics it names)."""
    from bayes_amb.discrepancy.adequacy import nominal_assessment
    from bayes_amb.discrepancy.likelihood import P_CH

    names = ("k_By", "c_By")
    for learn, kept in ((True, False), (False, True)):
        _, fm, _ = nominal_assessment(line_record, names, learn=learn)
        like = fm.like
        f = like.k / (like.n * like.forward.dt)
        assert (np.min(np.abs(f - 150.0)) < 0.5) == kept, learn
        assert like.counts.sum() == like.k.size
        assert np.allclose(like.nu, like.prior_weight * like.counts + P_CH + 1.0)
        assert np.isfinite(fm.log_post)
