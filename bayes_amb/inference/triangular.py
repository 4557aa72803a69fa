"""Modal form of a block lower-triangular loop whose trailing block is fixed.

The loop the identification sees with any controller but the observer at its Youla port
(loop_model.loop_matrices) has the states z = [x_p; x_k; x_o]: the plant and the recorded
controller (together x_1, n1 states, theta-dependent), and the offline filter's observer
x_o (no states). The observer is driven by the loop but does not drive it, and its own
matrix A22 = A + L C is the nominal one, the same for every theta:

    A = [[A11, 0], [A21, A22]],   B = [B1; B2],   C = [C1, C2].

Its eigenvalues are those of A11 and of A22. With A11 = V1 diag(lam1) V1^-1 and
A22 = W diag(lam2) W^-1 (once, at the model's construction), the eigenvectors are
V = [[V1, 0], [W Z, W]], Z_ij = (W^-1 A21 V1)_ij / (lam1_j - lam2_i), so that

    Bm = V^-1 B = [V1^-1 B1;  W^-1 B2 - Z V1^-1 B1],   Cm = C V = [C1 V1 + C2 W Z,  C2 W].

Only A11 is decomposed per theta: on ROSS's test rig (a 12-state plant, its 28-state
controllers and the 12-state observer) an n1 = 40 eigenproblem instead of n = 52, about
half the work (n^3). A21 V1 comes out of the same compiled decomposition as C1 V1 (its rows
are appended to C1). A member whose lam1 comes within GAP_TOL of an observer eigenvalue (Z
then loses its digits, as the whole loop's eigenvectors do) is left to the caller.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bayes_amb.inference.eigen import modal_batch

GAP_TOL = 1e-8
"""Smallest |lam1_j - lam2_i| (discrete eigenvalues, |lam| < 1 where stable) kept here."""
COND_MAX = 1e8
"""Largest condition number of the observer's eigenvectors W for which it is used."""


@dataclass(frozen=True)
class FixedBlock:
    """The fixed trailing block A22 (no, no) of the loop, diagonalised once: its eigenvalues
    lam (conjugate pairs adjacent and exact), eigenvectors W and W^-1."""

    A22: NDArray
    lam: NDArray
    W: NDArray
    Winv: NDArray

    @property
    def n(self) -> int:
        return self.A22.shape[0]


def fixed_block(A22: NDArray) -> FixedBlock | None:
    """A22 diagonalised (LAPACK), or None where its eigenvectors are ill-conditioned
    (cond > COND_MAX) or it is not finite: the loop is then decomposed whole.

    Examples
    --------
    >>> fb = fixed_block(np.array([[0.5, 0.2], [-0.2, 0.5]]))
    >>> bool(np.allclose(fb.W @ np.diag(fb.lam) @ fb.Winv, fb.A22))
    True
    """
    A22 = np.ascontiguousarray(A22, dtype=float)
    if A22.size == 0 or not np.all(np.isfinite(A22)):
        return None
    lam, W = np.linalg.eig(A22)
    if not np.isfinite(np.linalg.cond(W)) or np.linalg.cond(W) > COND_MAX:
        return None
    real = lam.imag == 0
    W = W.astype(complex)
    W[:, real] = W[:, real].real
    return FixedBlock(A22, lam, W, np.linalg.inv(W))


def takes(A: NDArray, fixed: FixedBlock) -> bool:
    """Whether every member of the batch A (nb, n, n) has the form above with this block:
    exact zeros above it, and A22 itself in its place."""
    n1 = A.shape[1] - fixed.n
    return (n1 > 0 and not np.any(A[:, :n1, n1:])
            and bool(np.all(A[:, n1:, n1:] == fixed.A22)))


def modal_triangular(A: NDArray, B: NDArray, C: NDArray, fixed: FixedBlock
                     ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Modal form of a stack (A, B, C) of the form above (see :func:`takes`): lam (nb, n),
    Bm (nb, n, m), Cm (nb, p, n) and ok (nb,), as eigen.modal_batch returns them (the
    observer's modes last). Members not ok are meaningless: decompose them whole.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> A22 = np.array([[0.3, 0.4], [-0.4, 0.3]])
    >>> A = np.zeros((1, 5, 5))
    >>> A[0, :3, :3] = 0.4 * rng.standard_normal((3, 3))
    >>> A[0, 3:, :3] = rng.standard_normal((2, 3))
    >>> A[0, 3:, 3:] = A22
    >>> B, C = rng.standard_normal((1, 5, 2)), rng.standard_normal((1, 2, 5))
    >>> lam, Bm, Cm, ok = modal_triangular(A, B, C, fixed_block(A22))
    >>> z = 1.2 - 0.3j
    >>> H = C[0] @ np.linalg.solve(z * np.eye(5) - A[0], B[0])
    >>> bool(ok[0] and np.allclose(Cm[0] @ (Bm[0] / (z - lam[0])[:, None]), H))
    True
    """
    nb, n, _ = A.shape
    no = fixed.n
    n1 = n - no
    B = np.broadcast_to(B, (nb, n, B.shape[-1]))
    C = np.broadcast_to(C, (nb, C.shape[-2], n))
    p = C.shape[1]
    rows = np.concatenate([C[:, :, :n1], A[:, n1:, :n1]], axis=1)      # [C1; A21]
    lam1, Bm1, Cm_aug, ok = modal_batch(A[:, :n1, :n1], B[:, :n1], rows)
    gap = lam1[:, None, :] - fixed.lam[None, :, None]                   # (nb, no, n1)
    ok &= np.min(np.abs(gap), axis=(1, 2)) > GAP_TOL
    gap = np.where(ok[:, None, None], gap, 1.0)
    Z = (fixed.Winv @ Cm_aug[:, p:]) / gap                              # (nb, no, n1)
    CW = C[:, :, n1:] @ fixed.W                                         # (nb, p, no)
    Bm2 = fixed.Winv @ B[:, n1:] - Z @ Bm1
    lam = np.concatenate([lam1, np.broadcast_to(fixed.lam, (nb, no))], axis=1)
    Bm = np.concatenate([Bm1, Bm2], axis=1)
    Cm = np.concatenate([Cm_aug[:, :p] + CW @ Z, CW], axis=2)
    return lam, *exact_pairs(lam, Bm, Cm), ok


def exact_pairs(lam: NDArray, Bm: NDArray, Cm: NDArray) -> tuple[NDArray, NDArray]:
    """Bm and Cm with the symmetry of a real system exact, in place: the second mode of each
    adjacent exactly conjugate pair takes the conjugates of the first's rows, a real mode
    real rows (the compiled modal form's convention, which its consumers rely on)."""
    pair = np.zeros(lam.shape, dtype=bool)
    pair[:, 1:] = (lam[:, 1:] == np.conj(lam[:, :-1])) & (lam[:, 1:].imag != 0)
    for s in range(1, lam.shape[1]):            # a pair, not a chain
        pair[:, s] &= ~pair[:, s - 1]
    b, s = np.nonzero(pair)
    Bm[b, s] = np.conj(Bm[b, s - 1])
    Cm[b, :, s] = np.conj(Cm[b, :, s - 1])
    real = lam.imag == 0
    Bm[real] = Bm[real].real
    b, s = np.nonzero(real)
    Cm[b, :, s] = Cm[b, :, s].real
    return Bm, Cm
