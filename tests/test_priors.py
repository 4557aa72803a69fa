"""Priors: parsing, densities and sampling, including the truncated normal."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, stats

from bayes_amb.errors import ParameterError
from bayes_amb.inference.priors import NOISE_LOG10_BOUNDS, PriorSet, parse_prior

PRIORS = ["uniform(-0.9, 0.9)", "normal(0.2, 0.3)", "normal(0.0, 0.3, -0.95, 0.95)",
          "normal(0.5, 0.2, 0.0, 0.6)", "lognormal(-1.0, 0.5)"]


@pytest.mark.parametrize("text", PRIORS)
def test_density_integrates_to_one_and_round_trips(text):
    pr = parse_prior(text)
    lo, hi = pr.support
    lo, hi = max(lo, -50.0), min(hi, 50.0)
    mass, _ = integrate.quad(lambda x: float(np.exp(pr.logpdf(x))), lo, hi, limit=200,
                             points=[pr.a] if lo < pr.a < hi else None)
    assert mass == pytest.approx(1.0, abs=1e-6)
    assert parse_prior(str(pr)) == pr


@pytest.mark.parametrize("text", PRIORS)
def test_samples_follow_the_density(text):
    """Kolmogorov-Smirnov of 4000 draws against the numerical CDF of logpdf; with a fixed
    seed a p-value below 1e-3 would mean sample() and logpdf() disagree."""
    pr = parse_prior(text)
    x = pr.sample(np.random.default_rng(7), 4000)
    lo, hi = pr.support
    assert np.all((x >= lo) & (x <= hi))
    grid = np.linspace(max(lo, x.min()), min(hi, x.max()), 4001)
    pdf = np.exp(pr.logpdf(grid))
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (pdf[1:] + pdf[:-1]) * np.diff(grid))])
    cdf /= cdf[-1]
    assert stats.kstest(x, lambda v: np.interp(v, grid, cdf)).pvalue > 1e-3
    assert np.std(x) == pytest.approx(pr.sd, rel=4 / math.sqrt(4000) * 2)


def test_truncated_normal_is_zero_outside_and_renormalised():
    pr = parse_prior("normal(0, 0.3, -0.3, 0.3)")
    assert np.all(np.isneginf(pr.logpdf(np.array([-0.31, 0.31]))))
    inside = stats.norm.pdf(0.0, 0, 0.3) / (stats.norm.cdf(1) - stats.norm.cdf(-1))
    assert float(np.exp(pr.logpdf(0.0))) == pytest.approx(inside)
    assert pr.support == (-0.3, 0.3)


@pytest.mark.parametrize("text", ["uniform(0, 1, 2, 3)", "normal(0, 0.3, 0.5)",
                                  "normal(0, 0.3, 0.5, 0.2)", "lognormal(0, 1, 0, 2)",
                                  "normal(0, 0.01, 5, 6)", "normal(0, x)", "beta(1, 2)"])
def test_bad_prior_text_is_a_parameter_error(text):
    with pytest.raises(ParameterError, match="prior for k_By"):
        parse_prior(text, "k_By")


def test_compiled_joint_log_prior_is_the_sum_of_the_densities():
    """PriorSet.log_prior (compiled for uniform and normal priors) equals the sum of each
    Prior.logpdf in parameter order plus the log-uniform noise terms, exactly; outside a
    support or a noise bound it is -inf; with a lognormal prior numpy takes over."""
    names = ("k_Ax", "k_Ay", "c_Bx", "c_By")
    over = {"k_Ay": parse_prior("normal(0.1, 0.3)"),
            "c_Bx": parse_prior("normal(0, 0.3, -0.5, 0.5)")}
    priors = PriorSet.build(names, over)
    rng = np.random.default_rng(0)
    theta = rng.uniform(-1.0, 1.0, (200, 4))
    ls = np.column_stack([rng.uniform(-13, -2, 200), rng.uniform(-13, -2, 200),
                          rng.uniform(-9, 2, 200)])
    new = priors.log_prior(theta, ls)
    ref = np.zeros(200)
    for j, pr in enumerate(priors.priors):
        ref = ref + pr.logpdf(theta[:, j])
    for j, (lo, hi) in enumerate(NOISE_LOG10_BOUNDS.values()):
        inside = (ls[:, j] >= lo) & (ls[:, j] <= hi)
        ref = np.where(inside, ref - np.log(hi - lo), -np.inf)
    assert priors._table is not None
    assert np.array_equal(new, ref)
    assert 0 < np.isfinite(new).sum() < 200
    logn = PriorSet.build(("c_Ax",), {"c_Ax": parse_prior("lognormal(-1, 0.5)")})
    assert logn._table is None
    x = np.array([[0.5], [-0.1]])
    ls2 = np.array([[-5.0, -5.0, -1.0], [-5.0, -5.0, -1.0]])
    noise = sum(np.log(hi - lo) for lo, hi in NOISE_LOG10_BOUNDS.values())
    lp = logn.log_prior(x, ls2)
    assert np.isfinite(lp[0]) and lp[1] == -np.inf
    assert np.isclose(lp[0], logn.priors[0].logpdf(x[:1, 0])[0] - noise, rtol=1e-14)
