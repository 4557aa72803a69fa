"""bayes_amb.engineering: closed-loop modes, log decrements, margins and sensitivities
from posterior draws.

Reference tests build the sampled closed loop of the full 320-state plant by hand (truth
plant of the simulator, scipy's matrix exponential, u = K y) and compare eigenvalues and
sensitivities, and check that the rigid-body modes are the regulator poles the controller
placed and that their labels are continuous in speed in the paper case; identity tests
check the log-decrement identities and the alias-free continuous equivalent; the
statistical tests check that the 90 % interval of a quantity
with a ridge maximum is calibrated over 1000 simulated posteriors, and that the interval of
every derived quantity covers its truth in >= 26 of 30 simulated recordings (85 %).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.linalg as sla

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.engineering import (
    MODE_LABELS,
    Draws,
    central_region,
    closed_loop_modes,
    draws_from,
    interval90,
    log_decrement,
    physical_quantities,
    required_separation_margin,
)
from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.io.recording import make_recording
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, simulate_recording
from bayes_amb.simulate.truth import build_truth

THETA = {"k_By": 0.3, "c_By": 0.2}
SPEED = 31500.0


@pytest.fixture(scope="module")
def rig():
    return load_rig()


@pytest.fixture(scope="module")
def ctrl(rig):
    return {dt: export_controller(reference_controller(rig, dt), rig) for dt in (1e-3, 1e-4)}


def _hand_loop(rig, ctrl, dt):
    """Sampled closed loop of the full truth plant with THETA, built here from scratch."""
    tp = build_truth(rig, SPEED, "full", THETA)
    n, m = tp.B.shape
    E = np.zeros((n + m, n + m))
    E[:n, :n], E[:n, n:] = tp.A, tp.B
    Ed = sla.expm(E * dt)
    Ad, Bd = Ed[:n, :n], Ed[:n, n:]
    Ak, Bk, Ck, Dk = ctrl.A, ctrl.B[:, :4], ctrl.C[:4], ctrl.D[:4, :4]
    # u = Ck xk + Dk y, y = C x;  x+ = Ad x + Bd u;  xk+ = Ak xk + Bk y
    top = np.hstack([Ad + Bd @ Dk @ tp.C, Bd @ Ck])
    bottom = np.hstack([Bk @ tp.C, Ak])
    return np.vstack([top, bottom]), (Ad, Bd, tp.C), (Ak, Bk, Ck, Dk)


@pytest.mark.parametrize("dt", [1e-3, 1e-4])
def test_modes_are_eigenvalues_of_the_hand_built_loop(rig, ctrl, dt):
    Acl, _, _ = _hand_loop(rig, ctrl[dt], dt)
    z_hand = np.linalg.eigvals(Acl)
    lm = closed_loop_modes(rig, ctrl[dt], SPEED, THETA)
    assert np.all(np.isfinite(lm.lam)), lm.lam
    for lam in lm.lam:
        z = np.exp(lam * dt)
        # eigenvalues of modulus ~1; 1e-9 is ~1e3 x the eig round-off of a 328-state matrix
        assert np.min(np.abs(z_hand - z)) < 1e-9, (lam, dt)


def test_sensitivity_equals_direct_inverse(rig, ctrl):
    dt = 1e-4
    _, (Ad, Bd, C), (Ak, Bk, Ck, Dk) = _hand_loop(rig, ctrl[dt], dt)
    lm = closed_loop_modes(rig, ctrl[dt], SPEED, THETA)
    f = np.array([3.0, 60.0, 140.0, 400.0, 1026.0, 2500.0])
    got = lm.sensitivity_diag(f)
    for i, fk in enumerate(f):
        z = np.exp(2j * np.pi * fk * dt)
        G = C @ np.linalg.solve(z * np.eye(Ad.shape[0]) - Ad, Bd)
        K = Ck @ np.linalg.solve(z * np.eye(Ak.shape[0]) - Ak, Bk) + Dk
        S = np.linalg.inv(np.eye(4) - G @ K)
        np.testing.assert_allclose(got[i], np.abs(np.diag(S)), rtol=1e-7)


def test_log_decrement_identities(rig, ctrl):
    lm = closed_loop_modes(rig, ctrl[1e-4], SPEED, THETA)
    lam = lm.lam
    zeta = -lam.real / np.abs(lam)
    np.testing.assert_allclose(log_decrement(lam), 2 * np.pi * zeta / np.sqrt(1 - zeta**2),
                               rtol=1e-12)
    np.testing.assert_allclose(log_decrement(lam), -2 * np.pi * lam.real / lam.imag,
                               rtol=1e-12)
    # log dec is the log of the ratio of successive peaks of the free decay
    t_period = 2 * np.pi / lam.imag
    np.testing.assert_allclose(log_decrement(lam), np.log(np.abs(
        np.exp(lam * 0.0) / np.exp(lam * t_period))), rtol=1e-12)


def test_bending_modes_above_nyquist_are_not_aliased(rig, ctrl):
    """At 1 kHz the first bending modes (~1.0 and 1.3 kHz) lie above Nyquist; the
    continuous equivalent is put back on the branch of the open-loop mode. The frequencies
    must agree with the 10 kHz loop, where they are below Nyquist (the controllers differ,
    but the bending modes hardly couple to them: 1 % tolerance)."""
    slow = closed_loop_modes(rig, ctrl[1e-3], SPEED, THETA).lam
    fast = closed_loop_modes(rig, ctrl[1e-4], SPEED, THETA).lam
    b = [MODE_LABELS.index("bending 1 (lower)"), MODE_LABELS.index("bending 1 (upper)")]
    assert np.all(slow[b].imag / (2 * np.pi) > 500.0)
    np.testing.assert_allclose(slow[b].imag, fast[b].imag, rtol=0.01)


def test_required_separation_margin_formula():
    # AF = 1/(2 zeta): zeta 0.1 -> AF 5 -> 17 (1 - 1/3.5) = 12.14 % below, 22.14 % above
    got = required_separation_margin(np.array([0.1, 0.1, 0.25]), np.array([True, False, True]))
    np.testing.assert_allclose(got, [17 * (1 - 1 / 3.5), 10 + 17 * (1 - 1 / 3.5), 0.0])


def _empty_recording(rig, ctrl, dt):
    z = np.zeros((4, 4))
    return make_recording(z, z, {"eta": z}, dt, ctrl[dt], speed_rpm=SPEED, rig=rig)


def test_quantities_at_a_single_draw_are_the_model_values(rig, ctrl):
    rec = _empty_recording(rig, ctrl, 1e-4)
    r = physical_quantities(Draws(tuple(THETA), [list(THETA.values())]), rec, [SPEED])
    q = r.quantities
    assert q["bearing By: ks"].value == pytest.approx(rig.ks * (1 - THETA["k_By"]))
    assert q["bearing By: c"].value == pytest.approx(THETA["c_By"] * rig.c_ref)
    assert q["bearing Ax: ks"].value == rig.ks and not q["bearing Ax: ks"].estimated
    lm = closed_loop_modes(rig, ctrl[1e-4], SPEED, THETA)
    f = q[f"bending 1 (lower): frequency @ {SPEED:.0f} rpm"]
    assert f.lo == f.hi == pytest.approx(lm.lam[4].imag / (2 * np.pi))
    sm = q["bending 1 (lower): separation margin"].value
    assert sm == pytest.approx(100 * abs(f.value - SPEED / 60) / (SPEED / 60))
    ld = [q[f"{m}: log dec @ {SPEED:.0f} rpm"].value for m in MODE_LABELS]
    assert q[f"minimum log dec @ {SPEED:.0f} rpm"].value == pytest.approx(min(ld))


def test_the_pool_of_threads_gives_the_serial_answers_to_the_bit(rig, ctrl, monkeypatch):
    """The points run in a pool of threads (threads.pool_threads): two threads and one give
    the same quantities, value and interval, to the bit."""
    rec = _empty_recording(rig, ctrl, 1e-3)
    draws = Draws(("k_By", "c_Bx"), 0.05 * np.random.default_rng(3).standard_normal((12, 2)))
    got = {}
    for n in ("1", "2"):
        monkeypatch.setenv("BAYES_AMB_POOL", n)
        q = physical_quantities(draws, rec, [0.9 * SPEED, SPEED], model="reduced").quantities
        got[n] = {k: (v.value, v.lo, v.hi) for k, v in q.items()}
    assert got["1"].keys() == got["2"].keys()
    for k, a in got["1"].items():
        assert np.array_equal(a, got["2"][k], equal_nan=True), k


def test_bad_speeds_are_rejected(rig, ctrl):
    rec = _empty_recording(rig, ctrl, 1e-3)
    with pytest.raises(BayesAmbError, match="speeds"):
        physical_quantities(Draws(("k_By",), [[0.1]]), rec, [-5.0], model="reduced")


def _laplace_draws(rec, names, n, seed):
    """Draws of a MAP-only identification, through the path a report takes (draws_from on
    the result: summary.json's Laplace mean and covariance)."""
    res = identify(rec, names, options=IdentifyOptions(map_only=True))
    return draws_from(res, n, seed)


def test_laplace_draws_keep_the_correlations():
    """A MAP-only summary's "laplace_cov" is what draws_from samples: the sample
    correlation of 4000 draws is within 4/sqrt(4000) = 0.063 of rho = -0.9 (its sd is
    (1 - rho^2)/sqrt(n) = 0.003, so the bound is loose); without it the draws were
    independent (rho 0)."""
    cov = [[0.01**2, -0.9 * 0.01 * 0.02], [-0.9 * 0.01 * 0.02, 0.02**2]]
    from bayes_amb.results import Identification, Posterior

    par = {n: Posterior(mean=m, sd=s, hdi90=[m - 2 * s, m + 2 * s], unit="-",
                        physical_mean=m, physical_hdi90=[m - 2 * s, m + 2 * s])
           for n, m, s in (("k_By", 0.3, 0.01), ("c_By", 0.2, 0.02))}
    src = Identification.from_dict(
        {"package_version": "test", "parameters_estimated": ["k_By", "c_By"], "priors": {},
         "map": {"k_By": 0.3, "c_By": 0.2}, "inference": "MAP with Laplace approximation",
         "parameters": par, "converged": True,
         "laplace_cov": {"names": ["k_By", "c_By"], "theta": cov}})
    src = dataclasses.replace(src, names=("k_By", "c_By"))
    th = draws_from(src, 4000, seed=1).theta
    assert np.corrcoef(th.T)[0, 1] == pytest.approx(-0.9, abs=0.063)
    np.testing.assert_allclose(th.std(axis=0), [0.01, 0.02], rtol=4 / np.sqrt(2 * 4000))


def coverage(n_rec: int, model: str, n_draws: int, names: tuple[str, ...] = ("k_By",),
             dt: float = 1e-3, duration: float = 0.5):
    """Per derived quantity: did its 90 % interval cover the truth, one bool per recording."""
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, dt), rig)
    hits: dict[str, list[bool]] = {}
    for seed in range(n_rec):
        cfg = SimulationConfig(truth="reduced", params=THETA, dt=dt, duration=duration,
                               noise_rms=3e-7, seed=100 + seed)
        rec, _ = simulate_recording(rig, ctrl, cfg)
        draws = _laplace_draws(rec, names, n_draws, seed)
        post = physical_quantities(draws, rec, [SPEED], model=model)
        true = physical_quantities(Draws(names, [[THETA[n] for n in names]]), rec, [SPEED],
                                   model=model)
        for k, q in post.quantities.items():
            t = true.quantities[k].value
            if not q.estimated or not np.isfinite(t) or (q.lo == q.hi == t):
                continue                        # not a function of theta: nothing to cover
            hits.setdefault(k, []).append(q.covers(t))
    return hits


