"""The compiled likelihood kernels equal the numpy path they replace (issue 16).

The kernels' arithmetic is compared on one modal form: the numpy path against
``BAYES_AMB_KERNEL=lapack`` (the compiled band sums on LAPACK's modal form), and the
walker-vectorised kernels against the walker-by-walker one. The compiled modal form itself
(bayes_amb.inference.eigen) is tested against LAPACK's in tests/test_eigen.py; the default
path end to end against the numpy path at the end of this file.

Tolerances follow from the floating-point arithmetic (u = 2^-53, gamma_n = n u / (1 - n u),
Higham, Accuracy and Stability of Numerical Algorithms, ch. 3): both paths evaluate the same
terms and differ only in the order of the sums, so each side's error is bounded by gamma of
the number of operations along the way times the sum of the *absolute values* of the
terms (the "majorant"); the difference of the two is at most twice that. A factor 4 covers
the constants of complex multiplication and division (|fl(ab) - ab| <= sqrt(5) u |a||b|).
A wrong term, sign or band boundary gives differences of order one against these bounds.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.discrepancy import ActuatorLag, Unbalance
from bayes_amb.discrepancy.likelihood import RobustWhittle
from bayes_amb.discrepancy.model import ExtendedForwardModel
from bayes_amb.inference import band_algebra, block_sums, kernels, residual_rows, walker_kernels
from bayes_amb.inference.forward import ForwardModel
from bayes_amb.inference.offline import dual_youla_eps
from bayes_amb.inference.whittle import WhittleLikelihood
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, parse_effect, simulate_recording

U = 2.0**-53
NAMES = ("k_Ax", "k_By", "c_Bx", "c_By")


def gamma(n: int) -> float:
    return n * U / (1 - n * U)


@pytest.fixture(scope="module")
def rec():
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, 1e-4), rig)
    cfg = SimulationConfig(truth="reduced", params={"k_By": 0.3, "c_Bx": 0.1}, dt=1e-4,
                           duration=0.1, noise_rms=2e-8, r2_rms=0.02, seed=5,
                           effects=(parse_effect("unbalance:u_kgm=2e-5"),))
    return simulate_recording(rig, ctrl, cfg)[0]


def _likelihoods(rec):
    fm = ForwardModel(rec, NAMES)
    eps = dual_youla_eps(fm.parts, np.asarray(rec.y), np.asarray(rec.u))
    yield WhittleLikelihood(fm, eps), len(NAMES)
    ext = ExtendedForwardModel(rec, NAMES, (ActuatorLag("actuator_lag", "both"),
                                            Unbalance("unbalance", "D1")))
    like = RobustWhittle(ext, eps)
    like.set_noise_reference(np.r_[np.zeros(len(NAMES)), 0.05, 1.0, -0.5])
    assert len(like.lines) == 1                     # the unbalance line enters the kernel
    yield like, len(ext.params)


def _batch(p: int, rng: np.random.Generator) -> np.ndarray:
    P = 0.05 * rng.standard_normal((7, p))
    P[:, :len(NAMES)] += [0.0, 0.3, 0.1, 0.0]
    P[-1, 0] = -0.79                                # near the prior edge
    return P


def _residual_majorant(like, P):
    """|R| with every term in absolute value (nb, nf, 4), and the largest number of
    operations along one residual entry."""
    mb, xi = like.forward.modal(P, like.x_w)
    num = np.abs(like.X) @ np.abs(np.swapaxes(mb.Bm, 1, 2)) + np.abs(xi)[:, None, :]
    u_abs = num / np.abs(like.z[None, :, None] - mb.lam[:, None, :])       # (nb, nf, ns)
    r_abs = np.abs(like.E)[None] + u_abs @ np.abs(np.swapaxes(mb.Cm, 1, 2)) / like.scale
    lines, coef = like._line_terms(P)
    n_ops = mb.lam.shape[1] + like.X.shape[1] + 6
    if lines is not None:
        r_abs = r_abs + np.einsum("kij,bj->bki", np.abs(lines), np.abs(coef))
        n_ops += lines.shape[2]
    return r_abs, n_ops


def _majorant(like, P):
    """Sum over each band of |R_i| |R_j| with |R| the absolute-value majorant of the terms,
    and the largest number of operations along one residual entry."""
    r_abs, n_ops = _residual_majorant(like, P)
    outer = r_abs[..., :, None] * r_abs[..., None, :]
    return np.add.reduceat(outer, like.starts, axis=1), n_ops


@pytest.mark.parametrize("width", [512, 7])
def test_residual_dft_equals_the_numpy_path(rec, width, monkeypatch):
    """The kernel's residual DFT (used for Jacobians, the eq. 15 cost and the predictive
    checks) against dft_response: the same terms in another order."""
    monkeypatch.setattr(kernels, "CHUNK_BINS", width)
    rng = np.random.default_rng(5)
    for like, p in _likelihoods(rec):
        P = _batch(p, rng)
        monkeypatch.setattr(like.forward, "engine", kernels.Engine("numpy"))
        ref, stable = like.residual_dft(P)
        monkeypatch.setattr(like.forward, "engine", kernels.Engine("lapack"))
        fast, stable_fast = like.residual_dft(P)
        assert stable.all() and np.array_equal(stable, stable_fast)
        r_abs, n_ops = _residual_majorant(like, P)
        tol = 4 * 4 * gamma(n_ops) * r_abs
        assert np.all(np.abs(fast - ref) <= tol), float(np.max(np.abs(fast - ref) / tol))
        assert not np.all(np.abs(ref * (1 + 1e-9) - ref) <= tol)
        if isinstance(like, RobustWhittle):             # the prediction alone: E, lines out
            Y = like.prediction_dft(P)[0]
            monkeypatch.setattr(like.forward, "engine", kernels.Engine("numpy"))
            Y_ref = like.prediction_dft(P)[0]
            monkeypatch.setattr(like.forward, "engine", kernels.Engine("lapack"))
            assert np.all(np.abs(Y - Y_ref) <= tol)


def test_residual_dft_across_the_batch_equals_the_row_by_row_kernel(rec):
    """residual_rows.residual_dft_lanes (real 2 x 2 blocks, vectorised across the rows;
    the Gauss-Newton linearisations' kernel) against kernels.residual_dft on the same modal
    form, lines included, within the rounding of the terms; each row's residual does not
    depend on the batch it came in (bit for bit)."""
    rng = np.random.default_rng(12)
    for like, p in _likelihoods(rec):
        P = np.vstack([_batch(p, rng) for _ in range(6)])[:block_sums.LANES + 5]
        mb, xi = like.forward.modal(P, like.x_w)
        lines, coef = like._line_terms(P, (mb, xi))
        args = (like.X, like.z, like.E, like.scale, lines, coef)
        fast = residual_rows.residual_dft_lanes(mb.lam, mb.Bm, mb.Cm, xi, *args)
        assert fast is not None
        ref = kernels.residual_dft(mb.lam, mb.Bm, mb.Cm, xi, *args)
        r_abs, n_ops = _residual_majorant(like, P)
        tol = 4 * 4 * gamma(n_ops) * r_abs
        assert np.all(np.abs(fast - ref) <= tol), float(np.max(np.abs(fast - ref) / tol))
        some = np.array([P.shape[0] - 1, 3, 0])
        part = residual_rows.residual_dft_lanes(
            mb.lam[some], mb.Bm[some], mb.Cm[some], xi[some], like.X, like.z, like.E,
            like.scale, lines, None if coef is None else coef[some])
        assert np.array_equal(part, fast[some])
        # the likelihood's own residual (default engine) is this kernel's
        R, _ = like.residual_dft(P)
        assert np.array_equal(R, fast)


@pytest.mark.parametrize("width", [512, 7])     # one pass; many, some bands wider than 7
def test_band_sums_equal_the_numpy_path(rec, width, monkeypatch):
    monkeypatch.setattr(kernels, "CHUNK_BINS", width)
    rng = np.random.default_rng(0)
    for like, p in _likelihoods(rec):
        P = _batch(p, rng)
        R, stable = like.residual_dft(P)
        ref = like._band_sums(R)
        mb, xi = like.forward.modal(P, like.x_w)
        lines, coef = like._line_terms(P)
        fast = kernels.residual_band_sums(mb.lam, mb.Bm, mb.Cm, xi, like.X, like.z, like.E,
                                          like.scale, like.starts, like.counts, lines, coef)
        assert stable.all()
        bound, n_ops = _majorant(like, P)
        tol = 4 * (4 * gamma(n_ops) + gamma(int(like.counts.max()) + 2)) * bound
        err = np.abs(fast - ref)
        assert np.all(err <= tol), float(np.max(err / tol))
        # the bound is tight enough to see a residual wrong by one part in a million
        assert not np.all(np.abs(like._band_sums(R * (1 + 1e-6)) - ref) <= tol)
        # the walker-vectorised kernel: from the real 2 x 2 blocks (the compiled modal form
        # has exactly conjugate pairs), and in complex arithmetic when a member is not in
        # that form (its second mode of a pair no longer the exact conjugate)
        args = (like.X, like.z, like.E, like.scale, like.starts, like.counts, lines, coef)
        real_blocks = walker_kernels._real_blocks(mb.lam, mb.Bm, mb.Cm, xi, 1.0)[0]
        assert real_blocks.shape[0] >= mb.lam.shape[1] // 2
        lanes = walker_kernels.residual_band_sums_lanes(mb.lam, mb.Bm, mb.Cm, xi, *args)
        assert np.all(np.abs(lanes - ref) <= tol), float(np.max(np.abs(lanes - ref) / tol))
        Bm = mb.Bm.copy()
        s = next(i for i in range(1, Bm.shape[1]) if mb.lam[2, i].imag != 0
                 and mb.lam[2, i] == np.conj(mb.lam[2, i - 1]))
        Bm[2, s, 0] *= 1 + 1e-15
        assert walker_kernels._real_blocks(mb.lam, Bm, mb.Cm, xi, 1.0)[0].shape[0] == 0
        lanes = walker_kernels.residual_band_sums_lanes(mb.lam, Bm, mb.Cm, xi, *args)
        assert np.all(np.abs(lanes - ref) <= tol), float(np.max(np.abs(lanes - ref) / tol))


def test_logdet_and_trace_equal_the_numpy_path():
    rng = np.random.default_rng(1)
    n = 4
    A = rng.standard_normal((3, 50, n, n)) + 1j * rng.standard_normal((3, 50, n, n))
    Phi = A @ np.conj(np.swapaxes(A, -1, -2)) + 0.1 * np.eye(n)
    B = rng.standard_normal((3, 50, n, 2 * n)) + 1j * rng.standard_normal((3, 50, n, 2 * n))
    P = B @ np.conj(np.swapaxes(B, -1, -2))
    Phi[0, 0] = -np.eye(n)                              # not positive definite: flagged
    ld0, q0, ok0 = band_algebra.logdet_and_trace_numpy(Phi, P)
    ld1, q1, ok1 = kernels.logdet_and_trace(Phi, P)
    # the fused form (Phi from its sources, L D L^H, Phi^-1): Phi = 2 (3 Phi / 8 + Phi / 8)
    sources = np.stack([Phi, Phi, 0 * Phi], axis=1)                  # (3, 3, 50, n, n)
    sig2 = np.array([[0.375, 0.125, 0.7]])                           # exact in binary
    fused = [walker_kernels.whittle_terms(sig2, sources[b], 2.0, P[b:b + 1]) for b in range(3)]
    ld2, q2, ok2 = (np.concatenate([f[i] for f in fused]) for i in range(3))
    assert np.array_equal(ok0, ok1) and not ok1[0, 0] and ok1.sum() == ok1.size - 1
    assert np.array_equal(ok0, ok2)
    cond = np.linalg.cond(Phi[ok1])
    # Cholesky: backward error gamma_{n+1} |L||L^H| (Higham thm 10.3); log det sums n logs;
    # the quadratic form inherits the condition number of Phi
    tol_ld = 4 * gamma(n + 1) * n * (1 + cond) + 4 * gamma(n) * np.abs(ld0[ok1])
    tol_q = 4 * gamma(3 * n + 1) * cond * (np.abs(q0[ok1]) + 1e-300) * n
    assert np.all(np.abs(ld1[ok1] - ld0[ok1]) <= tol_ld)
    assert np.all(np.abs(q1[ok1] - q0[ok1]) <= tol_q)
    # the fused form also rounds Phi's sum of sources (a few units) and uses the L D L^H
    # factors: the same bounds with twice the constant
    assert np.all(np.abs(ld2[ok1] - ld0[ok1]) <= 2 * tol_ld)
    assert np.all(np.abs(q2[ok1] - q0[ok1]) <= 2 * tol_q)


def test_log_likelihood_is_the_same_on_both_paths(rec, monkeypatch):
    """Per band the two paths differ by tr(Phi^-1 dP) (dP within the band-sum bound above)
    plus the Cholesky rounding of each (bounds as in the test above)."""
    rng = np.random.default_rng(2)
    n = 4
    for like, p in _likelihoods(rec):
        P = _batch(p, rng)
        ls = np.tile([np.log10(2e-8), -9.0, np.log10(0.02)], (P.shape[0], 1))
        monkeypatch.setattr(like.forward, "engine", kernels.Engine("numpy"))
        ref = like.pointwise(P, ls)
        monkeypatch.setattr(like.forward, "engine", kernels.Engine("lapack"))
        fast = like.pointwise(P, ls)
        bound, n_ops = _majorant(like, P)
        tol_p = 4 * (4 * gamma(n_ops) + gamma(int(like.counts.max()) + 2)) * bound
        ps = like.phi_sources
        Phi = np.einsum("bs,sfij->bfij", 10.0 ** (2 * ls), ps) * like.n
        if isinstance(like, RobustWhittle):             # the likelihood's own Phi scaling
            Phi = Phi * (like.nu - like.shift)[None, :, None, None]
            weight = (like.nu + like.counts)[None]      # (nu + n_b) log det(Psi + P_b)
            Phi_used = Phi + like.band_sums(P)[0]
        else:
            weight, Phi_used = 1.0, Phi
        inv = np.abs(np.linalg.inv(Phi_used))
        cond = np.linalg.cond(Phi_used)
        via_p = weight * np.einsum("bfji,bfij->bf", inv, tol_p)
        chol = 8 * gamma(3 * n + 1) * n * (1 + cond) * (like.counts + np.abs(ref))
        assert np.all(np.abs(fast - ref) <= via_p + chol)


@pytest.mark.parametrize("batch", [7, 32])      # walker by walker; vectorised across them
def test_default_path_gives_the_numpy_paths_log_likelihood(rec, batch, monkeypatch):
    """The default path (compiled modal form, ZOH, band sums and band algebra) against the
    numpy path: the issue's acceptance, < 1e-9 relative on the log likelihood (measured
    ~1e-14: the modal forms agree to ~1e-12 relative, see tests/test_eigen.py)."""
    rng = np.random.default_rng(7)
    for like, p in _likelihoods(rec):
        P = np.vstack([_batch(p, rng) for _ in range(-(-batch // 7))])[:batch]
        ls = np.tile([np.log10(2e-8), -9.0, np.log10(0.02)], (batch, 1))
        ls[:, 0] += 0.1 * rng.standard_normal(batch)
        monkeypatch.setattr(like.forward, "engine", kernels.Engine("numpy"))
        ref = like(P, ls)
        monkeypatch.setattr(like.forward, "engine", kernels.Engine("numba"))
        like._last_sums = None
        fast = like(P, ls)
        assert np.all(np.isfinite(ref))
        assert np.all(np.abs(fast - ref) <= 1e-9 * np.abs(ref)), np.max(np.abs(fast / ref - 1))


def test_kernel_choice_is_validated_and_made_once_per_model(rec, monkeypatch):
    monkeypatch.setenv(kernels.KERNEL_ENV, "fortran")
    with pytest.raises(Exception, match="BAYES_AMB_KERNEL: expected one of numba, lapack, "
                                        "numpy, got 'fortran'"):
        kernels.engine_from_env()
    with pytest.raises(Exception, match="likelihood engine: expected one of"):
        kernels.Engine("fortran")
    monkeypatch.setenv(kernels.KERNEL_ENV, "lapack")
    like, _ = next(iter(_likelihoods(rec)))
    monkeypatch.setenv(kernels.KERNEL_ENV, "numpy")       # a model keeps the engine it has
    assert like.engine == kernels.Engine("lapack") and not like.engine.compiled_modal


def test_passes_cover_whole_bands_in_order():
    counts = np.array([1, 1, 1, 5, 9, 2, 30, 3, 3])
    edges, widest = kernels._chunks(counts, 8)
    assert edges[0] == 0 and edges[-1] == counts.size and np.all(np.diff(edges) > 0)
    sizes = [int(counts[a:b].sum()) for a, b in itertools.pairwise(edges)]
    assert sizes == [8, 9, 2, 30, 6] and widest == 30


def test_rows_sharing_theta_are_computed_once_and_equal_alone(rec):
    """A gradient's steps along the noise coordinates share theta: the band sums of such a
    batch equal those of each row alone (up to the transient's 1e-13 truncation, whose
    length follows the batch's slowest pole; with the actuator lag as added continuous
    states the log likelihoods then agree to ~1e-11 relative, so 1e-10 is asserted)."""
    rng = np.random.default_rng(3)
    for like, p in _likelihoods(rec):
        P = _batch(p, rng)[:3]
        theta = P[[0, 1, 0, 2, 0]]
        ls = np.tile([np.log10(2e-8), -9.0, np.log10(0.02)], (5, 1))
        ls[[2, 4], 0] += [0.01, -0.01]
        batch = like.pointwise(theta, ls)
        alone = np.concatenate([like.pointwise(theta[i:i + 1], ls[i:i + 1]) for i in range(5)])
        assert np.allclose(batch, alone, rtol=1e-10, atol=0)
        assert np.array_equal(like.band_sums(theta)[0][0], like.band_sums(theta)[0][2])


def test_remembered_band_sums_follow_the_noise_reference(rec):
    like, p = list(_likelihoods(rec))[1]              # RobustWhittle: lines move with it
    P = _batch(p, np.random.default_rng(4))[:2]
    before = like.band_sums(P)[0].copy()
    assert like.band_sums(P)[0] is like.band_sums(P)[0]          # remembered
    ref = np.r_[0.3, 0.5, -0.2, 0.1, 0.05, -2.0, 1.5]   # other plant: other line bases
    like.set_noise_reference(ref)
    assert like._last_sums is None
    after = like.band_sums(P)[0]
    fresh = like._compute_band_sums(P)[0]
    assert np.array_equal(after, fresh) and not np.allclose(after, before, rtol=1e-9)


def test_fused_call_gives_the_staged_paths_log_likelihood(rec):
    """The one compiled call (bayes_amb.inference.fused) chains the staged path's compiled
    stages: per band the same log-likelihood to rounding (a repeated row sends the batch
    the staged way; rows are independent)."""
    rng = np.random.default_rng(3)
    like, p = next(_likelihoods(rec))
    P = np.vstack([_batch(p, rng) for _ in range(3)])[:16]
    ls = np.tile([np.log10(2e-8), -9.0, np.log10(0.02)], (16, 1))
    like._last_sums, like._fused = None, None
    fused = like.pointwise(P, ls)
    assert like._fused is not None                  # the fused call was taken
    like._last_sums = None
    staged = like.pointwise(np.vstack([P, P[:1]]), np.vstack([ls, ls[:1]]))[:16]
    assert np.all(np.isfinite(fused[:-1]))
    ok = np.isfinite(staged)
    assert np.array_equal(ok, np.isfinite(fused))
    assert np.all(np.abs(fused[ok] - staged[ok]) <= 1e-12 * np.abs(staged[ok]))


def test_written_out_block_kernel_is_the_pairs_kernel_bit_for_bit(rec):
    """block_sums (4 inputs, 4 outputs written out, walkers in chunks of LANES) computes
    _band_sums_pairs' operations in its order: the same band sums exactly, with lines, for
    a batch of more than one chunk, and each walker's independent of the others."""
    rng = np.random.default_rng(11)
    like, p = list(_likelihoods(rec))[1]                # the one with a line
    P = np.vstack([_batch(p, rng) for _ in range(7)])[:block_sums.LANES + 13]
    mb, xi = like.forward.modal(P, like.x_w)
    lines, coef = like._line_terms(P)
    assert lines is not None and lines.shape[2] > 0
    nb = P.shape[0]

    def run(idx, kernel):
        M, B2, C2, x2 = walker_kernels._real_blocks(mb.lam[idx], mb.Bm[idx], mb.Cm[idx],
                                                    xi[idx], 1.0 / like.scale)
        assert M.shape[0] > 0
        data = (like.X.real.copy(), like.X.imag.copy(), like.z.real.copy(),
                like.z.imag.copy(), like.E.real.copy(), like.E.imag.copy(),
                lines.real.copy(), lines.imag.copy(), np.ascontiguousarray(coef[idx].T),
                like.starts, like.counts)
        out = np.empty((len(idx), like.starts.size, 4, 4), dtype=complex)
        if kernel == "pairs":
            walker_kernels._band_sums_pairs(M, B2, C2, x2, *data, out)
            return out
        packed = np.empty((band_algebra.n_chunks(len(idx)) if kernel == "packed" else 0,
                           like.starts.size, 16, band_algebra.LANES))
        block_sums._band_sums_blocks4(block_sums._pack_blocks(M, B2, C2, x2), len(idx),
                                      *data, out, packed)
        return band_algebra.unpack_band_sums(packed, len(idx)) if packed.size else out

    every = np.arange(nb)
    ref = run(every, "pairs")
    assert np.array_equal(run(every, "blocks"), ref)
    assert np.array_equal(run(every, "packed"), ref)   # the packed form holds the same
    some = np.array([nb - 1, 3, 0, 17])                 # other neighbours, other lanes
    assert np.array_equal(run(some, "blocks"), ref[some])


