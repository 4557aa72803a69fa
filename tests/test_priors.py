"""Priors: parsing, densities and sampling, including the truncated normal."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, stats

from bayes_amb.errors import ParameterError
from bayes_amb.inference.priors import parse_prior

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
