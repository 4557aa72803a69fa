"""MAP search of the diagnosis on the linearised residual (Gauss-Newton, trust region).

The whole-band likelihood (likelihood.py) depends on the parameters only through the
residual DFT R_k(theta) = E_k - S(theta) x_k - lines_k . coef, and on the noise
intensities only through the band spectra Psi_b(sigma). Linearised at theta_0,

    R_k(theta_0 + delta) ~ R_k + sum_j J_kj delta_j,     J_kj = dR_k / dtheta_j,

the band sums are quadratic in delta,

    P_b(delta) = sum_{a,c = 0..q} w_a w_c M_b[a, c],   w = (1, delta),
    M_b[a, c] = sum_{k in b} G_ka G_kc^H,   G_k0 = R_k, G_kj = J_kj,

so the log posterior of the linearised model, exact in the noise intensities, costs the
4 x 4 algebra of the bands only, with an analytic gradient and an analytic Hessian in the
parameters (LinearModel.hessian; the noise intensities' rows by differences of the
gradient). The Hessian's diagonal scales the coordinates, and the search of the linear
model starts from its Newton step, and stops at an ftol of 1e-9, above the rounding of a
log posterior of order 1e5: L-BFGS-B then takes a median of 3 evaluations (mean 5.7)
per search on the diagnosis of ROSS's test rig in `bayes-amb bench --only rigs`, where
from the model's point with an ftol of 1e-14 it took 12 (mean 21, a tenth of the
searches above 50, grinding against that rounding). J comes from one batch of q + 1
kernel rows (forward differences of R: R is close to linear in theta, so its differences
are accurate to about the step, where differences of log L near the optimum are not). The
linearised posterior is maximised inside a trust region (box of +-radius curvature scales
on theta), the step kept when the exact log posterior improves, the region widened or
narrowed by the ratio of actual to predicted gain (Nocedal & Wright, Numerical
Optimization, ch. 4 and 10.3). Near the optimum the neglected term sum R d2R is noise
against the excitation's signal, so few steps are needed: each costs q + 1 kernel rows,
where an L-BFGS step with central-difference gradients costs 2 q + 1 and many more steps.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.optimize as so
from numpy.typing import NDArray

from bayes_amb.discrepancy.likelihood import P_CH, RobustWhittle
from bayes_amb.inference.estimate import LogPosterior
from bayes_amb.inference.hermitian_kernels import linear_terms
from bayes_amb.inference.least_squares import gauss_newton_least_squares
from bayes_amb.inference.priors import Prior, bound_arrays

_LN10 = np.log(10.0)
_STEP = 1e-5
"""Forward-difference step of J (theta is dimensionless, of order 0.01-10)."""


def band_moments(G: NDArray, starts: NDArray, counts: NDArray) -> NDArray:
    """M_b[a, c] = sum_{k in b} G_a,k G_c,k^H for G (A, nf, 4): shape (A, A, n_bands, 4, 4).

    Examples
    --------
    >>> G = np.arange(24.0).reshape(2, 3, 4) * (1 + 1j)
    >>> M = band_moments(G, np.array([0, 1]), np.array([1, 2]))
    >>> bool(np.allclose(M[0, 1, 1], np.outer(G[0, 1], G[1, 1].conj())
    ...                  + np.outer(G[0, 2], G[1, 2].conj())))
    True
    """
    n_a, nf, p = G.shape
    X = np.ascontiguousarray(G.transpose(1, 0, 2).reshape(nf, n_a * p))
    out = np.empty((n_a, n_a, starts.size, p, p), dtype=complex)
    for b, (s, c) in enumerate(zip(starts, counts, strict=True)):
        Xb = X[s:s + c]
        Mb = (Xb.T @ Xb.conj()).reshape(n_a, p, n_a, p)
        out[:, :, b] = Mb.transpose(0, 2, 1, 3)
    return out


def prior_gradient(post: LogPosterior, theta: NDArray) -> NDArray:
    """d log p(theta) / d theta inside the support (uniform 0, normal, lognormal)."""
    return log_prior_gradient(post.priors.priors, theta)


def log_prior_gradient(priors: Sequence[Prior], theta: NDArray) -> NDArray:
    """d log p / d theta of independent priors, one per entry of theta, inside their
    support (uniform 0, normal, lognormal)."""
    g = np.zeros(theta.size)
    for j, pr in enumerate(priors):
        if pr.kind == "normal":
            g[j] = -(theta[j] - pr.a) / pr.b**2
        elif pr.kind == "lognormal" and theta[j] > 0:
            g[j] = -((np.log(theta[j]) - pr.a) / pr.b**2 + 1.0) / theta[j]
    return g


def log_prior_curvature(priors: Sequence[Prior], theta: NDArray, h: float = 1e-6
                        ) -> NDArray:
    """-d2 log p / d theta_j2 of independent priors, one per entry of theta: central
    differences (step h) of :func:`log_prior_gradient`."""
    return -(log_prior_gradient(priors, theta + h) - log_prior_gradient(priors, theta - h)) / (
        2 * h)


@dataclass
class LinearModel:
    """The log posterior of the model linearised at x0 in the parameters ``cols`` (see
    module docstring); the noise intensities enter exactly."""

    post: LogPosterior
    x0: NDArray
    cols: NDArray
    MT: NDArray            # (A, n_bands * 16, A): M[a, c] with c last, for Q = MT @ w

    def __post_init__(self) -> None:
        like = self.like
        # the noise sources' band spectra as they enter Psi_b (likelihood.RobustWhittle)
        self.phi = like.phi_sources * (like.n * (like.nu - like.shift))[None, :, None, None]
        self._noise_key: bytes | None = None
        self._hess_key: bytes | None = None     # hessian's and hessian_with_noise's ls
        self._full_key: bytes | None = None

    @property
    def like(self) -> RobustWhittle:
        return self.post.likelihood  # type: ignore[return-value]

    def point(self, delta: NDArray, ls: NDArray) -> NDArray:
        x = self.x0.copy()
        x[self.cols] += delta
        x[self.post.p:] = ls
        return x

    def _noise_terms(self, ls: NDArray) -> tuple[NDArray, NDArray, NDArray, NDArray, bool]:
        """sigma^2, Psi_b, sum_b nu_b log|Psi_b| and tr(Psi_b^-1 Phi_sb) at log10 sigma ls
        (remembered: a search with the noise held evaluates one ls many times)."""
        key = np.asarray(ls, dtype=float).tobytes()
        if key != self._noise_key:
            like = self.like
            sig2 = 10.0 ** (2 * np.asarray(ls, dtype=float))
            Psi = np.tensordot(sig2, self.phi, axes=(0, 0))
            s0, ld0 = np.linalg.slogdet(Psi)
            ok = bool(np.all(s0.real > 0))
            tr_psi = (np.einsum("bij,sbji->sb", np.linalg.inv(Psi), self.phi).real if ok
                      else np.zeros((3, like.starts.size)))
            self._noise_cache = (sig2, Psi, float(np.sum(like.nu * ld0)), tr_psi, ok)
            self._noise_key = key
        return self._noise_cache

    def value_grad(self, delta: NDArray, ls: NDArray) -> tuple[float, NDArray, NDArray]:
        """Linearised log posterior and its gradient along delta (cols) and log10 sigma."""
        like = self.like
        w = np.concatenate([[1.0], delta])
        sig2, Psi, nu_ld0, tr_psi, ok = self._noise_terms(ls)
        wt = like.nu + like.counts
        terms = (linear_terms(self.MT, w, Psi, self.phi, wt) if like.engine.compiled
                 else self._terms_numpy(w, Psi, wt))
        if not (ok and terms[0]):
            return -np.inf, np.zeros(delta.size), np.zeros(3)
        _, wld1, tr_kq, tr_k = terms
        ll = float(np.sum(like._gamma_term) - wld1
                   - P_CH * np.log(np.pi) * float(np.sum(like.counts)))
        ll += nu_ld0 - 2 * P_CH * like.k.size * np.log(like.scale) + like.jacobian
        theta = self.x0[:self.post.p].copy()
        theta[self.cols] += delta
        lp = self.post.priors.log_prior(theta[None], np.asarray(ls)[None])[0]
        g_delta = -2.0 * tr_kq + prior_gradient(self.post, theta)[self.cols]
        g_ls = 2 * _LN10 * sig2 * (tr_psi @ like.nu - tr_k)
        return ll + float(lp), g_delta, g_ls

    def hessian(self, ls: NDArray) -> NDArray:
        """-d2 m / d delta_j d delta_k at delta = 0 (q x q), analytic: with K_b = S_b^-1 at
        w = (1, 0, ..), D_jb = M_b[j, 0] + M_b[j, 0]^H (dS_b / d delta_j) and d2S_b /
        d delta_j d delta_k = M_b[j, k] + M_b[j, k]^H, each entry is sum_b wt_b (2 Re
        tr(K_b M_b[j, k]) - Re tr(K_b D_jb K_b D_kb)), plus the prior's curvature on the
        diagonal (differences of its gradient; the priors are independent). NaN where a
        band's S_b is not positive definite. Remembered for the last ls."""
        key = np.asarray(ls, dtype=float).tobytes()
        if key == self._hess_key:
            return self._hess
        like = self.like
        nb = like.starts.size
        q = self.cols.size
        _, Psi, _, _, ok = self._noise_terms(ls)
        MT = self.MT.reshape(q + 1, nb, P_CH, P_CH, q + 1)
        S = Psi + MT[0, :, :, :, 0]
        H = np.full((q, q), np.nan)
        if ok and np.all(np.linalg.eigvalsh(S)[:, 0] > 0):
            K = np.linalg.inv(S)
            Q = MT[1:, :, :, :, 0]
            KD = K[None] @ (Q + Q.conj().transpose(0, 1, 3, 2))
            wt = like.nu + like.counts
            t1 = 2 * np.einsum("b,bil,jblik->jk", wt, K, MT[1:, :, :, :, 1:]).real
            t2 = np.einsum("b,jbil,kbli->jk", wt, KD, KD).real
            prior = log_prior_curvature(self.post.priors.priors, self.x0[:self.post.p])
            H = t1 - t2 + np.diag(prior[self.cols])
        self._hess_key, self._hess = key, H
        return H

    def hessian_with_noise(self, ls: NDArray, eps: float = 1e-4) -> NDArray:
        """-d2 m over (delta, log10 sigma) at delta = 0, (q + 3) x (q + 3): the parameters'
        block analytic (:meth:`hessian`), the noise intensities' columns from central
        differences (step eps) of the analytic gradient, symmetrised. Remembered for the
        last ls."""
        key = np.asarray(ls, dtype=float).tobytes()
        if key == self._full_key:
            return self._full
        q = self.cols.size
        H = np.zeros((q + 3, q + 3))
        H[:q, :q] = self.hessian(ls)
        zero = np.zeros(q)
        for t in range(3):
            g = []
            for s in (eps, -eps):
                lsv = np.array(ls, dtype=float)
                lsv[t] += s
                _, gd, gl = self.value_grad(zero, lsv)
                g.append(np.concatenate([gd, gl]))
            H[:, q + t] = -(g[0] - g[1]) / (2 * eps)
        H[q:, :q] = H[:q, q:].T
        H[q:, q:] = 0.5 * (H[q:, q:] + H[q:, q:].T)
        self._full_key, self._full = key, H
        return H

    def _terms_numpy(self, w: NDArray, Psi: NDArray, wt: NDArray
                     ) -> tuple[bool, float, NDArray, NDArray]:
        """hermitian_kernels.linear_terms in numpy (BAYES_AMB_KERNEL=numpy)."""
        nb = self.like.starts.size
        Q = (self.MT @ w).reshape(w.size, nb, P_CH, P_CH)       # Q_a = sum_c w_c M[a, c]
        P = np.tensordot(w, Q, axes=(0, 0))
        s1, ld1 = np.linalg.slogdet(Psi + P)
        if not np.all(s1.real > 0):
            return False, 0.0, np.zeros(w.size - 1), np.zeros(3)
        K = np.linalg.inv(Psi + P)
        tr_kq = np.einsum("bij,abji->ab", K, Q[1:]).real
        tr_k = np.einsum("bij,sbji->sb", K, self.phi).real
        return True, float(wt @ ld1), tr_kq @ wt, tr_k @ wt


