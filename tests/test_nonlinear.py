"""The magnets' force law and the amplifier's slew limit as transforms of the recorded
signals (discrepancy/nonlinear.py): the laws themselves, and the screen's decision on
records whose nonlinearity is known."""

from __future__ import annotations

import numpy as np
import pytest

from bayes_amb.discrepancy.nonlinear import (
    force_law_defect,
    force_law_regressors,
    nonlinear_part,
    slew_defect,
)
from bayes_amb.planning.plan import magnet_range_note
from bayes_amb.rig import load_rig
from bayes_amb.rig.force_law import actuator_displacement


@pytest.fixture(scope="module")
def rig():
    return load_rig()


def _saturating_at_b(rig, bias: float = 2.0, ratio: float = 1.5):
    """The reference rig with bearing B's magnets given a bias current and an iron that
    saturates at ``ratio`` times the bias flux density (A linear)."""
    from bayes_amb.rig.rig import rig_from_dict
    d = rig.to_dict()
    bt = d["bearings"]
    ki, ks = bt.pop("ki"), bt.pop("ks")
    bt["A"] = {**bt["A"], "ki": ki, "ks": ks}
    bt["B"] = {**bt["B"], "ki": ki, "ks": ks, "bias_current": bias, "saturation_ratio": ratio}
    return rig_from_dict(d)


def test_force_law_defect_is_the_cubic_expansion_for_small_signals(rig):
    """d = N / ki with N = F0 (4 xi iota^2 + 12 iota xi^2 + 8 xi^3) + O(5th order), i.e.
    d = (x u^2 / rho + 3 u x^2 + 2 rho x^3) / g0^2 (module docstring)."""
    rng = np.random.default_rng(0)
    g0 = 4e-4
    rho = rig.magnets["A"].ks / rig.magnets["A"].ki
    i0 = rho * g0
    u = 0.01 * i0 * rng.standard_normal((2000, 4))
    x = 0.01 * g0 * rng.standard_normal((2000, 4))
    u -= np.median(u, axis=0)
    x -= np.median(x, axis=0)
    d = force_law_defect(rig, u, x, {"A": g0, "B": g0})
    cubic = (x * u ** 2 / rho + 3 * u * x ** 2 + 2 * rho * x ** 3) / g0 ** 2
    # fifth-order terms: relative (4 sd of 1 %)^2 times a coefficient of a few
    assert np.max(np.abs(d - cubic)) < 1e-2 * np.max(np.abs(cubic))
    # and the exact law is the differential pair's force beyond ki i + ks x
    i, xx = u[:, 0], x[:, 0]
    F0 = rig.magnets["A"].ki * i0 / 4
    f = F0 * ((1 + i / i0) ** 2 / (1 - xx / g0) ** 2 - (1 - i / i0) ** 2 / (1 + xx / g0) ** 2)
    lin = rig.magnets["A"].ki * i + rig.magnets["A"].ks * xx
    np.testing.assert_allclose(d[:, 0], (f - lin) / rig.magnets["A"].ki, rtol=1e-8,
                               atol=1e-12 * np.max(np.abs(f)))
    # a bearing without a gap is linear
    assert np.all(force_law_defect(rig, u, x, {"A": g0})[:, 2:] == 0)


def test_force_law_regressors_hold_no_linear_part(rig):
    """The screen's regressors are free of [1, u, x] per channel: the probes' noise in x
    (which the residual also holds) cannot make them significant."""
    rng = np.random.default_rng(1)
    u, x = rng.standard_normal((3000, 4)), 1e-5 * rng.standard_normal((3000, 4))
    h = force_law_regressors(rig, u, x)
    for b, cols in (("A", [0, 1]), ("B", [2, 3])):
        other = [c for c in range(4) if c not in cols]
        assert np.all(h[b][:, other] == 0)
        for c in cols:
            Z = np.column_stack([np.ones(3000), u[:, c] - np.median(u[:, c]),
                                 x[:, c] - np.median(x[:, c])])
            assert np.max(np.abs(Z.T @ h[b][:, c])) < 1e-8 * np.linalg.norm(Z) * \
                np.linalg.norm(h[b][:, c])
    d = rng.standard_normal((500, 4))
    assert np.allclose(nonlinear_part(d + 3.0 * u[:500] - 2.0, u[:500], x[:500]),
                       nonlinear_part(d, u[:500], x[:500]))


