"""The compiled modal form (bayes_amb.inference.eigen) against LAPACK's (issue 16).

A modal form is right when it reproduces the system's transfer function: for every
member, Cm diag(1 / (z - lam)) Bm must equal C (z I - A)^-1 B. The reference is the direct
solve at each point (backward stable; its own error is of the order of u kappa(zI - A)).
The compiled decomposition must be as accurate as the one it replaces (np.linalg.eig, which
balances, then runs LAPACK geev, then solves V Bm = B): its error against the solve at most
a few times LAPACK's, plus a few units of rounding. Members it cannot take (a failed QR
iteration, an eigenvector residual above tolerance, a singular eigenvector basis) are flagged
and decomposed by LAPACK instead (diagonalise), never returned wrong.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.inference import kernels
from bayes_amb.inference.batched import zoh_batched, zoh_compiled
from bayes_amb.inference.eigen import final_state, modal_batch
from bayes_amb.inference.forward import (
    ForwardModel,
    _diagonalise_lapack,
    diagonalise,
    final_modal_state,
)
from bayes_amb.inference.hessenberg import _hqr
from bayes_amb.inference.loop_model import error_form_compiled, error_form_matrices
from bayes_amb.inference.qr_lanes import hqr_lanes
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, simulate_recording

U = 2.0**-53
NAMES = ("k_Ax", "k_Ay", "k_Bx", "k_By", "c_Ax", "c_Ay", "c_Bx", "c_By")


def _transfer(lam, Bm, Cm, z):
    """(nz, p, m) from a modal form of one member."""
    return np.einsum("ps,sm,ks->kpm", Cm, Bm, 1.0 / (z[:, None] - lam[None]))


def _solve(A, B, C, z):
    n = A.shape[0]
    return np.stack([C @ np.linalg.solve(zk * np.eye(n) - A, B) for zk in z])


def _errors(A, B, C, z):
    """Relative transfer-function error of the compiled and of LAPACK's modal form per
    member, and the compiled ok flags."""
    lam, Bm, Cm, ok = modal_batch(A, B, C)
    mb, _ = _diagonalise_lapack(A, B, C, None)
    new, old = [], []
    for b in range(A.shape[0]):
        ref = _solve(A[b], B[b], C[b], z)
        scale = np.max(np.abs(ref))
        new.append(np.max(np.abs(_transfer(lam[b], Bm[b], Cm[b], z) - ref)) / scale)
        old.append(np.max(np.abs(_transfer(mb.lam[b], mb.Bm[b], mb.Cm[b], z) - ref)) / scale)
    return np.array(new), np.array(old), ok


@pytest.fixture(scope="module")
def forward():
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, 1e-4), rig)
    cfg = SimulationConfig(truth="reduced", params={"k_By": 0.3}, dt=1e-4, duration=0.05,
                           seed=2)
    return ForwardModel(simulate_recording(rig, ctrl, cfg)[0], NAMES)


def _thetas(n, rng, spread=0.3):
    return np.clip(spread * rng.standard_normal((n, len(NAMES))), -0.79, 0.79)


def test_modal_form_of_the_likelihood_is_as_accurate_as_lapack(forward):
    A, B, C = forward.excitation_system(_thetas(24, np.random.default_rng(0)))
    C = np.broadcast_to(C, (A.shape[0], *C.shape[-2:]))
    z = np.exp(2j * np.pi * np.linspace(0.001, 0.5, 40))
    new, old, ok = _errors(A, B, C, z)
    assert ok.all()
    assert np.all(new <= 4 * old + 64 * A.shape[1] * U), np.max(new / old)
    # and the eigenvalues are LAPACK's (they are well conditioned here)
    lam = modal_batch(A, B, C)[0]
    ref = np.linalg.eigvals(A)
    for b in range(A.shape[0]):
        assert np.allclose(np.sort_complex(lam[b]), np.sort_complex(ref[b]), rtol=0, atol=1e-12)


@pytest.mark.parametrize("n", [1, 2, 3, 5, 8, 13, 24])
def test_random_systems_with_real_and_complex_modes(n):
    rng = np.random.default_rng(n)
    A = rng.standard_normal((40, n, n)) / np.sqrt(n)
    A[::4] *= 3.0                                    # some unstable members too
    A[1::4, :, : n // 2] *= 1e3                     # badly scaled ones (balancing)
    B, C = rng.standard_normal((40, n, 2)), rng.standard_normal((40, 3, n))
    z = np.exp(2j * np.pi * np.linspace(0.01, 0.5, 9)) * 1.3
    new, old, ok = _errors(A, B, C, z)
    assert ok.mean() > 0.9                           # LAPACK takes the rest
    assert np.all(new[ok] <= 4 * old[ok] + 1e3 * n * U), np.max(new[ok] / old[ok])
    n_real = (np.linalg.eigvals(A).imag == 0).sum()
    assert n_real > 0


def _hqr_alone(H):
    """EISPACK hqr on one Hessenberg matrix (member by member, as before the lock-step)."""
    a = np.triu(H, -1).copy()
    wr, wi = np.zeros(H.shape[0]), np.zeros(H.shape[0])
    ok = _hqr(a, wr, wi)
    return wr + 1j * wi, ok


STALLS = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""hqr does not converge on this (nilpotent) matrix in 30 iterations."""