def linearise(post: LogPosterior, x: NDArray, cols: NDArray, step: float = _STEP
              ) -> LinearModel | None:
    """The linear model at x in the parameters cols: R and J from one batch of
    cols.size + 1 kernel rows (steps taken inward at an upper prior bound). None where a
    row is not stabilised."""
    like: RobustWhittle = post.likelihood  # type: ignore[assignment]
    theta = x[:post.p]
    h = np.full(cols.size, step)
    for i, j in enumerate(cols):
        hi = post.bounds()[j][1]
        if hi is not None and theta[j] + step > hi:
            h[i] = -step
    rows = np.tile(theta, (cols.size + 1, 1))
    rows[1 + np.arange(cols.size), cols] += h
    R, stable = like.residual_dft(rows)
    post.n_evals += rows.shape[0]
    if not np.all(stable):
        return None
    G = np.concatenate([R[:1], (R[1:] - R[:1]) / h[:, None, None]])
    M = band_moments(G, like.starts, like.counts)
    n_a = G.shape[0]
    MT = np.ascontiguousarray(M.reshape(n_a, n_a, -1).transpose(0, 2, 1))
    return LinearModel(post, np.asarray(x, dtype=float).copy(), cols, MT)


def _model_hessian(lin: LinearModel, ls: NDArray, noise: bool) -> NDArray:
    """-d2 m over the linear model's free coordinates: the parameters (hessian), and the
    noise intensities after them when they are free (hessian_with_noise)."""
    return lin.hessian_with_noise(ls) if noise else lin.hessian(ls)


