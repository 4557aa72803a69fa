"""Tests of the foreign recording generator (benchmarks/foreign): independence, identity with the
tool's reduced model and forward model, habits and concealment.

Only these tests may import the tool beside the generator (to compare against it).
"""

from __future__ import annotations

import ast
import itertools
import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.signal as sps

from bayes_amb.rig import load_rig
from benchmarks.foreign import CaseSpec, Effect, Habits, closed_loop, read_controller, rotor
from benchmarks.foreign.cases import simulate
from benchmarks.foreign.habits import habit_signals
from benchmarks.foreign.plant import AXES, dof
from tests.helpers import C_NSM, K_THETA

FOREIGN = Path(__file__).resolve().parents[1] / "benchmarks" / "foreign"
RUNNER = "benchmark.py"
"""The benchmark's runner and scorer: it drives the product (diagnose, identify) on the
generator's recordings, so it is the one module here that imports it; no generator module
imports the runner."""
ALLOWED = {"bayes_amb.rig", "bayes_amb.rotor"}
FORBIDDEN = ("simulate", "discrepancy", "reduction", "uncertainty", "inference", "control")


# ------------------------------------------------------------------ independence
def _imports(path: Path) -> set[str]:
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            out.add(node.module)
    return out


def test_generator_imports_no_tool_stage():
    files = sorted(f for f in FOREIGN.glob("*.py") if f.name != RUNNER)
    assert len(files) >= 6 and (FOREIGN / RUNNER).is_file()
    for f in files:
        assert "benchmarks.foreign.benchmark" not in _imports(f), f.name
        for mod in _imports(f):
            if mod.startswith("bayes_amb"):
                assert mod in ALLOWED, f"{f.name} imports {mod}"
    code = ("import sys, benchmarks.foreign; print(','.join(m for m in sys.modules "
            "if m.startswith('bayes_amb')))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True, cwd=FOREIGN.parent.parent).stdout.strip().split(",")
    bad = [m for m in loaded if any(m.startswith(f"bayes_amb.{s}") for s in FORBIDDEN)]
    assert not bad, f"importing benchmarks.foreign loads {bad}"
    assert "bayes_amb.rotor" in loaded


# --------------------------------------------------------- identity with the tool
def test_reduced_frequency_response_agrees_with_the_tool():
    from bayes_amb.reduction import reduce_pseudo_modal
    from bayes_amb.rotor import full_model
    rig = load_rig()
    R = rotor(rig, rig.nominal_speed_rpm, "reduced")
    Bi = np.column_stack([rig.ki * R.force[:, dof(rig.bearing_nodes[a[0]], a[1])]
                          for a in AXES])
    Cy = np.vstack([R.disp[dof(rig.sensor_nodes[a[0]], a[1])] for a in AXES])
    red = reduce_pseudo_modal(full_model(rig, rig.nominal_speed_rpm))
    for f_hz in (1.0, 30.0, 120.0, 400.0, 1000.0, 2500.0):
        s = 2j * np.pi * f_hz
        mine = Cy @ np.linalg.solve(s * np.eye(R.n) - R.A, Bi)
        tool = red.C @ np.linalg.solve(s * np.eye(red.n_states) - red.A, red.B)
        rel = np.abs(mine - tool).max() / np.abs(tool).max()
        assert rel < 1e-6, f"{f_hz} Hz: relative difference {rel:.2e}"


def test_full_frequency_response_agrees_with_the_tool():
    from bayes_amb.rotor import full_model
    rig = load_rig()
    R = rotor(rig, rig.nominal_speed_rpm, "full")
    Bi = np.column_stack([rig.ki * R.force[:, dof(rig.bearing_nodes[a[0]], a[1])]
                          for a in AXES])
    Cy = np.vstack([R.disp[dof(rig.sensor_nodes[a[0]], a[1])] for a in AXES])
    fm = full_model(rig)
    for f_hz in (5.0, 200.0, 1027.0, 3000.0):
        s = 2j * np.pi * f_hz
        mine = Cy @ np.linalg.solve(s * np.eye(R.n) - R.A, Bi)
        tool = fm.C @ np.linalg.solve(s * np.eye(fm.n_states) - fm.A, fm.B)
        assert np.abs(mine - tool).max() < 1e-9 * np.abs(tool).max()


def test_effect_free_reduced_recording_is_reproduced_by_the_tools_forward_model(
        controller_file, tmp_path):
    """eps from the recording (tool's offline filter) = S(theta_true) eta (tool's forward
    model), with all eight bearing coefficients changed: the two worlds agree."""
    from bayes_amb.inference.forward import ForwardModel
    from bayes_amb.inference.offline import dual_youla_eps
    from bayes_amb.io import load_recording
    from benchmarks.foreign import write_case
    spec = CaseSpec(k_theta=K_THETA, c_nsm=C_NSM, habits=Habits(noise_rms_m=0.0),
                    duration_s=0.5, controller_file=controller_file)
    paths = write_case(spec, tmp_path, "clean", np.random.default_rng(1))
    rec = load_recording(paths["csv"])
    truth = json.loads(paths["truth"].read_text())
    params = tuple(truth["theta"])
    fm = ForwardModel(rec, params)
    eps = dual_youla_eps(fm.parts, rec.y, rec.u)
    th = np.array([truth["theta"][p] for p in params])
    rms = np.sqrt(np.mean(eps**2))
    rel = np.sqrt(np.mean((eps - fm.simulate(th)) ** 2)) / rms
    rel0 = np.sqrt(np.mean((eps - fm.simulate(0 * th)) ** 2)) / rms
    assert rel < 1e-6
    assert rel0 > 0.5           # the changed coefficients do matter: theta = 0 is far off
    # the recorded eta is the excitation the loop ran with
    assert np.array_equal(rec.excitation["eta"], np.abs(rec.excitation["eta"]) * np.sign(
        rec.excitation["eta"]))


# ------------------------------------------------------------------------ habits
def _spec(controller_file, **habits):
    return CaseSpec(k_theta=K_THETA, c_nsm=C_NSM, duration_s=0.4,
                    habits=Habits(**{"noise_rms_m": 0.0, **habits}),
                    controller_file=controller_file)


def test_offsets_give_a_steady_dc_shift(controller_file):
    off = (3e-6, -2e-6, 1e-6, 4e-6)
    amp = (0.05, 0.0, -0.03, 0.0)
    a = simulate(_spec(controller_file, burn_in_s=0.2), None, np.random.default_rng(3))
    b = simulate(_spec(controller_file, burn_in_s=0.2, sensor_offset_m=off, amp_offset_a=amp),
                 None, np.random.default_rng(3))
    dy, du = b.y - a.y, b.u - a.u
    # a constant shift (the burn-in has settled it) of the size of the offsets
    assert np.max(np.abs(dy - dy.mean(0))) < 1e-3 * np.max(np.abs(dy.mean(0)))
    assert np.max(np.abs(du - du.mean(0))) < 1e-3 * np.max(np.abs(du.mean(0)))
    assert 0.1 < np.max(np.abs(dy.mean(0))) / max(off) < 10
    # the habit signal itself has exactly the offset as its mean (no noise here)
    sig, _ = habit_signals(Habits(noise_rms_m=0.0, sensor_offset_m=off), 100, 1e-4,
                           np.random.default_rng(0))
    assert np.allclose(sig["m"].mean(0), off, rtol=1e-12)


def test_one_channel_excitation_changes_no_other_draw():
    """A one-channel test (kind control_one_channel) excites one channel; the others are
    drawn and zeroed, so every other signal is the four-channel record's, draw for draw."""
    h = Habits(noise_rms_m=5e-8)
    all4, _ = habit_signals(h, 2000, 1e-4, np.random.default_rng(3))
    one, _ = habit_signals(replace(h, eta_channels=("Bx",)), 2000, 1e-4,
                           np.random.default_rng(3))
    assert np.array_equal(one["eta"][:, 2], all4["eta"][:, 2])
    assert not one["eta"][:, [0, 1, 3]].any() and np.array_equal(one["m"], all4["m"])


def test_record_starts_mid_operation(controller_file):
    from bayes_amb.inference.forward import ForwardModel
    from bayes_amb.inference.offline import dual_youla_eps
    from bayes_amb.io import make_recording
    from bayes_amb.io.controller_file import load_controller
    ctrl = load_controller(controller_file)
    res = {}
    for burn in (0.0, 0.3):
        sim = simulate(_spec(controller_file, burn_in_s=burn), None, np.random.default_rng(4))
        rec = make_recording(sim.y, sim.u, {"eta": sim.eta}, 1e-4, ctrl, speed_rpm=31500.0)
        eps_rest = dual_youla_eps(ForwardModel(rec, "k_By").parts, rec.y, rec.u)
        res[burn] = np.abs(eps_rest - sim.eps).max(axis=1) / np.abs(sim.eps).max()
    assert res[0.0].max() < 1e-9          # from rest: the offline filter is the controller
    assert res[0.3][0] > 1e-2             # mid-operation: the controller's state is not zero
    assert res[0.3][-1] < 1e-6            # ... and the difference decays


@pytest.mark.parametrize("kind", ["ar1", "pink"])
def test_noise_is_coloured_with_the_given_rms(kind):
    sig, _ = habit_signals(Habits(noise_rms_m=5e-8, noise_ar=0.8, noise_kind=kind), 100000,
                           1e-4, np.random.default_rng(5))
    n = sig["noise"]
    assert abs(n.std() / 5e-8 - 1) < (0.05 if kind == "ar1" else 0.15)
    assert abs(np.corrcoef(n.T)[0, 1]) < 0.05               # independent channels
    f, p = sps.welch(n, fs=1e4, nperseg=4096, axis=0)
    p = p.mean(axis=1)
    assert p[(f > 20) & (f < 300)].mean() > 5 * p[f > 3000].mean()
    if kind == "pink":   # about 1/f: each decade 3-30-300 Hz drops by 3-30 x
        decade = [p[(f > lo) & (f < 3 * lo)].mean() for lo in (3.0, 30.0, 300.0)]
        assert all(3 < a / b < 30 for a, b in itertools.pairwise(decade))


def test_the_mains_lines_are_in_the_record(controller_file):
    # in the record, the lines are exactly sinusoids at 50 and 150 Hz (the loop filters
    # them, it does not remove them): the difference to the same record without lines
    lines = {50.0: 5e-8, 150.0: 3e-8}
    a, b = (simulate(_spec(controller_file, noise_rms_m=5e-8, burn_in_s=0.3, **kw), None,
                     np.random.default_rng(6)) for kw in ({}, {"mains_m": lines}))
    # same draws up to the line phases: draw order is eta, noise, then the phases
    d = b.y - a.y
    t = np.arange(d.shape[0]) * 1e-4
    X = np.column_stack([g(2 * np.pi * f * t) for f in lines for g in (np.cos, np.sin)])
    coef, *_ = np.linalg.lstsq(X, d, rcond=None)
    assert np.abs(d - X @ coef).max() < 1e-9 * np.abs(d).max()
    amp50 = np.hypot(coef[0], coef[1])
    assert np.all(amp50 > 0.05 * lines[50.0]), amp50


def _fine_grid_loop(plant, ctrl, eta, tau_a_sub, tau_s_sub, sub=10):
    """Reference: the same loop integrated on a grid sub times finer (plain ZOH per
    substep). The fine grid starts at t = -tau_s (rotor at rest, lines at their phase
    there); sample k is the state at k dt - tau_s; the current commanded at k dt acts from
    k dt + tau_a on."""
    n, dt = plant.A.shape[0], ctrl.dt
    h = dt / sub
    M = np.zeros((n + 4, n + 4))
    M[:n, :n], M[:n, n:] = plant.A * h, plant.B * h
    E = sla.expm(M)
    Ph, Gh = E[:n, :n], E[:n, n:]
    N = eta.shape[0]
    x, xk = plant.state_at(-tau_s_sub * h), np.zeros(ctrl.Ak.shape[0])
    w_hist = {}
    y = np.zeros((N, 4))
    for k in range(N):
        y[k] = plant.C @ x                     # x at fine index k sub, time k dt - tau_s
        w_hist[k] = ctrl.Cu @ xk + ctrl.Duy @ y[k] + ctrl.Due @ eta[k]
        xk = ctrl.Ak @ xk + ctrl.By @ y[k] + ctrl.Be @ eta[k]
        for i in range(k * sub, (k + 1) * sub):
            idx = (i - tau_s_sub - tau_a_sub) // sub
            x = Ph @ x + Gh @ w_hist.get(idx, np.zeros(4))
    return y


@pytest.mark.parametrize("lines", [False, True])
def test_delays_are_exact_piecewise_integration(controller_file, lines):
    """Fractional delays on both sides (0.3 and 1.2 samples) against a 10x finer grid,
    also with a 1x unbalance and runout (their phase refers to t = 0 of the record)."""
    from benchmarks.foreign.cases import clean_response, plant_of
    rig = load_rig()
    ctrl = read_controller(controller_file)
    spec = _spec(controller_file)
    eta = 0.3 * np.random.default_rng(10).choice([-1.0, 1.0], size=(600, 4))
    extra = (Effect("unbalance", {"planes": [{"node": 20, "u_kgm": 1e-5, "phase_rad": 1.0}]}),
             Effect("runout", {"channel": "Ay", "amplitude_m": 1e-7, "phase_rad": 2.0})
             ) if lines else ()
    effects = (Effect("actuator_delay", {"delay_s": 0.3e-4}),
               Effect("sensor_delay", {"delay_s": 1.2e-4}), *extra)
    mine = clean_response(spec, ctrl, eta, rig, effects)
    ref = _fine_grid_loop(plant_of(spec, rig, extra), ctrl, eta, 3, 12)
    y0 = clean_response(spec, ctrl, eta, rig, extra)
    scale = np.abs(ref).max()
    assert np.abs(mine - ref).max() < 1e-9 * scale
    assert np.abs(y0 - ref).max() > 1e-2 * scale      # the delays do matter


def test_runout_is_a_1x_line_on_its_own_channel(controller_file):
    from benchmarks.foreign.cases import clean_response
    rig = load_rig()
    ctrl = read_controller(controller_file)
    base = _spec(controller_file)
    eta = 0.3 * np.random.default_rng(9).choice([-1.0, 1.0], size=(4000, 4))
    y0 = clean_response(base, ctrl, eta, rig, ())
    e = Effect("runout", {"channel": "Bx", "amplitude_m": 1e-6, "phase_rad": 0.3})
    yr = clean_response(base, ctrl, eta, rig, (e,)) - y0
    f, p = sps.periodogram(yr[1000:], fs=1e4, axis=0)
    k = np.argmin(np.abs(f - 31500 / 60))
    assert abs(int(np.argmax(p[:, 2])) - k) <= 1
    assert p[k, 2] > 10 * p[k, [0, 1, 3]].max()


# ------------------------------------------------------------ effect physics
def _frf(A, B, C, f_hz):
    s = 2j * np.pi * f_hz
    return C @ np.linalg.solve(s * np.eye(A.shape[0]) - A, B)


def _plant(effects, truth="reduced", changed=True):
    from benchmarks.foreign.cases import plant_of
    spec = (CaseSpec(k_theta=K_THETA, c_nsm=C_NSM, truth=truth) if changed
            else CaseSpec(truth=truth))
    return plant_of(spec, load_rig(), tuple(effects))


def _h1(bw):
    return lambda s: 1 / (1 + s / (2 * np.pi * bw))


def _h2(fn, z):
    wn = 2 * np.pi * fn
    return lambda s: wn**2 / (s * s + 2 * z * wn * s + wn**2)


@pytest.mark.parametrize("effect, side, diag", [
    (Effect("actuator_lag", {"bandwidth_hz": 800.0, "where": "A"}), "in",
     lambda s: [_h1(800)(s)] * 2 + [1, 1]),
    (Effect("actuator_2nd", {"natural_hz": 1500.0, "zeta": 0.5, "where": "all"}), "in",
     lambda s: [_h2(1500, 0.5)(s)] * 4),
    (Effect("sensor_lag", {"bandwidth_hz": 2000.0, "where": "B"}), "out",
     lambda s: [1, 1] + [_h1(2000)(s)] * 2),
    (Effect("actuator_gain", {"axis": "Ay", "gain": 0.05}), "in",
     lambda s: [1, 1.05, 1, 1]),
    (Effect("sensor_gain", {"channel": "By", "gain": -0.04}), "out",
     lambda s: [1, 1, 1, 0.96]),
])
def test_actuator_and_sensor_effects_are_the_right_multiplicative_dynamics(effect, side, diag):
    """G_eff = G diag(h) (actuator side) or diag(h) G (sensor side), h analytic."""
    p0, p1 = _plant(()), _plant((effect,))
    for f_hz in (20.0, 300.0, 1200.0):
        s = 2j * np.pi * f_hz
        G0, G1 = _frf(p0.A, p0.B, p0.C, f_hz), _frf(p1.A, p1.B, p1.C, f_hz)
        D = np.diag(diag(s))
        expect = G0 @ D if side == "in" else D @ G0
        assert np.abs(G1 - expect).max() < 1e-9 * np.abs(G0).max()
        assert np.abs(G1 - G0).max() > 1e-3 * np.abs(G0).max()


def test_eddy_currents_are_the_slab_diffusion_law_not_a_first_order_lag():
    """G_eff = G diag(h) with h = tanh(sqrt(s tau)) / sqrt(s tau) on bearing B's axes, to
    the truncation of its partial fractions (the tail beyond 16 terms differs from its
    static gain by at most sum 2 |s tau| / a_k^4 < 1e-4 below 1.2 kHz); at 1.2 kHz it is
    not the first-order lag of the same corner (a foreign form of actuator_lag)."""
    fc = 900.0
    tau = 3.0 / (2 * np.pi * fc)
    p0 = _plant(())
    p1 = _plant((Effect("eddy_current", {"corner_hz": fc, "where": "B"}),))
    for f_hz in (20.0, 300.0, 1200.0):
        s = 2j * np.pi * f_hz
        z = np.sqrt(s * tau)
        h = np.tanh(z) / z
        G0, G1 = _frf(p0.A, p0.B, p0.C, f_hz), _frf(p1.A, p1.B, p1.C, f_hz)
        assert np.abs(G1 - G0 @ np.diag([1, 1, h, h])).max() < 1e-4 * np.abs(G0).max()
    assert abs(h - _h1(fc)(s)) > 0.05


@pytest.mark.parametrize("deg", [5.0, -90.0])
def test_a_turned_probe_pair_sees_the_displacement_in_its_own_frame(deg):
    """G_eff = T G with T the turn of bearing A's probe pair (p_x = cos a q_x + sin a q_y,
    p_y = -sin a q_x + cos a q_y); at -90 degrees p_x = -q_y and p_y = q_x."""
    a = np.radians(deg)
    T = np.eye(4)
    T[:2, :2] = [[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]]
    p0 = _plant(())
    p1 = _plant((Effect("probe_angle", {"bearing": "A", "angle_deg": deg}),))
    for f_hz in (20.0, 300.0, 1200.0):
        G0, G1 = _frf(p0.A, p0.B, p0.C, f_hz), _frf(p1.A, p1.B, p1.C, f_hz)
        assert np.abs(G1 - T @ G0).max() < 1e-9 * np.abs(G0).max()
        assert np.abs(G1 - G0).max() > 1e-2 * np.abs(G0).max()
    if deg == -90.0:
        assert np.allclose(G1[0], -G0[1]) and np.allclose(G1[1], G0[0])


def test_cross_coupling_is_the_tools_kxy_parameter():
    """kxy at disc D1 in the reduced truth = the tool's reduced LFT at theta = kxy / k_ref."""
    from bayes_amb.reduction import reduce_pseudo_modal
    from bayes_amb.rotor import full_model
    from bayes_amb.uncertainty import lft_reduced
    rig = load_rig()
    kxy = 4e4
    p0 = _plant((), changed=False)
    p1 = _plant((Effect("cross_coupling", {"where": "D1", "kxy_nm": kxy}),), changed=False)
    red = reduce_pseudo_modal(full_model(rig))
    up = lft_reduced(red, rig, "kxy_D1")
    A1 = up.A + up.B_w @ np.diag(up.theta_diag([kxy / rig.k_ref])) @ up.C_z
    for f_hz in (10.0, 150.0, 700.0):
        G0 = _frf(p0.A, p0.B, p0.C, f_hz)
        dmine = _frf(p1.A, p1.B, p1.C, f_hz) - G0
        dtool = _frf(A1, up.B, up.C, f_hz) - _frf(up.A, up.B, up.C, f_hz)
        assert np.abs(dmine - dtool).max() < 1e-6 * np.abs(dtool).max()


def test_a_rigid_pedestal_changes_nothing_and_a_soft_one_resonates():
    p0 = _plant(())
    stiff = _plant((Effect("pedestal", {"bearing": "A", "mass_kg": 50.0,
                                        "natural_hz": 1e6, "zeta": 0.03}),))
    soft = _plant((Effect("pedestal", {"bearing": "A", "mass_kg": 50.0,
                                       "natural_hz": 250.0, "zeta": 0.03}),))
    for f_hz in (15.0, 250.0, 900.0):
        G0 = _frf(p0.A, p0.B, p0.C, f_hz)
        assert np.abs(_frf(stiff.A, stiff.B, stiff.C, f_hz) - G0).max() < 1e-6 * np.abs(G0).max()
    # the soft housing adds a lightly damped pair near 250 Hz (shifted a little by ks)
    lam = np.linalg.eigvals(soft.A)
    f_n = np.abs(lam) / (2 * np.pi)
    zeta = -lam.real / np.abs(lam)
    near = (f_n > 200) & (f_n < 300) & (zeta > 0.01) & (zeta < 0.1)
    assert near.sum() == 4                    # x and y, each a conjugate pair
    # ... and changes channels A more than channels B
    G0 = _frf(p0.A, p0.B, p0.C, 250.0)
    d = np.abs(_frf(soft.A, soft.B, soft.C, 250.0) - G0) / np.abs(G0).max()
    assert d[:2].max() > 5 * d[2:].max()


def test_unbalance_force_rotates_forward_at_the_true_speed():
    """Full truth (its force map is invertible): the oscillator states reproduce
    u Omega^2 [cos, sin](Omega t + phi) as the force the rotor feels (rotor rows of A)."""
    from benchmarks.foreign.plant import node_of
    rig = load_rig()
    u, ph, rpm = 2e-5, 0.7, 31000.0
    spec = CaseSpec(k_theta=K_THETA, c_nsm=C_NSM, speed_rpm_true=rpm, truth="full")
    from benchmarks.foreign.cases import plant_of
    p = plant_of(spec, rig, (Effect("unbalance", {"planes": [
        {"node": "D2", "u_kgm": u, "phase_rad": ph}]}),))
    R = rotor(rig, rpm, "full")
    n_r = p.n_rotor
    osc = slice(p.A.shape[0] - 2, p.A.shape[0])
    om = rpm * np.pi / 30
    F = np.linalg.lstsq(R.force, p.A[:n_r, osc], rcond=None)[0]     # force per osc state
    n = node_of(rig, "D2")
    for t in (0.0, 1.3e-3, 7.7e-3):
        o = np.array([np.cos(om * t), np.sin(om * t)])   # the oscillator from x0 = [1, 0]
        E = sla.expm(p.A[osc, osc] * t) @ p.x0[osc]
        assert np.allclose(E, o, atol=1e-12)
        f = F @ o
        assert np.allclose(f[[dof(n, "x"), dof(n, "y")]],
                           u * om**2 * np.array([np.cos(om * t + ph), np.sin(om * t + ph)]),
                           rtol=1e-9, atol=1e-12 * u * om**2)
        assert np.abs(np.delete(f, [dof(n, "x"), dof(n, "y")])).max() < 1e-9 * u * om**2


def test_line_phases_refer_to_the_start_of_the_record(controller_file):
    """With and without a burn-in, a runout and an unbalance give the same steady 1x
    signal in the record: their phases are those of the truth at t = 0 of the record."""
    from benchmarks.foreign.cases import clean_response
    effects = (Effect("runout", {"channel": "Bx", "amplitude_m": 2e-7, "phase_rad": 0.4}),
               Effect("unbalance", {"planes": [{"node": 5, "u_kgm": 1e-5, "phase_rad": 2.0}]}))
    spec = replace(_spec(controller_file, burn_in_s=0.37, eta_amplitude_a=0.0),
                   effects=effects, speed_rpm_true=31400.0)
    rec = simulate(spec, None, np.random.default_rng(12))
    rest = clean_response(spec, read_controller(controller_file), np.zeros_like(rec.y),
                          load_rig(), effects)
    tail = slice(2000, None)
    assert np.abs(rec.y[tail] - rest[tail]).max() < 1e-6 * np.abs(rest[tail]).max()
    assert np.abs(rest[tail]).max() > 1e-8


# ------------------------------------------------- held-out families of issue 27
def _reference_loop(plant, ctrl, eta, force=None, i_max=np.inf, sub=4):
    """Reference for the nonlinear loop and the disc forces, written apart from
    loop.run_segments: no delays; the controller sample by sample, the amplifier's current
    clip(w, +-i_max) held over the sample and the plant integrated on a grid sub times
    finer, the disc force (N, 4) held over each sample like the current."""
    n, dt = plant.A.shape[0], ctrl.dt
    B = np.hstack([plant.B, plant.F])
    M = np.zeros((n + 8, n + 8))
    M[:n, :n], M[:n, n:] = plant.A * dt / sub, B * dt / sub
    E = sla.expm(M)
    Ph, Gh = E[:n, :n], E[:n, n:]
    x, xk = plant.state_at(0.0), np.zeros(ctrl.Ak.shape[0])
    y = np.zeros((eta.shape[0], 4))
    for k in range(eta.shape[0]):
        y[k] = plant.C @ x
        w = ctrl.Cu @ xk + ctrl.Duy @ y[k] + ctrl.Due @ eta[k]
        xk = ctrl.Ak @ xk + ctrl.By @ y[k] + ctrl.Be @ eta[k]
        v = np.concatenate([np.clip(w, -i_max, i_max),
                            np.zeros(4) if force is None else force[k]])
        for _ in range(sub):
            x = Ph @ x + Gh @ v
    return y


def _limit(i_max, recorded="command"):
    return Effect("current_limit", {"i_max_a": i_max, "recorded": recorded,
                                    "clipped_share_target": 0.03})


def test_a_current_limit_clips_the_amplifier_as_a_reference_loop_does(controller_file):
    """eta 0.3 A with the limit at 0.35 A: the loop (open-loop form with the clip) agrees
    with a plain reference recursion, and differs from the linear loop."""
    from benchmarks.foreign.cases import clean_response, plant_of
    rig = load_rig()
    ctrl = read_controller(controller_file)
    spec = _spec(controller_file)
    eta = 0.3 * np.random.default_rng(20).choice([-1.0, 1.0], size=(800, 4))
    mine = clean_response(spec, ctrl, eta, rig, (_limit(0.35),))
    ref = _reference_loop(plant_of(spec, rig, ()), ctrl, eta, i_max=0.35)
    lin = clean_response(spec, ctrl, eta, rig, ())
    scale = np.abs(ref).max()
    assert np.abs(mine - ref).max() < 1e-9 * scale
    assert np.abs(lin - ref).max() > 1e-2 * scale          # the limit does act


def test_an_unreachable_current_limit_is_the_linear_run(controller_file):
    """All habits on (noise, offsets, r2, lines) and a fractional actuator delay: a limit
    of 1e6 A gives the linear run to 1e-12 (the open-loop form Aop + Bw Cw = Acl)."""
    hab = dict(noise_rms_m=5e-8, noise_ar=0.7, sensor_offset_m=(1e-6, -2e-6, 0.0, 3e-6),
               amp_offset_a=(0.02, 0.0, -0.01, 0.0), r2_rms_a=0.01, burn_in_s=0.05,
               mains_m={50.0: 3e-8})
    delay = Effect("actuator_delay", {"delay_s": 1.3e-4})
    runs = [simulate(replace(_spec(controller_file, **hab), duration_s=0.2, effects=eff),
                     None, np.random.default_rng(21))
            for eff in ((delay,), (delay, _limit(1e6)))]
    for a in ("y", "u", "eps"):
        x0, x1 = getattr(runs[0], a), getattr(runs[1], a)
        assert np.abs(x1 - x0).max() <= 1e-12 * np.abs(x0).max(), a
    assert runs[1].draws["clipped_share"] == 0.0


@pytest.mark.parametrize("recorded", ["command", "coil"])
def test_the_current_limit_is_calibrated_to_its_clipped_share(controller_file, recorded):
    from benchmarks.foreign.cases import calibrate_current_limit
    rig = load_rig()
    ctrl = read_controller(controller_file)
    spec = replace(_spec(controller_file, noise_rms_m=5e-8, amp_offset_a=(0.03, 0, 0, 0),
                         burn_in_s=0.05),
                   duration_s=0.3, effects=(_limit(None, recorded),))
    rng = np.random.default_rng(22)
    state = rng.bit_generator.state
    spec, out = calibrate_current_limit(spec, ctrl, rng, rig)
    assert rng.bit_generator.state == state                 # rng not advanced
    assert abs(out["clipped_share"] - 0.03) <= 0.15 * 0.03
    sim = simulate(spec, ctrl, rng, rig)
    i_max = spec.effects[0].params["i_max_a"]
    assert sim.draws["clipped_share"] == out["clipped_share"]   # the record's own draws
    assert np.mean(np.abs(sim.w) > i_max) == sim.draws["clipped_share"]
    if recorded == "coil":      # the DAQ's current sensor: never beyond the limit
        assert np.array_equal(sim.u, np.clip(sim.w, -i_max, i_max))
    else:                       # the command: beyond it exactly where it clips
        assert np.mean(np.abs(sim.u) > i_max) > 0.005
        assert np.abs(sim.u).max() > i_max


def _seal(K=0.0, k=0.0, C=0.0, c=0.0, node="D2"):
    return Effect("seal", {"node": node, "k_direct_nm": K, "k_cross_nm": k,
                           "c_direct_nsm": C, "c_cross_nsm": c})


def test_a_seal_is_the_node_impedance_of_its_coefficients():
    """Full truth: G_seal = G0 - G_yn Z (I + G_nn Z)^-1 G_nu (a force -Z q at the node fed
    back through the seal-free plant), Z = [[K + sC, k + sc], [-(k + sc), K + sC]]."""
    from benchmarks.foreign.plant import node_of
    rig = load_rig()
    K, k, C, c = 2e5, 6e4, 40.0, 8.0
    p0, p1 = _plant((), truth="full"), _plant((_seal(K, k, C, c, node=20),), truth="full")
    R = rotor(rig, rig.nominal_speed_rpm, "full")
    n = node_of(rig, 20)
    Fn = np.zeros((p0.A.shape[0], 2))
    Fn[:R.n] = R.force[:, [dof(n, "x"), dof(n, "y")]]
    Cn = np.zeros((2, p0.A.shape[0]))
    Cn[:, :R.n] = R.disp[[dof(n, "x"), dof(n, "y")]]
    change = []
    for f_hz in (20.0, 180.0, 900.0):
        s = 2j * np.pi * f_hz
        G0 = _frf(p0.A, p0.B, p0.C, f_hz)
        Gyn, Gnn, Gnu = (_frf(p0.A, b, cc, f_hz) for b, cc in
                         ((Fn, p0.C), (Fn, Cn), (p0.B, Cn)))
        Z = np.array([[K + s * C, k + s * c], [-(k + s * c), K + s * C]])
        expect = G0 - Gyn @ Z @ np.linalg.solve(np.eye(2) + Gnn @ Z, Gnu)
        G1 = _frf(p1.A, p1.B, p1.C, f_hz)
        # full FE model (condition ~1e15): the formula loses ~1e-8 relative
        assert np.abs(G1 - expect).max() < 1e-6 * np.abs(G0).max()
        change.append(np.abs(G1 - G0).max() / np.abs(G0).max())
    assert max(change) > 1e-3                                # the seal does matter


@pytest.mark.parametrize("coef, sign", [("C", -1.0), ("k", +1.0)])
def test_seal_energy_direct_damping_dissipates_cross_coupling_feeds_forward_whirl(coef, sign):
    """The seal force recovered from the state matrix (full truth): with C alone its power
    f.v on the node is -C |v|^2 <= 0 for any motion; with k alone, on a forward circular
    whirl (x, y) = r (cos, sin)(w t), it is +k r^2 w > 0 (the destabilising sign)."""
    from benchmarks.foreign.plant import node_of
    rig = load_rig()
    e = _seal(C=50.0) if coef == "C" else _seal(k=5e4)
    p0, p1 = _plant((), truth="full", changed=False), _plant((e,), truth="full", changed=False)
    R = rotor(rig, rig.nominal_speed_rpm, "full")
    n = R.n
    F = np.linalg.lstsq(R.force, p1.A[:n, :n] - p0.A[:n, :n], rcond=None)[0]   # force/state
    j = [dof(node_of(rig, "D2"), a) for a in "xy"]
    rng = np.random.default_rng(23)
    for _ in range(5):
        if coef == "C":
            x = rng.standard_normal(n)
        else:                       # position on a forward whirl, velocity along it
            r, w, t = 1e-5, 2 * np.pi * 150.0, rng.uniform(0, 1e-2)
            x = np.zeros(n)
            x[j] = r * np.array([np.cos(w * t), np.sin(w * t)])
            x[n // 2 + np.array(j)] = r * w * np.array([-np.sin(w * t), np.cos(w * t)])
        f, v = F @ x, R.vel @ x
        power = f[j] @ v[j]
        expect = -50.0 * v[j] @ v[j] if coef == "C" else 5e4 * (1e-5) ** 2 * 2 * np.pi * 150.0
        assert np.sign(power) == sign
        assert abs(power - expect) < 1e-8 * abs(expect)
        assert np.abs(np.delete(f, j)).max() < 1e-8 * np.abs(f[j]).max()


def test_ks_drift_is_a_staircase_centred_on_theta(controller_file):
    """Each step's plant is the constant plant at theta + rate (mid-point - t_ref); the
    steps' mean over the record is theta; before the first switch the drifting run is the
    constant run at the first step's value; rate 0 is the plain run."""
    from benchmarks.foreign.cases import clean_response, loops, plant_of
    rig = load_rig()
    ctrl = read_controller(controller_file)
    spec = replace(_spec(controller_file), duration_s=0.2)
    d = Effect("ks_drift", {"where": "A", "rate_per_s": 0.3, "t_ref_s": 0.1,
                            "segment_s": 0.025})
    segs, _ = loops(spec, rig, ctrl, 0, 2000, (d,))
    assert [k for k, _ in segs] == list(range(0, 2000, 250))
    shifts = 0.3 * ((np.arange(8) + 0.5) * 0.025 - 0.1)
    assert abs(np.mean(shifts)) < 1e-15
    for (_, cl), sh in zip(segs, shifts, strict=True):
        kt = {a: v + (sh if a[0] == "A" else 0.0) for a, v in spec.k_theta.items()}
        want = closed_loop(plant_of(replace(spec, k_theta=kt), rig, ()), ctrl)
        assert np.array_equal(cl.Acl, want.Acl)
    eta = 0.3 * np.random.default_rng(24).choice([-1.0, 1.0], size=(2000, 4))
    y = clean_response(spec, ctrl, eta, rig, (d,))
    kt0 = {a: v + (shifts[0] if a[0] == "A" else 0.0) for a, v in spec.k_theta.items()}
    y0 = clean_response(replace(spec, k_theta=kt0), ctrl, eta, rig, ())
    assert np.array_equal(y[:250], y0[:250])
    assert np.abs(y[250:] - y0[250:]).max() > 1e-3 * np.abs(y0).max()
    flat = Effect("ks_drift", {**d.params, "rate_per_s": 0.0})
    assert np.array_equal(clean_response(spec, ctrl, eta, rig, (flat,)),
                          clean_response(spec, ctrl, eta, rig, ()))


def test_the_process_force_is_band_limited_with_its_rms():
    h = Habits(noise_rms_m=0.0, force_rms_n=7.5, force_band_hz=(12.0, 250.0),
               force_at=("D2",))
    sig, _ = habit_signals(h, 40000, 1e-4, np.random.default_rng(25))
    f = sig["force"]
    assert np.all(f[:, :2] == 0.0)                          # D1 not forced
    assert np.allclose(np.sqrt(np.mean(f[:, 2:] ** 2, axis=0)), 7.5, rtol=1e-12)
    fr, p = sps.welch(f[:, 2:], fs=1e4, nperseg=4096, axis=0)
    p = p.mean(axis=1)
    inside = p[(fr > 30) & (fr < 200)].mean()
    assert p[(fr > 1500)].max() < 1e-4 * inside
    assert p[(fr > 0) & (fr < 3)].max() < 1e-2 * inside
    assert abs(np.corrcoef(f[:, 2], f[:, 3])[0, 1]) < 0.05  # independent axes
    assert habit_signals(replace(h, force_rms_n=0.0), 100, 1e-4,
                         np.random.default_rng(0))[0]["force"] is None


def test_the_process_force_acts_at_its_disc_as_a_reference_loop_does(controller_file):
    from benchmarks.foreign.cases import plant_of
    from benchmarks.foreign.loop import run_segments
    rig = load_rig()
    ctrl = read_controller(controller_file)
    spec = _spec(controller_file)
    plant = plant_of(spec, rig, ())
    cl = closed_loop(plant, ctrl)
    eta = 0.3 * np.random.default_rng(26).choice([-1.0, 1.0], size=(600, 4))
    force = np.zeros((600, 4))
    force[:, 0] = 5.0 * np.random.default_rng(27).standard_normal(600)   # D1 x
    z = np.zeros_like(eta)
    mine = run_segments([(0, cl)], np.hstack([eta, z, z]), cl.initial_state(plant.x0),
                        force=force).y
    ref = _reference_loop(plant, ctrl, eta, force=force)
    no_force = _reference_loop(plant, ctrl, eta)
    scale = np.abs(ref).max()
    assert np.abs(mine - ref).max() < 1e-9 * scale
    assert np.abs(ref - no_force).max() > 1e-3 * scale


def test_new_kinds_draw_their_family():
    from benchmarks.foreign import draw_case
    for kind, name in (("current_limit", "current_limit"), ("seal", "seal"),
                       ("ks_drift", "ks_drift"), ("pedestal", "pedestal")):
        spec = draw_case(kind, np.random.default_rng(28))
        assert [e.name for e in spec.effects] == [name]
    spec = draw_case("control_force", np.random.default_rng(29))
    assert not spec.effects and 2.5 <= spec.habits.force_rms_n <= 12.5
    assert draw_case("control", np.random.default_rng(30)).habits.force_rms_n == 0.0


def test_a_weightless_coupling_changes_nothing_and_a_heavy_one_resonates():
    """The held-out shaft-end coupling: a hung mass of 1 mg changes no FRF; 2 kg on a 150 Hz
    spring at the last node is a damped pair a little above 150 Hz in x and y (the shaft end
    moves with it), 20 kg one near 240-255 Hz, which moves the FRF there."""
    p0 = _plant(())

    def coupled(m):
        return _plant((Effect("coupling", {"end": "last", "mass_kg": m, "natural_hz": 150.0,
                                           "zeta": 0.05}),))

    tiny = coupled(1e-6)
    for f_hz in (15.0, 150.0, 900.0):
        G0 = _frf(p0.A, p0.B, p0.C, f_hz)
        assert np.abs(_frf(tiny.A, tiny.B, tiny.C, f_hz) - G0).max() < 1e-6 * np.abs(G0).max()

    def window(A, lo, hi):
        lam = np.linalg.eigvals(A)
        f_n, zeta = np.abs(lam) / (2 * np.pi), -lam.real / np.abs(lam)
        return int(((f_n > lo) & (f_n < hi) & (zeta > 0.03) & (zeta < 0.12)).sum())

    assert window(p0.A, 100, 300) == 0
    assert window(coupled(2.0).A, 150.5, 180) == 4      # x and y, each a conjugate pair
    heavy = coupled(20.0)
    assert window(heavy.A, 220, 270) == 4
    G0 = _frf(p0.A, p0.B, p0.C, 245.0)
    assert np.abs(_frf(heavy.A, heavy.B, heavy.C, 245.0) - G0).max() > 0.05 * np.abs(G0).max()
