"""Tests of the foreign recording generator (tests/foreign): independence, identity with the
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
from tests.foreign import CaseSpec, Effect, Habits, read_controller, rotor
from tests.foreign.cases import simulate
from tests.foreign.habits import habit_signals
from tests.foreign.plant import AXES, dof
from tests.helpers import C_NSM, K_THETA

FOREIGN = Path(__file__).parent / "foreign"
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
    files = sorted(FOREIGN.glob("*.py"))
    assert len(files) >= 6
    for f in files:
        for mod in _imports(f):
            if mod.startswith("bayes_amb"):
                assert mod in ALLOWED, f"{f.name} imports {mod}"
    code = ("import sys, tests.foreign; print(','.join(m for m in sys.modules "
            "if m.startswith('bayes_amb')))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True, cwd=FOREIGN.parent.parent).stdout.strip().split(",")
    bad = [m for m in loaded if any(m.startswith(f"bayes_amb.{s}") for s in FORBIDDEN)]
    assert not bad, f"importing tests.foreign loads {bad}"
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
    from tests.foreign import write_case
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
    from tests.foreign.cases import clean_response, plant_of
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
    from tests.foreign.cases import clean_response
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
    from tests.foreign.cases import plant_of
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
    from tests.foreign.plant import node_of
    rig = load_rig()
    u, ph, rpm = 2e-5, 0.7, 31000.0
    spec = CaseSpec(k_theta=K_THETA, c_nsm=C_NSM, speed_rpm_true=rpm, truth="full")
    from tests.foreign.cases import plant_of
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
    from tests.foreign.cases import clean_response
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