N_REC = 30
MIN_HITS = 26
"""The issue's target, ">= 85 % of 30" per quantity, asserted at fixed seeds (the test is
deterministic). Hits of a calibrated 90 % interval are Binomial(30, 0.9) per quantity:
P(hits <= 25) = 0.175, so on a fresh seed set a calibrated interval misses this bound for
a given quantity about one time in six, and all of the ~8 distinct functions of (k_By,
c_By) pass together only ~20-35 % of the time. The bound is therefore not a 1 % test of
calibration (that would be hits <= 22, P = 0.008); it is a regression guard that these
seeds pass with a margin of 0-2 hits, and it can fail: an interval with true coverage 0.8
passes it with probability 0.26 per quantity, and the plain equal-tailed interval fails it
here (rigid 3's frequency and separation margin 23/30). A change of seeds, draws or sampler
that drops one quantity to 25/30 is not by itself evidence of miscalibration; look at
test_interval_is_calibrated_on_the_rigid_3_ridge (1000 posteriors) before moving the
bound."""


def test_intervals_cover_the_truth_in_30_recordings():
    """Reduced truth, k_By = 0.3, c_By = 0.2, 0.5 s at 1 kHz, sensor noise 0.3 um; k_By and
    c_By estimated (MAP + Laplace with correlations: 1000 draws through draws_from as a
    report takes them, thinned evenly to physical_quantities' default 200), quantities from
    the reduced plant with their interval (interval90: the equal-tailed interval widened to
    the quantity's range over the central region). Every quantity that depends on theta:
    >= 26 of 30 (MIN_HITS); mean over the quantities >= 85 %.

    Measured (23 s on 2 idle cores, about 4 min on a loaded one): 23 quantities, all
    26-28/30, mean 89.9 %; rigid 3 frequency and separation margin 28/30.
    With the equal-tailed interval alone (before): rigid 3 frequency and separation margin
    23/30, the others 26-27/30, mean 87.1 %. Rigid 3 is not mislabelled: by eigenvalue
    continuation the modes keep their frequency order over the whole posterior
    (test_rigid_modes_keep_their_frequency_order), and relabelling every 10th draw by MAC
    against the posterior median's modes changed no label in any of the 30 recordings. Its
    frequency sits next to a ridge: rigid 3 and 4 veer near an exceptional point at (k_By,
    c_By) = (0.27, 0.16) (eigenvectors MAC 0.96 at the truth), and at k_By = 0.3 rigid 3's
    frequency peaks at c_By = 0.19 (146.71 Hz; truth 146.66 Hz). Every posterior draw away
    from the ridge gives a lower value, so the 7 misses of the equal-tailed interval all had
    the truth above it; it covers 85-86 % even under an exactly calibrated posterior
    (test_interval_is_calibrated_on_the_rigid_3_ridge), the interval used now 91-92 %.

    Earlier, with k_By and c_By estimated: 24-28/30. The likelihood's prewhitening
    FIR was designed from eps, whose low band is S(theta) x, and leakage left 1.39 x the
    modelled residual power in the 0-35 Hz bins (test_forward.py): c_By's z-scores had sd
    1.22 (1.06 now). The minimum log dec took the quantiles of the per-draw minimum, biased
    low where two modes tie (25/30, 27/30 now). The Laplace intervals agree with emcee: on
    seeds 0, 1, 9, 24, 26 the emcee 90 % interval of c_By was within 0.004 of MAP +- 1.645 sd.
    """
    hits = coverage(N_REC, "reduced", 1000, ("k_By", "c_By"), duration=0.5)
    assert len(hits) >= 20
    low = {k: f"{np.sum(v)}/{len(v)}" for k, v in hits.items()
           if len(v) < N_REC or np.sum(v) < MIN_HITS}
    assert not low, low
    assert np.mean([np.mean(v) for v in hits.values()]) >= 0.85