def test_slew_defect_limits_the_rate_and_vanishes_for_a_fast_amplifier():
    rng = np.random.default_rng(2)
    dt = 1e-4
    u = 0.3 * np.sign(rng.standard_normal((4000, 4)))      # random binary steps of 0.6 A
    assert np.max(np.abs(slew_defect(u, 1e9, dt))) < 1e-3   # 0.6 A in 0.6 us
    rate = 2000.0                                             # 0.2 A per sample at most
    d = slew_defect(u, rate, dt)
    assert np.mean(np.abs(d) > 1e-12) > 0.5
    # a ramp that ends inside the sample: the triangle's mean rate tau^2 / (2 dt), its
    # first moment at tau / 3 from the sample's start (held samples sit at their middles)
    step = np.zeros((4, 1))
    step[2:] = 0.1                                            # 0.1 A: tau = 50 us < dt
    dd = slew_defect(step, rate, dt)[:, 0]
    tau = 0.1 / rate
    assert dd.sum() == pytest.approx(-rate * tau ** 2 / (2 * dt))
    centre = np.sum(dd * (np.arange(4) + 0.5)) / dd.sum()
    assert centre == pytest.approx(2 + tau / (3 * dt))
    assert dd[0] == 0.0 and dd[3] == 0.0
    # a step beyond the limit: held short of the command until the ramp gets there
    big = np.zeros((5, 1))
    big[1:] = 0.5                                             # 2.5 samples of ramp
    db = slew_defect(big, rate, dt)[:, 0]
    # the charge the plant misses is the ramp's triangle: 0.5 A over 2.5 samples, halved
    assert db.sum() * dt == pytest.approx(-0.5 * (0.5 / rate) / 2, rel=1e-12)


def test_actuator_displacement_is_rigid_body_kinematics(rig):
    """At the sensor planes it returns the probes; a tilt is interpolated linearly."""
    z = rig.shaft.node_z
    za, zb = z[rig.sensor_nodes["A"] - 1], z[rig.sensor_nodes["B"] - 1]
    ba, bb = z[rig.bearing_nodes["A"] - 1], z[rig.bearing_nodes["B"] - 1]
    y = np.array([[1.0, 2.0, 3.0, 5.0]])                      # Ax, Ay, Bx, By
    q = actuator_displacement(rig, y)
    slope_x, slope_y = (3.0 - 1.0) / (zb - za), (5.0 - 2.0) / (zb - za)
    np.testing.assert_allclose(q[0], [1 + slope_x * (ba - za), 2 + slope_y * (ba - za),
                                      1 + slope_x * (bb - za), 2 + slope_y * (bb - za)])


def test_plan_warns_when_the_current_leaves_the_magnets_linear_range(rig):
    """With a bias current in the rig file, a current whose (i/i0)^2 exceeds the stiffness
    interval's half-width is named, with the rms current where the range ends."""
    import dataclasses

    from bayes_amb.rig.rig import Magnet
    m = rig.magnets["A"]
    biased = dataclasses.replace(rig, magnets={
        b: Magnet(m.ki, m.ks, (("gap", 4e-4), ("bias_current", 1.6))) for b in "AB"})
    pars = {f"k_{b}{a}": {"sd": 0.002} for b in "AB" for a in "xy"}
    rng = np.random.default_rng(3)
    small = 0.05 * rng.standard_normal((5000, 4))             # (0.05/1.6)^2 = 0.1 %
    assert magnet_range_note(biased, small, pars) is None
    big = 0.4 * rng.standard_normal((5000, 4))                # 6 % > 0.33 %
    note = magnet_range_note(biased, big, pars)
    assert note is not None and "bearing A" in note and "bearing B" in note
    assert magnet_range_note(rig, big, pars) is None          # no bias in the rig file
    stated = dataclasses.replace(rig, magnets={                # bias_current beside ki, ks
        b: Magnet(m.ki, m.ks, bias=1.6) for b in "AB"})
    assert magnet_range_note(stated, big, pars) == note


