"""The Laplace approximation cut at the prior's bounds (inference/bounded.py): its draws
of a truncated normal against the exact moments. Tolerances are 4 standard errors of the
4000 independent draws (the Gibbs path's chains are independent of each other)."""

import numpy as np
import pytest
from scipy import stats

from bayes_amb.inference.bounded import CHAINS, truncated_normal_draws


def _close(draws, mean, sd):
    se = sd / np.sqrt(CHAINS)
    assert abs(draws.mean() - mean) < 4 * se
    assert abs(draws.std() - sd) < 4 * sd / np.sqrt(2 * CHAINS)


@pytest.mark.parametrize("center,sd", [(0.5, 0.3),      # a quarter inside: rejection
                                       (0.5, 0.1),      # 3 sd past the bound: Gibbs
                                       (0.5, 0.001)])   # 300 sd past: against the bound
def test_one_coordinate_has_the_truncated_normal_moments(center, sd):
    lo, hi = -0.8, 0.2
    d = truncated_normal_draws(np.array([center]), np.array([[sd ** 2]]), np.array([lo]),
                               np.array([hi]), np.random.default_rng(0))[:, 0]
    exact = stats.truncnorm((lo - center) / sd, (hi - center) / sd, loc=center, scale=sd)
    assert d.min() >= lo and d.max() <= hi
    _close(d, exact.mean(), exact.std())


def test_a_correlated_coordinate_follows_the_cut_one():
    """x0 cut 3 sd past its bound (Gibbs), x1 free and correlated 0.9 with it: x1's
    marginal is its regression on the cut x0 plus the conditional noise."""
    mu, s, rho = np.array([0.5, 0.0]), np.array([0.1, 0.2]), 0.9
    cov = np.array([[s[0] ** 2, rho * s[0] * s[1]], [rho * s[0] * s[1], s[1] ** 2]])
    d = truncated_normal_draws(mu, cov, np.array([-0.8, -5.0]), np.array([0.2, 5.0]),
                               np.random.default_rng(1))
    x0 = stats.truncnorm((-0.8 - mu[0]) / s[0], (0.2 - mu[0]) / s[0], loc=mu[0], scale=s[0])
    slope = rho * s[1] / s[0]
    mean1 = mu[1] + slope * (x0.mean() - mu[0])
    sd1 = np.sqrt(slope ** 2 * x0.var() + (1 - rho ** 2) * s[1] ** 2)
    _close(d[:, 0], x0.mean(), x0.std())
    _close(d[:, 1], mean1, sd1)


def test_a_laplace_interval_is_cut_at_the_prior_support():
    """identify's normal 90 % interval of a weakly informed coefficient passed the prior's
    bound (c_By [0.10, 1.24] under uniform(-0.8, 0.8)); cut to the support it is the
    truncated normal's, and a well-informed one is left exactly as it was."""
    from bayes_amb.inference.laplace_rows import within_support

    mean, sd, lo, hi = within_support(0.67, 0.35, (-0.8, 0.8))
    exact = stats.truncnorm((-0.8 - 0.67) / 0.35, (0.8 - 0.67) / 0.35, loc=0.67, scale=0.35)
    assert hi <= 0.8 and (lo, hi) == pytest.approx(tuple(exact.ppf([0.05, 0.95])))
    assert (mean, sd) == pytest.approx((exact.mean(), exact.std()))
    assert within_support(0.2, 0.01, (-0.8, 0.8)) == (0.2, 0.01, 0.2 - 1.6449 * 0.01,
                                                      0.2 + 1.6449 * 0.01)


def test_a_free_coordinate_is_integrated_over_the_prior_of_an_uninformed_one():
    """x1 free, correlated with x0 (correlation 0.9999), which the record barely informs
    (sd 4 against a uniform(-0.8, 0.8) prior) and whose MAP ran to the bound -0.8. The
    exact marginal of x1 integrates x1 | x0 over x0's posterior, the normal truncated to
    the prior: its mean and variance in closed form. Held at the bound, x1's mean is 1.7
    of its marginal sd off; integrated over x0's prior it is within 0.05 of x1's marginal
    sd (the prior is not quite the truncated normal), and its sd within 2 %."""
    from bayes_amb.inference.bounded import BoundedLaplace
    from bayes_amb.inference.priors import PriorSet, parse_prior

    mu, s, rho = np.array([0.3, 0.1]), np.array([4.0, 2.0]), 0.9999
    cov = np.array([[s[0] ** 2, rho * s[0] * s[1]], [rho * s[0] * s[1], s[1] ** 2]])
    slope, cond = cov[1, 0] / cov[0, 0], cov[1, 1] - cov[1, 0] ** 2 / cov[0, 0]
    lo, hi = np.array([-0.8, -5.0]), np.array([0.8, 5.0])
    bl = BoundedLaplace(center=mu, cov=cov, lo=lo, hi=hi, bound=np.array([True, False]))
    priors = PriorSet(("k_Ax", "k_Ay"), (parse_prior("uniform(-0.8, 0.8)"),) * 2)
    theta = np.array([-0.8, mu[1] + slope * (-0.8 - mu[0])])   # the MAP on the bound
    held = np.array([[0.0, 0.0], [0.0, cond]])
    center, out = bl.integrated(theta, held, priors)
    x0 = stats.truncnorm((-0.8 - mu[0]) / s[0], (0.8 - mu[0]) / s[0], loc=mu[0], scale=s[0])
    mean1 = mu[1] + slope * (x0.mean() - mu[0])
    sd1 = np.sqrt(cond + slope ** 2 * x0.var())
    assert abs(theta[1] - mean1) > 1.5 * sd1                   # held: far off
    assert abs(center[1] - mean1) < 0.05 * sd1
    assert np.sqrt(out[1, 1]) == pytest.approx(sd1, rel=0.02)
    assert center[0] == theta[0] and out[0, 0] == 0.0          # the bound one: its prior's
    informed = BoundedLaplace(center=mu, cov=np.diag([1e-4, s[1] ** 2]), lo=lo, hi=hi,
                              bound=np.array([True, False]))
    same = informed.integrated(theta, held, priors)            # not weak: left as it is
    assert same[0] is theta and same[1] is held