@pytest.mark.parametrize("n", [1, 2, 3, 5, 8, 16, 24])
def test_lock_step_qr_is_member_by_member_hqr_bit_for_bit(n):
    """Each member's eigenvalues are those of hqr run on it alone, exactly, whatever else is
    in the batch (members of other scales, a repeated eigenvalue, one that does not
    converge, one not finite), and LAPACK's to rounding."""
    rng = np.random.default_rng(10 + n)
    H = np.triu(rng.standard_normal((37, n, n)), -1)
    H[1::5] *= 1e4
    H[2::5] *= 1e-3
    H[3] = np.diag(np.full(n, 0.5))                  # a repeated eigenvalue (deflates at once)
    H[4, 0, 0] = np.nan                              # not finite: not iterated
    if n == 3:
        H[5] = STALLS
    lam, ok = hqr_lanes(H)
    for b in range(37):
        if b == 4:
            assert not ok[b]
            continue
        ref, ok_ref = _hqr_alone(H[b])
        assert ok[b] == ok_ref
        if ok_ref:
            assert np.array_equal(lam[b], ref)
    assert ok.sum() == 35 if n == 3 else ok.sum() == 36
    lam_r, ok_r = hqr_lanes(H[::-1])                 # other neighbours, other order
    assert np.array_equal(lam_r[::-1][ok], lam[ok]) and np.array_equal(ok_r[::-1], ok)
    alone = hqr_lanes(H[7:8])[0]
    assert np.array_equal(alone[0], lam[7])
    for b in np.flatnonzero(ok):
        ref = np.linalg.eigvals(H[b])
        scale = np.abs(H[b]).max()
        assert np.allclose(np.sort_complex(lam[b]), np.sort_complex(ref), rtol=0,
                           atol=1e-9 * scale)


def test_lock_step_qr_on_the_likelihoods_matrices(forward):
    """The benchmark's kind of matrix (S(theta) in error coordinates, 16 states) after
    balancing and the Hessenberg reduction, as the modal form sees it; a member that does
    not converge is reported so and leaves the others alone."""
    A = forward.excitation_system(_thetas(20, np.random.default_rng(8)))[0]
    H = np.stack([sla.hessenberg(a) for a in A])
    H[6, :3, :3], H[6, 3:, :3] = STALLS, 0.0
    H[6, :3, 3:] = 0.0
    lam, ok = hqr_lanes(H)
    assert not ok[6] and ok.sum() == 19
    for b in np.flatnonzero(ok):
        ref, ok_ref = _hqr_alone(H[b])
        assert ok_ref and np.array_equal(lam[b], ref)
        assert np.allclose(np.sort_complex(lam[b]), np.sort_complex(np.linalg.eigvals(A[b])),
                           rtol=0, atol=1e-12)
    assert not _hqr_alone(H[6])[1]


def test_members_it_cannot_take_are_flagged_and_decomposed_by_lapack():
    rng = np.random.default_rng(1)
    A = 0.3 * rng.standard_normal((4, 6, 6))
    A[1] = np.diag(np.full(6, 0.5)) + np.diag(np.ones(5), 1)      # one Jordan block
    A[2] = 0.5 * np.eye(6)                                          # a repeated eigenvalue
    A[3, 2, 2] = np.nan
    B, C = rng.standard_normal((6, 2)), rng.standard_normal((3, 6))
    ok = modal_batch(A, B, C)[3]
    assert ok.tolist() == [True, False, False, False]
    mb, _ = diagonalise(A, B, C)
    assert mb.stable.tolist() == [True, True, True, False]
    ref, _ = _diagonalise_lapack(A[1:3], np.broadcast_to(B, (2, 6, 2)),
                                 np.broadcast_to(C, (2, 3, 6)), None)
    assert np.array_equal(mb.lam[1:3], ref.lam)                    # LAPACK's eigenvalues
    z = np.array([1.2 + 0.3j, -0.9j])                    # (the Jordan block has no modal
    assert np.allclose(_transfer(mb.lam[2], mb.Bm[2], mb.Cm[2], z),    # form at all)
                       _solve(A[2], B, C, z), rtol=1e-12)