@pytest.fixture(scope="module")
def foreign(tmp_path_factory):
    """A slew-limited and an effect-free record of the foreign generator (1 s), with their
    truths (read here only, for scoring)."""
    import json

    from benchmarks.foreign import draw_case, write_case
    from benchmarks.foreign.benchmark import _controller_file
    out = tmp_path_factory.mktemp("nl")
    ctrl = _controller_file(out, 1e-4)
    recs = {}
    for kind, seed in (("slew_limit", 3), ("control", 4)):
        rng = np.random.default_rng(seed)
        spec = draw_case(kind, rng, controller_file=str(ctrl), duration_s=1.0)
        paths = write_case(spec, out, kind, rng)
        recs[kind] = (paths["csv"], json.loads(paths["truth"].read_text()))
    return recs


def test_the_screen_finds_and_models_a_slew_limit_and_leaves_a_linear_record(foreign):
    """On a foreign record whose amplifiers are slew-limited the linearity check fails,
    names the slew limit (not a current limit), and its 90 % interval holds the true rate;
    on an effect-free one it passes and models nothing."""
    from bayes_amb.discrepancy.adequacy import nominal_assessment
    from bayes_amb.discrepancy.library.bearing_coefficient import BEARING_COEFFICIENTS
    from bayes_amb.io.recording import load_recording
    path, truth = foreign["slew_limit"]
    checks, _, _ = nominal_assessment(load_recording(path), BEARING_COEFFICIENTS)
    lin = next(c for c in checks.checks if c.name == "linearity")
    assert not lin.ok and lin.values["modelled"] == "slew_limit"
    rate = next(e["params"]["slew_a_per_s"] for e in truth["effects"])
    lo, hi = lin.values["nonlinearity"]["interval90"]["all"]
    assert lo <= rate <= hi and hi / lo < 1.1
    path, _ = foreign["control"]
    checks, _, _ = nominal_assessment(load_recording(path), BEARING_COEFFICIENTS)
    lin = next(c for c in checks.checks if c.name == "linearity")
    assert lin.ok and lin.values["modelled"] is None
    assert all(not s["found"] for s in lin.values["screens"])


def test_the_rig_files_bias_current_gives_the_force_law(rig):
    """bearings.bias_current beside ki and ks: read, written back, and the law's gap is
    i0 ki / ks with a 5 % sd; without it there is no law to model."""
    from bayes_amb.discrepancy.nonlinear import BIAS_REL_SD, rig_force_law
    from bayes_amb.errors import BayesAmbError
    from bayes_amb.rig.rig import rig_from_dict
    assert rig_force_law(rig) is None
    d = rig.to_dict()
    d["bearings"]["bias_current"] = 1.6
    biased = rig_from_dict(d)
    assert rig_from_dict(biased.to_dict()) == biased
    law = rig_force_law(biased)
    g0 = 1.6 * rig.ki / rig.ks
    assert law.where == ("A", "B") and law.estimate["A"] == pytest.approx(g0)
    lo, hi = law.interval90["B"]
    assert (hi - lo) / 2 == pytest.approx(1.645 * BIAS_REL_SD * g0)
    d["bearings"]["bias_current"] = -1.0
    with pytest.raises(BayesAmbError, match=r"bearings\.bias_current"):
        rig_from_dict(d)