def _curvature_scales(lin: LinearModel, ls: NDArray, noise: bool, width: NDArray
                      ) -> NDArray:
    """1/sqrt(-d2 m / dv_j2) per free coordinate of the linear model (the diagonal of
    LinearModel.hessian, or of hessian_with_noise with the noise intensities), the prior
    width where the curvature is not usable."""
    out = np.diag(_model_hessian(lin, ls, noise)).copy()
    ok = np.isfinite(out) & (out > 0)
    return np.clip(np.where(ok, 1.0 / np.sqrt(np.where(ok, out, 1.0)), width), 1e-12, width)


def _maximise_model(lin: LinearModel, ls0: NDArray, noise: bool, lo: NDArray, hi: NDArray,
                    scale: NDArray) -> tuple[NDArray, NDArray, float]:
    """Maximise the linear model over delta (and log10 sigma if noise) within [lo, hi]
    (in the same units), in coordinates scaled by ``scale``; returns delta, ls, gain."""
    q = lin.cols.size
    f0, gd0, gl0 = lin.value_grad(np.zeros(q), ls0)

    def split(u: NDArray) -> tuple[NDArray, NDArray]:
        v = u * scale
        return v[:q], (ls0 + v[q:] if noise else ls0)

    last: dict[bytes, tuple[float, NDArray]] = {}

    def fun(u: NDArray) -> tuple[float, NDArray]:
        # remembered for the last u: L-BFGS-B's first call is at the Newton start, which
        # _newton_start has just evaluated
        key = np.asarray(u, dtype=float).tobytes()
        if key not in last:
            delta, ls = split(u)
            f, gd, gl = lin.value_grad(delta, ls)
            g = np.concatenate([gd, gl]) if noise else gd
            last.clear()
            last[key] = ((1e300, np.zeros_like(u)) if not np.isfinite(f)
                         else (-(f - f0), -g * scale))
        f_u, g_u = last[key]
        return f_u, g_u.copy()

    bounds = list(zip(lo / scale, hi / scale, strict=True))
    g0 = np.concatenate([gd0, gl0]) if noise else gd0
    res = so.minimize(fun, _newton_start(lin, ls0, noise, g0, lo, hi, scale, fun), jac=True,
                      method="L-BFGS-B", bounds=bounds,
                      options={"maxiter": 500, "ftol": 1e-9, "gtol": 1e-7})
    delta, ls = split(res.x)
    gain = -float(res.fun)
    return delta, ls, (gain if np.isfinite(gain) and gain > 0 else 0.0)