def test_interval_of_a_monotone_quantity_is_the_image_of_the_parameter_interval(rig, ctrl):
    """ks = ks_nom (1 - theta) is monotone in the one parameter: its 90 % interval must be
    the image of [min(q05, m - z s), max(q95, m + z s)] of theta exactly (m, s the draws'
    mean and sd, z = 1.645: with one parameter the central region is that interval and its
    edge points are its ends), and the frequency of the first rigid mode (monotone in k_By
    near the nominal) must lie between its values at those ends."""
    rec = _empty_recording(rig, ctrl, 1e-3)
    th = np.random.default_rng(3).normal(0.3, 0.05, size=(200, 1))
    r = physical_quantities(Draws(("k_By",), th), rec, [SPEED], model="reduced")
    m, s = th[:, 0].mean(), th[:, 0].std(ddof=1)
    q05, q95 = np.quantile(th[:, 0], [0.05, 0.95])
    lo_th, hi_th = min(q05, m - 1.6448536269514722 * s), max(q95, m + 1.6448536269514722 * s)
    ks = r.quantities["bearing By: ks"]
    assert ks.lo == pytest.approx(rig.ks * (1 - hi_th), rel=1e-12)
    assert ks.hi == pytest.approx(rig.ks * (1 - lo_th), rel=1e-12)
    assert r.region.edge.shape == (np.sum(np.abs(th[:, 0] - m) > 1.6448536269514722 * s), 1)
    ends = [closed_loop_modes(rig, ctrl[1e-3], SPEED, {"k_By": v}, "reduced").lam[0].imag
            / (2 * np.pi) for v in (lo_th, hi_th)]
    f1 = r.quantities[f"rigid 1: frequency @ {SPEED:.0f} rpm"]
    assert min(ends) - 1e-3 <= f1.lo <= f1.hi <= max(ends) + 1e-3   # Hz
    assert f1.lo < f1.hi


