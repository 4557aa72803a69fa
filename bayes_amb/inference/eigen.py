"""Compiled (numba) modal form of a stack of small discrete systems (issue 16).

The likelihood needs, for every member of a batch of 16-state systems x -> eps, the modal
form lam (nb, ns), Bm = V^-1 B and Cm = C V, and the modal state after the record. Through
numpy that was LAPACK's geev matrix by matrix (``np.linalg.eig``, ~33 us each at this size)
plus a complex solve for Bm (~10 us each). Here, in one compiled call for the batch:

1. balancing by exact powers of 2, A <- D^-1 A D (EISPACK balanc without permutations, as
   geev balances: without it the modal form of the discrepancy models' lag states lost up
   to two digits against LAPACK's);
2. Householder reduction to upper Hessenberg form H = Q^T A Q, applied to B and C (Q is never
   formed: a modal form of (H, Q^T B, C Q) is one of (A, B, C)), all members at once;
3. the eigenvalues of H by the Francis double-shift QR iteration without Schur vectors
   (EISPACK hqr), all members in lock-step (bayes_amb.inference.qr_lanes: each member's
   arithmetic is hqr's on it alone, bit for bit);
4. one eigenvector per real eigenvalue or conjugate pair by inverse iteration on H (the
   pivoted LU of H - lam I, one solve, LAPACK dlaein's growth test; a second step with the
   residual computed where that test fails), one eigenvalue of every member at a time,
   each normalised to unit 2-norm with its largest entry real, as geev does;
5. the real basis V_r = [v, ..., Re v, Im v, ...] (a real similarity), its LU with partial
   pivoting, Bm and Cm from it; conjugate pairs come out adjacent and exactly conjugate
   (lam, Bm, Cm), real modes with real Bm and Cm.

Every member is checked: the QR iteration must converge, every eigenvector's residual must be
below RESIDUAL_FACTOR n u ||H||_1, V_r's LU must not break down (smallest pivot above
PIVOT_RATIO of the largest). A member that fails (a repeated or defective eigenvalue, a
non-finite matrix) is flagged, and :func:`bayes_amb.inference.forward.diagonalise` gives it
to ``np.linalg.eig``: the result is always a modal form to rounding, never a wrong one.
tests/test_eigen.py holds the transfer functions of both to the direct solve.

:func:`final_state` is the modal state after the record, xi = sum_q lam^q Bm x_{N-1-q}.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from bayes_amb.inference.hessenberg import (
    EPS,
    RESIDUAL_FACTOR,
    _hessenberg_lanes,
    _inverse_iteration,
    _inverse_iteration_lanes,
)
from bayes_amb.inference.qr_lanes import _hqr_lanes
from bayes_amb.threads import over_rows

PIVOT_RATIO = 1e-13
"""The eigenvector basis V_r is refused when its smallest LU pivot is below this fraction
of its largest."""


@njit(cache=True, nogil=True, error_model="numpy")
def _balance(A, B, C):  # pragma: no cover - compiled
    # In place: A <- D^-1 A D, B <- D^-1 B, C <- C D with D diagonal, powers of 2 (exact),
    # chosen so that each state's row and column norms are of one size (EISPACK balanc
    # without permutations; as LAPACK geev balances before its QR iteration)
    n = A.shape[0]
    done = False
    sweeps = 0
    while not done and sweeps < 32:
        done = True
        sweeps += 1
        for i in range(n):
            c = 0.0
            r = 0.0
            for j in range(n):
                if j != i:
                    c += abs(A[j, i])
                    r += abs(A[i, j])
            if c == 0.0 or r == 0.0:
                continue
            g = r / 2.0
            f = 1.0
            tot = c + r
            while c < g:
                f *= 2.0
                c *= 4.0
            g = r * 2.0
            while c > g:
                f /= 2.0
                c /= 4.0
            if (c + r) / f < 0.95 * tot:
                done = False
                g = 1.0 / f
                for j in range(n):
                    A[i, j] *= g
                    A[j, i] *= f
                for j in range(B.shape[1]):
                    B[i, j] *= g
                for j in range(C.shape[0]):
                    C[j, i] *= f


@njit(cache=True, nogil=True)
def _lu_solve_real(V, B, piv_ratio):  # pragma: no cover - compiled
    # V <- its LU (partial pivoting), B <- V^-1 B; False if a pivot is below piv_ratio x max
    n = V.shape[0]
    m = B.shape[1]
    pmax = 0.0
    pmin = np.inf
    for k in range(n):
        ip = k
        big = abs(V[k, k])
        for i in range(k + 1, n):
            if abs(V[i, k]) > big:
                big = abs(V[i, k])
                ip = i
        if big == 0.0:
            return False
        pmax = max(pmax, big)
        pmin = min(pmin, big)
        if ip != k:
            for j in range(n):
                t = V[k, j]
                V[k, j] = V[ip, j]
                V[ip, j] = t
            for j in range(m):
                t = B[k, j]
                B[k, j] = B[ip, j]
                B[ip, j] = t
        d = V[k, k]
        for i in range(k + 1, n):
            f = V[i, k] / d
            V[i, k] = f
            for j in range(k + 1, n):
                V[i, j] -= f * V[k, j]
            for j in range(m):
                B[i, j] -= f * B[k, j]
    for i in range(n - 1, -1, -1):                   # by columns of U
        d = 1.0 / V[i, i]
        for j in range(m):
            B[i, j] *= d
        for k in range(i):
            f = V[k, i]
            for j in range(m):
                B[k, j] -= f * B[i, j]
    return pmin > piv_ratio * pmax


@njit(cache=True, nogil=True)
def _modal_batch(A, B, C, lam, Bm, Cm, ok):  # pragma: no cover - compiled
    nb, n, _ = A.shape
    m = B.shape[2]
    p = C.shape[1]
    # 1. Hessenberg form of every member at once (walkers last)
    Hl, Bl, Cl = np.empty((n, n, nb)), np.empty((n, m, nb)), np.empty((p, n, nb))
    finite = np.ones(nb, np.bool_)
    Ab, Bb, Cb = np.empty((n, n)), np.empty((n, m)), np.empty((p, n))
    for b in range(nb):
        for i in range(n):
            for j in range(n):
                if not np.isfinite(A[b, i, j]):
                    finite[b] = False
        for i in range(n):
            for j in range(n):
                Ab[i, j] = A[b, i, j] if finite[b] else 0.0
            for j in range(m):
                Bb[i, j] = B[b, i, j]
        for i in range(p):
            for j in range(n):
                Cb[i, j] = C[b, i, j]
        _balance(Ab, Bb, Cb)
        for i in range(n):
            for j in range(n):
                Hl[i, j, b] = Ab[i, j]
            for j in range(m):
                Bl[i, j, b] = Bb[i, j]
        for i in range(p):
            for j in range(n):
                Cl[i, j, b] = Cb[i, j]
    _hessenberg_lanes(Hl, Bl, Cl)
    # 2. eigenvalues, every member at once (qr_lanes: member by member hqr's arithmetic);
    # the eigenvalues whose vectors are computed (a real one, or the first of a conjugate
    # pair, with Im > 0) listed per member
    H = np.empty((n, n))
    T = np.empty((n, n, nb))
    wr, wi = np.zeros((nb, n)), np.zeros((nb, n))
    hnorm, s = np.zeros(nb), np.empty(nb)
    for j in range(n):
        for b in range(nb):
            s[b] = 0.0
        for i in range(min(j + 2, n)):
            for b in range(nb):
                T[i, j, b] = Hl[i, j, b]
                s[b] += abs(Hl[i, j, b])
        for i in range(j + 2, n):
            for b in range(nb):
                T[i, j, b] = 0.0
        for b in range(nb):
            hnorm[b] = max(hnorm[b], s[b])
    tol = np.empty(nb)
    for b in range(nb):
        tol[b] = RESIDUAL_FACTOR * n * EPS * hnorm[b]
        ok[b] = finite[b]
    _hqr_lanes(T, wr, wi, ok)
    kind = np.zeros((nb, n), np.int64)             # 0 real, 1 first of a pair, 2 second
    own = np.zeros((n, nb), np.int64)              # column of the j-th computed vector
    n_own = np.zeros(nb, np.int64)
    for b in range(nb):
        if not ok[b]:
            continue
        j = 0
        while j < n:
            own[n_own[b], b] = j
            n_own[b] += 1
            if wi[b, j] == 0.0:
                j += 1
            else:
                li = abs(wi[b, j])
                wi[b, j] = li
                wi[b, j + 1] = -li
                kind[b, j] = 1
                kind[b, j + 1] = 2
                j += 2
    # 3. eigenvectors by inverse iteration, one eigenvalue of every member at a time
    Vr = np.empty((nb, n, n))
    vr, vi = np.empty((n, nb)), np.empty((n, nb))
    Ur, Ui = np.empty((n, n, nb)), np.empty((n, n, nb))
    pv = np.empty(nb, np.bool_)
    mr, mi, xr, xi = np.empty(nb), np.empty(nb), np.empty(nb), np.empty(nb)
    lr, li, good = np.empty(nb), np.empty(nb), np.empty(nb, np.bool_)
    v1r, v1i = np.empty(n), np.empty(n)
    U1r, U1i = np.empty((n, n)), np.empty((n, n))
    piv1 = np.empty(n, np.int64)
    m1r, m1i, r1r, r1i = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    n_max = 0
    for b in range(nb):
        n_max = max(n_max, n_own[b] if ok[b] else 0)
    for q in range(n_max):
        for b in range(nb):
            active = ok[b] and q < n_own[b]
            lr[b] = wr[b, own[q, b]] if active else 0.0
            li[b] = wi[b, own[q, b]] if active else 0.0
        _inverse_iteration_lanes(Hl, lr, li, tol, vr, vi, Ur, Ui, pv, mr, mi, xr, xi, good)
        for b in range(nb):
            if not (ok[b] and q < n_own[b]):
                continue
            j = own[q, b]
            if good[b]:
                for i in range(n):
                    v1r[i] = vr[i, b]
                    v1i[i] = vi[i, b]
            else:                                    # the one-vector form, up to two steps
                for i in range(n):
                    for k in range(n):
                        H[i, k] = Hl[i, k, b] if k >= i - 1 else 0.0
                r = _inverse_iteration(H, lr[b], li[b], tol[b], v1r, v1i, U1r, U1i, piv1,
                                       m1r, m1i, r1r, r1i)
                if not r <= tol[b]:
                    ok[b] = False
                    continue
            for i in range(n):
                Vr[b, i, j] = v1r[i]
            if kind[b, j] == 1:
                for i in range(n):
                    Vr[b, i, j + 1] = v1i[i]
    # 4. Bm = V_r^-1 Q^T B and Cm = C Q V_r, in the complex modal form
    Z = np.empty((n, m))
    Cr = np.empty((p, n))
    V = np.empty((n, n))
    for b in range(nb):
        if not ok[b]:
            continue
        for i in range(p):
            for j in range(n):
                Cr[i, j] = 0.0
            for k in range(n):
                f = Cl[i, k, b]
                for j in range(n):
                    Cr[i, j] += f * Vr[b, k, j]
        for i in range(n):
            for j in range(n):
                V[i, j] = Vr[b, i, j]
            for j in range(m):
                Z[i, j] = Bl[i, j, b]
        if not _lu_solve_real(V, Z, PIVOT_RATIO):
            ok[b] = False
            continue
        for j in range(n):
            lam[b, j] = wr[b, j] + 1j * wi[b, j]
            if kind[b, j] == 0:
                for c in range(m):
                    Bm[b, j, c] = Z[j, c]
                for i in range(p):
                    Cm[b, i, j] = Cr[i, j]
            elif kind[b, j] == 1:
                for c in range(m):
                    Bm[b, j, c] = 0.5 * (Z[j, c] - 1j * Z[j + 1, c])
                    Bm[b, j + 1, c] = 0.5 * (Z[j, c] + 1j * Z[j + 1, c])
                for i in range(p):
                    Cm[b, i, j] = Cr[i, j] + 1j * Cr[i, j + 1]
                    Cm[b, i, j + 1] = Cr[i, j] - 1j * Cr[i, j + 1]


def modal_batch(A: NDArray, B: NDArray, C: NDArray
                ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Modal form of a stack of real systems: lam (nb, n), Bm (nb, n, m), Cm (nb, p, n)
    (complex; conjugate pairs adjacent) and ok (nb,), False where a member failed a check
    or is not finite (its rows are then meaningless: decompose it with np.linalg.eig).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> A = 0.3 * rng.standard_normal((2, 6, 6))
    >>> B, C = rng.standard_normal((2, 6, 2)), rng.standard_normal((2, 3, 6))
    >>> lam, Bm, Cm, ok = modal_batch(A, B, C)
    >>> z = 1.5 + 0.5j
    >>> H = C[0] @ np.linalg.solve(z * np.eye(6) - A[0], B[0])
    >>> bool(ok.all() and np.allclose(Cm[0] @ (Bm[0] / (z - lam[0])[:, None]), H))
    True
    """
    # C-contiguous and writable, whatever the caller passed: the kernel then has one
    # signature, the one the warm-up compiles (a read-only view, as np.broadcast_to gives
    # where no broadcast is needed, is another type; it compiled for 7.6 s inside the first
    # diagnosis of a rig whose batch came in whole)
    A = np.require(A, np.float64, ("C", "W"))
    nb, n, _ = A.shape
    B = np.require(np.broadcast_to(B, (nb, n, B.shape[-1])), np.float64, ("C", "W"))
    C = np.require(np.broadcast_to(C, (nb, C.shape[-2], n)), np.float64, ("C", "W"))
    lam = np.zeros((nb, n), dtype=np.complex128)
    Bm = np.zeros((nb, n, B.shape[2]), dtype=np.complex128)
    Cm = np.zeros((nb, C.shape[1], n), dtype=np.complex128)
    ok = np.zeros(nb, dtype=np.bool_)
    over_rows(lambda lo, hi: _modal_batch(A[lo:hi], B[lo:hi], C[lo:hi], lam[lo:hi],
                                          Bm[lo:hi], Cm[lo:hi], ok[lo:hi]), nb)
    return lam, Bm, Cm, ok