def test_fused_rows_do_not_depend_on_the_batch(rec):
    """Each row's log likelihood on the fused path is a function of that row alone, bit for
    bit: the same rows in another batch (other neighbours, other order, other size) give
    the same values (the modal form, the QR iteration in lock-step, the band sums and the
    band algebra all run per walker)."""
    rng = np.random.default_rng(12)
    like, p = next(_likelihoods(rec))
    P = np.vstack([_batch(p, rng) for _ in range(8)])[:50]
    ls = np.tile([np.log10(2e-8), -9.0, np.log10(0.02)], (50, 1))
    ls[:, 0] += 0.1 * rng.standard_normal(50)
    like._last_sums, like._fused = None, None
    first = like.pointwise(P[:20], ls[:20])
    assert like._fused is not None
    order = rng.permutation(50)
    like._last_sums = None
    second = like.pointwise(P[order], ls[order])
    back = np.empty_like(second)
    back[order] = second
    assert np.array_equal(back[:20], first)
    assert np.all(np.isfinite(first))


def test_written_out_band_algebra_is_the_loops_bit_for_bit():
    """band_algebra._whittle_terms4 (the 4 x 4 algebra written out, vectorised across the
    walkers in chunks of LANES) computes walker_kernels._whittle_terms' operations in its
    order: the same log det, trace and flags exactly, for more walkers than a chunk, a band
    that is not positive definite and bands whose determinant leaves the range of its
    product."""
    rng = np.random.default_rng(13)
    nb, nbands, n = band_algebra.LANES + 5, 70, 4
    def hermitian(*shape):
        A = rng.standard_normal(shape) + 1j * rng.standard_normal(shape)
        H = A @ np.conj(np.swapaxes(A, -1, -2))
        return 0.5 * (H + np.conj(np.swapaxes(H, -1, -2)))

    ps = hermitian(3, nbands, n, 2 * n)
    ps[1, 3] = -np.eye(n)                               # with sig2 large: not positive definite
    P = hermitian(nb, nbands, n, 3 * n)
    sig2 = 10.0 ** rng.uniform(-2, 1, (nb, 3))
    sig2[0, 1] = 1e3
    sig2[1] = 1e-100                                    # det ~ 1e-400: log of the pivots
    sig2[2] = 1e100                                     # det ~ 1e400
    ref = [np.empty((nb, nbands)), np.empty((nb, nbands)), np.empty((nb, nbands), bool)]
    walker_kernels._whittle_terms(sig2, ps, 2.5, P, *ref)
    new = [np.empty((nb, nbands)), np.empty((nb, nbands)), np.empty((nb, nbands), bool)]
    band_algebra._whittle_terms4(sig2, band_algebra.pack_band_sources(ps), 2.5,
                                 band_algebra.pack_band_sums(P), *new)
    assert not ref[2][0, 3] and ref[2].mean() > 0.9
    assert np.all(np.isfinite(ref[0])) and np.abs(ref[0][1:3]).min() > 600
    for r, x in zip(ref, new, strict=True):
        assert np.array_equal(r, x)
    assert np.array_equal(band_algebra.unpack_band_sums(band_algebra.pack_band_sums(P), nb),
                          P)
