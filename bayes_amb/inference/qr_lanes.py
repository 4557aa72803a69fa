"""The eigenvalues of a batch of upper Hessenberg matrices by the Francis double-shift QR
iteration, all members in lock-step (issue 16).

EISPACK hqr (:func:`bayes_amb.inference.hessenberg._hqr`) run member by member spends ~1.2k
cycles per double-shift sweep of a 16 x 16 matrix at about one flop per cycle: short loops
whose lengths depend on the data, which do not vectorise. :func:`_hqr_lanes` runs the same
algorithm on every member of a batch at once, the matrices laid out walkers last
(n, n, nb), in rounds: in each round every member not yet finished first deflates what has
converged and chooses its shifts and starting row (member by member: O(n) work), then all
members take one double-shift sweep together, reflector position k by reflector position k.
A member takes part at position k only inside its own active window (rows l..nn, starting
row m <= k < nn), and each element update is a per-member select between the updated and
the old value, so that every member sees exactly the operations, in exactly the order, of
hqr run on it alone: the eigenvalues are those of ``_hqr`` bit for bit, whatever else is
in the batch (tests/test_eigen.py checks both). The loops over the members are innermost
and contiguous, so each operation of a sweep acts on a vector of members.

References: Wilkinson and Reinsch, Handbook for Automatic Computation II (1971), procedure
hqr; Press et al., Numerical Recipes, 2nd ed., sec. 11.6.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from bayes_amb.inference.hessenberg import MAX_QR_ITERATIONS


@njit(cache=True, nogil=True, error_model="numpy")
def _hqr_lanes(a, wr, wi, ok):  # pragma: no cover - compiled
    # Eigenvalues of every member of a (n, n, nb), upper Hessenberg (zero below the
    # subdiagonal; destroyed), into wr, wi (nb, n); ok (nb,): on entry the members to do,
    # on return those whose iteration converged. Member b's arithmetic is that of
    # _hqr(a[:, :, b]) exactly (module docstring).
    n, _, nb = a.shape
    anorm = np.zeros(nb)
    for i in range(n):
        for j in range(max(i - 1, 0), n):
            for b in range(nb):
                anorm[b] += abs(a[i, j, b])
    t = np.zeros(nb)
    nn = np.full(nb, n - 1, np.int64)
    its = np.zeros(nb, np.int64)
    live = ok.copy()
    # per member, packed into two arrays (few arrays: the loops over the members vectorise)
    # iw: 0 m (-1: no sweep this round), 1 nn, 2 l of the sweep; 3..5 the window of the
    # updates at k, columns k..iw[3] and rows iw[4]..iw[5] (empty where the member does not
    # take part); cf: 0..2 the first column (p, q, r), 3..7 the reflector (x, y, z, q, r),
    # 8 whether it is 3 x 3 (1.0) or 2 x 2 (0.0), 9 the subdiagonal element it leaves
    iw = np.zeros((6, nb), np.int64)
    cf = np.zeros((10, nb))
    while True:
        kmin, kmax = n, -1
        for b in range(nb):                          # member by member: deflate what has
            iw[0, b] = -1                            # converged, then the shifts and the
            if not live[b]:                          # starting row m of the next sweep
                continue
            while True:
                n_ = nn[b]
                if n_ < 0:
                    live[b] = False
                    break
                l = 0
                for ll in range(n_, 0, -1):  # look for a small subdiagonal element
                    s = abs(a[ll - 1, ll - 1, b]) + abs(a[ll, ll, b])
                    if s == 0.0:
                        s = anorm[b]
                    if abs(a[ll, ll - 1, b]) + s == s:
                        a[ll, ll - 1, b] = 0.0
                        l = ll
                        break
                x = a[n_, n_, b]
                if l == n_:                  # one root found
                    wr[b, n_] = x + t[b]
                    wi[b, n_] = 0.0
                    nn[b] = n_ - 1
                    its[b] = 0
                    continue
                y = a[n_ - 1, n_ - 1, b]
                w = a[n_, n_ - 1, b] * a[n_ - 1, n_, b]
                if l == n_ - 1:              # two roots found
                    p = 0.5 * (y - x)
                    q = p * p + w
                    z = np.sqrt(abs(q))
                    x += t[b]
                    if q >= 0.0:             # a real pair
                        z = p + (z if p >= 0 else -z)
                        wr[b, n_ - 1] = wr[b, n_] = x + z
                        if z != 0.0:
                            wr[b, n_] = x - w / z
                        wi[b, n_ - 1] = wi[b, n_] = 0.0
                    else:                    # a complex pair
                        wr[b, n_ - 1] = wr[b, n_] = x + p
                        wi[b, n_ - 1] = -z
                        wi[b, n_] = z
                    nn[b] = n_ - 2
                    its[b] = 0
                    continue
                if its[b] == MAX_QR_ITERATIONS:
                    live[b] = False
                    ok[b] = False
                    break
                if its[b] == 10 or its[b] == 20:  # exceptional shift
                    t[b] += x
                    for i in range(n_ + 1):
                        a[i, i, b] -= x
                    s = abs(a[n_, n_ - 1, b]) + abs(a[n_ - 1, n_ - 2, b])
                    x = y = 0.75 * s
                    w = -0.4375 * s * s
                its[b] += 1
                m = n_ - 2
                p = q = r = 0.0
                while m >= l:                # two consecutive small subdiagonals
                    z = a[m, m, b]
                    r = x - z
                    s = y - z
                    h = a[m + 1, m, b]
                    p = (r * s - w) + a[m, m + 1, b] * h
                    q = (a[m + 1, m + 1, b] - z - r - s) * h
                    r = a[m + 2, m + 1, b] * h
                    if m == l:
                        break
                    u = abs(a[m, m - 1, b]) * (abs(q) + abs(r))
                    v = abs(p) * (abs(a[m - 1, m - 1, b]) + abs(z) + abs(a[m + 1, m + 1, b]))
                    if u + v == v:
                        break
                    m -= 1
                s = 1.0 / (abs(p) + abs(q) + abs(r))
                cf[0, b] = p * s
                cf[1, b] = q * s
                cf[2, b] = r * s
                for i in range(m + 2, n_ + 1):
                    a[i, i - 2, b] = 0.0
                    if i != m + 2:
                        a[i, i - 3, b] = 0.0
                iw[0, b], iw[1, b], iw[2, b] = m, n_, l
                break
            if iw[0, b] >= 0:
                kmin = min(kmin, iw[0, b])
                kmax = max(kmax, iw[1, b] - 1)
        if kmax < 0:
            return
        jmax, imin = -1, n                           # the round's windows, all members
        for b in range(nb):
            if iw[0, b] >= 0:
                jmax = max(jmax, iw[1, b])
                imin = min(imin, iw[2, b])
        for k in range(kmin, kmax + 1):              # one double-shift sweep, all at once
            imax = min(jmax, k + 3)
            kp = max(k - 1, 0)
            k2 = k + 2 if k + 2 < n else k
            for b in range(nb):                      # the reflector at k of each member
                m = iw[0, b]                         # (selects, no branches; in two loops,
                at_m = k == m                        # which vectorise where one does not)
                last = k == iw[1, b] - 1
                p = a[k, kp, b]
                q = a[k + 1, kp, b]
                r = a[k2, kp, b]
                r = 0.0 if last | (k2 == k) else r
                x = abs(p) + abs(q) + abs(r)
                f = 1.0 / x
                scale = x != 0.0
                p = p * f if scale else p
                q = q * f if scale else q
                r = r * f if scale else r
                p = cf[0, b] if at_m else p
                q = cf[1, b] if at_m else q
                r = cf[2, b] if at_m else r
                s = np.sqrt(p * p + q * q + r * r)
                s = -s if p < 0 else s
                cf[9, b] = -s * x
                cf[3, b] = p + s
                cf[4, b] = q
                cf[5, b] = r
                cf[6, b] = s
            for b in range(nb):
                m = iw[0, b]
                n_ = iw[1, b]
                p, q, r, s = cf[3, b], cf[4, b], cf[5, b], cf[6, b]
                do = (m >= 0) & (k >= m) & (k < n_) & (s != 0.0)
                f = 1.0 / s
                cf[3, b] = p * f
                cf[4, b] = q * f
                cf[5, b] = r * f
                f = 1.0 / p
                cf[6, b] = q * f
                cf[7, b] = r * f
                cf[8, b] = 0.0 if k == n_ - 1 else 1.0
                iw[3, b] = n_ if do else -1
                iw[4, b] = iw[2, b] if do else n
                iw[5, b] = min(n_, k + 3) if do else -1
            if k > 0:                                # the subdiagonal element at (k, k - 1)
                for b in range(nb):
                    old = a[k, k - 1, b]
                    new = cf[9, b]
                    if k == iw[0, b]:
                        new = -old if iw[2, b] != k else old
                    a[k, k - 1, b] = new if iw[3, b] >= 0 else old
            if k + 2 < n:                            # rows k..k+2 (k..k+1 where 2 x 2)
                for j in range(k, jmax + 1):
                    for b in range(nb):
                        a0, a1, a2 = a[k, j, b], a[k + 1, j, b], a[k + 2, j, b]
                        pp = a0 + cf[6, b] * a1
                        th = cf[8, b] != 0.0
                        pp = pp + cf[7, b] * a2 if th else pp
                        sel = j <= iw[3, b]
                        a[k + 2, j, b] = a2 - pp * cf[5, b] if sel & th else a2
                        a[k + 1, j, b] = a1 - pp * cf[4, b] if sel else a1
                        a[k, j, b] = a0 - pp * cf[3, b] if sel else a0
                for i in range(imin, imax + 1):      # columns k..k+2 likewise
                    for b in range(nb):
                        c0, c1, c2 = a[i, k, b], a[i, k + 1, b], a[i, k + 2, b]
                        pp = cf[3, b] * c0 + cf[4, b] * c1
                        th = cf[8, b] != 0.0
                        pp = pp + cf[5, b] * c2 if th else pp
                        sel = (iw[4, b] <= i) & (i <= iw[5, b])
                        a[i, k + 2, b] = c2 - pp * cf[7, b] if sel & th else c2
                        a[i, k + 1, b] = c1 - pp * cf[6, b] if sel else c1
                        a[i, k, b] = c0 - pp if sel else c0
            else:                                    # k = n - 2: the last, 2 x 2 step
                for j in range(k, jmax + 1):
                    for b in range(nb):
                        a0, a1 = a[k, j, b], a[k + 1, j, b]
                        pp = a0 + cf[6, b] * a1
                        sel = j <= iw[3, b]
                        a[k + 1, j, b] = a1 - pp * cf[4, b] if sel else a1
                        a[k, j, b] = a0 - pp * cf[3, b] if sel else a0
                for i in range(imin, imax + 1):
                    for b in range(nb):
                        c0, c1 = a[i, k, b], a[i, k + 1, b]
                        pp = cf[3, b] * c0 + cf[4, b] * c1
                        sel = (iw[4, b] <= i) & (i <= iw[5, b])
                        a[i, k + 1, b] = c1 - pp * cf[6, b] if sel else c1
                        a[i, k, b] = c0 - pp if sel else c0


def hqr_lanes(H: NDArray) -> tuple[NDArray, NDArray]:
    """Eigenvalues of a stack of upper Hessenberg matrices H (nb, n, n), in lock-step: lam
    (nb, n) complex (hqr's order: deflated from the bottom, conjugate pairs adjacent) and
    ok (nb,), False where the QR iteration did not converge (that member's lam is then
    meaningless). Each member's eigenvalues are those of hqr run on it alone, bit for bit.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> H = np.triu(rng.standard_normal((3, 6, 6)), -1)
    >>> lam, ok = hqr_lanes(H)
    >>> ref = np.linalg.eigvals(H)
    >>> bool(ok.all() and all(np.allclose(np.sort_complex(lam[b]), np.sort_complex(ref[b]))
    ...                       for b in range(3)))
    True
    """
    H = np.asarray(H, dtype=np.float64)
    nb, n, _ = H.shape
    a = np.ascontiguousarray(np.triu(H, -1).transpose(1, 2, 0))
    wr, wi = np.zeros((nb, n)), np.zeros((nb, n))
    ok = np.isfinite(H).all(axis=(1, 2))
    a[:, :, ~ok] = 0.0
    _hqr_lanes(a, wr, wi, ok)
    return wr + 1j * wi, ok
