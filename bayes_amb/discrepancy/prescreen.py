"""Fingerprint pre-screening: which candidates of a round are worth a full screen.

A candidate's fingerprint is what it would change in the residual of the current model:
the columns J_j = dR/dphi_j of the residual DFT at its null, in every band, channel and
line. The *linear screen* projects the residual on them: the log posterior of the model
linearised at the null in the candidate's own parameters (gauss_newton.LinearModel: R + J
delta, exact in the noise intensities, which are held), maximised over the prior box. Its
predicted gain over the current model is the score (Lagrange multiplier) test in the form
of the screening gain it predicts (Rao 1948; Buse 1982, The American Statistician 36,
153-157): for a small effect it is the screen's own gain to second order, and it costs the
q + 1 kernel rows of one Jacobian, where the full screen (select.screen: a grid over the
prior, then Gauss-Newton) costs 13-49 rows for the grid alone.

Every candidate of a round is linear-screened; each then takes one of three routes:

exact    the residual is affine in the candidate's parameters (the coefficients of a
         synchronous line: unbalance, runout), so the linearised model is the model and
         its maximum is the screen (no grid, no Gauss-Newton).
pruned   the candidate is *nested* (at its null the model is the current one, so the
         predicted gain there is its log prior alone) and *regular* (every one of its
         parameters moves the residual at the null), and the predicted gain is below
         screen_min - margin: a full screen could not reach the gain at which select.py
         refines a candidate. Its score is the prediction, marked as such.
outranked  nested and regular, and even three times its prediction plus 10 nats stays
         below the gain of the n_refine-th best candidate already screened in the round:
         it cannot be among the candidates refined (select.py screens the others first,
         in decreasing order of prediction). Its score is the prediction, marked as such.
full     everything else: the null is not the current model (flexible modes add the FE
         bending pair at its nominal frequency); a parameter that does nothing at the
         null (the damping of a second-order actuator with no dynamics: a resonance far
         from the null is invisible to the linearisation); a linearisation step the loop
         does not stabilise; a prediction near or above the bar.

The margin. On the foreign benchmark (10 recordings, 696 screens of the 31 candidates in
every round of the greedy search) the linear and the full screen of nested, regular
candidates differ by at most 0.09 nats below 5 nats of gain, and the linear one predicts
less than the full one above it (by up to 10 %: it does not see the curvature the grid
and Gauss-Newton follow). The default margin, 0.5 nats, is five times that error. For
large effects the two differed by a factor of up to 1.7 either way (a 1.6 ms sensor lag:
9002 nats screened, 5403 predicted), hence the factor 3 of the outranking bound.

The multiplicity adjustment (select.py, "Multiplicity") is not changed by the pruning: K
stays the size of the whole group, the number of hypotheses the prior is spread over.
The pre-screen is a test on the same data; counting only its survivors would let it spend
the data twice and lower the bar for each.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bayes_amb.discrepancy.gauss_newton import (
    linearise,
    maximise_in_box,
)
from bayes_amb.inference.estimate import LogPosterior
from bayes_amb.inference.priors import bound_arrays

NESTED_TOL = 1e-3
"""Nats: a candidate is nested when the log posterior at its null differs from the current
model's by its own log prior there, to within this (line bases are re-referenced at the
current MAP, which moves the likelihood by ~1e-6 nats)."""

PRUNE_MARGIN = 0.5
"""Nats below screen_min under which a nested, regular candidate's predicted gain prunes
it (module docstring)."""

OUTRANK_FACTOR = 3.0
OUTRANK_SLACK = 10.0
"""A nested, regular candidate's full screen is taken to be at most OUTRANK_FACTOR times
its predicted gain plus OUTRANK_SLACK nats (module docstring)."""


@dataclass(frozen=True)
class LinearScreen:
    """The linear screen of one candidate on top of the current model.

    gain: predicted gain in log posterior over the current model (nats; -inf where the
    linearisation failed); null_gain: the exact gain at the null (its log prior if
    nested); phi: the candidate's parameters at the predicted optimum; nested, regular:
    see the module docstring; exact: the residual is affine in the parameters.
    """

    gain: float
    null_gain: float
    phi: NDArray
    nested: bool
    regular: bool
    exact: bool

    @property
    def bounded(self) -> bool:
        """Whether the full screen is bounded by :attr:`upper` (nested and regular)."""
        return bool(self.nested and self.regular and np.isfinite(self.gain))

    @property
    def upper(self) -> float:
        """The gain a full screen of a bounded candidate is taken not to exceed."""
        return OUTRANK_FACTOR * max(self.gain, 0.0) + OUTRANK_SLACK

    def route(self, screen_min: float, margin: float = PRUNE_MARGIN) -> str:
        """'exact', 'pruned' or 'full' (module docstring)."""
        if not np.isfinite(self.gain):
            return "full"
        if self.exact and self.nested:
            return "exact"
        if self.nested and self.regular and self.gain < screen_min - margin:
            return "pruned"
        return "full"


def linear_screen(post: LogPosterior, x0: NDArray, idx: NDArray, base: float,
                  exact: bool = False) -> LinearScreen:
    """Linearise the log posterior at x0 (the current MAP with the candidate at its null)
    in the candidate's parameters ``idx`` and maximise the linear model over their prior
    box, the noise intensities held. ``base`` is the current model's log posterior;
    ``exact`` declares the residual affine in these parameters."""
    p = post.p
    bnds = post.bounds()
    lo, hi = bound_arrays([bnds[j] for j in idx])
    log_prior_null = float(sum(post.priors.priors[j].logpdf(np.array([x0[j]]))[0]
                               for j in idx))
    lin = linearise(post, x0, idx)
    if lin is None:
        return LinearScreen(-np.inf, -np.inf, x0[idx].copy(), False, False, exact)
    ls = x0[p:]
    f0 = lin.value_grad(np.zeros(idx.size), ls)[0]
    null_gain = f0 - base
    if not np.isfinite(null_gain):
        return LinearScreen(-np.inf, -np.inf, x0[idx].copy(), False, False, exact)
    nested = bool(abs(null_gain - log_prior_null) < NESTED_TOL)
    regular = bool(np.all(column_norms(lin.MT, idx.size) > 0.0))
    delta, pred = maximise_in_box(lin, ls, lo - x0[idx], hi - x0[idx])
    return LinearScreen(float(null_gain + pred), float(null_gain), x0[idx] + delta, nested,
                        regular, exact)


def column_norms(MT: NDArray, q: int) -> NDArray:
    """sum_k |J_j,k|^2 per parameter j from the band moments of a LinearModel (the traces
    of its diagonal blocks M[j, j] summed over bands); exactly 0 for a parameter whose
    forward-difference rows equal the null's."""
    n_a = q + 1
    M = MT.reshape(n_a, -1, 4, 4, n_a)
    return np.array([np.trace(M[j, :, :, :, j], axis1=1, axis2=2).real.sum()
                     for j in range(1, n_a)])
