"""Log posterior and the MAP point estimate (Nelder-Mead baseline, L-BFGS-B fast path).

The sampled vector is [theta (p), log10 sigma (3)] with sigma = (sigma_noise, sigma_r1,
sigma_r2). Gradients are central differences computed in one vectorised likelihood call.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.optimize as so
from numpy.typing import NDArray

from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.least_squares import gauss_newton_least_squares
from bayes_amb.inference.priors import NOISE_LOG10_BOUNDS, PriorSet, bound_arrays
from bayes_amb.inference.whittle import WhittleLikelihood
from bayes_amb.threads import limited_threads

_BIG = 1e300


class LogPosterior:
    """Vectorised log posterior: call with P (nb, p + 3); -inf outside the prior or where the
    controller does not stabilise G(theta). Counts likelihood evaluations (rows)."""

    def __init__(self, likelihood: WhittleLikelihood, priors: PriorSet):
        self.likelihood = likelihood
        self.priors = priors
        self.p = len(priors.names)
        self.n_evals = 0

    @property
    def ndim(self) -> int:
        return self.p + 3

    def __call__(self, P: NDArray) -> NDArray:
        P = np.atleast_2d(np.asarray(P, dtype=float))
        lp = self.priors.log_prior(P[:, :self.p], P[:, self.p:])
        ok = np.isfinite(lp)
        if ok.all():                                # the usual case: no copies
            out = lp + self.likelihood(P[:, :self.p], P[:, self.p:])
            self.n_evals += P.shape[0]
            out[~np.isfinite(out)] = -np.inf
            return out
        out = np.full(P.shape[0], -np.inf)
        if np.any(ok):
            ll = self.likelihood(P[ok, :self.p], P[ok, self.p:])
            self.n_evals += int(ok.sum())
            out[ok] = lp[ok] + ll
        out[~np.isfinite(out)] = -np.inf
        return out

    def with_bands(self, P: NDArray) -> NDArray:
        """(nb, 1 + n_bands): the log posterior, then the likelihood's per-band terms
        (WhittleLikelihood.with_bands; NaN where the prior is zero), as emcee takes a
        vectorised log probability with blobs."""
        P = np.atleast_2d(np.asarray(P, dtype=float))
        lp = self.priors.log_prior(P[:, :self.p], P[:, self.p:])
        ok = np.isfinite(lp)
        out = np.full((P.shape[0], 1 + self.likelihood.n_bands), np.nan)
        out[:, 0] = -np.inf
        if np.any(ok):
            total, bands = self.likelihood.with_bands(P[ok, :self.p], P[ok, self.p:])
            self.n_evals += int(ok.sum())
            out[ok, 0] = lp[ok] + total
            out[ok, 1:] = bands
        out[~np.isfinite(out[:, 0]), 0] = -np.inf
        return out

    def bounds(self) -> list[tuple[float | None, float | None]]:
        b: list[tuple[float | None, float | None]] = []
        for pr in self.priors.priors:
            lo, hi = pr.support
            if pr.kind == "lognormal":
                lo = 1e-12
            b.append((lo if np.isfinite(lo) else None, hi if np.isfinite(hi) else None))
        b += list(NOISE_LOG10_BOUNDS.values())
        return b


@dataclass(frozen=True)
class MapResult:
    """MAP estimate: theta (p,), log10_sigma (3,), log posterior, method, evaluations, time,
    and the Laplace covariance of [theta, log10 sigma] (None if not computed)."""

    theta: NDArray
    log10_sigma: NDArray
    log_post: float
    method: str
    n_evals: int
    wall_s: float
    success: bool
    cov: NDArray | None = None


def _grad(post: LogPosterior, x: NDArray, h: NDArray, idx: NDArray | None = None
          ) -> tuple[float, NDArray]:
    """Log posterior at x and its central-difference gradient along the coordinates idx
    (all by default), with steps h (one per coordinate of x). Where one of the two points
    lies outside the prior (x on its bound) the difference is one-sided, towards the
    inside: a zero there told L-BFGS-B that a coefficient on its bound was optimal, and on
    foreign band-limited-force records k_By stayed on -0.8 where 0.6 inside it the log
    posterior was 7.8 higher (14 of 30 replicates had a coefficient on a bound)."""
    idx = np.arange(x.size) if idx is None else idx
    steps = np.zeros((idx.size, x.size))
    steps[np.arange(idx.size), idx] = h[idx]
    v = post(np.vstack([x, x + steps, x - steps]))
    f = v[0]
    up, down = v[1:idx.size + 1], v[idx.size + 1:]
    with np.errstate(invalid="ignore"):              # -inf - -inf outside the prior
        g = (up - down) / (2 * h[idx])
        inward_up = np.isfinite(up) & ~np.isfinite(down)
        inward_down = np.isfinite(down) & ~np.isfinite(up)
        g[inward_up] = (up[inward_up] - f) / h[idx][inward_up]
        g[inward_down] = (f - down[inward_down]) / h[idx][inward_down]
    g[~np.isfinite(g)] = 0.0
    return f, g


def _steps(post: LogPosterior) -> NDArray:
    return np.concatenate([np.full(post.p, 1e-5), np.full(3, 1e-4)])


def laplace_covariance(post: LogPosterior, x: NDArray) -> NDArray | None:
    """Inverse of the negative Hessian of the log posterior at x (central differences).

    If the full Hessian is not usable (a noise intensity at its prior bound, as for
    noise-free data), the theta block conditional on the noise intensities is returned
    inside an otherwise diagonal covariance (1e-6 on log10 sigma).
    """
    cov = hessian_covariance(post, x, np.arange(x.size))
    if cov is not None:
        return cov
    sub = hessian_covariance(post, x, np.arange(post.p))
    if sub is None:
        return None
    full = np.diag(np.full(x.size, 1e-6))
    full[:post.p, :post.p] = sub
    return full


def at_prior_bound(post: LogPosterior, x: NDArray) -> NDArray:
    """Which coordinates of x (parameters, then log10 sigma) sit on a bound of their prior
    (within 1e-6 of its span)."""
    out = np.zeros(x.size, dtype=bool)
    for j, (lo, hi) in enumerate(post.bounds()):
        lo_f = -np.inf if lo is None else lo
        hi_f = np.inf if hi is None else hi
        span = hi_f - lo_f if np.isfinite(hi_f - lo_f) else 1.0
        out[j] = min(abs(x[j] - lo_f), abs(hi_f - x[j])) < 1e-6 * span
    return out


def free_theta_covariance(post: LogPosterior, x: NDArray) -> tuple[NDArray | None, NDArray]:
    """The Laplace covariance of the parameters not on a prior bound, the noise intensities
    held at x: (p, p), zero in the rows and columns of those on a bound, or None where it is
    not negative definite either; and the mask of the parameters on a bound. What identify
    reports when the full Hessian cannot be formed because a parameter the record does not
    inform ran to its bound (a stencil point then leaves the prior)."""
    bound = at_prior_bound(post, x)[:post.p]
    free = np.flatnonzero(~bound)
    cov = np.zeros((post.p, post.p))
    if free.size:
        sub = hessian_covariance(post, x, free)
        if sub is None:
            return None, bound
        cov[np.ix_(free, free)] = sub
    return cov, bound


def hessian_covariance(post: LogPosterior, x: NDArray, idx: NDArray) -> NDArray | None:
    """Inverse of the negative Hessian of the log posterior at x over the coordinates idx
    (four-point central differences, steps 10x those of the gradient), or None where it is
    not negative definite. The points of entry (j, i) are those of (i, j), so each pair is
    evaluated once (d (d + 1) / 2 stencils instead of d^2) and both entries are formed from
    the same four values, in the order the full loop would have used."""
    d = idx.size
    h = (_steps(post) * 10)[idx]
    pts = [x]
    for i in range(d):
        for j in range(i, d):
            for si, sj in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
                e = x.copy()
                e[idx[i]] += si * h[i]
                e[idx[j]] += sj * h[j]
                pts.append(e)
    v = post(np.array(pts))
    if not np.all(np.isfinite(v)):
        return None
    H = np.empty((d, d))
    k = 1
    for i in range(d):
        for j in range(i, d):
            pp, pm, mp, mm = v[k:k + 4]
            H[i, j] = (pp - pm - mp + mm) / (4 * h[i] * h[j])
            H[j, i] = (pp - mp - pm + mm) / (4 * h[j] * h[i])
            k += 4
    H = 0.5 * (H + H.T)
    try:
        cov = np.linalg.inv(-H)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.linalg.eigvalsh(0.5 * (cov + cov.T)) > 0):
        return None
    return cov


def _theta_start(post: LogPosterior) -> NDArray:
    return np.array([np.exp(pr.a) if pr.kind == "lognormal" else
                     float(np.clip(0.0, lo if lo is not None else -np.inf,
                                   hi if hi is not None else np.inf))
                     for pr, (lo, hi) in zip(post.priors.priors, post.bounds()[:post.p],
                                             strict=True)])


def least_squares_theta(post: LogPosterior, method: str, theta0: NDArray) -> NDArray:
    """Stage 1: minimise the paper's eq. 15 cost sum |eps - S(theta) x|^2 over theta, by
    Gauss-Newton (least_squares.py; "nelder-mead": the paper's fminsearch)."""
    like = post.likelihood
    bounds = post.bounds()[:post.p]
    if method != "nelder-mead":
        theta, _, rows = gauss_newton_least_squares(like, *bound_arrays(bounds), theta0)
        post.n_evals += rows
        return theta

    def cost(th: NDArray) -> float:
        v = float(like.sum_squares(th[None])[0])
        return v if np.isfinite(v) else _BIG

    res = so.minimize(cost, theta0, method="Nelder-Mead",
                      options={"xatol": 1e-9, "fatol": 1e-12, "maxiter": 20000,
                               "adaptive": True})
    post.n_evals += res.nfev
    return np.asarray(res.x, dtype=float)


def _initial_point(post: LogPosterior, theta0: NDArray) -> NDArray:
    """Noise intensities on a coarse grid at theta0 (their MAP follows in the full search)."""
    grid = np.array([[a, b, c] for a in (-11, -9, -7, -5) for b in (-11, -8, -6, -4)
                     for c in (-7, -5, -3, -1)], dtype=float)
    v = post(np.hstack([np.tile(theta0, (grid.shape[0], 1)), grid]))
    x = np.concatenate([theta0, grid[int(np.argmax(v))]])
    return _fit_noise(post, x)


def _fit_noise(post: LogPosterior, x: NDArray, maxiter: int = 60) -> NDArray:
    """The noise intensities maximised at fixed theta (a 3-dimensional L-BFGS-B): a joint
    search started with them decades off sees a distorted theta landscape and can run into
    a corner of the prior."""
    p = post.p
    h = _steps(post)
    noise = np.arange(p, x.size)

    def fun(s: NDArray) -> tuple[float, NDArray]:
        f, g = _grad(post, np.concatenate([x[:p], s]), h, noise)
        return (-(f - f0), -g) if np.isfinite(f) else (_BIG, np.zeros_like(s))

    f0 = float(post(x[None])[0])
    if not np.isfinite(f0):
        return x
    res = so.minimize(fun, x[p:], jac=True, method="L-BFGS-B", bounds=post.bounds()[p:],
                      options={"maxiter": maxiter, "ftol": 1e-12, "gtol": 1e-6})
    return np.concatenate([x[:p], res.x]) if res.fun <= 0 else x     # fun = f0 - f


def _curvature_scale(post: LogPosterior, x: NDArray, h: NDArray) -> tuple[float, NDArray]:
    """Log posterior at x and a scale per coordinate: 1/sqrt(curvature) from the second
    differences of one gradient call (the prior width where the curvature is not usable)."""
    d = x.size
    v = post(np.vstack([x, x + np.diag(h), x - np.diag(h)]))
    with np.errstate(invalid="ignore", divide="ignore"):
        curv = -(v[1:d + 1] - 2 * v[0] + v[d + 1:]) / h**2
        inv_sqrt = 1.0 / np.sqrt(np.abs(curv))
    width = np.array([hi - lo if lo is not None and hi is not None else 1.0
                      for lo, hi in post.bounds()])
    scale = np.where(np.isfinite(curv) & (curv > 0), inv_sqrt, width)
    return (float(v[0]) if np.isfinite(v[0]) else 0.0), np.clip(scale, 1e-9, width)


def _stationary(res: so.OptimizeResult, bounds: list[tuple[float | None, float | None]]
                ) -> bool:
    """Projected gradient (whitened units) below 1e-2: less than ~1e-4 nats are left."""
    g = np.asarray(res.jac, dtype=float)
    lo, hi = bound_arrays(bounds)
    g = np.where((res.x <= lo + 1e-12) & (g > 0), 0.0, g)
    g = np.where((res.x >= hi - 1e-12) & (g < 0), 0.0, g)
    return bool(np.all(np.isfinite(g)) and np.max(np.abs(g), initial=0.0) < 1e-2)


_TRUST = 3.0
"""Half-width of the trust box of one L-BFGS-B run, in curvature scales (about 3 sd)."""
_MAX_RECENTRES = 20


def local_search(post: LogPosterior, method: str, x: NDArray, maxiter: int = 500
                 ) -> tuple[NDArray, bool]:
    """One local maximisation of the log posterior from x (Nelder-Mead or L-BFGS-B).

    L-BFGS-B runs in whitened coordinates u = (x - x0) / scale, scale from the curvature
    at the start, on the log posterior measured from its start value: without that its
    first projected step (identity Hessian) can jump to a corner of the box, and its ftol
    (relative to |f| ~ 4e5) lets it stop after a negligible step. A line search that can
    improve no further at a stationary point (rounding; very peaked noise-free posteriors)
    counts as converged. Each run confines theta (not the noise intensities, whose
    curvature scale far from their optimum is tiny) to a trust box of +-_TRUST scales around
    its start, re-centred (and the scales re-measured) while the optimum lies on the box's
    edge: an unconfined first step can land in a corner of the prior with a poorer local
    maximum (seen with 0.5 um noise and r2 on: k_By, c_By = 0.8, 0.8, 72 nats below the MAP).
    """
    if method == "nelder-mead":
        def neg(v: NDArray) -> float:
            f = post(v[None])[0]
            return -f if np.isfinite(f) else _BIG

        res = so.minimize(neg, x, method="Nelder-Mead",
                          options={"xatol": 1e-7, "fatol": 1e-6, "maxiter": 40 * maxiter,
                                   "maxfev": 40 * maxiter, "adaptive": True})
        return res.x, True
    if method != "lbfgs":
        raise BayesAmbError(f"unknown MAP method {method!r}; known: lbfgs, nelder-mead")
    h = _steps(post)
    x = np.asarray(x, dtype=float)
    remaining = maxiter
    for _ in range(_MAX_RECENTRES):
        f0, scale = _curvature_scale(post, x, h)

        def fun(u: NDArray, x: NDArray = x, f0: float = f0, scale: NDArray = scale
                ) -> tuple[float, NDArray]:
            f, g = _grad(post, x + scale * u, h)
            return (-(f - f0), -g * scale) if np.isfinite(f) else (_BIG, np.zeros_like(u))

        prior = [(None if lo is None else (lo - xi) / si, None if hi is None else (hi - xi) / si)
                 for (lo, hi), xi, si in zip(post.bounds(), x, scale, strict=True)]
        ubounds = [(max(lo, -_TRUST) if lo is not None else -_TRUST,
                    min(hi, _TRUST) if hi is not None else _TRUST) if j < post.p else (lo, hi)
                   for j, (lo, hi) in enumerate(prior)]
        res = so.minimize(fun, np.zeros(x.size), jac=True, method="L-BFGS-B", bounds=ubounds,
                          options={"maxiter": remaining, "ftol": 1e-10, "gtol": 1e-5})
        x = x + scale * res.x
        remaining -= res.nit
        # re-centre while a theta coordinate stops on the trust box (not on the prior)
        on_trust_edge = any((u <= lo + 1e-9 and lo == -_TRUST) or (u >= hi - 1e-9 and hi == _TRUST)
                            for (lo, hi), u in zip(ubounds[:post.p], res.x, strict=False))
        if not on_trust_edge or remaining <= 0:
            break
    return x, bool(res.success) or _stationary(res, ubounds)


def _starts(post: LogPosterior, theta_ls: NDArray, n_random: int, seed: int) -> list[NDArray]:
    """Starting points: the eq. 15 estimate, the nominal model and draws from the prior."""
    rng = np.random.default_rng(seed)
    thetas = [theta_ls, _theta_start(post)]
    for _ in range(n_random):
        thetas.append(np.array([pr.sample(rng, 1)[0] for pr in post.priors.priors]))
    starts = [_initial_point(post, th) for th in thetas]
    # sigma_r1 reaches eps only through S(theta) Ut: from its lower bound the gradient is
    # ~0, so also start the eq. 15 estimate with r1 switched on at two levels
    for level in (-6.0, -4.0):
        alt = starts[0].copy()
        alt[post.p + 1] = level
        starts.append(alt)
    return starts


@limited_threads
def find_map(post: LogPosterior, method: str = "lbfgs", x0: NDArray | None = None,
             refresh_noise: bool = True, n_random_starts: int = 3, seed: int = 0) -> MapResult:
    """MAP of the log posterior.

    Stage 1 minimises the paper's eq. 15 cost over theta. Stage 2 maximises the full log
    posterior over theta and the noise intensities, with a short search from several starts
    (the stage 1 estimate, the nominal model and draws from the prior: with high sensor noise
    the unweighted eq. 15 estimate can be far off), then a full search from the best.
    method "nelder-mead" is the paper's fminsearch (baseline); "lbfgs" is L-BFGS-B with
    vectorised central-difference gradients (faster). With refresh_noise the plug-in noise
    filters are re-evaluated at the MAP and stage 2 repeated.
    """
    t0 = time.perf_counter()
    n0 = post.n_evals
    if x0 is None:
        theta_ls = least_squares_theta(post, method, _theta_start(post))
        # noise filters at the eq. 15 estimate: at theta = 0 the r1 filter S Ut is zero, so
        # sigma_r1 would be invisible to the start and stuck wherever it began
        post.likelihood.set_noise_reference(theta_ls)
        starts = _starts(post, theta_ls, n_random_starts, seed)
        short = [local_search(post, method, s, maxiter=15)[0] for s in starts]
        vals = post(np.array(short))
        x = short[int(np.argmax(vals))]
    else:
        x = np.asarray(x0, dtype=float)
    success = True
    for rnd in range(2 if refresh_noise else 1):
        if rnd > 0:
            # re-seed the noise intensities on the grid at the current theta (a sigma
            # stuck at a bound has no gradient to leave it by), keep the better point
            alt = _initial_point(post, x[:post.p])
            if post(alt[None])[0] > post(x[None])[0]:
                x = alt
        x, success = local_search(post, method, x)
        if refresh_noise:
            post.likelihood.set_noise_reference(x[:post.p])
    lp = float(post(x[None])[0])
    return MapResult(theta=x[:post.p].copy(), log10_sigma=x[post.p:].copy(), log_post=lp,
                     method=method, n_evals=post.n_evals - n0,
                     wall_s=time.perf_counter() - t0, success=success and np.isfinite(lp))
