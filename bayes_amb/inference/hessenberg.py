"""Compiled (numba) building blocks of the modal form (bayes_amb.inference.eigen): Householder
reduction to Hessenberg form across a batch, the Francis double-shift QR iteration for the
eigenvalues of one matrix (EISPACK hqr: the reference that the lock-step iteration of
bayes_amb.inference.qr_lanes, which the modal form runs, reproduces bit for bit), and
inverse iteration for the eigenvectors (one vector, or one eigenvalue of every member of a
batch at once).

References: Wilkinson and Reinsch, Handbook for Automatic Computation II (1971), procedures
orthes, hqr and invit; Press et al., Numerical Recipes, 2nd ed., sec. 11.5-11.7; Golub and
Van Loan, Matrix Computations, 4th ed., sec. 7.4-7.6; LAPACK dlaein (the growth test).
"""

from __future__ import annotations

import numpy as np
from numba import njit

EPS = 2.220446049250313e-16
MAX_QR_ITERATIONS = 30
"""Per eigenvalue, as in EISPACK hqr (exceptional shifts at iterations 10 and 20)."""
RESIDUAL_FACTOR = 1e3
"""Eigenvector tolerance: ||H v - lam v|| <= RESIDUAL_FACTOR n u ||H||_1 ||v||."""


@njit(cache=True, nogil=True, error_model="numpy")
def _hessenberg_lanes(A, B, C):  # pragma: no cover - compiled
    # In place, for a whole batch at once, walkers last (A (n, n, nb), B (n, m, nb),
    # C (p, n, nb)): A <- Q^T A Q upper Hessenberg, B <- Q^T B, C <- C Q, with the
    # Householder reflectors H_k = I - beta v v^T, v = x - alpha e1 zeroing column k below
    # the subdiagonal (alpha = -sign(x_1) ||x||); a zero column gives beta = 0, and that
    # walker's step changes nothing. Every loop runs over the walkers innermost.
    n, _, nb = A.shape
    m = B.shape[1]
    p = C.shape[0]
    v = np.zeros((n, nb))
    w = np.empty((n, nb))
    wb = np.empty((m, nb))
    alpha = np.empty(nb)
    beta = np.empty(nb)
    for k in range(n - 2):
        for b in range(nb):
            alpha[b] = 0.0
        for i in range(k + 1, n):
            for b in range(nb):
                alpha[b] += A[i, k, b] * A[i, k, b]
        for b in range(nb):
            a = np.sqrt(alpha[b])
            x0 = A[k + 1, k, b]
            if x0 > 0:
                a = -a
            alpha[b] = a
            v[k + 1, b] = x0 - a
        for i in range(k + 1):
            for b in range(nb):
                v[i, b] = 0.0
        for i in range(k + 2, n):
            for b in range(nb):
                v[i, b] = A[i, k, b]
        for b in range(nb):
            beta[b] = 0.0
        for i in range(k + 1, n):
            for b in range(nb):
                beta[b] += v[i, b] * v[i, b]
        for b in range(nb):
            beta[b] = 2.0 / beta[b] if alpha[b] != 0.0 and beta[b] != 0.0 else 0.0
        for j in range(n):                   # left: A <- A - beta v (v^T A), B likewise
            for b in range(nb):
                w[j, b] = 0.0
        for j in range(m):
            for b in range(nb):
                wb[j, b] = 0.0
        for i in range(k + 1, n):
            for j in range(n):
                for b in range(nb):
                    w[j, b] += v[i, b] * A[i, j, b]
            for j in range(m):
                for b in range(nb):
                    wb[j, b] += v[i, b] * B[i, j, b]
        for i in range(k + 1, n):
            for j in range(n):
                for b in range(nb):
                    A[i, j, b] -= beta[b] * v[i, b] * w[j, b]
            for j in range(m):
                for b in range(nb):
                    B[i, j, b] -= beta[b] * v[i, b] * wb[j, b]
        for i in range(n):                   # right: A <- A - beta (A v) v^T, C likewise
            for b in range(nb):
                w[i, b] = 0.0
            for j in range(k + 1, n):
                for b in range(nb):
                    w[i, b] += A[i, j, b] * v[j, b]
            for j in range(k + 1, n):
                for b in range(nb):
                    A[i, j, b] -= beta[b] * w[i, b] * v[j, b]
        for i in range(p):
            for b in range(nb):
                wb[0, b] = 0.0
            for j in range(k + 1, n):
                for b in range(nb):
                    wb[0, b] += C[i, j, b] * v[j, b]
            for j in range(k + 1, n):
                for b in range(nb):
                    C[i, j, b] -= beta[b] * wb[0, b] * v[j, b]
        for b in range(nb):
            if beta[b] != 0.0:
                A[k + 1, k, b] = alpha[b]
                for i in range(k + 2, n):
                    A[i, k, b] = 0.0