@njit(cache=True, nogil=True, error_model="numpy")
def _final_state(lr, li, n_terms, tail, pr, pi):  # pragma: no cover - compiled
    # p_c(lam_j) = sum_{q < n_terms[j]} tail[q, c] lam_j^q by Horner, all points at once;
    # the points are sorted by n_terms (descending): at step q the first `active` take part
    m = tail.shape[1]
    n = lr.size
    for c in range(m):
        for j in range(n):
            pr[c, j] = 0.0
            pi[c, j] = 0.0
    active = 0
    for q in range(n_terms[0] - 1 if n else -1, -1, -1):
        while active < n and n_terms[active] > q:
            active += 1
        for c in range(m):
            t = tail[q, c]
            for j in range(active):
                a, b = pr[c, j], pi[c, j]
                pr[c, j] = a * lr[j] - b * li[j] + t
                pi[c, j] = a * li[j] + b * lr[j]


@njit(cache=True, nogil=True, error_model="numpy")
def _final_state_batch(lam, Bm, x, tol, xi):  # pragma: no cover - compiled
    nb, ns = lam.shape
    m = Bm.shape[2]
    n_rec = x.shape[0]
    flat = lam.ravel()
    npt = flat.size
    conj_prev = np.zeros(npt, np.bool_)
    for j in range(1, npt):
        if j % ns and not conj_prev[j - 1] and flat[j].imag != 0.0 \
                and flat[j] == np.conj(flat[j - 1]):
            conj_prev[j] = True
    own = np.flatnonzero(~conj_prev)
    n_terms = np.empty(own.size, np.int64)
    log_tol = np.log(tol)
    for q in range(own.size):
        rho = min(max(abs(flat[own[q]]), 1e-3), 1 - 1e-9)
        n_terms[q] = min(n_rec, int(np.ceil(log_tol / np.log(rho))) + 1)
    order = np.argsort(-n_terms, kind="mergesort")
    npo = own.size
    lr, li, nt = np.empty(npo), np.empty(npo), np.empty(npo, np.int64)
    for q in range(npo):
        lr[q] = flat[own[order[q]]].real
        li[q] = flat[own[order[q]]].imag
        nt[q] = n_terms[order[q]]
    n_max = nt[0] if npo else 0
    tail = np.empty((n_max, m))
    for q in range(n_max):
        for c in range(m):
            tail[q, c] = x[n_rec - 1 - q, c]
    pr, pi = np.empty((m, npo)), np.empty((m, npo))
    _final_state(lr, li, nt, tail, pr, pi)
    p = np.empty((m, npt), np.complex128)
    for q in range(npo):
        for c in range(m):
            p[c, own[order[q]]] = pr[c, q] + 1j * pi[c, q]
    for j in range(npt):
        if conj_prev[j]:
            for c in range(m):
                p[c, j] = np.conj(p[c, j - 1])
    for b in range(nb):
        for s in range(ns):
            acc = 0j
            for c in range(m):
                acc += Bm[b, s, c] * p[c, b * ns + s]
            xi[b, s] = acc


def final_state(lam: NDArray, Bm: NDArray, x: NDArray, tol: float) -> NDArray:
    """Modal state after the record x (N, m), xi = sum_q lam^q Bm x_{N-1-q}, (nb, ns): the
    compiled form of forward.final_modal_state. Each eigenvalue takes the q with
    |lam|^q above tol (at least |lam| = 1e-3, at most N terms), evaluated by Horner's rule
    in every eigenvalue of the batch at once; the second of two adjacent exactly conjugate
    eigenvalues takes the conjugate of the first's sum (the coefficients are real)."""
    xi = np.empty(lam.shape, dtype=np.complex128)
    lam = np.require(lam, np.complex128, ("C", "W"))                 # one signature
    Bm = np.require(Bm, np.complex128, ("C", "W"))                   # (modal_batch)
    x = np.require(x, np.float64, ("C", "W"))
    over_rows(lambda lo, hi: _final_state_batch(lam[lo:hi], Bm[lo:hi], x, float(tol),
                                                xi[lo:hi]), lam.shape[0])
    return xi
