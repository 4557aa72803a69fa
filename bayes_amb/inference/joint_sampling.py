"""emcee on the joint posterior of several recordings (issue 29).

The joint MAP and Laplace approximation (joint.py) hold each record's noise intensities at
that record's MAP. Sampling frees them: the state is the joint coefficients followed by
three log10 noise intensities per record,

    log p(theta, sigma_1..R | all) = log p(theta) + sum_r [log p(sigma_r)
                                      + log L_r(theta_r, sigma_r)],

theta_r the shared coefficients plus record r's own copies of the per-record ones. The
records are independent given the parameters; each keeps its own forward model, controller
and dt. The sampler is identify's (sampler.run_emcee): Laplace independence proposals of
theta from the joint Laplace approximation, differential-evolution steps of all the noise
intensities, and differential evolution of everything, run until 50 autocorrelation
times with R-hat <= 1.01 and bulk ESS >= 400 per coefficient.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.estimate import LogPosterior
from bayes_amb.inference.posterior import identifiability, summarise, walkers_datatree
from bayes_amb.inference.priors import PriorSet, noise_log_prior
from bayes_amb.inference.sampler import (
    SamplerRun,
    chains_converged,
    initial_ball,
    run_emcee,
    sampler_block,
)
from bayes_amb.inference.whittle import NOISE_SOURCES, NOISE_UNITS, WhittleLikelihood

if TYPE_CHECKING:
    import xarray as xr

START_NOISE_SD = 0.01
"""sd (log10 units) of the walkers' start about each record's noise MAP; the burn-in of two
autocorrelation times of the slowest coordinate removes the start."""


class JointLogPosterior:
    """Vectorised joint log posterior: call with P (nb, p + 3 R), the joint coefficients
    then each record's log10 noise intensities; -inf outside the priors or where a
    record's controller does not stabilise its model."""

    def __init__(self, likes: list[WhittleLikelihood], idx: list[NDArray],
                 priors: PriorSet):
        self.likes = likes
        self.idx = idx
        self.priors = priors
        self.p = len(priors.names)
        self.n_evals = 0

    @property
    def ndim(self) -> int:
        return self.p + 3 * len(self.likes)

    def bounds(self) -> list[tuple[float | None, float | None]]:
        """Each coordinate's prior bounds (None: unbounded), as LogPosterior.bounds."""
        one = LogPosterior(self.likes[0], self.priors).bounds()
        return one[:self.p] + one[self.p:] * len(self.likes)

    def noise(self, P: NDArray, r: int) -> NDArray:
        """Record r's log10 noise intensities in the rows of P."""
        return P[:, self.p + 3 * r:self.p + 3 * r + 3]

    def __call__(self, P: NDArray) -> NDArray:
        P = np.atleast_2d(np.asarray(P, dtype=float))
        lp = self.priors.log_prior(P[:, :self.p], self.noise(P, 0))
        for r in range(1, len(self.likes)):
            lp = lp + noise_log_prior(self.noise(P, r))
        ok = np.isfinite(lp)
        out = np.full(P.shape[0], -np.inf)
        if np.any(ok):
            total = lp[ok]
            theta = P[ok, :self.p]
            for r, (like, ix) in enumerate(zip(self.likes, self.idx, strict=True)):
                total = total + like(theta[:, ix], self.noise(P[ok], r))
            self.n_evals += int(ok.sum())
            out[ok] = total
        out[~np.isfinite(out)] = -np.inf
        return out


