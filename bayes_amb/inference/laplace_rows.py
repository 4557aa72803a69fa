"""The rows of an identification that is not a sample, and what its summary says of why.

identify reports the Laplace approximation (laplace_summary, cut to the prior's support by
within_support) with --map-only, and also where it does not sample (not_sampled_note: a
coefficient the record does not inform on its prior's bound, a noise model the check
doubts); a coefficient on a bound gets its prior's interval and a note (bound_notes, and
warn_bound for a sampled posterior whose MAP sits on one). The joint posterior of several
records takes the same rows (joint.py).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import stats

from bayes_amb.inference.bounded import BoundedLaplace, bounded_laplace, sampled_bound_notes
from bayes_amb.inference.estimate import LogPosterior, at_prior_bound
from bayes_amb.inference.noise_check import CHAIN_KEYS
from bayes_amb.inference.posterior import approximate_row, draws_row
from bayes_amb.inference.priors import PriorSet


def laplace_summary(names: tuple[str, ...], center: np.ndarray, cov: np.ndarray | None,
                     rig: Any, prior_set: PriorSet | None = None,
                     bound: np.ndarray | None = None, seed: int = 0
                     ) -> dict[str, dict[str, Any]]:
    """Per parameter: the centre (the MAP, or where bounded.BoundedLaplace.integrated moved
    it), the Laplace sd and the normal 90 % interval about it.
    A parameter on its prior's bound (``bound``; its curvature left out of ``cov``) gets
    its prior's mean, sd and central 90 % interval instead: the record does not inform it,
    or pushes it past what the prior allows, and either way no narrower interval is known."""
    out = {}
    rng = np.random.default_rng(seed)
    for j, n in enumerate(names):
        if bound is not None and prior_set is not None and bound[j]:
            out[n] = draws_row(n, rig, prior_set.priors[j].sample(rng, 20000))
            continue
        sd = float(math.sqrt(cov[j, j])) if cov is not None else float("nan")
        mean, lo, hi = float(center[j]), center[j] - 1.6449 * sd, center[j] + 1.6449 * sd
        if prior_set is not None:
            mean, sd, lo, hi = within_support(mean, sd, prior_set.priors[j].support)
        out[n] = approximate_row(n, rig, mean, sd, float(lo), float(hi))
    return out


OUTSIDE_SUPPORT = 1e-3
"""Mass of the Laplace normal outside the prior's support above which it is truncated."""


def within_support(mu: float, sd: float, support: tuple[float, float]
                   ) -> tuple[float, float, float, float]:
    """The Laplace normal N(mu, sd^2) truncated to the prior's support: its mean, sd and
    central 90 % interval. The posterior is zero where the prior is; an untruncated normal
    of a weakly informed coefficient would give an interval past the prior's bound (c_By
    [0.10, 1.24] under uniform(-0.8, 0.8) on a one-channel record). Unchanged when less
    than OUTSIDE_SUPPORT of its mass lies outside."""
    lo, hi = mu - 1.6449 * sd, mu + 1.6449 * sd
    if not (np.isfinite(sd) and sd > 0):
        return mu, sd, lo, hi
    za, zb = (support[0] - mu) / sd, (support[1] - mu) / sd
    if stats.norm.cdf(za) + stats.norm.sf(zb) < OUTSIDE_SUPPORT:
        return mu, sd, lo, hi
    t = stats.truncnorm(za, zb, loc=mu, scale=sd)
    q05, q95 = (float(q) for q in t.ppf([0.05, 0.95]))
    return float(t.mean()), float(t.std()), q05, q95


def bound_notes(names: tuple[str, ...], bound: np.ndarray) -> dict[str, Any]:
    """The identifiability block of a MAP whose Laplace approximation leaves out the
    parameters on a prior bound."""
    at = [n for n, b in zip(names, bound, strict=True) if b]
    one = len(at) == 1
    return {"identifiable": False, "at_prior_bound": at,
            "notes": [f"{', '.join(at)} {'is' if one else 'are'} not identified by these "
                      f"data: {'its MAP sits' if one else 'their MAPs sit'} on the prior's "
                      "bound (the record does not inform "
                      f"{'it' if one else 'them'}, or pushes past the prior), so "
                      f"{'its interval is' if one else 'their intervals are'} the prior's. "
                      "Excite the channels they act on, or leave them out of --params "
                      "(held at the nominal value)."]}


def not_sampled_note(weak: list[str], misspecified: bool) -> str:
    """Why a record was not sampled: coefficients the record does not inform on their
    prior's bound (``weak``, their posterior is their prior), else a noise model the check
    doubts. (The joint posterior of several records is still sampled: there the joint
    sandwich at the joint MAP, each record's noise held at its own MAP, held 24/32 on four
    three-speed process-force groups where the sampled joint held 30/32.)"""
    if weak:
        return (f"not sampled: {', '.join(weak)} not informed by the record (the MAP on "
                "the prior's bound, the sd there at least half the prior's), so "
                f"{'its posterior is its' if len(weak) == 1 else 'their posterior is their'}"
                " prior's; the others' intervals are the Laplace approximation over them, "
                "integrated over that prior (linearised). A sample of such a posterior "
                "took minutes and did not converge.")
    assert misspecified
    return ("not sampled: the noise check doubts the noise model (the residual's colour "
            "is not the model's), so the intervals are the sandwich posterior at the MAP "
            "(Mueller 2013), which a sample of that likelihood would not give: its draws "
            "lean where the wrong noise model puts them")


def warn_bound(summary: dict[str, Any], post: LogPosterior, x_map: np.ndarray,
                names: tuple[str, ...], prior_set: PriorSet, rig: Any, seed: int,
                bl: BoundedLaplace | None = None) -> None:
    """A sampled posterior whose MAP has a coefficient on a prior bound, not informed or
    pushed past (bounded.sampled_bound_notes), unless the draws already said it is not
    identified: the note says so, and the coefficient reports its prior's interval, as
    the MAP-only path does (its draws lean on the bound: on 41 foreign process-force
    records such intervals held the truth in 17 of 32). The sampler's diagnostics stay.
    ``bl``: the bounded Laplace approximation at x_map where the caller formed it."""
    if not at_prior_bound(post, x_map)[:post.p].any():
        return
    ident = summary["identifiability"]
    bl = bl if bl is not None else bounded_laplace(post, x_map)
    said = {n.split(" ")[0] for n in ident["notes"] if " is not identified" in n}
    notes = [] if bl is None else [n for n in sampled_bound_notes(names, bl, prior_set)
                                   if n.split(" ")[0] not in said]
    if not notes:
        return
    ident["notes"] = [*ident["notes"], *notes]
    ident["identifiable"] = False
    ident["at_prior_bound"] = [n.split(" ")[0] for n in notes]
    rng = np.random.default_rng(seed)
    rows = summary["parameters"]
    for n in ident["at_prior_bound"]:
        prior = prior_set.priors[names.index(n)]
        rows[n] = {**draws_row(n, rig, prior.sample(rng, 20000)),
                   **{k: rows[n][k] for k in CHAIN_KEYS}}