def test_conjugate_pairs_are_exact_and_adjacent(forward):
    A, B, C = forward.excitation_system(_thetas(5, np.random.default_rng(2)))
    lam, Bm, Cm, _ = modal_batch(A, B, C)
    for b in range(5):
        s = 0
        while s < lam.shape[1]:
            if lam[b, s].imag == 0:
                assert not np.any(Bm[b, s].imag) and not np.any(Cm[b, :, s].imag)
                s += 1
                continue
            assert lam[b, s].imag > 0 and lam[b, s + 1] == np.conj(lam[b, s])
            assert np.array_equal(Bm[b, s + 1], np.conj(Bm[b, s]))
            assert np.array_equal(Cm[b, :, s + 1], np.conj(Cm[b, :, s]))
            s += 2


def test_compiled_modal_state_equals_the_numpy_one(forward):
    """Each eigenvalue's own number of terms (|lam|^q > 1e-13) instead of the batch's: the
    sums agree to the truncation, 1e-13 of the terms' sizes."""
    mb, _ = diagonalise(*forward.excitation_system(_thetas(6, np.random.default_rng(3))))
    x = np.random.default_rng(4).standard_normal((3000, 4))
    new = final_state(mb.lam, mb.Bm, x, 1e-13)
    ref = final_modal_state(mb.lam, mb.Bm, x)
    size = np.abs(mb.Bm).sum(axis=2) * np.abs(x).max() / (1 - np.abs(mb.lam))
    assert np.all(np.abs(new - ref) <= 1e-12 * size)
    assert not np.all(np.abs(new * (1 + 1e-9) - ref) <= 1e-12 * size)


@pytest.mark.parametrize("dt", [1e-4, 1e-3, 2e-2])     # no, one and several squarings
def test_compiled_zoh_and_error_form_equal_the_numpy_ones(forward, dt):
    pl = forward.plant
    th = _thetas(7, np.random.default_rng(5))
    diag = np.repeat(th, pl.blocks, axis=1)
    A = pl.A[None] + np.einsum("ir,br,rj->bij", pl.B_w, diag, pl.C_z)
    F0, G0 = zoh_batched(A, pl.B, dt)
    F1, G1 = zoh_compiled(A, pl.B, dt)
    # both are the exponential to rounding: the Taylor series truncated below 1e-20, then
    # s squarings, each multiplying the relative error by about 2 ||F||
    s = max(0, int(np.ceil(np.log2(np.abs(np.concatenate([A, np.broadcast_to(
        pl.B, (7, *pl.B.shape))], axis=2)).sum(axis=2).max() * dt / 0.5))))
    tol = 64 * U * 4.0**s
    assert np.max(np.abs(F1 - F0)) <= tol * np.max(np.abs(F0))
    assert np.max(np.abs(G1 - G0)) <= tol * np.max(np.abs(G0))
    Ad, Bd, C = forward.nominal
    ref = error_form_matrices(Ad, Bd, C, forward.F, forward.L, F0, G0)
    new = error_form_compiled(Ad, Bd, C, forward.F, forward.L, F0, G0)
    for r, n in zip(ref, new, strict=True):
        assert np.allclose(n, r, rtol=0, atol=8 * U * np.max(np.abs(r)))


def test_non_finite_plants_are_flagged_not_raised(forward):
    th = _thetas(3, np.random.default_rng(6))
    th[1, 0] = np.inf
    mb, _ = forward.modal(th)
    assert mb.stable.tolist() == [True, False, True]


def test_the_kernel_choice_selects_the_modal_form(forward, monkeypatch):
    th = _thetas(3, np.random.default_rng(7))
    monkeypatch.setattr(forward, "engine", kernels.Engine("lapack"))
    mb_lapack, _ = forward.modal(th)
    ref, _ = _diagonalise_lapack(*forward.excitation_system(th), None)
    monkeypatch.setattr(forward, "engine", kernels.Engine("numba"))
    mb_numba, _ = forward.modal(th)
    assert np.array_equal(mb_lapack.lam, ref.lam) and np.array_equal(mb_lapack.Bm, ref.Bm)
    assert not np.allclose(mb_numba.Bm, ref.Bm)              # another eigenvector scaling
    z = np.exp(0.3j)
    for b in range(3):
        assert np.allclose(_transfer(mb_numba.lam[b], mb_numba.Bm[b], mb_numba.Cm[b], z[None]),
                           _transfer(ref.lam[b], ref.Bm[b], ref.Cm[b], z[None]), rtol=1e-10)