def sample_joint(post: JointLogPosterior, theta_map: NDArray, cov: NDArray | None,
                 sigmas: list[NDArray], walkers: int | None, steps: int | None,
                 max_steps: int, seed: int, progress: Any = None
                 ) -> tuple[SamplerRun, int, bool]:
    """emcee from the joint MAP (noise at each record's MAP). The Laplace proposals use
    ``cov`` (the joint theta covariance; a coefficient it holds on a prior bound is given
    a tenth of its prior sd, so that the walkers spread there too). Returns the run, the
    number of walkers and whether the Laplace proposals were used."""
    rng = np.random.default_rng(seed)
    ndim = post.ndim
    n_walkers = walkers or max(24, 2 * ndim + 2)
    n_walkers += n_walkers % 2
    if n_walkers < 2 * ndim:
        raise BayesAmbError(f"option --walkers: value {n_walkers} out of range: must be >= "
                            f"{2 * ndim} (2 x {ndim} sampled dimensions: the coefficients "
                            "and three noise intensities per record)")
    center = np.concatenate([theta_map, *sigmas])
    laplace = None
    start_cov = np.eye(ndim) * START_NOISE_SD ** 2
    start_cov[:post.p, :post.p] = np.diag(np.full(post.p, 1e-8))
    if cov is not None:
        c = np.array(cov, dtype=float)
        held = np.diag(c) <= 0
        c[held, held] = (0.1 * np.array([pr.sd for pr in post.priors.priors]))[held] ** 2
        laplace = (theta_map, c)
        start_cov[:post.p, :post.p] = c
    start = initial_ball(post, center, start_cov, n_walkers, rng)
    for like in post.likes:
        like.remember_rows(4 * n_walkers)     # the noise-only moves reuse the band sums
    try:
        run = run_emcee(post, start, rng, n_steps=steps, max_steps=max_steps,
                        laplace=laplace, progress=progress)
    finally:
        for like in post.likes:
            like.remember_rows(0)
    return run, n_walkers, laplace is not None


def joint_datatree(names: list[str], run: SamplerRun, n_rec: int,
                   attrs: dict[str, Any]) -> xr.DataTree:
    """Groups posterior (the joint coefficients, and each record's noise intensities as
    'sigma_noise@1', ...) and sample_stats; walkers are the chains."""
    p = len(names)
    post = {n: run.samples[:, :, j] for j, n in enumerate(names)}
    for r in range(n_rec):
        for k, s in enumerate(NOISE_SOURCES):
            post[f"{s}@{r + 1}"] = 10.0 ** run.samples[:, :, p + 3 * r + k]
    dt = walkers_datatree({"posterior": post, "sample_stats": {"lp": run.log_post}})
    dt.attrs.update({k: (v if isinstance(v, (str, int, float)) else str(v))
                     for k, v in attrs.items()})
    dt.attrs["tau"] = ",".join(f"{v:.3f}" for v in run.tau)
    return dt


def sampled_summary(names: list[str], run: SamplerRun, n_walkers: int, used_laplace: bool,
                    post: JointLogPosterior, rig: Any, attrs: dict[str, Any]
                    ) -> tuple[dict[str, Any], list[dict[str, Any]], xr.DataTree]:
    """The summary entries of a sampled joint posterior (parameters, sampler,
    identifiability, converged), each record's noise posterior, and the DataTree."""
    dt = joint_datatree(names, run, len(post.likes), attrs)
    params = summarise(dt, tuple(names), run.tau, rig)
    noise = []
    for r in range(len(post.likes)):
        rows = {}
        for k, (s, u) in enumerate(zip(NOISE_SOURCES, NOISE_UNITS, strict=True)):
            v = np.asarray(dt["posterior"][f"{s}@{r + 1}"].values).ravel()
            rows[s] = {"mean": float(v.mean()), "q05": float(np.quantile(v, 0.05)),
                       "q95": float(np.quantile(v, 0.95)), "unit": u,
                       "tau": float(run.tau[post.p + 3 * r + k])}
        noise.append(rows)
    out = {
        "inference": "joint emcee posterior (each record's noise intensities sampled)",
        "parameters": params,
        "sampler": sampler_block(run, n_walkers, used_laplace, post.n_evals),
        "identifiability": identifiability(run.samples, tuple(names), post.priors),
        "converged": chains_converged(params, run),
    }
    return out, noise, dt