def test_interval_reaches_a_maximum_that_the_quantiles_miss():
    """A quantity with a maximum inside the central region (1 - theta_2^2 at theta = 0):
    the 95 % quantile of its draws stays below 1, the interval reaches 1 to within the
    edge point's distance; and a linear quantity's interval holds the equal-tailed one."""
    th = np.random.default_rng(0).standard_normal((400, 2))
    reg = central_region(th)
    v = 1.0 - th[:, 1] ** 2
    lo, hi = interval90(v, reg.inside, 1.0 - reg.edge[:, 1] ** 2)
    assert np.quantile(v, 0.95) < 0.999 and hi > 0.999
    lin = th @ [1.0, 2.0]
    lo, hi = interval90(lin, reg.inside, reg.edge @ [1.0, 2.0])
    q05, q95 = np.quantile(lin, [0.05, 0.95])
    # widened only by the sampling error of the quantiles (sd/sqrt(400) scale), here < 5 %
    assert lo <= q05 and hi >= q95 and (hi - lo) < 1.05 * (q95 - q05)


@pytest.mark.parametrize(("inside", "edge", "match"), [
    (np.ones(3, bool), None, "inside has shape"),
    (np.ones(4, bool), np.zeros((2, 3)), "edge_values has shape"),
])
def test_interval_rejects_mismatched_shapes(inside, edge, match):
    with pytest.raises(BayesAmbError, match=match):
        interval90(np.zeros((4, 2)), inside, edge)