def test_the_simulator_plays_the_law_the_rig_file_states_and_diagnosis_models_it(rig):
    """A rig file with bias_current and, at bearing B, the iron's saturation_ratio: the
    product's simulator plays the saturating law (the record differs from the linear
    rig's), and the nominal assessment models it from the same file, so its k_By covers the
    truth; read as linear, the same record passes the linearity check with k_By far off
    (what one record cannot tell without the rig file). The shipped rigs state no bias
    (their magnets' constants do not turn the law on)."""
    import dataclasses

    from bayes_amb.control.export import export_controller, reference_controller
    from bayes_amb.discrepancy.adequacy import nominal_assessment
    from bayes_amb.rig.force_law import rig_gaps
    from bayes_amb.simulate import SimulationConfig, simulate_recording
    assert rig_gaps(rig) == {} and rig_gaps(load_rig("ross_test_rig")) == {}
    saturating = _saturating_at_b(rig)
    ctrl = export_controller(reference_controller(rig, 1e-4), rig)
    cfg = SimulationConfig(truth="reduced", params={"k_By": 0.1}, amplitude=0.3,
                           duration=0.5, dt=1e-4, noise_rms=5e-8, seed=3)
    rec, _ = simulate_recording(saturating, ctrl, cfg)
    lin, _ = simulate_recording(rig, ctrl, cfg)
    assert np.max(np.abs(np.asarray(rec.y) - np.asarray(lin.y))) > 1e-3 * np.max(
        np.abs(np.asarray(lin.y)))
    checks, fit, _ = nominal_assessment(rec, ("k_By",))
    line = next(c for c in checks.checks if c.name == "linearity")
    assert line.ok and line.values["modelled"] == "rig_force_law"
    assert line.values["nonlinearity"]["saturation"] == {"B": 1.5}
    sd = float(np.sqrt(fit.cov[0, 0] + fit.extra_cov[0, 0]))
    assert abs(fit.params[0] - 0.1) < 4 * sd
    checks, blind, _ = nominal_assessment(dataclasses.replace(rec, rig=rig), ("k_By",))
    assert next(c for c in checks.checks if c.name == "linearity").ok
    assert abs(blind.params[0] - 0.1) > 4 * float(np.sqrt(blind.cov[0, 0]))


def test_a_saturating_magnet_keeps_the_rig_slopes_and_softens(rig):
    """saturation_ratio r: the law's linearisation stays ki and ks (d is third order in
    small signals), it takes force away from large currents (d opposes u at the centre,
    and odd in u there), and it tends to the unsaturated law as r grows."""
    from bayes_amb.rig.force_law import law_current
    rng = np.random.default_rng(1)
    g0 = 4e-4
    i0 = rig.magnets["A"].ks / rig.magnets["A"].ki * g0
    gaps = {"A": g0, "B": g0}
    u = i0 * rng.standard_normal((500, 4))
    x = g0 * rng.standard_normal((500, 4))
    for scale in (1e-2, 1e-3):                      # cubic: d / u falls as scale^2
        d = law_current(rig, scale * 0.1 * u, scale * 0.1 * x, gaps, {"A": 1.5, "B": 1.5})
        assert np.max(np.abs(d)) < 10 * scale ** 2 * np.max(np.abs(scale * 0.1 * u))
    big = np.linspace(-0.5, 0.5, 11)[:, None] * i0 * np.ones((1, 4))
    zero = np.zeros_like(big)
    d = law_current(rig, big, zero, gaps, {"A": 1.5, "B": 1.5})
    assert np.all(d[big > 0] < 0) and np.all(d[big < 0] > 0)      # softening
    np.testing.assert_allclose(d, -d[::-1], atol=1e-15)            # odd in u
    plain = law_current(rig, 0.2 * u, 0.01 * x, gaps, {})
    far = law_current(rig, 0.2 * u, 0.01 * x, gaps, {"A": 1e4, "B": 1e4})
    np.testing.assert_allclose(far, plain, atol=1e-6 * np.max(np.abs(0.2 * u)))


def test_the_rig_files_saturation_ratio_saturates_the_law(rig):
    """bearings.saturation_ratio beside bias_current: read, written back, carried by the
    rig's force law with its own 5 % sd (two more refits), and refused without a bias or
    at or below 1, naming the field."""
    from bayes_amb.discrepancy.nonlinear import SATURATION_REL_SD, rig_force_law
    from bayes_amb.errors import BayesAmbError
    from bayes_amb.rig.rig import rig_from_dict
    d = rig.to_dict()
    d["bearings"]["B"] = {**d["bearings"]["B"], "ki": rig.ki, "ks": rig.ks,
                          "bias_current": 1.6, "saturation_ratio": 1.8}
    d["bearings"]["A"] = {**d["bearings"]["A"], "ki": rig.ki, "ks": rig.ks}
    del d["bearings"]["ki"], d["bearings"]["ks"]
    sat = rig_from_dict(d)
    assert sat.magnets["B"].saturation == 1.8 and sat.magnets["A"].saturation is None
    assert rig_from_dict(sat.to_dict()) == sat
    law = rig_force_law(sat)
    assert law.where == ("B",) and law.saturation == {"B": 1.8}
    assert "saturating at 1.8 times the bias flux density" in law.text()
    ends = law.saturation_ends()
    assert [e["B"] for e in ends] == pytest.approx([1.8 * (1 - SATURATION_REL_SD),
                                                    1.8 * (1 + SATURATION_REL_SD)])
    assert law.to_dict()["saturation"] == {"B": 1.8}
    d["bearings"]["B"]["saturation_ratio"] = 0.9
    with pytest.raises(BayesAmbError, match=r"bearings\.B\.saturation_ratio.*not above 1"):
        rig_from_dict(d)
    del d["bearings"]["B"]["bias_current"]
    d["bearings"]["B"]["saturation_ratio"] = 1.8
    with pytest.raises(BayesAmbError, match=r"bearings\.B\.saturation_ratio.*bias_current"):
        rig_from_dict(d)


