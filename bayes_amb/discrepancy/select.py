"""Fit extended models and choose between them: screening, MAP, Laplace Bayes factor, greedy.

Criterion. Models are compared by their Bayes factor against the model they extend,
computed from the noise-marginalised whole-band Whittle likelihood (likelihood.py), whose
frequency bands are independent even though the time-domain residual is autocorrelated.
The evidence is approximated by Laplace's method on the candidate's own parameters, with
the shared stiffness/damping and noise parameters profiled (their Occam factors are taken
equal in both models):

    log BF = [log p(D, x_hat_ext) - log p(D, x_hat_parent)] + 1/2 log det(2 pi Sigma_phi)

with Sigma_phi the candidate block of the inverse negative Hessian at the extended MAP
(marginal over the shared parameters; dimensions sitting on a prior bound are held fixed).
The candidate's physical prior enters through log p(phi_hat): a wide prior costs evidence,
as it should. Unlike cross-validation in time (blocked or leave-future-out), which would
need many refits per candidate, this costs one MAP and one Hessian, and unlike a
time-domain PSIS-LOO it does not treat autocorrelated samples as exchangeable.

Search. Every candidate is first *screened*: its own parameters are fitted with everything
else held at the current model's MAP (a grid over the prior, then a local search). The
likelihood gain of that short fit is how well the candidate's fingerprint matches the
residual; it ranks the candidates. The best few are then fitted fully (all parameters) and
scored by their Bayes factor; the best above the threshold is accepted and the search is
repeated on top of it (greedy forward selection), so that two hidden effects yield both.

Pre-screening (prescreen.py). Before the grid, each candidate's fingerprint is tested
against the residual: the model linearised in its own parameters at its null (the score
test, q + 1 kernel rows), maximised over its prior box. A line's linear screen is its
screen (the residual is affine in its coefficients). A candidate that nests the current
model and whose parameters all act at the null is not fitted when that prediction is well
below screen_min, or so far below the round's n_refine best screens that it cannot be
refined; everything else is screened in full, as before. The refits, and so what is
accepted, are those of a full screen of every candidate wherever the linearisation stays
inside the margins of prescreen.py (checked in tests/test_prescreen.py and on the foreign
benchmark, benchmarks/README.md); pruned candidates are reported with their prediction. A line
is refitted from both starts of the record, and only the better MAP gets a Hessian when
the two are apart by more than their Occam factors can differ (refine_line).

Multiplicity. A round tries K candidates, and the best of K null Bayes factors is larger
than one of them: on effect-free foreign recordings with the 31-candidate library, one in
ten named a 0.5 % actuator gain at log BF 3.1. The prior is made explicit instead: the
prior probability that the model lacks something in a round is spread evenly over the K
candidates of the group tried, so each has prior odds 1/K against the model without it,
and a candidate is accepted when its log *posterior* odds, log BF - log K, exceed the
threshold (with K = 31, a log BF above 6.4). This is the usual Bayesian adjustment for
multiplicity (Scott & Berger 2010): adding candidates to the library raises the bar for
each of them, so a wider library does not mean more false alarms. K counts every candidate
of the group, pre-screened away or not: the prior is spread over all the hypotheses of the
library before the data are seen, and the pre-screen is a test on the same data, so
counting only its survivors would spend the data twice and lower the bar unfairly.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from bayes_amb.discrepancy.family import VirtualPlane, member_screens, scan_families
from bayes_amb.discrepancy.fitting import (
    FittedModel,
    _embed,
    bound_occam,
    extend,
    free_covariance,
    local_fit,
)
from bayes_amb.discrepancy.gauss_newton import gauss_newton
from bayes_amb.discrepancy.library import Candidate, SynchronousLine, all_candidates
from bayes_amb.discrepancy.library.cross_coupling import DirectTerms
from bayes_amb.discrepancy.library.registry import admissible
from bayes_amb.discrepancy.likelihood import RobustWhittle
from bayes_amb.discrepancy.model import ExtendedForwardModel
from bayes_amb.discrepancy.prescreen import PRUNE_MARGIN, linear_screen
from bayes_amb.inference.estimate import (
    LogPosterior,
)
from bayes_amb.inference.priors import Prior
from bayes_amb.rig import node_label

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SelectOptions:
    """log_bf_threshold: accept an effect when its log posterior odds (log Bayes factor -
    log of the number of candidates tried in the round) exceed it (3: "strong" on the
    Kass-Raftery scale, 2 ln BF > 6); max_effects: greedy rounds; n_refine: how many
    screened candidates per round are fitted fully; screen_min: the screening gain (nats)
    below which a candidate is not refined; prescreen: route each candidate by its linear
    screen (prescreen.py) instead of screening every one fully; prescreen_margin: nats
    below screen_min under which the linear screen prunes a candidate."""

    log_bf_threshold: float = 3.0
    max_effects: int = 4
    n_refine: int = 3
    screen_min: float = 2.0
    candidates: tuple[Candidate, ...] = field(default_factory=all_candidates)
    prescreen: bool = True
    prescreen_margin: float = PRUNE_MARGIN


def _grid(prior: Prior, n: int) -> NDArray:
    """n screening points spread over a prior (quantiles; uniform grids include the ends)."""
    q = np.linspace(0.02, 0.98, n)
    if prior.kind == "uniform":
        return prior.a + (prior.b - prior.a) * np.concatenate([[0.0], q ** 2])
    z = stats.norm.ppf(q)
    return prior.a + prior.b * z if prior.kind == "normal" else np.exp(prior.a + prior.b * z)


@dataclass
class Screen:
    """A candidate's screening: the gain in log posterior of fitting only its parameters.

    how: 'full' (grid and Gauss-Newton, :func:`screen`), 'exact' (the linear screen of a
    candidate the residual is affine in: the same optimum), 'pruned' or 'outranked' (the
    linear screen's prediction, below the bar or below the round's best: not fitted; see
    prescreen.py), 'family' (a location of an unbalance or cross-coupling node scan whose
    linear screen came from the one linearisation of the whole scan: a line's screen, or
    a coupling's prediction below the bar; see family.py).
    linear_gain: the linear screen's prediction (None where it was not run).
    """

    candidate: Candidate
    gain: float
    phi: dict[str, float]
    how: str = "full"
    linear_gain: float | None = None


def _own_columns(fwd: ExtendedForwardModel) -> NDArray:
    """Indices of the last candidate's parameters in the parameter vector."""
    return np.arange(fwd.slices[-1].start, fwd.slices[-1].stop)


def screen(parent: FittedModel, cand: Candidate, priors: dict[str, Prior] | None = None,
           model: tuple[ExtendedForwardModel, RobustWhittle, LogPosterior] | None = None
           ) -> Screen:
    """Fit only the candidate's parameters, the rest held at the parent's MAP (``model``:
    the extended model if already built by :func:`extend`)."""
    fwd, _, post = model or extend(parent, cand, priors)
    x0 = _embed(parent, fwd)
    idx = _own_columns(fwd)
    eff = fwd.effect_params[-len(idx):]
    grids = np.meshgrid(*[_grid(e.prior, 12 if idx.size == 1 else 6) for e in eff])
    pts = np.tile(x0, (grids[0].size, 1))
    for j, g in zip(idx, grids, strict=True):
        pts[:, j] = g.ravel()
    base = parent.log_post      # the parent is not always the child at its null (flexible)
    vals = post(pts)
    best = pts[int(np.argmax(vals))] if np.any(np.isfinite(vals)) else x0
    x, f = gauss_newton(post, best, cols=idx, noise=False)
    gain = f - base
    if not np.isfinite(gain):
        gain = -np.inf
    return Screen(cand, gain, {fwd.params[j]: float(x[j]) for j in idx})


def prescreened(parent: FittedModel, cand: Candidate, screen_min: float,
                margin: float = PRUNE_MARGIN, priors: dict[str, Prior] | None = None
                ) -> Screen:
    """One candidate's screen by the route its linear screen decides (prescreen.py): the
    linear screen itself where it is exact or prunes the candidate, the full screen
    otherwise (on the same extended model)."""
    return screen_round(parent, [cand], SelectOptions(screen_min=screen_min,
                                                      prescreen_margin=margin,
                                                      candidates=()), priors)[0]


def screen_round(parent: FittedModel, pool: list[Candidate], opt: SelectOptions,
                 priors: dict[str, Prior] | None = None) -> list[Screen]:
    """The screens of a round's pool, in pool order. Without ``opt.prescreen`` every
    candidate is screened fully. With it (prescreen.py), every candidate is linear-screened
    first; exact ones keep that screen; nested, regular ones below screen_min - margin are
    pruned; the others are screened fully, the candidates without a bound first, then the
    bounded ones in decreasing order of prediction, each unless it is outranked by the
    opt.n_refine best gains already known."""
    if not opt.prescreen:
        return [screen(parent, c, priors) for c in pool]
    out: dict[str, Screen] = {}
    for members, basis in scan_families(parent, pool):
        # every location's linear screen from one linearisation of its scan (family.py):
        # a line's is its screen; a coupling below the bar is pruned, as alone
        proj = member_screens(parent, basis, members, priors) or {}
        lines = isinstance(basis[0], VirtualPlane)
        for c in members:
            ms = proj.get(c.key)
            if ms is not None and (lines or ms.gain < opt.screen_min - opt.prescreen_margin):
                out[c.key] = Screen(c, ms.gain, ms.phi, how="family",
                                    linear_gain=_num(ms.gain))
    staged = []
    for c in pool:
        if c.key in out:
            continue
        model = extend(parent, c, priors)
        fwd, _, post = model
        idx = _own_columns(fwd)
        lin = linear_screen(post, _embed(parent, fwd), idx, parent.log_post,
                            exact=isinstance(c, SynchronousLine))
        how = lin.route(opt.screen_min, opt.prescreen_margin)
        if how == "full":
            staged.append((c, model, lin))
        else:
            out[c.key] = Screen(c, lin.gain, dict(zip([fwd.params[j] for j in idx],
                                                      map(float, lin.phi), strict=True)),
                                how=how, linear_gain=_num(lin.gain))
    staged.sort(key=lambda t: (t[2].bounded, -t[2].gain))       # unbounded first
    for c, model, lin in staged:
        known = sorted((s.gain for s in out.values()), reverse=True)
        if lin.bounded and len(known) >= opt.n_refine and lin.upper < known[opt.n_refine - 1]:
            fwd = model[0]
            idx = _own_columns(fwd)
            out[c.key] = Screen(c, lin.gain, dict(zip([fwd.params[j] for j in idx],
                                                      map(float, lin.phi), strict=True)),
                                how="outranked", linear_gain=_num(lin.gain))
            continue
        sc = screen(parent, c, priors, model)
        sc.linear_gain = _num(lin.gain)
        out[c.key] = sc
    return [out[c.key] for c in pool]


def refit(parent: FittedModel, sc: Screen, priors: dict[str, Prior] | None = None
          ) -> FittedModel:
    """Full MAP of parent + candidate from the screening point (no covariance, no Bayes
    factor yet: see :func:`score`)."""
    fwd, like, post = extend(parent, sc.candidate, priors, sc.phi)
    x0 = _embed(parent, fwd, sc.phi)
    # two starts: the parent's stiffness/damping values, which may sit where they absorbed
    # the missing physics (e.g. on a prior bound), and those parameters at their null
    alt0 = x0.copy()
    alt0[:len(fwd.theta_names)] = 0.0
    v = post(np.vstack([x0, alt0]))
    x, log_post = local_fit(post, x0 if v[0] >= v[1] else alt0)
    return FittedModel((*parent.candidates, sc.candidate), fwd, like, post, x, log_post)


def score(parent: FittedModel, fm: FittedModel) -> FittedModel:
    """The refitted model's Laplace covariance and its log Bayes factor against the
    parent (module docstring), set in place; returns it."""
    idx = _own_columns(fm.forward)
    fm.cov = free_covariance(fm.post, fm.x, last=idx.size)
    log_bf = -np.inf
    if fm.cov is not None and np.isfinite(fm.log_post):
        # an own parameter on its prior's bound (an overdamped second-order actuator at
        # zeta's upper bound) has a one-sided factor, the others their Laplace one
        log_bound, on = bound_occam(fm.post, fm.x, idx)
        free = idx[~on]
        block = fm.cov[np.ix_(free, free)]
        sign, logdet = np.linalg.slogdet(2 * np.pi * block) if free.size else (1.0, 0.0)
        if sign > 0 and np.all(np.diag(block) > 0) and np.isfinite(log_bound):
            log_bf = (fm.log_post - parent.log_post) + 0.5 * logdet + log_bound
    fm.log_bf = float(log_bf)
    log.info("refined %s: log BF %.1f", fm.candidates[-1].key, log_bf)
    return fm


def refine(parent: FittedModel, sc: Screen, priors: dict[str, Prior] | None = None
           ) -> FittedModel:
    """Full MAP of parent + candidate from the screening point; Laplace Bayes factor."""
    return score(parent, refit(parent, sc, priors))


START_OCCAM_TOL = 0.05
"""Nats. A line's two starts ('rest', 'steady') differ only by the transient at the start
of the record: their Laplace Occam factors (1/2 log det of the candidate block) agreed
to 3e-4 nats in every pair refitted on the foreign benchmark (21 pairs, log posteriors
0.002-0.48 nats apart). When the two MAPs are further apart than this, the lower one
cannot have the larger Bayes factor, and its Hessian is not formed."""


def refine_line(parent: FittedModel, sc: Screen, priors: dict[str, Prior] | None = None
                ) -> FittedModel:
    """A synchronous line refined from both starts of the record, 'rest' (the screen's)
    and 'steady' (the rotor already in synchronous steady state); the one with the larger
    Bayes factor is kept (the 'rest' one on a tie). Only the better MAP is scored when
    the two are more than START_OCCAM_TOL apart."""
    rest = refit(parent, sc, priors)
    steady = refit(parent, Screen(replace(sc.candidate, start="steady"), sc.gain, sc.phi),
                   priors)
    gap = steady.log_post - rest.log_post
    if np.isfinite(gap) and abs(gap) > START_OCCAM_TOL:
        return score(parent, steady if gap > 0 else rest)
    rest, steady = score(parent, rest), score(parent, steady)
    return steady if (steady.log_bf or -np.inf) > (rest.log_bf or -np.inf) else rest


@dataclass
class Selection:
    """The greedy search: the chosen model, the nominal, and every candidate's scores."""

    nominal: FittedModel
    final: FittedModel
    accepted: list[FittedModel]
    scores: list[dict[str, Any]]


def _try(current: FittedModel, pool: list[Candidate], rnd: int, opt: SelectOptions,
         priors: dict[str, Prior] | None, progress: Callable[[str], None] | None,
         scores: list[dict[str, Any]]) -> FittedModel | None:
    """Screen a pool on top of ``current``, fit the best few fully, record every score and
    return the best refined model (None if none was refined)."""
    if progress:
        progress(f"round {rnd}: screening {len(pool)} candidates")
    screens = screen_round(current, pool, opt, priors)
    screens.sort(key=lambda s: -s.gain)
    refined: list[FittedModel] = []
    for sc in screens[:opt.n_refine]:
        if sc.gain < opt.screen_min:
            break
        if progress:
            progress(f"round {rnd}: fitting {sc.candidate.key}")
        # a line: the record may begin with the rotor already in synchronous steady state
        refined.append(refine_line(current, sc, priors)
                       if isinstance(sc.candidate, SynchronousLine)
                       else refine(current, sc, priors))
    by_key = {f.candidates[-1].key: f for f in refined}
    for sc in screens:
        f = by_key.get(sc.candidate.key)
        scores.append({"effect": sc.candidate.effect, "location": sc.candidate.location,
                       "round": rnd, "screen_gain": _num(sc.gain), "screen": sc.how,
                       "linear_gain": sc.linear_gain,
                       "log_bayes_factor": None if f is None else _num(f.log_bf),
                       "log_posterior_odds": None if f is None or f.log_bf is None
                       else _num(posterior_log_odds(f.log_bf, len(pool))),
                       "fingerprint": sc.candidate.fingerprint})
    if not refined:
        return None
    return max(refined, key=lambda f: f.log_bf if f.log_bf is not None else -np.inf)


def select(nominal: FittedModel, options: SelectOptions | None = None,
           priors: dict[str, Prior] | None = None,
           progress: Callable[[str], None] | None = None) -> Selection:
    """Greedy forward selection of candidate physics on top of the nominal fit.

    In every round the nominal model's own left-out coefficients (``nominal_family``
    candidates) are tried first, and the best of them is chosen when it passes the
    threshold, unless physics beats it by the threshold again (:func:`_choose`). A
    repeatable effect may be added again at another location (registry.admissible).
    """
    opt = options or SelectOptions()
    current = nominal
    accepted: list[FittedModel] = []
    scores: list[dict[str, Any]] = []
    for rnd in range(1, opt.max_effects + 1):
        pool = [c for c in opt.candidates if admissible(c, current.candidates)]
        best = []
        for group in ([c for c in pool if c.nominal_family],
                      [c for c in pool if not c.nominal_family]):
            fit = _try(current, group, rnd, opt, priors, progress, scores) if group else None
            odds = (posterior_log_odds(fit.log_bf, len(group))
                    if fit is not None and fit.log_bf is not None else -np.inf)
            if odds > opt.log_bf_threshold:
                best.append((fit, odds))
        chosen = _choose(best, opt.log_bf_threshold)
        if chosen is None:
            break
        chosen = refine_node(current, chosen, priors, rnd, scores, progress)
        accepted.append(chosen)
        current = chosen
    return Selection(nominal=nominal, final=current, accepted=accepted, scores=scores)


def _choose(passed: list[tuple[FittedModel, float]], margin: float) -> FittedModel | None:
    """The round's choice from the groups' best fits that passed (left-out coefficients
    first, then physics; each with its log posterior odds): the coefficient, the simpler
    explanation, unless the physics' odds exceed its own by ``margin`` (the acceptance
    threshold: the same strength of evidence that names anything).

    A coefficient chosen merely because it was tried first took what a delay or a sensor
    gain leaves at its bearing, and the physics then went unnamed or was named beside it
    (the concealed benchmark, where only k_By and c_By are fitted: 6 of its 10 extra names
    at bfd77fd were a coefficient taken for a delay or a gain)."""
    if not passed:
        return None
    fit, odds = passed[0]
    if len(passed) > 1 and fit.candidates[-1].nominal_family \
            and passed[1][1] > odds + margin:
        fit, odds = passed[1]
    fit.log_odds = odds
    return fit


NODE_FREE = ("unbalance",)
"""Node effects whose node is not physics: an unbalance at any two shaft nodes with the
same resultant and moment gives the same lines below the first bending mode, and its
answer is the two-plane balancing, the same from any node. Their node is not refined here,
and across records (records.py) one named at another node counts as the same effect."""


def refine_node(parent: FittedModel, chosen: FittedModel,
                priors: dict[str, Prior] | None = None, rnd: int = 0,
                scores: list[dict[str, Any]] | None = None,
                progress: Callable[[str], None] | None = None) -> FittedModel:
    """A force named at a shaft node is moved to the node where it fits best: the default
    candidates sit at a few nodes only (the discs, mid-span), and a seal two nodes away
    from the mid-span node otherwise leaves a remainder that a later round names as a
    second, wrong force. The neighbours are fitted one node at a time in each direction,
    with the direct terms a node force carries (_with_companion), on past the best until
    the fit has fallen NODE_NATS below it; the nodes within NODE_NATS of the best become
    ``node_range``. The chosen node is then refitted and scored as the search does, and
    keeps the prior odds of its round; without a finite Bayes factor there the force stays
    where it was, with no range. Effects in NODE_FREE and effects not at a shaft node are
    returned as they are; every neighbour tried is appended to ``scores`` with round
    '<rnd> node'."""
    cand = chosen.candidates[-1]
    k = node_label(cand.location)
    if k is None or cand.effect in NODE_FREE or chosen.log_bf is None:
        return chosen
    n_nodes = parent.forward.recording.rig.n_nodes
    fit = {k: _with_companion(parent, cand, priors)}
    for step in (-1, 1):
        node = k
        # walk while the fit rises, and on past the best until it has fallen NODE_NATS
        # below it, so that every node within NODE_NATS of the best is seen (node_range)
        while 1 <= node + step <= n_nodes and fit[node] > max(fit.values()) - NODE_NATS:
            node += step
            alt = replace(cand, location=f"n{node}")
            fit[node] = _with_companion(parent, alt, priors)
            if scores is not None:
                scores.append({"effect": alt.effect, "location": alt.location,
                               "round": f"{rnd} node", "screen_gain": None,
                               "log_bayes_factor": None, "log_posterior_odds": None,
                               "log_posterior_gain": _num(fit[node] - fit[k]),
                               "fingerprint": alt.fingerprint, "instead_of": cand.key})
    best_node = max(fit, key=fit.get)
    chosen.node_range = _within(fit, NODE_NATS)
    if best_node == k:
        return chosen
    alt = replace(cand, location=f"n{best_node}")
    best = refine(parent, screen(parent, alt, priors), priors)
    if best.log_bf is None or not np.isfinite(best.log_bf):
        chosen.node_range = None    # no Laplace evidence at the better node: stay, and
        return chosen               # claim no range the named node is not in
    best.log_odds = chosen.log_odds + (best.log_bf - chosen.log_bf)
    best.node_range = chosen.node_range
    if progress:
        progress(f"round {rnd}: {cand.key} moved to {best.candidates[-1].key}")
    return best


NODE_NATS = 2.0
"""Log posterior below the best node within which a node is as good a place for the
force: the reported node range (a log Bayes factor of 2 is not worth more than a bare
mention)."""


def _within(fit: dict[int, float], nats: float) -> list[int]:
    """[first, last] node whose fit is within ``nats`` of the best."""
    top = max(fit.values())
    near = [n for n, v in fit.items() if v >= top - nats]
    return [min(near), max(near)]


def _with_companion(parent: FittedModel, cand: Candidate,
                    priors: dict[str, Prior] | None) -> float:
    """The MAP log posterior of parent + a node force with the direct terms it carries (a
    seal's or impeller's K and C at the same node, direct_terms.py): the force's node is
    chosen with them, as its coefficients are reported with them."""
    extra = (cand, DirectTerms("direct_terms", cand.location)) \
        if cand.effect == "cross_coupling" else (cand,)
    fwd, _, post = extend(parent, extra, priors)
    _, log_post = local_fit(post, _embed(parent, fwd))
    return log_post


def try_candidate(parent: FittedModel, cand: Candidate,
                  priors: dict[str, Prior] | None = None, force: bool = False
                  ) -> tuple[FittedModel | None, dict[str, Any]]:
    """One pre-specified candidate on top of a fitted model (a hypothesis from another
    record, records.py): screened, and fitted fully unless its screening gain is below
    screen_min (``force``: whatever its gain, for evidence that is added up across
    records). Returns the fitted model (None if not fitted) and its score row."""
    scores: list[dict[str, Any]] = []
    opt = SelectOptions(candidates=(cand,), prescreen=False,
                        **({"screen_min": -np.inf} if force else {}))
    fm = _try(parent, [cand], 1, opt, priors, None, scores)
    return fm, scores[0]


def posterior_log_odds(log_bf: float, n_candidates: int) -> float:
    """Log posterior odds of one of n_candidates tried against the model without it, each
    with prior odds 1/n_candidates (module docstring, Multiplicity)."""
    return float(log_bf - np.log(max(n_candidates, 1)))


def _num(v: float | None) -> float | None:
    return None if v is None or not np.isfinite(v) else float(v)