def test_central_region_needs_p_plus_2_draws():
    """With fewer draws than p + 2 the covariance is not estimable: nothing inside, no
    edge, so the interval is the equal-tailed one."""
    reg = central_region(np.arange(6.0).reshape(3, 2))
    assert not reg.inside.any() and reg.edge.shape == (0, 2)
    v = np.array([1.0, 5.0, 3.0])
    np.testing.assert_allclose(interval90(v, reg.inside, v[:0]), np.quantile(v, [0.05, 0.95]))


def test_interval_is_calibrated_on_the_rigid_3_ridge(rig, ctrl):
    """Rigid 3's frequency on the reduced plant at 1 kHz peaks on a ridge beside the truth
    (k_By, c_By) = (0.3, 0.2) (146.66 Hz; 146.71 Hz at c_By = 0.19). Over 1000 simulated
    calibrated posteriors (MAP ~ N(truth, C), 200 draws ~ N(MAP, C), C = diag(0.0032,
    0.0176)^2, the coverage test's Laplace sd), with the frequency interpolated on a grid of
    the exact function, the interval covers the truth in 0.9 +- 3 binomial sd (0.872 to
    0.928) or a little more, while the equal-tailed interval undercovers.

    Measured: interval 0.909, equal-tailed 0.851; with 2000 posteriors, every rigid mode's
    frequency and damping ratio and ks at 0.896-0.944 (equal-tailed 0.850-0.923), widths
    +3 % (+9 % for rigid 3 and 4). The image of the joint 90 % region (chi-square, 2 dof)
    would cover 0.977 and the upper bound 0.96 fails it. Grid 41 x 73; 1 s."""
    from scipy.interpolate import RegularGridInterpolator

    K, C = np.linspace(0.27, 0.33, 41), np.linspace(0.06, 0.34, 73)
    f3 = np.array([[closed_loop_modes(rig, ctrl[1e-3], SPEED, {"k_By": k, "c_By": c},
                                      "reduced").lam[2].imag / (2 * np.pi) for c in C]
                   for k in K])
    f = RegularGridInterpolator((K, C), f3, bounds_error=False, fill_value=None)
    truth, sd = np.array([0.3, 0.2]), np.array([0.0032, 0.0176])
    t = float(f(truth[None])[0])
    rng = np.random.default_rng(5)
    hit, hit_et, n = 0, 0, 1000
    for _ in range(n):
        th = truth + sd * rng.standard_normal(2) + sd * rng.standard_normal((200, 2))
        v, reg = f(th), central_region(th)
        lo, hi = interval90(v, reg.inside, f(reg.edge))
        hit += lo <= t <= hi
        q05, q95 = np.quantile(v, [0.05, 0.95])
        hit_et += q05 <= t <= q95
    band = 3 * np.sqrt(0.9 * 0.1 / n)
    assert 0.9 - band <= hit / n <= 0.96, hit / n
    assert hit_et / n < 0.9 - band, hit_et / n


