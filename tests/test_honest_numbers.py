"""Issue 27 pieces: the model-error scale, the linearity check and the adequacy line."""

from types import SimpleNamespace

import numpy as np
import pytest

from bayes_amb.discrepancy.adequacy import judge
from bayes_amb.discrepancy.checks import Check
from bayes_amb.discrepancy.linearity import flat_tops
from bayes_amb.discrepancy.model_error import _fit_tau


@pytest.mark.parametrize("tau", [0.0, 0.05, 0.3])
def test_model_error_scale_is_recovered(tau):
    """Type-II ML of tau from estimates with known sampling precision: 40 bands of 32
    coordinates; the sd of log tau-hat is about 1/sqrt(2 * 1280 * share of the variance
    that is tau's), so +-30 % is > 5 sd where tau dominates; tau = 0 stays below the noise."""
    rng = np.random.default_rng(5)
    h = [rng.uniform(50.0, 5000.0, 32) for _ in range(40)]
    z2 = [rng.normal(0.0, np.sqrt(tau**2 / 2 + 1 / hb)) ** 2 for hb in h]
    est = _fit_tau(z2, h)
    if tau == 0:
        assert est < 0.02
    else:
        assert abs(est / tau - 1) < 0.3


def test_flat_tops_find_a_clipped_current_and_not_a_noisy_one():
    rng = np.random.default_rng(1)
    y = rng.normal(0, 1e-6, (5000, 4))
    u = rng.normal(0, 0.2, (5000, 4))
    assert flat_tops(SimpleNamespace(u=u, y=y)) == []
    u[:, 2] = np.clip(u[:, 2], -0.3, 0.3)           # 13 % of the samples beyond +-1.5 sd
    found = flat_tops(SimpleNamespace(u=u, y=y))
    assert len(found) == 1 and found[0].startswith("u_Bx")


def _checks(*failed):
    cs = tuple(Check(n, n not in failed, n) for n in ("excitation", "controller", "linearity"))
    return SimpleNamespace(checks=cs, failed=list(failed))


def _loc(detected):
    return SimpleNamespace(detected=detected, channels=["Ax"] if detected else [],
                           bands_hz=[[120.0, 450.0]] if detected else [],
                           evidence={"strength": "strong"})


def test_adequacy_line_says_what_was_found():
    a = judge(_checks(), _loc(False), 0.3)
    assert a.adequate and a.line.startswith("model adequate")
    a = judge(_checks(), _loc(True), 0.3)
    assert not a.adequate and "120-450 Hz" in a.line and "diagnose" in a.line
    assert a.channels == ["Ax"]
    a = judge(_checks("linearity"), _loc(False), 0.3)
    assert not a.adequate and a.failed == ["linearity"] and a.nonlinear
    assert "not linear" in a.line and "unreliable" in a.line
    a = judge(_checks("controller"), _loc(False), 0.3)
    assert not a.adequate and not a.nonlinear and "NOT assessed" in a.line
    a = judge(_checks(), _loc(True), 1e-9)                    # rounding, not a mismatch
    assert a.adequate and "rounding" in a.line


def test_rig_file_limits_are_a_linearity_data_check():
    """Issue 27: the rig file's [limits] (amplifier current, slew rate, probe range) fail
    the linearity check on a record that reaches them on >= 0.1 % of the samples."""
    from bayes_amb.discrepancy.linearity import limit_hits
    rng = np.random.default_rng(2)
    u = rng.normal(0, 0.2, (20000, 4))
    y = rng.normal(0, 1e-5, (20000, 4))
    rec = SimpleNamespace(u=u, y=y, dt=1e-4, rig=SimpleNamespace(limits={}))
    assert limit_hits(rec) == []
    # 0.6 A is 3 sd: 0.27 % of the samples of each channel reach it
    rec.rig.limits = {"current_a": 0.6}
    hits = limit_hits(rec)
    assert len(hits) == 4 and all("limits.current_a" in h for h in hits)
    rec.rig.limits = {"current_a": 1.0}                     # 5 sd: none
    assert limit_hits(rec) == []
    rec.rig.limits = {"sensor_range_m": 3.5e-5}             # 3.5 sd: 0.05 %, below 0.1 %
    assert limit_hits(rec) == []
    y[:50, 1] = 3.5e-5                                      # a probe at its range end
    assert [h.split()[0] for h in limit_hits(rec)] == ["y_Ay"]
    rec.rig.limits = {"slew_a_per_s": 0.2 * np.sqrt(2) * 3 / 1e-4}
    assert all("du/dt" in h for h in limit_hits(rec)) and len(limit_hits(rec)) == 4


