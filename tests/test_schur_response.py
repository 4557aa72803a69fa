"""The Schur-form frequency response (control/schur_response.py), the fallback of
ss_freqresp_modal for state matrices with ill-conditioned eigenvectors."""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_triangular

from bayes_amb.control.discrete import ss_freqresp, ss_freqresp_modal
from bayes_amb.control.schur_response import schur_freqresp


def _defective_loop(rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    """A badly scaled discrete system with Jordan blocks (a controller's repeated poles),
    built exactly in floating point: A = P S W U W^-1 S^-1 P^T with U upper triangular,
    W unit lower triangular with integer entries (so is W^-1), S powers of two from 2^-20
    to 2^20 and P a permutation, so that its response has an accurate reference through U
    alone. Its eigenvectors' condition number is far above 1e6."""
    n = 12
    U = np.diag([0.9375, 0.9375, 0.9375, 0.75, 0.75, 0.5, 0.5, 0.25, -0.5, -0.5, 0.875, 0.0])
    U += np.diag([1.0, 1.0, 0, 1.0, 0, 1.0, 0, 0, 1.0, 0, 0], 1)       # Jordan blocks
    U += np.triu(np.round(rng.standard_normal((n, n)) * 8) / 8, 2)     # exact couplings
    W = np.eye(n) + np.tril(rng.integers(-1, 2, (n, n)), -1)
    Wi = np.round(np.linalg.inv(W))
    assert np.array_equal(W @ Wi, np.eye(n))
    s = 2.0 ** rng.integers(-20, 21, n)
    P = np.eye(n)[rng.permutation(n)]
    A = P @ (s[:, None] * (W @ U @ Wi) / s[None, :]) @ P.T
    Bu, Cu = rng.standard_normal((n, 3)), rng.standard_normal((2, n))
    B, C = P @ (s[:, None] * (W @ Bu)), ((Cu @ Wi) / s[None, :]) @ P.T
    return A, B, C, rng.standard_normal((2, 3)), U, Bu, Cu


def test_schur_response_matches_dense_solve_where_modal_form_fails():
    A, B, C, D, U, Bu, Cu = _defective_loop(np.random.default_rng(3))
    assert np.linalg.cond(np.linalg.eig(A)[1]) > 1e6            # the modal form's fallback
    z = np.exp(1j * np.linspace(0.01, np.pi, 400))
    eye = np.eye(U.shape[0])
    ref = np.stack([Cu @ solve_triangular(zk * eye - U, Bu) for zk in z]) + D
    scale = np.max(np.abs(ref), axis=(1, 2))
    for got in (schur_freqresp(A, B, C, D, z), ss_freqresp_modal(A, B, C, D, z),
                ss_freqresp(A, B, C, D, z)):
        err = np.max(np.abs(got - ref), axis=(1, 2)) / scale
        assert err.max() < 1e-7, err.max()     # without the balance: 0.3 to 20


def test_schur_response_is_exact_on_a_triangular_system():
    """On an upper triangular A the forward substitution is the whole computation: one
    point by hand, (z - a)^-1 (z - d)^-1 b for the off-diagonal entry."""
    A = np.array([[0.5, 2.0], [0.0, -0.25]])
    z = np.array([0.3 + 0.4j])
    H = schur_freqresp(A, np.eye(2), np.eye(2), None, z)[0]
    want = np.array([[1 / (z[0] - 0.5), 2 / ((z[0] - 0.5) * (z[0] + 0.25))],
                     [0.0, 1 / (z[0] + 0.25)]])
    assert np.allclose(H, want, rtol=1e-13, atol=1e-15)
