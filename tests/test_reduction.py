"""Pseudo-modal reduction (eqs. 18-45) and its fidelity (Fig. 5): identity tests."""

from __future__ import annotations

import numpy as np
import pytest

from bayes_amb.errors import ReductionError
from bayes_amb.reduction import reduce_pseudo_modal
from bayes_amb.reduction.fidelity import singular_value_data
from bayes_amb.reduction.pseudo_modal import select_modes
from bayes_amb.rig import load_rig
from bayes_amb.rotor import FullModel, full_model
from bayes_amb.uncertainty.accuracy import matched_relative_error

SPEEDS = [0.0, 5000.0, 15000.0, 31500.0]


@pytest.fixture(scope="module")
def rig():
    return load_rig()


@pytest.fixture(scope="module")
def models(rig):
    return {s: full_model(rig, s) for s in SPEEDS}


@pytest.mark.parametrize("speed", SPEEDS)
@pytest.mark.parametrize(("n_bending", "n_states"), [(0, 8), (1, 12), (2, 16)])
def test_reduced_eigenvalues_are_the_kept_full_ones(models, speed, n_bending, n_states):
    """Identity: eig(T_L A_f T_R) equals the n smallest-modulus eigenvalues of A_f to
    relative 1e-8 (matched by assignment; measured ~5e-9, the eigensolver's accuracy on
    the 320-state A_f); T_L T_R = I to 1e-10; shapes of B and C."""
    fm = models[speed]
    red = reduce_pseudo_modal(fm, n_bending=n_bending)
    assert red.n_states == n_states
    assert red.B.shape == (n_states, 4) and red.C.shape == (4, n_states)
    assert np.isrealobj(red.A) and np.isrealobj(red.T_L) and np.isrealobj(red.T_R)
    kept = fm.poles[:n_states]
    assert np.max(matched_relative_error(np.linalg.eigvals(red.A), kept)) < 1e-8
    assert np.max(matched_relative_error(red.poles, kept)) < 1e-8
    assert np.abs(red.T_L @ red.T_R - np.eye(n_states)).max() < 1e-10


def test_reduced_model_keeps_the_four_unstable_poles(models):
    """The 8 kept eigenvalues at 31500 rpm contain the 4 RHP poles of the full model."""
    red = reduce_pseudo_modal(models[31500.0])
    assert np.sum(red.poles.real > 0) == 4
    assert np.sum(np.linalg.eigvals(red.A).real > 0) == 4


def test_reduce_from_rig_uses_nominal_speed(rig):
    red = reduce_pseudo_modal(rig)
    assert red.speed_rpm == rig.nominal_speed_rpm and red.n_states == 8


def test_select_modes_rejects_coinciding_moduli():
    """|lambda_8| = |lambda_9| (a real pair -4 and an imaginary pair +/-4j) -> error."""
    lam = np.array([1, -1, 2, -2, 3, -3, 4, -4, 4j, -4j, 9], dtype=complex)
    with pytest.raises(ReductionError, match="cannot be separated"):
        select_modes(lam, 8)
    assert np.array_equal(select_modes(lam, 6), np.arange(6))


def test_select_modes_rejects_split_pair():
    """A kept complex eigenvalue without its conjugate in the kept set -> error."""
    lam = np.array([1 + 2j, 1 + 2j, 5, 6], dtype=complex)
    with pytest.raises(ReductionError, match="splits the conjugate pair"):
        select_modes(lam, 2)


@pytest.mark.parametrize("n_keep", [0, 4])
def test_select_modes_rejects_out_of_range(n_keep):
    with pytest.raises(ReductionError, match=f"cannot keep {n_keep} modes"):
        select_modes(np.array([1, 2, 3, 4], dtype=complex), n_keep)


def _synthetic_model(eigs: list[complex]) -> FullModel:
    """Real block-diagonal A with the given eigenvalues (pairs as 2x2 blocks)."""
    blocks = []
    for e in eigs:
        if e.imag == 0:
            blocks.append(np.array([[e.real]]))
        else:
            blocks.append(np.array([[e.real, -e.imag], [e.imag, e.real]]))
    n = sum(b.shape[0] for b in blocks)
    A = np.zeros((n, n))
    i = 0
    for b in blocks:
        A[i:i + b.shape[0], i:i + b.shape[0]] = b
        i += b.shape[0]
    rng = np.random.default_rng(1)
    return FullModel(A=A, B=rng.standard_normal((n, 4)), C=rng.standard_normal((4, n)),
                     speed_rpm=0.0, matrices=None)