def test_rig_file_limits_are_read_and_checked():
    from bayes_amb.errors import RigError
    from bayes_amb.rig import load_rig
    from bayes_amb.rig.rig import rig_from_dict
    d = load_rig().to_dict()
    rig = rig_from_dict({**d, "limits": {"current_a": 2.0, "sensor_range_m": 4e-4}})
    assert rig.limits == {"current_a": 2.0, "sensor_range_m": 4e-4}
    assert rig_from_dict(rig.to_dict()).limits == rig.limits
    for bad, field in (({"current": 2.0}, "limits.current"),
                       ({"current_a": -1.0}, "limits.current_a"),
                       ({"slew_a_per_s": "fast"}, "limits.slew_a_per_s")):
        with pytest.raises(RigError, match=field.replace(".", r"\.")):
            rig_from_dict({**d, "limits": bad})


def _toy_loop(seed: int, theta0_of_f=None):
    """A linear toy of the loop for model_error: Y = (1 + t0 + i t1 f/f_max) X on four
    channels, white noise of known variance, the exact least-squares MAP and its Laplace
    covariance. theta0_of_f, when given, is the truth's t0 per bin (a missing physics that
    makes the bands want different values)."""
    from types import SimpleNamespace as NS
    rng = np.random.default_rng(seed)
    nf, n, dt, sigma = 600, 1200, 1e-3, 0.05
    k = np.arange(1, nf + 1)
    X = (rng.normal(size=(nf, 4)) + 1j * rng.normal(size=(nf, 4))) / np.sqrt(2)
    F = np.stack([np.ones(nf), 1j * k / nf], axis=1)               # (nf, 2)
    t_true = np.array([0.05, 0.1])
    t0 = np.full(nf, t_true[0]) if theta0_of_f is None else theta0_of_f(k / (n * dt))
    E = (1 + t0[:, None] + t_true[1] * F[:, 1:2]) * X
    E += sigma * (rng.normal(size=E.shape) + 1j * rng.normal(size=E.shape)) / np.sqrt(2)

    def residual_dft(rows):
        rows = np.atleast_2d(rows)
        Y = (1 + (rows[:, None, :2] * F[None]).sum(-1))[..., None] * X[None]
        return E[None] - Y, np.ones(len(rows), bool)

    J = -(F[:, None, :] * X[:, :, None])                             # (nf, 4, 2)
    H = 2 * np.einsum("kci,kcj->ij", J.conj(), J).real / sigma**2
    g = 2 * np.einsum("kci,kc->i", J.conj(), residual_dft(np.zeros(3))[0][0]).real / sigma**2
    theta = -np.linalg.solve(H, g)
    cov = np.zeros((3, 3))
    cov[:2, :2] = np.linalg.inv(H)
    cov[2, 2] = 1e-4
    like = NS(residual_dft=residual_dft, X=X, k=k, n=n, forward=NS(dt=dt),
              starts=np.array([0]), counts=np.array([nf]),
              curvature_weights=lambda th, ls: np.eye(4)[None] / sigma**2)
    return like, np.array([*theta, np.log10(sigma)]), cov


def test_band_sandwich_is_one_on_a_right_model_and_wide_on_a_wrong_one():
    """On a right model the leverage-corrected band sandwich's squared sd ratio averages 1
    (4 standard errors of the mean over 60 seeds, for the stiffness-like t0 informed
    evenly and the damping-like t1 informed by the top bands); a truth whose t0 jumps by
    0.1 across the band makes the bands disagree and the sandwich widen t0 several-fold,
    and the reported covariance is never narrower than the discrepancy's."""
    from bayes_amb.discrepancy.model_error import model_error
    names = ("t0", "t1")
    r2 = {"t0": [], "t1": []}
    for seed in range(60):
        like, x, cov = _toy_loop(seed)
        me = model_error(like, x, 2, cov, names, robust=True)
        for n in names:
            r2[n].append(me.sandwich_ratio[n] ** 2)
        if seed == 0:
            assert model_error(like, x, 2, cov, names).sandwich_ratio is None
    for n in names:
        v = np.array(r2[n])
        assert abs(v.mean() - 1) < 4 * v.std() / np.sqrt(v.size), n

    like, x, cov = _toy_loop(0, lambda f: np.where(f < 100, 0.1, 0.0))
    plain_fit = model_error(like, x, 2, cov, names)
    me = model_error(like, x, 2, cov, names, robust=True)
    assert me.sandwich_ratio["t0"] > 3
    assert np.linalg.eigvalsh(me.cov[:2, :2] - plain_fit.cov[:2, :2]).min() > -1e-12
    assert me.sd_ratio["t0"] >= max(plain_fit.sd_ratio["t0"], 0.999 * me.sandwich_ratio["t0"])
