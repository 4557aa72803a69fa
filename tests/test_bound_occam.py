"""The Occam factor of a candidate's parameter on its prior's bound (fitting.bound_occam),
which the diagnosis' Bayes factor uses where the Laplace factor cannot be formed.

An overdamped second-order actuator fitted to a first-order lag sits at zeta's upper bound
(2): before, its Bayes factor was -inf and a 324 Hz lag at both bearings of ROSS's test rig
ended 'unexplained' (log posterior gain 2761 nats, docs/validation.md). The factor is the
integral of the posterior over the prior's span, on a log-spaced grid with the log
posterior linear between its points: checked here against the numerical integral of known
log posteriors (exact where linear, low at a kink), and at the null bound, where the Bayes
factor can never exceed 1.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad

from bayes_amb.discrepancy.fitting import bound_occam

NOISE_BOUNDS = [(-12.0, 0.0)] * 3


class _Post:
    """A log posterior of one parameter on [lo, hi] (and three noise coordinates)."""

    p = 1

    def __init__(self, f, lo: float, hi: float) -> None:
        self.f, self.lo, self.hi = f, lo, hi

    def bounds(self):
        return [(self.lo, self.hi), *NOISE_BOUNDS]

    def __call__(self, X):
        return np.array([self.f(x[0]) for x in np.atleast_2d(X)])


@pytest.mark.parametrize("slope", [0.0, 0.3, 5.0, 400.0])
@pytest.mark.parametrize("at", ["lo", "hi"])
def test_the_factor_is_the_integral_of_a_linear_fall(slope, at):
    lo, hi = 0.05, 2.0
    edge = lo if at == "lo" else hi
    f = (lambda t: -slope * (t - lo)) if at == "lo" else (lambda t: -slope * (hi - t))
    log_f, on = bound_occam(_Post(f, lo, hi), np.array([edge, -7, -9, -3]), np.array([0]))
    exact = quad(lambda t: np.exp(f(t)), lo, hi, points=[edge])[0]
    assert bool(on[0])
    assert log_f == pytest.approx(np.log(exact), abs=1e-6)


def test_an_inner_maximum_is_not_on_a_bound():
    log_f, on = bound_occam(_Post(lambda t: -(t - 1) ** 2, 0.0, 2.0), np.array([1.0, -7, -9, -3]),
                            np.array([0]))
    assert not on[0] and log_f == 0.0


@pytest.mark.parametrize("slope", [0.01, 1.0, 50.0])
def test_at_the_null_the_bayes_factor_never_exceeds_one(slope):
    """A lag of 0 ms (the null, U(0, 1.6) prior): the model equals its parent there, so the
    log Bayes factor is the prior's log density plus the factor's: log((1 - e^-aW)/(aW))."""
    W = 1.6
    post = _Post(lambda t: -slope * t, 0.0, W)
    log_f, _ = bound_occam(post, np.array([0.0, -7, -9, -3]), np.array([0]))
    log_bf = np.log(1 / W) + log_f
    assert log_bf <= 1e-9
    assert log_bf == pytest.approx(np.log(-np.expm1(-slope * W) / (slope * W)), abs=1e-6)


def test_a_plateau_at_the_bound_is_charged_for_its_width_only():
    """Flat near the bound and falling steeply further in (an overdamped second-order
    actuator at zeta = 2 on a first-order lag): the factor is about the plateau's width
    (0.1 of a span of 1.95), not the whole span a local slope would credit (the demo's
    2500 Hz lag was otherwise taken for a second-order actuator with zeta unpaid for)."""
    lo, hi = 0.05, 2.0
    post = _Post(lambda t: -200.0 * max(hi - 0.1 - t, 0.0), lo, hi)
    log_f, _ = bound_occam(post, np.array([hi, -7, -9, -3]), np.array([0]))
    exact = 0.1 + quad(lambda t: np.exp(-200.0 * t), 0, hi - lo - 0.1)[0]
    assert log_f <= np.log(exact) + 1e-9              # never more than the integral
    assert log_f == pytest.approx(np.log(exact), abs=0.3)    # the grid errs low at the kink
    assert log_f < np.log(1.95) - 2.5
