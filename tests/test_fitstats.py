"""Draws of a fit at its prior's bound (discrepancy/fitstats.draws): a curvature taken on the
bound leaves a spread no record measures, and the interval must then be the prior's."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from bayes_amb.discrepancy.fitstats import draws


def _fit(params, cov):
    bounds = [(-0.8, 0.8)] * len(params)
    return SimpleNamespace(model_error=None, p=len(params), extra_cov=None, samples=None,
                           params=np.asarray(params, float), cov=np.asarray(cov, float),
                           post=SimpleNamespace(bounds=lambda: bounds))


def test_a_hair_wide_laplace_at_the_bound_gets_the_prior():
    # the foreign actuator_gain_00 case: k_By at 0.8 with sd 5e-10 (its truth -0.11)
    d = draws(_fit([0.8 - 4e-10, 0.1], np.diag([(5e-10) ** 2, 0.02 ** 2])), seed=3)
    assert 0.4 < d[:, 0].std() < 0.52                      # uniform(-0.8, 0.8): 0.46
    assert d[:, 0].min() < -0.7 and d[:, 0].max() > 0.7
    assert abs(d[:, 1].std() - 0.02) < 0.002               # the informed one untouched


def test_a_measured_spread_near_the_bound_is_kept():
    d = draws(_fit([0.75, 0.1], np.diag([0.02 ** 2, 0.02 ** 2])), seed=3)
    assert d[:, 0].max() <= 0.8 and abs(d[:, 0].std() - 0.018) < 0.004


def test_a_narrow_posterior_pressed_against_the_bound_gets_the_prior():
    # the foreign pair_current_limit_sensor_gain_00 case: k_Bx at -0.7952 (0.3 % of the
    # prior's width inside its bound) with sd 0.005, its truth 0.26: the data push it to
    # the wall, and [-0.8, -0.785] would have claimed it
    d = draws(_fit([-0.7952, 0.1], np.diag([0.005 ** 2, 0.02 ** 2])), seed=3)
    assert 0.4 < d[:, 0].std() < 0.52 and d[:, 0].max() > 0.7
    assert abs(d[:, 1].std() - 0.02) < 0.002


def test_a_wide_posterior_with_a_tail_past_the_bound_keeps_its_spread():
    # MAP far inside, 10 % of its Laplace mass beyond the wall: the data inform it
    d = draws(_fit([-0.42, 0.1], np.diag([0.3 ** 2, 0.02 ** 2])), seed=3)
    assert abs(np.mean(d[:, 0]) + 0.40) < 0.03 and d[:, 0].std() < 0.3   # prior: 0, 0.46