def test_rigid_modes_keep_their_frequency_order(rig, ctrl):
    """Naming the rigid modes by ascending frequency gives each draw the mode that eigenvalue
    continuation gives it, over the region the coverage test's posteriors cover (k_By 0.28
    to 0.32, c_By 0.11 to 0.33): stepping c_By by 0.005 moves the modes by at most ~5 rad/s,
    less than half the smallest distance of rigid 3 and 4 (measured 19 rad/s, at k_By 0.28,
    c_By 0.17), so nearest-eigenvalue tracking from step to step is unambiguous and must
    keep the frequency order. Mode shapes cannot do it here: the two
    eigenvectors have MAC 0.96 at the truth (they veer near an exceptional point at about
    (0.27, 0.16), outside the region)."""
    for k in (0.28, 0.30, 0.32):
        prev = None
        for c in np.arange(0.11, 0.3325, 0.005):
            lam = closed_loop_modes(rig, ctrl[1e-3], SPEED, {"k_By": k, "c_By": c},
                                    "reduced").lam[:4]
            assert np.all(np.diff(lam.imag) > 0), (k, c, lam)
            if prev is not None:
                dist = np.abs(lam[:, None] - prev[None, :])       # (new, previous)
                step = np.diag(dist).max()
                gap = min(np.abs(lam[2] - lam[3]), np.abs(prev[2] - prev[3]))
                assert step < gap / 2, (k, c, step, gap)
                assert np.array_equal(np.argmin(dist, axis=1), np.arange(4)), (k, c)
            prev = lam