def _newton_start(lin: LinearModel, ls0: NDArray, noise: bool, g0: NDArray, lo: NDArray,
                  hi: NDArray, scale: NDArray, fun: Callable[[NDArray], tuple[float, NDArray]]
                  ) -> NDArray:
    """Where the search of the linear model starts, in its scaled coordinates: its Newton
    step (LinearModel.hessian, or hessian_with_noise with the noise intensities) clipped
    into [lo, hi], where it is better than the model's point; the point otherwise. The
    linear model is close to quadratic, so from there L-BFGS-B needs a few steps where
    from the point it learns the coordinates' correlations first."""
    u0 = np.zeros(scale.size)
    H = _model_hessian(lin, ls0, noise)
    if not (np.all(np.isfinite(H)) and np.all(np.isfinite(g0))):
        return u0
    try:
        step = np.linalg.solve(H, g0)
    except np.linalg.LinAlgError:
        return u0
    if not np.all(np.isfinite(step)):
        return u0
    u = np.clip(step, lo, hi) / scale
    return u if fun(u)[0] < 0.0 else u0


def maximise_in_box(lin: LinearModel, ls: NDArray, lo: NDArray, hi: NDArray
                    ) -> tuple[NDArray, float]:
    """Maximise a linear model over its parameters within [lo, hi] (relative to its
    point), the noise held at log10 sigma ls, in coordinates scaled by its curvature (the
    box width where the curvature is not usable); returns delta and the gain."""
    width = np.where(np.isfinite(hi - lo), hi - lo, 1.0)
    scale = _curvature_scales(lin, ls, False, width)
    delta, _, pred = _maximise_model(lin, ls, False, lo, hi, scale)
    return delta, pred


