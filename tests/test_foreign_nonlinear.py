"""The foreign generator's nonlinear magnets and amplifiers (benchmarks/foreign): the
magnets' force law (and its saturating held-out variant), the amplifier's slew-rate limit
(and the held-out voltage-limited current loop). Each reduces to the linear loop when it
is made weak, does what its law says when it is not, and draws and writes as a case."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import scipy.linalg as sla

from bayes_amb.rig import load_rig
from benchmarks.foreign import KINDS, CaseSpec, Effect, Habits, draw_case, read_controller
from benchmarks.foreign.cases import clean_response, plant_of, simulate, write_case
from benchmarks.foreign.effects import Amplifier, magnet_law
from benchmarks.foreign.loop import closed_loop, run_segments
from tests.helpers import C_NSM, K_THETA

HABITS = dict(noise_rms_m=5e-8, noise_ar=0.7, sensor_offset_m=(1e-6, -2e-6, 0.0, 3e-6),
              amp_offset_a=(0.02, 0.0, -0.01, 0.0), r2_rms_a=0.01, burn_in_s=0.05,
              mains_m={50.0: 3e-8})


def _spec(controller_file, duration_s=0.2, **habits):
    return CaseSpec(k_theta=K_THETA, c_nsm=C_NSM, duration_s=duration_s,
                    habits=Habits(**{"noise_rms_m": 5e-8, **habits}),
                    controller_file=controller_file)


def _law(gap, where="all"):
    return Effect("magnet_force_law", {"gap_m": gap, "where": where})


def _slew(S):
    return Effect("slew_limit", {"slew_a_per_s": S, "recorded": "command",
                                 "limited_share_target": 0.1})


def _rel(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


# ------------------------------------------------------------------ force law
def test_a_huge_gap_gives_the_linear_record(controller_file):
    """All habits on: the remainder shrinks as 1/g0^2; at 1 m it is ~1e-9 of the force
    (rotor um, currents 0.3 A against i0 = 4000 A), at 1 km the record is the linear one
    to rounding."""
    spec = _spec(controller_file, **HABITS)
    runs = {g: simulate(replace(spec, effects=() if g is None else (_law(g),)), None,
                        np.random.default_rng(1)) for g in (None, 1.0, 1e3)}
    for a in ("y", "u", "eps"):
        lin = getattr(runs[None], a)
        assert _rel(getattr(runs[1.0], a), lin) < 1e-8, a
        assert _rel(getattr(runs[1e3], a), lin) < 1e-12, a
    m = runs[1e3].draws["magnets"][0]
    assert m["axes"] == ["Ax", "Ay", "Bx", "By"] and abs(m["i0_a"] - 4e6) < 1e-6


def test_the_remainder_is_the_law_beyond_its_linearisation():
    """i0 = g0 ks / ki, F0 = ki i0 / 4 make the slopes at 0 the rig's; the remainder agrees
    with the whole law minus ki i + ks x and, for small iota and xi, with its cubic
    expansion F0 (4 xi iota^2 + 12 iota xi^2 + 8 xi^3); touching the pole is refused."""
    rig = load_rig()
    law = magnet_law(_law(2.5e-4), rig)
    assert abs(law.i0_a - 1.0) < 1e-12 and abs(law.f0_n - 62.5) < 1e-12
    ki0, ks0 = law.slopes_at_zero()
    assert abs(ki0 / rig.ki - 1) < 1e-12 and abs(ks0 / rig.ks - 1) < 1e-12
    rng = np.random.default_rng(2)
    iota, xi = rng.uniform(-1e-3, 1e-3, 200), rng.uniform(-1e-3, 1e-3, 200)
    i, x = iota * law.i0_a, xi * law.gap_m
    n = law.remainder(i, x)
    cubic = law.f0_n * (4 * xi * iota**2 + 12 * iota * xi**2 + 8 * xi**3)
    assert np.all(np.abs(n - cubic) <= 1e-2 * np.abs(cubic))
    i, x = rng.uniform(-0.5, 0.5, 50), rng.uniform(-0.5, 0.5, 50) * law.gap_m
    big = law.force(i, x) - rig.ki * i - rig.ks * x
    assert np.abs(law.remainder(i, x) - big).max() < 1e-9 * np.abs(big).max()
    assert np.allclose(law.stiffness_at(i), rig.ks * (1 + i**2))     # ks (1 + iota^2)
    with pytest.raises(ValueError, match="touches the pole"):
        law.remainder(np.zeros(2), np.array([0.0, -2.5e-4]))


def _reference(plant, ctrl, eta):
    """Written apart from loop.run_segments: the controller sample by sample, the current
    w held, the remainder N(i, x) from the state at the sampling instant held over the
    sample at the bearing nodes."""
    n, dt = plant.A.shape[0], ctrl.dt
    M = np.zeros((n + 8, n + 8))
    M[:n, :n], M[:n, n:] = plant.A * dt, np.hstack([plant.B, plant.Fb]) * dt
    E = sla.expm(M)
    x, xk = plant.state_at(0.0), np.zeros(ctrl.Ak.shape[0])
    y = np.zeros((eta.shape[0], 4))
    for k in range(eta.shape[0]):
        y[k] = plant.C @ x
        w = ctrl.Cu @ xk + ctrl.Duy @ y[k] + ctrl.Due @ eta[k]
        xk = ctrl.Ak @ xk + ctrl.By @ y[k] + ctrl.Be @ eta[k]
        N = np.zeros(4)
        for law in plant.magnets:
            c = list(law.channels)
            N[c] = law.remainder((plant.cur_row @ x + plant.cur_dir * w)[c],
                                 (plant.xb_row @ x)[c])
        x = E[:n, :n] @ x + E[:n, n:] @ np.concatenate([w, N])
    return y


@pytest.mark.parametrize("extra", [(), ("actuator_lag",)])
def test_the_force_law_loop_is_a_plain_recursion(controller_file, extra):
    """A 0.25 mm gap at bearing B (i0 = 1 A; with and without an 800 Hz actuator lag, whose
    current is a state): the loop agrees with the reference recursion and differs from
    the linear loop; the current in force is the delivered one without actuator
    dynamics."""
    rig = load_rig()
    ctrl = read_controller(controller_file)
    spec = _spec(controller_file)
    eff = tuple(Effect("actuator_lag", {"bandwidth_hz": 800.0, "where": "all"})
                for _ in extra)
    eta = 0.3 * np.random.default_rng(3).choice([-1.0, 1.0], size=(1000, 4))
    law = _law(2.5e-4, "B")
    mine = clean_response(spec, ctrl, eta, rig, (*eff, law))
    ref = _reference(plant_of(spec, rig, (*eff, law)), ctrl, eta)
    lin = clean_response(spec, ctrl, eta, rig, eff)
    assert _rel(mine, ref) < 1e-11
    assert _rel(lin, ref) > 1e-4                           # the law does act
    plant = plant_of(spec, rig, (law,))
    cl = closed_loop(plant, ctrl)
    z = np.zeros_like(eta)
    r = run_segments([(0, cl)], np.hstack([eta, z, z]), cl.initial_state(plant.x0))
    assert _rel(r.i_mag[:, 2:], r.coil[:, 2:]) < 1e-13 and not r.i_mag[:, :2].any()
    pair = plant.magnets[0]
    assert np.array_equal(r.n_mag[:, 2:], pair.remainder(r.i_mag[:, 2:], r.x_mag[:, 2:]))


# ------------------------------------------------------------------ amplifiers
def test_the_amplifier_waveform_is_the_rate_capped_lag():
    """The exact sub-interval means and end value of di/dt = clip(wb (w - i), -S, S)
    against a fine Euler integration (slew: wb = inf, ramp then hold)."""
    dt, m, fine = 1e-4, 8, 80_000
    i0, w = np.array([0.1, -0.2, 0.3, 0.0]), np.array([0.7, 0.4, 0.29, -0.05])
    for amp in (Amplifier("slew_limit", 4000.0), Amplifier("amp_voltage_limit", 6000.0, 2500.0),
                Amplifier("amp_voltage_limit", np.inf, 2500.0)):
        end, means, limited, ramp = amp.waveform(i0, w, dt, m)
        h, i, path = dt / fine, i0.copy(), []
        wb = 2 * np.pi * amp.bandwidth_hz
        for _ in range(fine):
            rate = (w - i) / h if np.isinf(wb) else wb * (w - i)
            i = i + h * np.clip(rate, -amp.slew_a_per_s, amp.slew_a_per_s)
            path.append(i)
        path = np.array(path)
        assert np.abs(end - path[-1]).max() < 1e-4, amp
        assert np.abs(means - path.reshape(m, -1, 4).mean(axis=1)).max() < 1e-4, amp
    _, _, limited, ramp = Amplifier("slew_limit", 4000.0).waveform(i0, w, dt)
    assert list(limited) == [True, True, False, False]    # 4000 A/s x 0.1 ms = 0.4 A
    assert np.allclose(ramp, [1.0, 1.0, 0.01 / 0.4, 0.05 / 0.4])


def test_a_huge_slew_rate_gives_the_linear_record_and_a_small_one_caps_di_dt(
        controller_file):
    spec = _spec(controller_file, **HABITS)
    runs = {S: simulate(replace(spec, effects=() if S is None else (_slew(S),)), None,
                        np.random.default_rng(4)) for S in (None, 1e16, 3000.0)}
    for a in ("y", "u", "eps"):
        assert _rel(getattr(runs[1e16], a), getattr(runs[None], a)) < 1e-11, a
    assert runs[1e16].draws["slew_limited_share"] == 0.0
    slow = runs[3000.0]
    assert np.abs(np.diff(slow.coil, axis=0)).max() <= 3000.0 * spec.dt * (1 + 1e-12)
    assert slow.draws["slew_limited_share"] > 0.2
    assert np.abs(slow.w - slow.coil).max() > 0.1            # the command is not met
    with pytest.raises(ValueError, match="delay"):
        simulate(replace(spec, effects=(_slew(3000.0), Effect("sensor_delay",
                                                              {"delay_s": 5e-5}))),
                 None, np.random.default_rng(4))


def test_the_unlimited_voltage_limited_amplifier_is_a_first_order_lag(controller_file):
    """S = inf: the exact lag of actuator_lag to the sub-interval staircase (< 1e-2 of the
    lag's own effect); S finite: |di/dt| <= S."""
    rig = load_rig()
    ctrl = read_controller(controller_file)
    spec = _spec(controller_file)
    eta = 0.3 * np.random.default_rng(5).choice([-1.0, 1.0], size=(1000, 4))
    lin = clean_response(spec, ctrl, eta, rig, ())
    lag = clean_response(spec, ctrl, eta, rig,
                         (Effect("actuator_lag", {"bandwidth_hz": 2500.0, "where": "all"}),))

    def amp(S):
        return Effect("amp_voltage_limit", {"bandwidth_hz": 2500.0, "v_ratio": 1.0,
                                            "slew_a_per_s": S})
    free = clean_response(spec, ctrl, eta, rig, (amp(None),))
    assert np.sqrt(np.mean((free - lag) ** 2)) < 1e-2 * np.sqrt(np.mean((lag - lin) ** 2))
    plant = plant_of(spec, rig, (amp(5000.0),))
    cl = closed_loop(plant, ctrl)
    z = np.zeros_like(eta)
    r = run_segments([(0, cl)], np.hstack([eta, z, z]), cl.initial_state(plant.x0))
    assert np.abs(np.diff(r.coil, axis=0)).max() <= 5000.0 * spec.dt * (1 + 1e-12)
    assert r.limited.mean() > 0.1


# ------------------------------------------------------------------ cases
NEW_KINDS = ("force_law", "magnet_force_law", "slew_limit", "iron_saturation",
             "amp_voltage_limit", "pair:force_law+actuator_lag", "pair:slew_limit+unbalance")


@pytest.mark.parametrize("kind", NEW_KINDS)
def test_the_new_kinds_draw(kind):
    rig = load_rig()
    spec = draw_case(kind, np.random.default_rng(6), duration_s=0.5)
    names = [e.name for e in spec.effects]
    want = {"force_law": "magnet_force_law"}.get(kind.split(":")[-1].split("+")[0],
                                                 kind.split(":")[-1].split("+")[0])
    assert names[0] == want and len(names) == (2 if kind.startswith("pair") else 1)
    p = spec.effects[0].params
    if "gap_m" in p:                       # eta / i0 in the drawn excitation level range
        assert 0.1 <= spec.habits.eta_amplitude_a / (p["gap_m"] * rig.ks / rig.ki) <= 0.4
    big = draw_case(kind, np.random.default_rng(6), duration_s=0.5, eta_amplitude_a=0.6)
    assert big.habits.eta_amplitude_a == 0.6
    if "gap_m" in p:                       # the same level: the gap follows the excitation
        assert abs(big.effects[0].params["gap_m"] / p["gap_m"] - 2.0) < 1e-12
    assert {"force_law", "slew_limit", "iron_saturation", "amp_voltage_limit"} <= set(KINDS)


def test_a_force_law_case_writes_its_three_files_and_its_truth(controller_file, tmp_path):
    rng = np.random.default_rng(7)
    spec = draw_case("force_law", rng, controller_file=controller_file, duration_s=0.2)
    paths = write_case(spec, tmp_path, "fl", rng)
    assert all(paths[k].is_file() for k in ("csv", "json", "truth"))
    truth = json.loads(paths["truth"].read_text())
    m = truth["draws"]["magnets"][0]
    lvl = m["excitation_level"]
    assert 0.1 <= lvl <= 0.4 and abs(m["i0_a"] - m["gap_m"] * 1e6 / 250) < 1e-12
    for ax in m["axes"]:                   # the shift is ks mean((i / i0)^2)
        shift = m["ks_shift_n_per_m"][ax]
        assert abs(shift / 1e6 - m["i_rms_over_i0"][ax] ** 2) < 1e-12
        assert m["k_theta_linear_equivalent"][ax] == truth["theta"][f"k_{ax}"] - shift / 1e6
    assert "0:magnet_force_law" in truth["concealment"] and truth["concealment"]["all"] > 0
    assert truth["effects"][0]["name"] == "magnet_force_law"


def test_a_slew_limit_case_is_calibrated_to_its_share(controller_file, tmp_path):
    rng = np.random.default_rng(8)
    spec = draw_case("slew_limit", rng, controller_file=controller_file, duration_s=0.2)
    paths = write_case(spec, tmp_path, "sl", rng)
    truth = json.loads(paths["truth"].read_text())
    p = truth["effects"][0]["params"]
    assert p["slew_a_per_s"] > 0 and 0.05 <= p["limited_share_target"] <= 0.25
    assert abs(truth["draws"]["slew_limited_share"] - p["limited_share_target"]) \
        <= 0.15 * p["limited_share_target"]
