"""Fitting one model to a recording: the nominal MAP, a model extended by candidates, the
local Gauss-Newton search, and the Laplace covariance over its free dimensions.

Every model compared in the diagnosis (select.py) is a :class:`FittedModel`: the nominal
one (fit_nominal) and each extension of it by a candidate (extend, then the search in
select.py). Extensions share the parent's recording data and noise filters, so that models
compared with each other share one noise-spectrum family; the reported model is refitted
with its own noise filters at the end (own_noise_fit).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from bayes_amb.discrepancy.gauss_newton import gauss_newton, least_squares_start
from bayes_amb.discrepancy.library import Candidate
from bayes_amb.discrepancy.likelihood import RobustWhittle
from bayes_amb.discrepancy.model import ExtendedForwardModel
from bayes_amb.discrepancy.model_error import ModelError
from bayes_amb.inference.estimate import (
    LogPosterior,
    _initial_point,
    _theta_start,
    at_prior_bound,
    hessian_covariance,
)
from bayes_amb.inference.noise_fit import fit_noise_spectrum
from bayes_amb.inference.priors import Prior
from bayes_amb.inference.spectrum import synchronous_bins
from bayes_amb.io.recording import Recording


@dataclass
class FittedModel:
    """One model fitted to the recording: its candidates, likelihood and MAP.

    x is the MAP of [parameters, log10 sigma]; cov the Laplace covariance over the free
    dimensions (None where it could not be formed); log_bf the log Bayes factor against the
    model it extends (None for the nominal one); samples emcee draws if it was sampled.
    """

    candidates: tuple[Candidate, ...]
    forward: ExtendedForwardModel
    like: RobustWhittle
    post: LogPosterior
    x: NDArray
    log_post: float
    cov: NDArray | None = None
    log_bf: float | None = None
    samples: NDArray | None = None      # emcee draws (walkers, draws, p + 3) when sampled
    log_odds: float | None = None       # log posterior odds when accepted (Multiplicity)
    model_error: ModelError | None = None   # the band-wise model error, once assessed
    extra_cov: NDArray | None = None    # (p, p) what the fit modelled but does not know
    #                                     exactly (a modelled clip), added to every interval
    modelled_shift: NDArray | None = None  # (p,) how far modelling a nonlinearity moved
    #                                     the parameters (clip_model.take_in_clipping)
    node_range: list[int] | None = None  # a shaft-node force: the nodes as good as its
    #                                     own (select.refine_node)

    @property
    def names(self) -> tuple[str, ...]:
        return self.forward.params

    @property
    def p(self) -> int:
        return len(self.names)

    @property
    def params(self) -> NDArray:
        return self.x[:self.p]

    @property
    def log10_sigma(self) -> NDArray:
        return self.x[self.p:]

    def value(self, name: str) -> float:
        return float(self.x[self.names.index(name)])


def build(recording: Recording, params: tuple[str, ...], eps: NDArray,
          candidates: tuple[Candidate, ...] = (), priors: dict[str, Prior] | None = None,
          start: int = 0) -> tuple[ExtendedForwardModel, RobustWhittle, LogPosterior]:
    """Forward model, likelihood and posterior of the nominal model plus candidates
    (``start``: samples of pre-history, see likelihood.RobustWhittle)."""
    fwd = ExtendedForwardModel(recording, params, candidates, priors)
    like = RobustWhittle(fwd, eps, start=start)
    return fwd, like, LogPosterior(like, fwd.priors)


def extend(parent: FittedModel, cand: Candidate | tuple[Candidate, ...],
           priors: dict[str, Prior] | None = None, phi: dict[str, float] | None = None
           ) -> tuple[ExtendedForwardModel, RobustWhittle, LogPosterior]:
    """Parent + candidate (or several, in order), sharing the parent's recording data and
    noise filters (models compared with each other share one noise-spectrum family), with
    the line bases at the parent's MAP and the candidate at ``phi`` (default its null): the
    point its screen or refit starts from (see _embed)."""
    pf = parent.forward
    new = cand if isinstance(cand, tuple) else (cand,)
    fwd = ExtendedForwardModel(pf.recording, pf.theta_names, (*parent.candidates, *new),
                               priors, template=pf)
    like = parent.like.for_model(fwd, _embed(parent, fwd, phi)[:len(fwd.params)])
    return fwd, like, LogPosterior(like, fwd.priors)


def local_fit(post: LogPosterior, x0: NDArray) -> tuple[NDArray, float]:
    """Gauss-Newton trust-region MAP search from x0 over every dimension
    (gauss_newton.py), then the line bases (if any) are refreshed at the optimum and the
    search repeated."""
    x, _ = gauss_newton(post, x0)
    like: RobustWhittle = post.likelihood  # type: ignore[assignment]
    if like.lines:
        like.set_noise_reference(x[:post.p])
        x, _ = gauss_newton(post, x)
    return x, float(post(x[None])[0])


def nominal_map(post: LogPosterior) -> NDArray:
    """MAP of the nominal model, as identification's find_map searches it, but by
    Gauss-Newton: the eq. 15 estimate (its noise filters then used), starts at it (noise
    intensities on a grid, and with sigma_r1 switched on at two levels: from its lower
    bound its gradient is ~0) and at the nominal model, a short search from each and a full
    one from the best; the noise filters refreshed at that optimum, the noise intensities
    re-seeded on the grid, and the search repeated."""
    p = post.p
    theta_ls = least_squares_start(post, _theta_start(post))
    post.likelihood.set_noise_reference(theta_ls)
    starts = [_initial_point(post, theta_ls), _initial_point(post, _theta_start(post))]
    for level in (-6.0, -4.0):
        alt = starts[0].copy()
        alt[p + 1] = level
        starts.append(alt)
    short = [gauss_newton(post, s, max_iter=3) for s in starts]
    x = short[int(np.argmax([f for _, f in short]))][0]
    for rnd in range(2):
        if rnd > 0:
            alt = _initial_point(post, x[:p])
            if post(alt[None])[0] > post(x[None])[0]:
                x = alt
        x, _ = gauss_newton(post, x)
        post.likelihood.set_noise_reference(x[:p])
    return x


def learned_noise_map(post: LogPosterior, x: NDArray) -> NDArray:
    """The noise spectrum learned from the record at the white model's MAP x and the MAP
    under it, as identify has it (inference/noise_fit.fit_noise_spectrum), for identify's
    adequacy test (its location tests and model error), learned without the bins at
    multiples of the running speed (unbalance and runout are physics to find: learned as
    noise, a 2e-6 kg m unbalance's Bayes factor fell from above 3 to -67 where the
    diagnosis was tried with it). x as it was where the residual is as white as the three
    sources have it."""
    p = post.p

    def refit(theta: NDArray, ls: NDArray) -> tuple[NDArray, NDArray]:
        y, _ = gauss_newton(post, np.concatenate([theta, ls]))
        return y[:p], y[p:]

    like = post.likelihood
    sync = synchronous_bins(like, like.forward.recording.speed_rpm)
    theta, ls, _ = fit_noise_spectrum(like, x[:p], x[p:], refit, mask=sync)
    return np.concatenate([theta, ls])


def fit_nominal(recording: Recording, params: tuple[str, ...], eps: NDArray,
                priors: dict[str, Prior] | None = None, seed: int = 0,
                start: int = 0, leave_out_lines: bool = False) -> FittedModel:
    """The nominal model's MAP over the whole band (nominal_map; ``seed`` is kept for the
    interface: the search draws no random starts). ``leave_out_lines``: the record's
    narrowband lines leave the likelihood first, as identify's own likelihood has it
    (WhittleLikelihood.leave_out_lines; identify's adequacy test). The diagnosis keeps
    them: its bands' integrated spectra absorb a mains line, and a line at the running
    speed is physics it names."""
    fwd, like, post = build(recording, params, eps, (), priors, start)
    if leave_out_lines:
        like.leave_out_lines(_theta_start(post))
    x = nominal_map(post)
    # from here on the noise filters stay at this fit (shared with the extended models)
    like.fixed_filters = like.phi_sources
    x, log_post = local_fit(post, x)
    return FittedModel((), fwd, like, post, x, log_post, cov=free_covariance(post, x))


def with_learned_noise(fm: FittedModel) -> FittedModel:
    """The nominal fit ``fm`` with the noise spectrum learned from its residual
    (learned_noise_map) and refitted under it, its noise filters then held (as fit_nominal
    holds them); ``fm`` as it is where the residual is as white as the sources have it.
    Learned after the nonlinearity screens and their models (adequacy.nominal_assessment):
    learned before them, a clipped current's misfit became noise, and the clipping
    regression's gain fell from about 1 to 0.41."""
    like, post = fm.like, fm.post
    like.fixed_filters = None
    x = learned_noise_map(post, fm.x)
    like.fixed_filters = like.phi_sources
    if like.spectrum is None:
        return fm
    x, log_post = local_fit(post, x)
    return replace(fm, x=x, log_post=log_post, cov=free_covariance(post, x))


def _embed(parent: FittedModel, fwd: ExtendedForwardModel, phi: dict[str, float] | None = None
           ) -> NDArray:
    """The parent's MAP in the child's layout; the child's new parameters at their null."""
    x = np.concatenate([fwd.null, parent.log10_sigma])
    for j, n in enumerate(fwd.params):
        if n in parent.names:
            x[j] = parent.value(n)
        elif phi and n in phi:
            x[j] = phi[n]
    return x


def free_covariance(post: LogPosterior, x: NDArray, last: int = 0) -> NDArray | None:
    """Laplace covariance over the dimensions not on a prior bound (zeros elsewhere).

    The noise intensities are held fixed (they are nearly independent of the physical
    parameters, and one the data do not inform is flat); if that Hessian is not negative
    definite, all free dimensions are tried, then only the last ``last`` parameters (a
    candidate's own).
    """
    free = np.flatnonzero(~at_prior_bound(post, x))
    tries = [free[free < post.p], free]
    if last:
        tries.append(free[(free >= post.p - last) & (free < post.p)])
    for idx in tries:
        if idx.size == 0:
            continue
        sub = hessian_covariance(post, x, idx)
        if sub is not None:
            cov = np.zeros((x.size, x.size))
            cov[np.ix_(idx, idx)] = sub
            return cov
    return None


BOUND_GRID = np.concatenate([[0.0], np.geomspace(1e-4, 1.0, 17)])
"""Distances inward from a bound, as shares of the prior's span, at which the log
posterior is integrated (bound_occam)."""


def bound_occam(post: LogPosterior, x: NDArray, idx: NDArray) -> tuple[float, NDArray]:
    """The Occam factors of the parameters ``idx`` that sit on a bound of their prior at
    the MAP x: (sum of their log factors, the mask of idx on a bound).

    A Laplace factor needs a maximum inside the prior; on a bound the log posterior falls
    away on one side only, and often not as a parabola (an overdamped second-order
    actuator fitted to a first-order lag: flat near zeta's bound, falling steeply far from
    it). Its factor is the integral of exp(lp - lp(x)) over the prior's span, inward from
    the bound, on BOUND_GRID (log-spaced shares of the span) with lp linear between its
    points (_log_linear_integral: below the integral of a concave lp), and with the other
    parameters held at x: never more than the integral with them refitted, so the Bayes
    factor errs low. The prior's density is already in lp. A span without an end (a
    half-line prior) is integrated over ten times the parameter's size.

    Examples
    --------
    On a flat log posterior the factor is the span: log(2 - 0.05) for U(0.05, 2).

    >>> import numpy as np
    >>> class Flat:
    ...     p = 1
    ...     def bounds(self): return [(0.05, 2.0), (-12, 0), (-12, 0), (-12, 0)]
    ...     def __call__(self, X): return np.zeros(len(X))
    >>> log_f, on = bound_occam(Flat(), np.array([2.0, -7, -9, -3]), np.array([0]))
    >>> bool(on[0]), bool(np.isclose(log_f, np.log(1.95)))
    (True, True)
    """
    on = at_prior_bound(post, x)[idx]
    total = 0.0
    bounds = post.bounds()
    for j in np.asarray(idx)[on]:
        lo, hi = bounds[j]
        lo_f = -np.inf if lo is None else lo
        hi_f = np.inf if hi is None else hi
        span = hi_f - lo_f
        if not np.isfinite(span):
            span = 10.0 * max(abs(float(x[j])), 1.0)
        inward = 1.0 if abs(x[j] - lo_f) <= abs(hi_f - x[j]) else -1.0
        t = BOUND_GRID * span
        X = np.tile(np.asarray(x, dtype=float), (t.size, 1))
        X[:, j] += inward * t
        v = post(X)
        if not np.isfinite(v[0]):
            return -np.inf, on
        total += float(np.log(_log_linear_integral(t, v - v[0])))
    return total, on


def _log_linear_integral(t: NDArray, lp: NDArray) -> float:
    """Integral of exp(lp) over t with lp linear between the points (exact for a linear
    lp; below the integral of a concave one): each piece is its width times the
    logarithmic mean of its end values. A non-finite lp counts as exp(lp) = 0.

    >>> import numpy as np
    >>> t = np.array([0.0, 0.5, 2.0])
    >>> bool(np.isclose(_log_linear_integral(t, -3 * t), (1 - np.exp(-6)) / 3))
    True
    """
    lp = np.where(np.isfinite(lp), np.minimum(lp, 50.0), -np.inf)
    a, b, dt = lp[:-1], lp[1:], np.diff(t)
    d = b - a
    with np.errstate(invalid="ignore", over="ignore"):
        piece = np.where(np.abs(d) < 1e-9, np.exp(0.5 * (a + b)),
                         (np.exp(b) - np.exp(a)) / np.where(d == 0, 1.0, d))
    piece = np.where(np.isfinite(a) & np.isfinite(b), piece, 0.0)
    return float(np.sum(piece * dt))


def own_noise_fit(fm: FittedModel) -> FittedModel:
    """The model refitted with its own loop noise filters (eq. 14 through its extended
    loop, at its MAP) instead of the shared nominal ones: the filters the comparison shares
    are right for the nominal loop only, and a lag, delay or flexible mode changes how the
    noise reaches eps. Its posterior is the one reported; its Bayes factor stays the one
    from the comparison."""
    if not fm.candidates:
        return fm
    like = copy.copy(fm.like)
    like.fixed_filters = None
    like.set_noise_reference(fm.params)
    post = LogPosterior(like, fm.forward.priors)
    x, log_post = local_fit(post, fm.x)
    like.set_noise_reference(x[:fm.p])
    x, log_post = local_fit(post, x)
    idx = np.arange(fm.forward.slices[-1].start, fm.forward.slices[-1].stop)
    cov = free_covariance(post, x, last=idx.size)
    return FittedModel(fm.candidates, fm.forward, like, post, x, log_post, cov=cov,
                       log_bf=fm.log_bf, log_odds=fm.log_odds, node_range=fm.node_range)