def test_reduce_rejects_cut_between_equal_moduli():
    """Synthetic model: 8th and 9th eigenvalues have modulus 4 -> ReductionError."""
    fm = _synthetic_model([1, -1, 2, -2, 3, -3, 4, -4, 4j, 20 + 30j])
    with pytest.raises(ReductionError, match="cannot be separated"):
        reduce_pseudo_modal(fm)


def test_reduce_synthetic_model_with_a_gap():
    """Synthetic model with a gap after 8 eigenvalues: exact eigenvalues, T_L T_R = I."""
    fm = _synthetic_model([1, -1, 2, -2, 3 + 1j, -4, 5, 10j, 20 + 30j])
    red = reduce_pseudo_modal(fm)
    assert red.n_states == 8
    expected = np.array([1, -1, 2, -2, 3 + 1j, 3 - 1j, -4, 5], dtype=complex)
    assert np.max(matched_relative_error(np.linalg.eigvals(red.A), expected)) < 1e-12
    assert np.abs(red.T_L @ red.T_R - np.eye(8)).max() < 1e-12


def test_negative_n_bending_is_an_error(rig):
    with pytest.raises(ReductionError, match="n_bending must be >= 0"):
        reduce_pseudo_modal(rig, n_bending=-1)


@pytest.mark.parametrize("speed", SPEEDS)
def test_fidelity_below_half_first_bending(models, speed):
    """Fig. 5 analogue: largest singular value of the 8-state model within 1 dB of the full
    model up to half the first bending frequency (measured 0.04-0.05 dB); that limit is
    > 3000 rad/s, i.e. the first bending mode (not a rigid one) is the first left out."""
    sv = singular_value_data(reduce_pseudo_modal(models[speed]))
    assert sv.first_bending_rad_s > 6000.0
    assert sv.max_gap_db() < 1.0
    assert sv.sv_full.shape == sv.sv_reduced.shape == (sv.omega.size, 4)


def test_fidelity_gap_is_large_past_the_first_bending_mode(models):
    """The reduced model leaves the bending modes out: over the whole range (to 5e4 rad/s,
    past the second bending pair) the gap exceeds 10 dB, so max_gap_db can detect a misfit."""
    sv = singular_value_data(reduce_pseudo_modal(models[31500.0]))
    assert sv.max_gap_db(upto_rad_s=sv.omega[-1]) > 10.0


def test_keeping_chosen_bending_pairs_keeps_exactly_their_poles():
    """keep_bending_pairs(red, (2,)): the rigid-body poles and pair 2's, none of pair 1's;
    the kept system's poles are its A's eigenvalues (A block diagonal in the modal basis)."""
    from bayes_amb.reduction.pseudo_modal import keep_bending_pairs
    red = reduce_pseudo_modal(load_rig(), n_bending=2)
    sub = keep_bending_pairs(red, (2,))
    assert sub.n_states == 12
    want = np.concatenate([red.poles[:8], red.poles[12:16]])
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(sub.A)),
                               np.sort_complex(want), rtol=1e-8)
    assert np.min(np.abs(np.linalg.eigvals(sub.A)[:, None] - red.poles[8:12][None])) > 100
    np.testing.assert_allclose(sub.T_L @ sub.T_R, np.eye(12), atol=1e-9)
    with pytest.raises(ReductionError):
        keep_bending_pairs(red, (3,))


def test_residual_static_is_the_static_compliance_of_the_left_out_modes(models):
    """Identity: residual_static = C_f(-A_f^-1)B_f - C(-A^-1)B of the reduction, and the
    difference between two cuts is the static compliance of the pair between them.

    The first route is a difference of two numbers ~1e4 apart solved with A_f (condition
    ~7e14): it agrees to 1e-3 (measured 2e-4). The second involves only the reduced models
    and agrees to 1e-6 (measured 8e-8 and 7e-9 for pairs 1 and 2)."""
    from bayes_amb.reduction.pseudo_modal import keep_bending_pairs, residual_static
    fm = models[31500.0]
    red = reduce_pseudo_modal(fm, n_bending=2)
    kept_static = {p: -r.C @ np.linalg.solve(r.A, r.B)
                   for p, r in (((), keep_bending_pairs(red, ())),
                                ((1,), keep_bending_pairs(red, (1,))),
                                ((2,), keep_bending_pairs(red, (2,))))}
    full_static = -fm.C @ np.linalg.solve(fm.A, fm.B)
    res = {p: residual_static(fm, p) for p in kept_static}
    scale = np.abs(res[()]).max()
    assert np.abs(full_static - kept_static[()] - res[()]).max() < 1e-3 * scale
    for p in ((1,), (2,)):
        pair = kept_static[p] - kept_static[()]
        assert np.abs(pair).max() > 1e-3 * scale             # the pair matters
        assert np.abs(res[()] - res[p] - pair).max() < 1e-6 * np.abs(pair).max()