def test_rigid_modes_are_the_regulator_poles(rig, ctrl):
    """The reference controller is observer-based, designed on the 8-state reduced model at
    31500 rpm. By the separation principle that model's closed loop has the eigenvalues of
    A + B F (regulator) and A + L C (observer, near Nyquist), so the four rigid-body modes
    of the reduced plant at theta = 0 are eig(A + B F) (identity: measured 7e-14 relative,
    checked to 1e-9). The full plant adds the bending modes the design left out;
    they move the regulator poles by 0.16-2.0 % (measured), checked against 3 %. The mode
    that the displacement rule took for rigid 1 (the second bending pair's forward whirl,
    3094.6 Hz aliased to 94.5 Hz, zeta 0.23) is 63 % away from the nearest regulator pole,
    and the labels behind it were shifted by one (rigid 2 18 %, rigid 4 7 % away)."""
    c = ctrl[1e-3]
    A, B = (np.asarray(c.design["plant"][k]) for k in ("A", "B"))
    lam = np.log(np.linalg.eigvals(A + B @ np.asarray(c.design["F"])).astype(complex)) / c.dt
    lam = lam[lam.imag > 0]
    lam = lam[np.argsort(lam.imag)]
    assert lam.size == 4, lam
    red = closed_loop_modes(rig, c, SPEED, {}, "reduced").lam[:4]
    np.testing.assert_allclose(red, lam, rtol=1e-9)
    full = closed_loop_modes(rig, c, SPEED, {}, "full").lam[:4]
    assert np.all(np.abs(full - lam) / np.abs(lam) < 0.03), (full, lam)


def test_rigid_mode_curves_are_continuous_in_the_paper_case(rig, ctrl):
    """The paper case (k_By = 0.5, reference controller at 1 ms, full plant), over the
    report figure's speeds 0.8-1.05 x 31500 rpm on a grid of 33 (h = 246 rpm): four
    rigid-body modes at every speed, and no label jumps.

    The bound: numbered by frequency, each label is the k-th smallest of the continuous
    eigenvalue branches, hence continuous in speed, moving over one grid step by at most
    the fastest branch's slope times h. At a crossing a label takes over the slope of a
    branch that another label had, so the slopes available are those the steps of all
    four labels show at the adjacent grid intervals. A step may therefore not exceed twice
    the largest step of any label on the interval before or after it; the factor 2 leaves
    room for the slopes changing over 3 h (measured: at most 1.09 x, rigid 2 at 27500 rpm).
    A label that changes branch moves by the gap between branches instead: under the
    displacement rule, the aliased second bending mode entered as rigid 1 between 29900 and
    30100 rpm, a step of 40 Hz against adjacent steps of at most 2.3 Hz (17 x)."""
    speeds = np.linspace(0.8, 1.05, 33) * SPEED
    f = np.array([closed_loop_modes(rig, ctrl[1e-3], s, {"k_By": 0.5}).lam[:4].imag
                  for s in speeds]) / (2 * np.pi)
    assert np.all(np.isfinite(f)), speeds[~np.isfinite(f).all(axis=1)]
    step = np.abs(np.diff(f, axis=0))                     # (32, 4) Hz
    largest = step.max(axis=1)
    adjacent = np.maximum(np.r_[0.0, largest[:-1]], np.r_[largest[1:], 0.0])
    bad = step > 2 * adjacent[:, None]
    assert not bad.any(), [(speeds[i + 1], k + 1, step[i, k], adjacent[i])
                           for i, k in zip(*np.nonzero(bad), strict=True)]