@njit(cache=True, nogil=True, error_model="numpy")
def _hqr(a, wr, wi):  # pragma: no cover - compiled
    # Eigenvalues of the upper Hessenberg a (destroyed); False if the iteration failed.
    n = a.shape[0]
    anorm = 0.0
    for i in range(n):
        for j in range(max(i - 1, 0), n):
            anorm += abs(a[i, j])
    nn = n - 1
    t = 0.0
    p = q = r = s = w = x = y = z = 0.0
    while nn >= 0:
        its = 0
        while True:
            l = 0
            for ll in range(nn, 0, -1):             # look for a small subdiagonal element
                s = abs(a[ll - 1, ll - 1]) + abs(a[ll, ll])
                if s == 0.0:
                    s = anorm
                if abs(a[ll, ll - 1]) + s == s:
                    a[ll, ll - 1] = 0.0
                    l = ll
                    break
            x = a[nn, nn]
            if l == nn:                              # one root found
                wr[nn] = x + t
                wi[nn] = 0.0
                nn -= 1
                break
            y = a[nn - 1, nn - 1]
            w = a[nn, nn - 1] * a[nn - 1, nn]
            if l == nn - 1:                          # two roots found
                p = 0.5 * (y - x)
                q = p * p + w
                z = np.sqrt(abs(q))
                x += t
                if q >= 0.0:                         # a real pair
                    z = p + (z if p >= 0 else -z)
                    wr[nn - 1] = wr[nn] = x + z
                    if z != 0.0:
                        wr[nn] = x - w / z
                    wi[nn - 1] = wi[nn] = 0.0
                else:                                # a complex pair
                    wr[nn - 1] = wr[nn] = x + p
                    wi[nn - 1] = -z
                    wi[nn] = z
                nn -= 2
                break
            if its == MAX_QR_ITERATIONS:
                return False
            if its == 10 or its == 20:               # exceptional shift
                t += x
                for i in range(nn + 1):
                    a[i, i] -= x
                s = abs(a[nn, nn - 1]) + abs(a[nn - 1, nn - 2])
                x = y = 0.75 * s
                w = -0.4375 * s * s
            its += 1
            m = nn - 2
            while m >= l:                            # two consecutive small subdiagonals
                z = a[m, m]                          # (p, q, r: the first column of the
                r = x - z                            # shifted product, here times
                s = y - z                            # a[m + 1, m]: the test is invariant
                h = a[m + 1, m]                      # to the scale, normalised below)
                p = (r * s - w) + a[m, m + 1] * h
                q = (a[m + 1, m + 1] - z - r - s) * h
                r = a[m + 2, m + 1] * h
                if m == l:
                    break
                u = abs(a[m, m - 1]) * (abs(q) + abs(r))
                v = abs(p) * (abs(a[m - 1, m - 1]) + abs(z) + abs(a[m + 1, m + 1]))
                if u + v == v:
                    break
                m -= 1
            s = 1.0 / (abs(p) + abs(q) + abs(r))
            p *= s
            q *= s
            r *= s
            for i in range(m + 2, nn + 1):
                a[i, i - 2] = 0.0
                if i != m + 2:
                    a[i, i - 3] = 0.0
            for k in range(m, nn):                   # double QR step, rows l..nn, cols k..nn
                if k != m:
                    p = a[k, k - 1]
                    q = a[k + 1, k - 1]
                    r = 0.0
                    if k != nn - 1:
                        r = a[k + 2, k - 1]
                    x = abs(p) + abs(q) + abs(r)
                    if x != 0.0:
                        f = 1.0 / x
                        p *= f
                        q *= f
                        r *= f
                s = np.sqrt(p * p + q * q + r * r)
                if p < 0:
                    s = -s
                if s != 0.0:
                    if k == m:
                        if l != m:
                            a[k, k - 1] = -a[k, k - 1]
                    else:
                        a[k, k - 1] = -s * x
                    p += s
                    f = 1.0 / s
                    x = p * f
                    y = q * f
                    z = r * f
                    f = 1.0 / p
                    q *= f
                    r *= f
                    mmin = nn if nn < k + 3 else k + 3
                    if k != nn - 1:                  # a 3 x 3 reflector: rows, columns
                        for j in range(k, nn + 1):
                            p = a[k, j] + q * a[k + 1, j] + r * a[k + 2, j]
                            a[k + 2, j] -= p * z
                            a[k + 1, j] -= p * y
                            a[k, j] -= p * x
                        for i in range(l, mmin + 1):
                            p = x * a[i, k] + y * a[i, k + 1] + z * a[i, k + 2]
                            a[i, k + 2] -= p * r
                            a[i, k + 1] -= p * q
                            a[i, k] -= p
                    else:                            # the last step: 2 x 2
                        for j in range(k, nn + 1):
                            p = a[k, j] + q * a[k + 1, j]
                            a[k + 1, j] -= p * y
                            a[k, j] -= p * x
                        for i in range(l, mmin + 1):
                            p = x * a[i, k] + y * a[i, k + 1]
                            a[i, k + 1] -= p * q
                            a[i, k] -= p
            if l >= nn - 1:
                break
    return True


