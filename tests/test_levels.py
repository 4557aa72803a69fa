"""The magnets' force law from records at several excitation levels (discrepancy/levels.py):
the weighted least squares over the records' stiffness estimates, on synthetic estimates
whose law is known."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from bayes_amb.discrepancy.levels import force_law_levels, level_of
from bayes_amb.rig import load_rig

NAMES = ("k_Ax", "k_Ay", "k_Bx", "k_By")


@pytest.fixture(scope="module")
def rig():
    return load_rig()


def _records(rig, amplitudes, rng, n=4000):
    return [SimpleNamespace(u=a * np.sign(rng.standard_normal((n, 4))), rig=rig)
            for a in amplitudes]


def _diags(recs, theta, beta, sd, rng):
    out = []
    for r in recs:
        m = level_of(r)
        pars = {n: SimpleNamespace(mean=theta[j] - beta * m["AB".index(n[2])]
                                   + sd * rng.standard_normal(), sd=sd)
                for j, n in enumerate(NAMES)}
        out.append(SimpleNamespace(checks_failed=False, nonlinearity=None,
                                   parameters_after=pars))
    return out


def test_a_force_law_is_named_across_two_levels_and_its_gap_covers(rig):
    """gap 0.3 mm (bias 1.2 A) read at 0.15 and 0.3 A: the shift is 1.6 % and 6 %, against
    an sd of 0.2 %; over 300 seeds the 90 % interval of the gap covers within the binomial
    error (3 sd) and the small-signal stiffnesses too."""
    g0, sd = 3e-4, 0.002
    beta = g0 ** -2
    theta = np.array([0.1, -0.05, 0.2, 0.0])
    hits, ss_hits, named, n = 0, 0, 0, 300
    for s in range(n):
        rng = np.random.default_rng(s)
        recs = _records(rig, (0.15, 0.3), rng)
        fl = force_law_levels(recs, _diags(recs, theta, beta, sd, rng))
        named += fl["named"]
        if fl["named"]:
            lo, hi = fl["gap_hdi90"]
            hits += lo <= g0 <= hi
            ss = fl["small_signal"]["k_Bx"]["hdi90"]
            ss_hits += ss[0] <= theta[2] <= ss[1]
    assert named == n
    assert fl["where"] == ["A", "B"]
    tol = 3 * np.sqrt(0.9 * 0.1 / n)
    assert abs(hits / n - 0.9) < tol and abs(ss_hits / n - 0.9) < tol
    fl = force_law_levels(recs, _diags(recs, theta, beta, sd, rng))
    assert fl["bias_current_a"] == pytest.approx(g0 * rig.ks / rig.ki, rel=0.1)


def test_linear_magnets_are_not_named_and_bound_the_bias(rig):
    """beta = 0: named at about the test's level (ALPHA 1e-3, so none of 300), and the
    bias's lower bound is a number the line gives."""
    theta = np.zeros(4)
    named = 0
    for s in range(300):
        rng = np.random.default_rng(1000 + s)
        recs = _records(rig, (0.15, 0.3), rng)
        fl = force_law_levels(recs, _diags(recs, theta, 0.0, 0.002, rng))
        named += fl["named"]
    assert named <= stats.binom.ppf(0.999, 300, 1e-3)
    assert not fl["named"] and all(fl["bearings"][b]["bias_lower_bound_a"] > 0 for b in "AB")
    assert "bias is above" in fl["line"]


def test_a_law_at_one_bearing_is_named_there_only(rig):
    """Each magnet pair its own bias: a law at B alone is named at B, and A keeps a bound."""
    g0, sd = 3e-4, 0.002
    rng = np.random.default_rng(7)
    recs = _records(rig, (0.1, 0.3), rng)
    diags = _diags(recs, np.zeros(4), g0 ** -2, sd, rng)
    for d, r in zip(diags, recs, strict=True):            # undo the law at A
        m = level_of(r)
        for n in ("k_Ax", "k_Ay"):
            d.parameters_after[n].mean += g0 ** -2 * m[0]
    fl = force_law_levels(recs, diags)
    assert fl["where"] == ["B"] and "bias_lower_bound_a" in fl["bearings"]["A"]
    lo, hi = fl["bearings"]["B"]["gap_hdi90"]
    assert lo <= g0 <= hi


def test_one_level_cannot_tell_the_law_from_a_stiffness(rig):
    rng = np.random.default_rng(5)
    recs = _records(rig, (0.3, 0.3), rng)
    fl = force_law_levels(recs, _diags(recs, np.zeros(4), 1e7, 0.002, rng))
    assert not fl["named"] and "do not differ enough" in fl["line"]
    failed = _diags(recs, np.zeros(4), 0.0, 0.002, rng)
    failed[0].checks_failed = True
    assert force_law_levels(recs, failed) is None