def test_plan_warns_when_the_iron_saturates_beyond_the_intervals(rig):
    """A design on a rig whose file gives B's iron saturation: plan computes how far a
    linear fit would move B's coefficients (fisher.defect_shift, through the loop) and
    names bearing B with the rms current where the linearisation ends; the move it
    predicts is within 25 % of a linear fit's own on a record of that rig; on the linear
    rig there is no such note."""
    import dataclasses

    from bayes_amb.control.export import export_controller, reference_controller
    from bayes_amb.discrepancy.adequacy import nominal_assessment
    from bayes_amb.discrepancy.nonlinear import force_law_defect
    from bayes_amb.planning.fisher import defect_shift, log10_sigma_of
    from bayes_amb.planning.plan import Design, plan
    from bayes_amb.rig.force_law import rig_gaps
    from bayes_amb.simulate import SimulationConfig, simulate_recording
    saturating = _saturating_at_b(rig)
    ctrl = export_controller(reference_controller(rig, 1e-4), rig)
    p = plan(saturating, ctrl, Design(amplitude=0.3, duration=0.5))
    note = next(n for n in p.notes if "saturation_ratio" in n)
    assert "bearing B" in note and "bearing A" not in note
    assert not any("saturation_ratio" in n for n in
                   plan(rig, ctrl, Design(amplitude=0.3, duration=0.5)).notes)
    names = ("k_Bx", "k_By")
    cfg = SimulationConfig(truth="reduced", amplitude=0.3, duration=0.5, dt=1e-4,
                           noise_rms=5e-8, seed=3)
    rec, _ = simulate_recording(saturating, ctrl, cfg)
    d = force_law_defect(saturating, np.asarray(rec.u),
                         actuator_displacement(saturating, np.asarray(rec.y)),
                         rig_gaps(saturating))
    predicted = defect_shift(rec, names, np.zeros(2), log10_sigma_of(5e-8, 0, 0), d)
    _, linear, _ = nominal_assessment(dataclasses.replace(rec, rig=rig), names)
    np.testing.assert_allclose(predicted, linear.params[:2], rtol=0.25)


def test_a_modelled_laws_spread_goes_into_the_named_model():
    """The nominal fit's extra_cov (a modelled law's or clip's uncertainty) is carried
    into the named model's coefficients, padded with zeros for the named physics' own
    parameters; a model with its own, or whose names do not start with the nominal's,
    is left alone."""
    from types import SimpleNamespace

    from bayes_amb.discrepancy.diagnose import _carry_modelled_spread
    extra = np.array([[4.0, 1.0], [1.0, 9.0]])
    nominal = SimpleNamespace(p=2, names=("k_Ax", "k_Bx"), extra_cov=extra)
    named = SimpleNamespace(p=3, names=("k_Ax", "k_Bx", "lag"), extra_cov=None)
    _carry_modelled_spread(nominal, named)
    np.testing.assert_array_equal(named.extra_cov[:2, :2], extra)
    assert named.extra_cov.shape == (3, 3) and not named.extra_cov[2].any()
    own = SimpleNamespace(p=3, names=("k_Ax", "k_Bx", "lag"), extra_cov=np.eye(3))
    _carry_modelled_spread(nominal, own)
    np.testing.assert_array_equal(own.extra_cov, np.eye(3))
    other = SimpleNamespace(p=2, names=("k_Bx", "k_Ax"), extra_cov=None)
    _carry_modelled_spread(nominal, other)
    assert other.extra_cov is None