@njit(cache=True, nogil=True, error_model="numpy")
def _inverse_iteration(H, lr, li, tol, vr, vi, Ur, Ui, piv, mul_r, mul_i, rr, ri):
    # pragma: no cover - compiled
    # Eigenvector of the Hessenberg H for lam = lr + i li into (vr, vi), unit 2-norm with
    # its largest entry real: inverse iteration with the pivoted LU of H - lam I (real
    # arithmetic on real and imaginary parts). Returns a bound on ||H v - lam v|| / ||v||
    # (infinity norms; above tol: not converged).
    #
    # The first step solves U v = e (the start vector is P^T L e, of infinity norm <= 2
    # with |multipliers| <= 1), so ||(H - lam I) v|| <= 2 + (backward error of the LU)
    # and the residual of v / ||v|| is at most 2 / ||v|| plus rounding: accepted when
    # that is below tol / 2 (LAPACK dlaein's growth test). Otherwise the residual is
    # computed, and a second step (with P and L^-1) taken if it is above tol.
    n = H.shape[0]
    eps3 = tol / (RESIDUAL_FACTOR * n)                  # = eps ||H||_1
    for i in range(n):
        for j in range(max(i - 1, 0), n):
            Ur[i, j] = H[i, j]
            Ui[i, j] = 0.0
        Ur[i, i] -= lr
        Ui[i, i] = -li
    for k in range(n - 1):                           # LU with row pivoting (k <-> k + 1)
        ar, ai = Ur[k, k], Ui[k, k]
        br, bi = Ur[k + 1, k], Ui[k + 1, k]
        if br * br + bi * bi > ar * ar + ai * ai:
            piv[k] = 1
            for j in range(k, n):
                t = Ur[k, j]
                Ur[k, j] = Ur[k + 1, j]
                Ur[k + 1, j] = t
                t = Ui[k, j]
                Ui[k, j] = Ui[k + 1, j]
                Ui[k + 1, j] = t
            ar, ai, br, bi = br, bi, ar, ai
        else:
            piv[k] = 0
        d = ar * ar + ai * ai
        if d == 0.0:
            Ur[k, k] = ar = eps3
            d = eps3 * eps3
        d = 1.0 / d
        mr = (br * ar + bi * ai) * d                 # multiplier b / a
        mi = (bi * ar - br * ai) * d
        mul_r[k] = mr
        mul_i[k] = mi
        for j in range(k + 1, n):
            ur, ui = Ur[k, j], Ui[k, j]
            Ur[k + 1, j] -= mr * ur - mi * ui
            Ui[k + 1, j] -= mr * ui + mi * ur
    if Ur[n - 1, n - 1] == 0.0 and Ui[n - 1, n - 1] == 0.0:
        Ur[n - 1, n - 1] = eps3
    for i in range(n):
        vr[i] = 1.0
        vi[i] = 0.0
    res = np.inf
    for step in range(2):
        if step:                                     # apply P and L^-1 to v
            for k in range(n - 1):
                if piv[k]:
                    t = vr[k]
                    vr[k] = vr[k + 1]
                    vr[k + 1] = t
                    t = vi[k]
                    vi[k] = vi[k + 1]
                    vi[k + 1] = t
                vr[k + 1] -= mul_r[k] * vr[k] - mul_i[k] * vi[k]
                vi[k + 1] -= mul_r[k] * vi[k] + mul_i[k] * vr[k]
        for i in range(n - 1, -1, -1):               # U^-1 v, by columns
            ar, ai = Ur[i, i], Ui[i, i]
            d = ar * ar + ai * ai
            if d == 0.0:
                ar, d = eps3, eps3 * eps3
            sr, si = vr[i], vi[i]
            d = 1.0 / d
            xr = (sr * ar + si * ai) * d
            xi_ = (si * ar - sr * ai) * d
            vr[i] = xr
            vi[i] = xi_
            for j in range(i):
                vr[j] -= Ur[j, i] * xr - Ui[j, i] * xi_
                vi[j] -= Ur[j, i] * xi_ + Ui[j, i] * xr
        big = 0.0
        for i in range(n):
            big = max(big, abs(vr[i]), abs(vi[i]))
        if not (big > 0.0 and big < np.inf):
            return np.inf
        for i in range(n):
            vr[i] /= big
            vi[i] /= big
        if step == 0 and 4.0 / big <= tol:           # the growth test
            res = 2.0 / big
            break
        for i in range(n):                           # r = H v - lam v, by columns
            rr[i] = -(lr * vr[i] - li * vi[i])
            ri[i] = -(lr * vi[i] + li * vr[i])
        for j in range(n):
            for i in range(min(j + 2, n)):
                rr[i] += H[i, j] * vr[j]
                ri[i] += H[i, j] * vi[j]
        res = 0.0
        for i in range(n):
            res = max(res, abs(rr[i]), abs(ri[i]))
        if res <= tol:
            break
    k = 0                                            # unit 2-norm, largest entry real
    nrm = 0.0
    big = -1.0
    for i in range(n):
        a2 = vr[i] * vr[i] + vi[i] * vi[i]
        nrm += a2
        if a2 > big:
            big = a2
            k = i
    nrm = np.sqrt(nrm)
    cr, ci = vr[k] / np.sqrt(big), -vi[k] / np.sqrt(big)     # conj phase of v_k
    for i in range(n):
        a, b = vr[i], vi[i]
        vr[i] = (a * cr - b * ci) / nrm
        vi[i] = (a * ci + b * cr) / nrm
    vi[k] = 0.0
    return res


