"""emcee ensemble sampling of the log posterior, run until 50 autocorrelation times.

Walkers start from the Laplace approximation at the MAP when it is available (else a small
ball). The moves are differential evolution, mixed with independence proposals of theta
from the Laplace approximation when it is given (ensemble_moves). Sampling proceeds in
chunks; after each chunk the integrated autocorrelation time tau is estimated
(emcee.autocorr, tol=0) and sampling stops once the chain is at least 50 tau of theta long,
tau has settled (relative change < 5 % since the last check, or the chain is already 50 tau
of every coordinate, the noise intensities included) and every parameter of interest has
rank-normalised split R-hat <= 1.01 and bulk ESS >= 400 (walkers taken as chains), or at
max_steps. Then 2 tau of the slowest coordinate are discarded as burn-in and the chain is
thinned by tau_min / 2.

The second way to settle: with 24 walkers, a tau of 2-8 steps is estimated from a few
hundred steps with a scatter of several per cent, so "every one of 11 coordinates within
5 % of its last estimate" passes or fails by chance long after the chain is long enough.
On the posterior benchmark's record the chain was 50 tau of theta at 150 steps and passed
R-hat and ESS at 300, and the rule ran to 600 steps, waiting for the noise intensities'
tau (7-8 steps) to repeat itself within 5 %. A chain of 50 tau of every coordinate is the
length at which emcee's authors take tau's estimate as reliable; it stopped at 400 steps,
with the same posterior (means within 0.02 sd, sds within 2 %).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import emcee
import numpy as np
from numpy.typing import NDArray

from bayes_amb.inference.estimate import LogPosterior
from bayes_amb.inference.moves import BlockDEMove, LaplaceIndependenceMove, SequenceMove
from bayes_amb.threads import limited_threads

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SamplerRun:
    """Retained samples (n_walkers, n_draws, ndim), their log posterior (n_walkers, n_draws),
    tau per dimension, steps run, burn-in, thinning, acceptance fraction and wall time; with
    ``bands``, the likelihood's per-band terms at each retained sample (n_walkers, n_draws,
    n_bands), kept from the evaluations that drew it."""

    samples: NDArray
    log_post: NDArray
    tau: NDArray
    n_steps: int
    burn: int
    thin: int
    acceptance: NDArray
    wall_s: float
    n_tau: float
    bands: NDArray | None = None


LAPLACE_SWEEP_WEIGHT = 0.8   # per step: the Laplace sweep, else differential evolution
NOISE_SUBSTEPS = 4           # differential-evolution steps of the noise block per sweep


def ensemble_moves(laplace: tuple[NDArray, NDArray] | None = None, ndim: int | None = None
                   ) -> list[tuple[emcee.moves.Move, float]]:
    """The moves of the sampler, with their probabilities per step.

    Without ``laplace``: differential-evolution MCMC (ter Braak 2006): scaled differences
    of two other walkers, with a full-length jump (gamma = 1) one time in ten to move
    between modes.

    With ``laplace = (center, cov)``, the MAP and Laplace covariance of the first p
    coordinates (theta), and ndim > p coordinates in all, a mixture. With probability
    LAPLACE_SWEEP_WEIGHT a step is a sweep (moves.SequenceMove): theta proposed
    independently from a t around the MAP (moves.LaplaceIndependenceMove), then
    NOISE_SUBSTEPS differential-evolution steps of the other coordinates alone, the noise
    intensities (moves.BlockDEMove; the last with gamma = 1; with theta kept they cost the
    4 x 4 algebra of the bands, see WhittleLikelihood.remember_rows). Otherwise the step is
    the differential-evolution move above on all coordinates. Every part leaves the
    posterior invariant, so the mixture does whatever the Laplace approximation's quality;
    that only decides how fast theta decorrelates (on the 8-parameter benchmark tau fell
    from ~50 steps to ~2, the noise intensities' from ~50 to ~8 with two noise steps a
    sweep, to ~4 with four). Four: a noise step costs a quarter of a theta sweep (0.48 ms
    against 2.1 ms for 24 walkers), and with the noise intensities' tau halved the chain is
    50 tau of every coordinate sooner: on the posterior benchmark 300 steps in 1.77 s
    against 500 in 2.36 s (three: 350 in 1.94 s)).

    Fresh objects per sampler: emcee's DEMove fixes its scale to the dimension of the first
    ensemble it sees. emcee's DESnookerMove is not used: in emcee <= 3.1.6 its proposal is
    not normalised (fixed upstream in dfm/emcee#531, unreleased) and its stationary
    distribution is too narrow; mixed in at 20 % it shrank the 8-parameter posteriors by 6 %
    (SBC 90 % coverage 0.87) and a standard normal in 11 dimensions to sd 0.92
    (tests/test_sampler.py).
    """
    de: list[tuple[emcee.moves.Move, float]] = [(emcee.moves.DEMove(), 0.9),
                                                 (emcee.moves.DEMove(gamma0=1.0), 0.1)]
    if laplace is None:
        return de
    center, cov = laplace
    p = np.asarray(center).size
    d = p if ndim is None else ndim
    try:
        parts: list[emcee.moves.Move] = [LaplaceIndependenceMove(center, cov)]
    except np.linalg.LinAlgError:
        log.warning("Laplace covariance not positive definite: differential evolution only")
        return de
    if d > p:
        rest = np.arange(p, d)
        parts += [BlockDEMove(rest, gamma0=1.0 if k == NOISE_SUBSTEPS - 1 else None)
                  for k in range(NOISE_SUBSTEPS)]
    w = LAPLACE_SWEEP_WEIGHT
    return [(SequenceMove(parts), w)] + [(m, f * (1 - w)) for m, f in de]


def initial_ball(post: LogPosterior, center: NDArray, cov: NDArray | None, n_walkers: int,
                 rng: np.random.Generator, scale: float = 1.0) -> NDArray:
    """Walker starting points with finite log posterior: draws from the Laplace approximation
    N(center, scale^2 cov) when available (the ensemble then starts near stationarity), else
    a small ball."""
    d = center.size
    if cov is not None:
        chol = np.linalg.cholesky(cov * scale**2 + 1e-18 * np.eye(d))
    else:
        widths = np.concatenate([np.full(post.p, 1e-4), np.full(3, 1e-3)])
        chol = np.diag(widths)
    out = np.empty((n_walkers, d))
    filled = 0
    for _ in range(100):
        cand = center + rng.standard_normal((n_walkers, d)) @ chol.T
        ok = cand[np.isfinite(post(cand))]
        take = min(ok.shape[0], n_walkers - filled)
        out[filled:filled + take] = ok[:take]
        filled += take
        if filled == n_walkers:
            return out
        chol = chol * 0.5
    raise RuntimeError("could not place walkers with finite posterior around the MAP")


def _burn_thin(tau: NDArray, p: int, total: int) -> tuple[int, int]:
    """Burn-in 2 tau of the slowest coordinate (noise intensities included: a sampler that
    decorrelates theta in a few steps can still carry their start), at most half the chain;
    thinning by tau_min / 2 of theta. A coordinate whose tau is not known (NaN: a walker
    that never moved in it) counts as the slowest, and never sets the thinning; with no
    tau known, half the chain is burnt and none thinned (before, a run that ended so
    raised "cannot convert float NaN to integer" after sampling to the end)."""
    known = tau[np.isfinite(tau)]
    burn = total // 2 if known.size < tau.size else min(math.ceil(2 * float(known.max())),
                                                        total // 2)
    theta = tau[:p][np.isfinite(tau[:p])]
    thin = max(1, int(np.min(theta) / 2)) if p and theta.size else 1
    return burn, thin


def _retained(sampler: emcee.EnsembleSampler, tau: NDArray, p: int) -> NDArray:
    burn, thin = _burn_thin(tau, p, sampler.iteration)
    return np.swapaxes(sampler.get_chain(discard=burn, thin=thin), 0, 1)


def _diagnostics_ok(sampler: emcee.EnsembleSampler, tau: NDArray, p: int,
                    r_hat_max: float = 1.01, ess_min: float = 400.0) -> bool:
    """R-hat and bulk ESS of the retained draws of the first p dimensions."""
    import arviz as az  # 0.8 s to import: only where a chain is judged
    draws = _retained(sampler, tau, p)
    for j in range(p):
        x = draws[:, :, j]
        if not (float(az.rhat(x)) <= r_hat_max and float(az.ess(x)) >= ess_min):
            return False
    return True


REFIT_AFTER = 250   # steps of the first sampler before its proposal may be refitted, once
REFIT_TAU = 10.0    # ... where theta's tau is still above this many steps


def _pilot_moments(sampler: emcee.EnsembleSampler, p: int) -> tuple[NDArray, NDArray]:
    """Mean and covariance of theta (the first p coordinates) over the second half of a
    pilot chain, every walker."""
    chain = sampler.get_chain()
    x = chain[chain.shape[0] // 2:, :, :p].reshape(-1, p)
    return x.mean(axis=0), np.atleast_2d(np.cov(x, rowvar=False))


@limited_threads
def run_emcee(post: LogPosterior, start: NDArray, rng: np.random.Generator, *,
              n_steps: int | None = None, max_steps: int = 20000, chunk: int | None = None,
              n_tau: float = 50.0, laplace: tuple[NDArray, NDArray] | None = None,
              progress: Callable[[int, int, float], None] | None = None,
              bands: bool = False) -> SamplerRun:
    """Run emcee (vectorised over walkers). n_steps fixed, or None for the automatic rule,
    checked every ``chunk`` steps (default 250; 50 with ``laplace``, whose chains are a few
    tau per 10 steps). ``laplace = (center, cov)`` of theta (the first post.p coordinates)
    selects the mixture of ensemble_moves with Laplace independence proposals. ``bands``:
    keep the likelihood's per-band terms of every draw (post.with_bands, emcee's blobs),
    which the posterior's log_likelihood group would otherwise evaluate again.

    Where the Laplace approximation is a poor proposal (theta's tau still above REFIT_TAU
    steps after REFIT_AFTER, with the automatic rule), the proposal is refitted once to the
    mean and covariance of that pilot chain's second half and the sampling starts again
    from where the walkers are, the pilot discarded as burn-in (counted in ``burn`` and
    ``n_steps``); the chain after it has one fixed proposal, so it is a plain
    Metropolis-Hastings chain. On a three-speed joint posterior of process-force records
    the joint MAP lay 3.5 sd (c_Ax) from the posterior mean once the noise intensities
    were free: tau ~250 steps, 20 000 steps in 15 min, not converged."""
    n_walkers, d = start.shape
    if chunk is None:
        chunk = 250 if laplace is None else 50
    target_fn = post.with_bands if bands else post

    def new_sampler(proposal):
        s = emcee.EnsembleSampler(n_walkers, d, target_fn, vectorize=True,
                                  moves=ensemble_moves(proposal, d),
                                  blobs_dtype=float if bands else None)
        s.random_state = np.random.RandomState(int(rng.integers(2**31 - 1))).get_state()
        return s

    sampler = new_sampler(laplace)
    may_refit = laplace is not None and n_steps is None and post.p > 0
    t0 = time.perf_counter()
    state = start
    total = 0
    pilot = 0
    tau_prev = None
    tau = np.full(d, np.nan)
    target = n_steps if n_steps is not None else max_steps
    while total < target:
        step = min(chunk, target - total)
        state = sampler.run_mcmc(state, step, progress=False)
        total += step
        own = sampler.iteration                  # steps of this sampler (after any pilot)
        chain = sampler.get_chain()
        with np.errstate(divide="ignore", invalid="ignore"):
            # a walker that has not moved yet in a coordinate (its acf 0/0): NaN there,
            # so the chain is not taken as settled, and no numpy warning reaches the user
            tau = emcee.autocorr.integrated_time(chain, tol=0)
        tau_max = float(np.max(tau[:post.p])) if post.p else float(np.max(tau))
        if progress is not None:
            progress(total, target, tau_max)
        if may_refit and own >= REFIT_AFTER:
            may_refit = False
            if not tau_max <= REFIT_TAU:
                center, cov = _pilot_moments(sampler, post.p)
                try:                    # a pilot that did not spread: keep the proposal
                    np.linalg.cholesky(cov)
                    refit = new_sampler((center, cov))
                except np.linalg.LinAlgError:
                    refit = None
                if refit is not None:
                    log.info("emcee: theta's tau %.0f after %d steps; proposal refitted to "
                             "the pilot chain", tau_max, own)
                    sampler, pilot, tau_prev = refit, total, None
                    state = state.coords
                    continue
        if n_steps is None and tau_prev is not None:
            # tau settled between checks, or the chain n_tau times every coordinate's tau
            # (the noise intensities' too), where the estimate needs no second look
            settled = (np.all(np.abs(tau - tau_prev) / tau < 0.05)
                       or own >= n_tau * float(np.max(tau)))
            if own >= n_tau * tau_max and settled and _diagnostics_ok(sampler, tau, post.p):
                break
        tau_prev = tau
    own = sampler.iteration
    tau_max = float(np.max(tau[:post.p])) if post.p else float(np.max(tau))
    burn, thin = _burn_thin(tau, post.p, own)
    samples = np.swapaxes(sampler.get_chain(discard=burn, thin=thin), 0, 1)
    lp = np.swapaxes(sampler.get_log_prob(discard=burn, thin=thin), 0, 1)
    kept = np.swapaxes(sampler.get_blobs(discard=burn, thin=thin), 0, 1) if bands else None
    log.info("emcee: %d steps, tau_max %.1f, burn %d, thin %d", total, tau_max, pilot + burn,
             thin)
    return SamplerRun(samples=samples, log_post=lp, tau=tau, n_steps=total, burn=pilot + burn,
                      thin=thin, acceptance=sampler.acceptance_fraction,
                      wall_s=time.perf_counter() - t0, n_tau=own / tau_max, bands=kept)


def sampler_block(run: SamplerRun, n_walkers: int, used_laplace: bool, n_evals: int
                  ) -> dict[str, Any]:
    """The summary's 'sampler' entry of an emcee run."""
    return {"walkers": n_walkers, "moves": "laplace" if used_laplace else "de",
            "steps": run.n_steps, "burn": run.burn, "thin": run.thin, "n_tau": run.n_tau,
            "acceptance_mean": float(np.mean(run.acceptance)), "wall_s": run.wall_s,
            "likelihood_evals": n_evals}


def chains_converged(params: dict[str, dict[str, Any]], run: SamplerRun) -> bool:
    """Every parameter at R-hat <= 1.01 and bulk ESS >= 400, the chain 50 tau long."""
    return bool(all(v["r_hat"] <= 1.01 and v["ess_bulk"] >= 400 for v in params.values())
                and run.n_tau >= 50)