def gauss_newton(post: LogPosterior, x0: NDArray, cols: NDArray | None = None,
                 noise: bool = True, radius: float = 3.0, tol: float = 1e-6,
                 max_iter: int = 60) -> tuple[NDArray, float]:
    """Maximise the log posterior from x0 over the parameters cols (default all) and, if
    noise, the noise intensities (module docstring). Stops when the linear model predicts
    less than tol nats; returns the point and its (exact) log posterior."""
    p = post.p
    cols = np.arange(p) if cols is None else np.asarray(cols)
    blo, bhi = bound_arrays(post.bounds())
    width = np.where(np.isfinite(bhi - blo), bhi - blo, 1.0)
    x = np.asarray(x0, dtype=float).copy()
    f = float(post(x[None])[0])
    if not np.isfinite(f):
        return x, f
    free = np.concatenate([cols, np.arange(p, p + 3)]) if noise else cols
    lin = None
    for _ in range(max_iter):
        if lin is None:
            lin = linearise(post, x, cols)
            if lin is None:
                break
            scale = _curvature_scales(lin, x[p:], noise, width[free])
        q = cols.size
        lo = blo[free] - x[free]
        hi = bhi[free] - x[free]
        lo[:q] = np.maximum(lo[:q], -radius * scale[:q])
        hi[:q] = np.minimum(hi[:q], radius * scale[:q])
        delta, ls, pred = _maximise_model(lin, x[p:], noise, lo, hi, scale)
        if pred < tol:
            break
        x_new = lin.point(delta, ls)
        f_new = float(post(x_new[None])[0])
        gain = f_new - f
        rho = gain / pred
        if np.isfinite(f_new) and gain > 0:
            on_edge = np.any(np.abs(np.abs(delta) - radius * scale[:q]) < 1e-9 * scale[:q])
            x, f = x_new, f_new
            lin = None
            if rho > 0.75 and on_edge:
                radius *= 2.0
            elif rho < 0.25:
                radius *= 0.25
            if gain < tol:
                break
        else:
            radius *= 0.25
            if radius < 1e-6:
                break
    return x, f


def least_squares_start(post: LogPosterior, theta0: NDArray, max_iter: int = 8
                        ) -> NDArray:
    """The paper's eq. 15 estimate, argmin sum_k |R_k(theta)|^2 over the prior box, by
    Gauss-Newton (inference/least_squares.py, as identify's MAP starts)."""
    lo, hi = bound_arrays(post.bounds()[:post.p])
    theta, _, rows = gauss_newton_least_squares(post.likelihood, lo, hi, theta0, max_iter,
                                                _STEP)
    post.n_evals += rows
    return theta