@njit(cache=True, nogil=True, error_model="numpy")
def _inverse_iteration_lanes(H, lr, li, tol, vr, vi, Ur, Ui, piv, mr, mi, xr, xi, good):
    # pragma: no cover - compiled
    # The first step of _inverse_iteration (LU of H - lam I, U v = e, the growth test and
    # the normalisation) for one eigenvalue of every walker at once: H (n, n, nb) Hessenberg,
    # lr, li, tol (nb,); v (n, nb); good (nb,): the growth test passed (the others are
    # redone by _inverse_iteration). Row pivoting is a per-lane select.
    n, _, nb = H.shape
    for i in range(n):
        for j in range(max(i - 1, 0), n):
            for b in range(nb):
                Ur[i, j, b] = H[i, j, b]
                Ui[i, j, b] = 0.0
        for b in range(nb):
            Ur[i, i, b] -= lr[b]
            Ui[i, i, b] = -li[b]
    for k in range(n - 1):
        for b in range(nb):
            a2 = Ur[k, k, b] * Ur[k, k, b] + Ui[k, k, b] * Ui[k, k, b]
            b2 = Ur[k + 1, k, b] * Ur[k + 1, k, b] + Ui[k + 1, k, b] * Ui[k + 1, k, b]
            piv[b] = b2 > a2
        for j in range(k, n):
            for b in range(nb):
                ar, ai = Ur[k, j, b], Ui[k, j, b]
                br, bi = Ur[k + 1, j, b], Ui[k + 1, j, b]
                sw = piv[b]
                Ur[k, j, b] = br if sw else ar
                Ui[k, j, b] = bi if sw else ai
                Ur[k + 1, j, b] = ar if sw else br
                Ui[k + 1, j, b] = ai if sw else bi
        for b in range(nb):
            eps3 = tol[b] / (RESIDUAL_FACTOR * n)
            ar, ai = Ur[k, k, b], Ui[k, k, b]
            d = ar * ar + ai * ai
            zero = d == 0.0
            ar = eps3 if zero else ar
            Ur[k, k, b] = ar
            d = eps3 * eps3 if zero else d
            d = 1.0 / d
            br, bi = Ur[k + 1, k, b], Ui[k + 1, k, b]
            mr[b] = (br * ar + bi * ai) * d
            mi[b] = (bi * ar - br * ai) * d
        for j in range(k + 1, n):
            for b in range(nb):
                ur, ui = Ur[k, j, b], Ui[k, j, b]
                Ur[k + 1, j, b] -= mr[b] * ur - mi[b] * ui
                Ui[k + 1, j, b] -= mr[b] * ui + mi[b] * ur
    for i in range(n):
        for b in range(nb):
            vr[i, b] = 1.0
            vi[i, b] = 0.0
    for i in range(n - 1, -1, -1):                   # U^-1 v, by columns
        for b in range(nb):
            eps3 = tol[b] / (RESIDUAL_FACTOR * n)
            ar, ai = Ur[i, i, b], Ui[i, i, b]
            d = ar * ar + ai * ai
            zero = d == 0.0
            ar = eps3 if zero else ar
            d = eps3 * eps3 if zero else d
            d = 1.0 / d
            sr, si = vr[i, b], vi[i, b]
            xr[b] = (sr * ar + si * ai) * d
            xi[b] = (si * ar - sr * ai) * d
            vr[i, b] = xr[b]
            vi[i, b] = xi[b]
        for j in range(i):
            for b in range(nb):
                vr[j, b] -= Ur[j, i, b] * xr[b] - Ui[j, i, b] * xi[b]
                vi[j, b] -= Ur[j, i, b] * xi[b] + Ui[j, i, b] * xr[b]
    for b in range(nb):
        big = 0.0
        for i in range(n):
            big = max(big, abs(vr[i, b]), abs(vi[i, b]))
        good[b] = big > 0.0 and big < np.inf and 4.0 / big <= tol[b]
        if not good[b]:
            continue
        for i in range(n):
            vr[i, b] /= big
            vi[i, b] /= big
        k = 0                                        # unit 2-norm, largest entry real
        nrm = 0.0
        best = -1.0
        for i in range(n):
            a2 = vr[i, b] * vr[i, b] + vi[i, b] * vi[i, b]
            nrm += a2
            if a2 > best:
                best = a2
                k = i
        nrm = np.sqrt(nrm)
        cr, ci = vr[k, b] / np.sqrt(best), -vi[k, b] / np.sqrt(best)
        for i in range(n):
            a, c = vr[i, b], vi[i, b]
            vr[i, b] = (a * cr - c * ci) / nrm
            vi[i, b] = (a * ci + c * cr) / nrm
        vi[k, b] = 0.0
