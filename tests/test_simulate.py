"""Simulator (issue 5): exact-ZOH loop, fractional delay, S(theta) identity, hidden effects,
reproducibility and truth isolation.

References used below: python-control's forced_response on a closed loop assembled by hand,
a first-order system's analytic delayed step response, an exact-ZOH fine-grid simulation,
scipy's cont2discrete and dlsim, and S(theta) of bayes_amb.control.youla (METHOD.md section 3).
Nothing here is timed: these are correctness tests, not benchmarks.
"""

from __future__ import annotations

import itertools
import json

import control as ct
import numpy as np
import pytest
import scipy.linalg as sla
import scipy.signal as sps

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.control.youla import s_theta
from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.forward import ForwardModel
from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.inference.offline import dual_youla_eps, dual_youla_x
from bayes_amb.io.recording import load_recording, load_truth, save_recording
from bayes_amb.reduction import reduce_pseudo_modal
from bayes_amb.rig import CHANNELS, load_rig
from bayes_amb.rotor import assemble, dof_index
from bayes_amb.simulate import (
    EFFECT_DEFAULTS,
    SimulationConfig,
    TruthPlant,
    build_truth,
    excitation,
    make_effect,
    parse_effect,
    simulate_loop,
    simulate_recording,
)
from bayes_amb.simulate.loop import closed_loop_spectral_radius, delayed_input_matrices
from bayes_amb.uncertainty import lft_reduced

# ---------------------------------------------------------------------------------------------
# helpers: an independent closed-loop reference


def _gamma(A: np.ndarray, B: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """(e^{At}, int_0^t e^{As} ds B) from one block exponential (Van Loan)."""
    n, m = B.shape
    E = sla.expm(np.block([[A, B], [np.zeros((m, n + m))]]) * t)
    return E[:n, :n], E[:n, n:]


def reference_closed_loop(tp: TruthPlant, K: tuple, dt: float) -> ct.StateSpace:
    """Discrete closed loop of Fig. 2 built by hand, states [x; x_k; u_p[k-1..k-m-1]].

    Inputs [eta (4); n (4); r1 (4); r2 (4); Re c, Im c (4)] with the continuous unbalance
    force f(t) = Re(c_k e^{j w (t - t_k)}) over sample k, integrated exactly: its term is
    Re(G_w c_k), G_w = int_0^dt e^{A (dt - s)} B_f e^{j w s} ds (the top-right block of
    expm([[A, B_f], [0, j w I]] dt), complex),
    outputs [y (4); u (4); eps (4)]. The input delay tau = m dt + phi enters as
    x+ = e^{A dt} x + Gamma(dt - phi) u_p[k-m] + e^{A(dt-phi)} Gamma(phi) u_p[k-m-1].
    """
    Ak, Bk, Ck, Dk = K
    A, B, C = tp.A, tp.B, tp.sensor_gain[:, None] * tp.C
    n, nk, nu = A.shape[0], Ak.shape[0], 4
    m = int(np.floor(tp.delay_s / dt + 1e-9))
    phi = tp.delay_s - m * dt
    Ad, _ = _gamma(A, B, dt)
    E1, G_now = _gamma(A, B, dt - phi)
    G_prev = E1 @ _gamma(A, B, phi)[1]
    nh = nu * (m + 1)
    N, n_in = n + nk + nh, 20
    sx, sk = slice(0, n), slice(n, n + nk)
    ie, i_n, i1, i2, i_f = (slice(0, 4), slice(4, 8), slice(8, 12), slice(12, 16),
                            slice(16, 20))

    def h(j: int) -> slice:
        return slice(n + nk + (j - 1) * nu, n + nk + j * nu)

    # controller input v = [C x + n + r1; eta] as (rows over state, rows over input)
    v_s = np.zeros((8, N))
    v_s[:4, sx] = C
    v_i = np.zeros((8, n_in))
    v_i[:4, i_n] = np.eye(4)
    v_i[:4, i1] = np.eye(4)
    v_i[4:, ie] = np.eye(4)
    out_s = Dk @ v_s
    out_s[:, sk] += Ck
    out_i = Dk @ v_i
    up_s, up_i = out_s[:4].copy(), out_i[:4].copy()       # u_p[k] = u[k] + r2[k]
    up_i[:, i2] += np.eye(4)
    Acl, Bcl = np.zeros((N, N)), np.zeros((N, n_in))
    Acl[sx, sx] = Ad
    if m == 0:
        Acl[sx] += G_now @ up_s
        Bcl[sx] += G_now @ up_i
    else:
        Acl[sx, h(m)] += G_now
    Acl[sx, h(m + 1)] += G_prev
    if tp.B_f is not None:
        w = tp.speed_rpm * 2 * np.pi / 60
        M = np.zeros((n + 2, n + 2), dtype=complex)
        M[:n, :n], M[:n, n:], M[n:, n:] = A, tp.B_f, 1j * w * np.eye(2)
        G_w = sla.expm(M * dt)[:n, n:]
        Bcl[sx, i_f] = np.hstack([G_w.real, -G_w.imag])
    Acl[sk] = Bk @ v_s
    Acl[sk, sk] += Ak
    Bcl[sk] = Bk @ v_i
    Acl[h(1)], Bcl[h(1)] = up_s, up_i
    for j in range(2, m + 2):
        Acl[h(j), h(j - 1)] = np.eye(nu)
    Ccl = np.vstack([v_s[:4], out_s])
    Dcl = np.vstack([v_i[:4] - np.hstack([np.zeros((4, 8)), np.eye(4), np.zeros((4, 8))]),
                     out_i])                                # recorded y excludes r1
    return ct.ss(Acl, Bcl, Ccl, Dcl, dt)


def small_loop(delay_s: float, unbalance: bool) -> tuple[TruthPlant, tuple, float]:
    """A 2-state stable plant (50 Hz, 5 % damping), 4 in / 4 out, and a 2-state controller
    in the exported (A, B, C, D) form with inputs [y; eta] and outputs [u; eps]."""
    rng = np.random.default_rng(11)
    w, z = 2 * np.pi * 50.0, 0.05
    A = np.array([[0.0, 1.0], [-w**2, -2 * z * w]])
    B = np.vstack([np.zeros((1, 4)), rng.normal(size=(1, 4)) * 1e3])
    C = rng.normal(size=(4, 2)) * np.array([1.0, 1e-3])
    B_f = np.vstack([np.zeros((1, 2)), rng.normal(size=(1, 2)) * 10.0]) if unbalance else None
    tp = TruthPlant(A=A, B=B, C=C, B_f=B_f, delay_s=delay_s,
                    sensor_gain=np.array([1.0, 1.05, 0.97, 1.0]),
                    unbalance=(0.7, 0.3) if unbalance else None, speed_rpm=3000.0,
                    kind="small")
    th = 0.4
    Ak = 0.8 * np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    Bk = rng.normal(size=(2, 8)) * 0.3
    Ck = rng.normal(size=(8, 2)) * 0.3
    Dk = rng.normal(size=(8, 8)) * 0.05
    return tp, (Ak, Bk, Ck, Dk), 1e-3


def rel_err(a: np.ndarray, ref: np.ndarray) -> float:
    return float(np.max(np.abs(a - ref)) / np.max(np.abs(ref)))


# ---------------------------------------------------------------------------------------------
# the loop against python-control


@pytest.mark.parametrize(("delay_samples", "unbalance"),
                         [(0.0, False), (0.0, True), (1.3, False), (2.0, True), (0.45, True)])
def test_simulate_loop_matches_python_control(delay_samples, unbalance):
    """Reference: control.forced_response of the hand-built closed loop with inputs
    [eta; n; r1; r2; f]; relative error per signal < 1e-9 (measured ~1e-14)."""
    tp, K, dt = small_loop(delay_samples * 1e-3, unbalance)
    sys = reference_closed_loop(tp, K, dt)
    assert np.max(np.abs(np.linalg.eigvals(sys.A))) < 0.99        # the reference loop is stable
    rng = np.random.default_rng(5)
    n = 400
    eta = rng.choice([-1.0, 1.0], size=(n, 4))
    noise, r1, r2 = (s * rng.standard_normal((n, 4)) for s in (1e-3, 2e-3, 0.3))
    if unbalance:
        wt = tp.speed_rpm * 2 * np.pi / 60 * np.arange(n) * dt + tp.unbalance[1]
        c = tp.unbalance[0] * np.exp(1j * wt)[:, None] * np.array([1.0, -1j])
        f = np.hstack([c.real, c.imag])
    else:
        f = np.zeros((n, 4))
    sig = simulate_loop(tp, K, dt, eta, noise=noise, r1=r1, r2=r2)
    assert not sig.unstable
    resp = ct.forced_response(sys, U=np.hstack([eta, noise, r1, r2, f]).T)
    out = resp.outputs.T
    for got, ref in ((sig.y, out[:, :4]), (sig.u, out[:, 4:8]), (sig.eps, out[:, 8:])):
        assert rel_err(got, ref) < 1e-9
    # the loop's own stability check agrees with the reference closed loop
    rho = closed_loop_spectral_radius(tp, K, dt)
    assert rho == pytest.approx(np.max(np.abs(np.linalg.eigvals(sys.A))), rel=1e-9)


def test_simulate_loop_flags_an_unstable_loop_that_stays_finite():
    """A loop with closed-loop pole radius > 1 (reference: eigenvalues of the hand-built loop)
    is flagged even when the short record has not overflowed."""
    tp, (Ak, Bk, Ck, Dk), dt = small_loop(0.0, False)
    Dk = Dk.copy()
    Dk[:4, :4] = -100.0 * np.eye(4)                    # too much direct feedback y -> u
    K = (Ak, Bk, Ck, Dk)
    rho_ref = np.max(np.abs(np.linalg.eigvals(reference_closed_loop(tp, K, dt).A)))
    assert 1.0 < rho_ref < 2.0
    sig = simulate_loop(tp, K, dt, np.ones((200, 4)))     # grows ~1.11^200, stays finite
    assert np.all(np.isfinite(sig.y))
    assert sig.unstable


# ---------------------------------------------------------------------------------------------
# fractional time delay under ZOH


@pytest.mark.parametrize("delay_s", [0.0, 0.3e-3, 1e-3, 2.75e-3, 3e-3])
def test_delay_first_order_analytic_step(delay_s):
    """x' = -a x + b u(t - tau), u a unit step at t = 0: x(t) = (b/a)(1 - e^{-a(t - tau)})
    for t >= tau (else 0). Sampled recursion vs analytic: absolute error < 1e-12 b/a."""
    a, b, dt, n = 300.0, 2.0, 1e-3, 40
    Ad, m, G_now, G_prev = delayed_input_matrices(np.array([[-a]]), np.array([[b]]), dt,
                                                  delay_s)
    u = np.ones(n)
    x = np.zeros(n + 1)
    for k in range(n):
        u_now = u[k - m] if k - m >= 0 else 0.0
        u_prev = u[k - m - 1] if k - m - 1 >= 0 else 0.0
        x[k + 1] = Ad[0, 0] * x[k] + G_now[0, 0] * u_now + G_prev[0, 0] * u_prev
    t = np.arange(n + 1) * dt
    ref = np.where(t >= delay_s, b / a * (1 - np.exp(-a * (t - delay_s))), 0.0)
    assert np.max(np.abs(x - ref)) < 1e-12 * b / a


@pytest.mark.parametrize(("m", "phi_sub"), [(0, 5), (0, 12), (2, 7), (1, 19)])
def test_delay_matches_fine_grid_exact_zoh(m, phi_sub):
    """4-state MIMO plant, random ZOH input, delay m dt + phi with phi = phi_sub dt / 20.
    Reference: exact ZOH on a 20x finer grid with the delayed held input; relative error of
    the sampled state < 1e-10 (measured ~1e-15)."""
    rng = np.random.default_rng(3)
    A = rng.normal(size=(4, 4)) * 50.0 - 80.0 * np.eye(4)
    B = rng.normal(size=(4, 2))
    dt, sub, n = 1e-3, 20, 60
    delay = m * dt + phi_sub * dt / sub
    u = rng.normal(size=(n, 2))
    Ad, m_got, G_now, G_prev = delayed_input_matrices(A, B, dt, delay)
    assert m_got == m
    x = np.zeros((n + 1, 4))
    for k in range(n):
        un = u[k - m] if k - m >= 0 else np.zeros(2)
        up = u[k - m - 1] if k - m - 1 >= 0 else np.zeros(2)
        x[k + 1] = Ad @ x[k] + G_now @ un + G_prev @ up
    Eh, Gh = _gamma(A, B, dt / sub)
    xf = np.zeros(4)
    ref = [xf.copy()]
    for i in range(n * sub):
        j = (i - m * sub - phi_sub) // sub                   # index of the held input now
        xf = Eh @ xf + (Gh @ u[j] if j >= 0 else 0.0)
        if (i + 1) % sub == 0:
            ref.append(xf.copy())
    assert rel_err(x, np.array(ref)) < 1e-10


def test_delay_zero_and_whole_samples_give_plain_zoh():
    """Reference: scipy.signal.cont2discrete(..., 'zoh'). Delay 0 -> (Ad, 0, Bd, 0); a whole
    number of samples (including 3 dt, which is 2.9999999999999996 dt in floating point)
    -> (Ad, m, Bd, 0). Relative tolerance 1e-12."""
    rng = np.random.default_rng(4)
    A, B, dt = rng.normal(size=(3, 3)) * 100, rng.normal(size=(3, 2)), 1e-4
    Ad_ref, Bd_ref, *_ = sps.cont2discrete((A, B, np.eye(3), np.zeros((3, 2))), dt, "zoh")
    for delay, m_ref in ((0.0, 0), (2e-4, 2), (3e-4, 3)):
        Ad, m, G_now, G_prev = delayed_input_matrices(A, B, dt, delay)
        assert m == m_ref
        np.testing.assert_allclose(Ad, Ad_ref, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(G_now, Bd_ref, rtol=1e-12, atol=1e-16)
        assert not np.any(G_prev)


# ---------------------------------------------------------------------------------------------
# the reference rig


@pytest.fixture(scope="module")
def rig():
    return load_rig()


@pytest.fixture(scope="module")
def controllers(rig):
    """Reference observer controllers at 1 kHz and 10 kHz: {dt: (ObserverController, file)}."""
    out = {}
    for dt in (1e-3, 1e-4):
        c = reference_controller(rig, dt)
        out[dt] = (c, export_controller(c, rig))
    return out


@pytest.mark.parametrize(("dt", "duration"), [(1e-3, 0.5), (1e-4, 0.1)])
def test_eps_equals_s_theta_eta_noise_free(rig, controllers, dt, duration):
    """Reduced truth, k_By = 0.5, no noise or effects, observer controller: the controller's
    eps and the offline dual-Youla eps both equal S(theta) eta (scipy dlsim on
    s_theta(...)) to relative 1e-8 (measured ~1e-11), and x = eta to 1e-12 A."""
    ctrl, cf = controllers[dt]
    cfg = SimulationConfig(truth="reduced", params={"k_By": 0.5}, duration=duration, dt=dt,
                           seed=3)
    rec, truth = simulate_recording(rig, cf, cfg)
    assert truth["params"] == {"k_By": 0.5} and truth["plant"] == "reduced"
    eta = np.asarray(rec.excitation["eta"])
    S = s_theta(ctrl, lft_reduced(reduce_pseudo_modal(rig), rig, "k_By"), [0.5])
    _, eps_ref, _ = sps.dlsim((S.A, S.B, S.C, S.D, dt), eta)
    assert np.max(np.abs(eps_ref)) > 1e-10                    # S(0.5) eta is not trivially 0
    tp = build_truth(rig, rig.nominal_speed_rpm, "reduced", {"k_By": 0.5})
    sig = simulate_loop(tp, (cf.A, cf.B, cf.C, cf.D), dt, eta)
    np.testing.assert_array_equal(sig.y, rec.y)
    assert rel_err(sig.eps, eps_ref) < 1e-8
    parts = ForwardModel(rec, "k_By").parts
    y, u = np.asarray(rec.y), np.asarray(rec.u)
    assert rel_err(dual_youla_eps(parts, y, u), eps_ref) < 1e-8
    assert np.max(np.abs(dual_youla_x(parts, ctrl.F, y, u) - eta)) < 1e-12


# ---------------------------------------------------------------------------------------------
# hidden effects


def _sim(rig, cf, truth="full", effects=(), duration=0.2, seed=7, **kw):
    cfg = SimulationConfig(truth=truth, effects=tuple(effects), duration=duration,
                           dt=cf.dt, seed=seed, **kw)
    return simulate_recording(rig, cf, cfg)[0]


@pytest.fixture(scope="module")
def base_full(rig, controllers):
    """Effect-free full-truth recording at 10 kHz, 0.2 s, seed 7."""
    return _sim(rig, controllers[1e-4][1])


@pytest.mark.parametrize("name", sorted(EFFECT_DEFAULTS))
def test_effect_default_full_truth_stable_and_visible(rig, controllers, base_full, name):
    """Each effect at its default on the full truth at 10 kHz for 0.2 s: the loop stays
    stable (eigenvalue check) and the recording changes (relative RMS change of y > 1e-4;
    measured 3e-4 (cross_coupling) .. 1.8 (unbalance)). flexible_mode is part of the full FE
    truth already (documented), so there the recording is identical."""
    cf = controllers[1e-4][1]
    eff = make_effect(name)
    tp = build_truth(rig, rig.nominal_speed_rpm, "full", effects=[eff])
    assert closed_loop_spectral_radius(tp, (cf.A, cf.B, cf.C, cf.D), cf.dt) < 1.0
    rec = _sim(rig, cf, effects=[eff])
    y0, y = np.asarray(base_full.y), np.asarray(rec.y)
    np.testing.assert_array_equal(rec.excitation["eta"], base_full.excitation["eta"])
    change = np.sqrt(np.mean((y - y0) ** 2)) / np.sqrt(np.mean(y0**2))
    if name == "flexible_mode":
        assert change == 0.0
    else:
        assert change > 1e-4


def test_unbalance_adds_forward_whirl_line_at_running_speed(rig, controllers, base_full):
    """Unbalance alone (difference to the effect-free run, same seed) is a line at the
    running speed, 31500 rpm = 525 Hz (bin 105 of 2000 samples at 10 kHz) on all four
    channels, with y lagging x by 90 deg +/- 2 deg (forward whirl; measured -90.01/-90.04)."""
    rec = _sim(rig, controllers[1e-4][1], effects=[make_effect("unbalance")])
    d = np.asarray(rec.y) - np.asarray(base_full.y)
    F = np.fft.rfft(d, axis=0)
    f = np.fft.rfftfreq(d.shape[0], 1e-4)
    k = int(np.argmin(np.abs(f - rig.nominal_speed_rpm / 60)))
    assert f[k] == pytest.approx(525.0)
    assert np.all(np.argmax(np.abs(F), axis=0) == k)
    for ix, iy in ((0, 1), (2, 3)):
        assert np.rad2deg(np.angle(F[k, iy] / F[k, ix])) == pytest.approx(-90.0, abs=2.0)


def test_sensor_gain_scales_the_measured_row(rig, controllers, base_full):
    """sensor_gain g on By: (a) exactly the loop with C's By row scaled by 1 + g (relative
    1e-12); (b) in closed loop on the full truth, By changes by about g (first-order direct
    term g y_By; accepted 0.5 g .. 1.5 g, measured 0.8 g) and at least 4x more than any other
    channel (measured 8.8x)."""
    cf = controllers[1e-3][1]
    eff = make_effect("sensor_gain", gain=0.05, channel="By")
    tp = build_truth(rig, rig.nominal_speed_rpm, "reduced", {"k_Ax": -0.3}, [eff])
    C2 = tp.C.copy()
    C2[CHANNELS.index("By")] *= 1.05
    tp2 = TruthPlant(A=tp.A, B=tp.B, C=C2, B_f=None, delay_s=0.0, sensor_gain=np.ones(4),
                     unbalance=None, speed_rpm=tp.speed_rpm, kind="reduced")
    eta = np.random.default_rng(1).choice([-0.5, 0.5], size=(300, 4))
    K = (cf.A, cf.B, cf.C, cf.D)
    s1, s2 = simulate_loop(tp, K, 1e-3, eta), simulate_loop(tp2, K, 1e-3, eta)
    for a, b in ((s1.y, s2.y), (s1.u, s2.u), (s1.eps, s2.eps)):
        assert rel_err(a, b) < 1e-12
    g = EFFECT_DEFAULTS["sensor_gain"]["gain"]
    rec = _sim(rig, controllers[1e-4][1], effects=[make_effect("sensor_gain")])
    y0, y = np.asarray(base_full.y), np.asarray(rec.y)
    change = np.sqrt(np.mean((y - y0) ** 2, axis=0)) / np.sqrt(np.mean(y0**2, axis=0))
    i = CHANNELS.index("By")
    assert 0.5 * g < change[i] < 1.5 * g
    assert change[i] > 4 * np.max(np.delete(change, i))


def test_cross_coupling_is_the_documented_stiffness(rig):
    """cross_coupling kxy at D1 (f_x = -kxy y, f_y = +kxy x, effects.py docstring): the full
    truth's A changes in exactly the two position columns of the D1 node, by -kxy M^-1 e_x
    (y column) and +kxy M^-1 e_y (x column) (relative 1e-9); on the reduced truth it equals
    the parameter kxy_D1 = kxy / k_ref (relative 1e-12)."""
    speed = rig.nominal_speed_rpm
    kxy = 3.0e4
    eff = make_effect("cross_coupling", kxy=kxy, location="D1")
    dA = build_truth(rig, speed, "full", effects=[eff]).A - build_truth(rig, speed, "full").A
    mats = assemble(rig)
    node, n_q = rig.disc("D1").node, mats.n_q
    jx, jy = dof_index(node, "x"), dof_index(node, "y")
    assert sorted(np.flatnonzero(np.any(dA != 0, axis=0))) == sorted([jx, jy])
    assert not np.any(dA[:n_q])
    scale = kxy * np.max(np.abs(mats.M_inv))
    np.testing.assert_allclose(dA[n_q:, jy], -kxy * mats.M_inv[:, jx], rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(dA[n_q:, jx], kxy * mats.M_inv[:, jy], rtol=0, atol=1e-9 * scale)
    A_eff = build_truth(rig, speed, "reduced", effects=[eff]).A
    A_par = build_truth(rig, speed, "reduced", {"kxy_D1": kxy / rig.k_ref}).A
    np.testing.assert_allclose(A_eff, A_par, rtol=1e-12, atol=1e-12 * np.abs(A_par).max())


def test_flexible_mode_on_reduced_truth_approaches_full(rig, controllers, base_full):
    """flexible_mode n_modes = k on a reduced truth adds 4k states; the recording moves
    towards the full-truth one: relative RMS distance with 6 pairs < 0.1 x that with none
    (measured 0.094 -> 0.0004), and the default (2 pairs) already differs from none."""
    cf = controllers[1e-4][1]
    y_full = np.asarray(base_full.y)

    def dist(n_modes: int) -> float:
        eff = make_effect("flexible_mode", n_modes=n_modes)
        assert build_truth(rig, rig.nominal_speed_rpm, "reduced", effects=[eff]).n_states \
            == 8 + 4 * n_modes
        y = np.asarray(_sim(rig, cf, truth="reduced", effects=[eff]).y)
        return float(np.sqrt(np.mean((y - y_full) ** 2)) / np.sqrt(np.mean(y_full**2)))

    d0, d2, d6 = dist(0), dist(EFFECT_DEFAULTS["flexible_mode"]["n_modes"]), dist(6)
    assert d2 != d0
    assert d6 < 0.1 * d0


@pytest.mark.parametrize(("name", "key", "values"),
                         [("time_delay", "delay_s", (0.0, 2.5e-5, 5e-5, 1e-4, 2e-4)),
                          ("actuator_lag", "bandwidth_hz", (1e5, 5000.0, 2000.0, 1000.0,
                                                            500.0))])
def test_lag_and_delay_grow_the_model_residual(rig, controllers, name, key, values):
    """Reduced truth at theta = 0 and no noise: S(0) = 0, so the controller's eps is the
    effect alone. eps RMS grows strictly as the delay grows / the bandwidth falls
    (measured delay 0 -> 2e-4 s: 5e-21 -> 1.1e-7 m; lag 1e5 -> 500 Hz: 1.3e-9 -> 8.9e-8 m);
    with no delay it is < 1e-15 m."""
    cf = controllers[1e-4][1]
    eta = np.random.default_rng(2).choice([-0.5, 0.5], size=(2000, 4))
    rms = []
    for v in values:
        tp = build_truth(rig, rig.nominal_speed_rpm, "reduced",
                         effects=[make_effect(name, **{key: v})])
        sig = simulate_loop(tp, (cf.A, cf.B, cf.C, cf.D), 1e-4, eta)
        assert not sig.unstable
        rms.append(float(np.sqrt(np.mean(sig.eps**2))))
    assert all(b > a for a, b in itertools.pairwise(rms))
    if name == "time_delay":
        assert rms[0] < 1e-15


@pytest.mark.parametrize(("effect", "unstable"),
                         [("time_delay:delay_s=4e-4", False), ("time_delay:delay_s=8e-4", True),
                          ("actuator_lag:bandwidth_hz=250", False),
                          ("actuator_lag:bandwidth_hz=100", True)])
def test_enough_lag_or_delay_destabilises(rig, controllers, effect, unstable):
    """Lag and delay eat phase margin: on the full truth at 10 kHz the reference loop keeps
    its poles inside the unit circle up to 0.4 ms delay / 250 Hz bandwidth (radius 0.9984 /
    0.9979) and loses stability at 0.8 ms / 100 Hz (radius 1.026 / 1.013). An unstable
    truth is refused, not recorded, even though 0.2 s of it stays finite."""
    cf = controllers[1e-4][1]
    eff = parse_effect(effect)
    rho = closed_loop_spectral_radius(build_truth(rig, rig.nominal_speed_rpm, "full",
                                                  effects=[eff]), (cf.A, cf.B, cf.C, cf.D),
                                      cf.dt)
    assert (rho > 1.005) if unstable else (rho < 0.9995)
    if unstable:
        with pytest.raises(BayesAmbError, match="unstable"):
            _sim(rig, cf, effects=[eff])
    else:
        assert np.all(np.isfinite(_sim(rig, cf, effects=[eff]).y))


@pytest.mark.parametrize(("text", "match"), [
    ("wobble", "unknown effect 'wobble'"),
    ("actuator_lag:bw=3", "effect actuator_lag: unknown parameter 'bw'"),
    ("actuator_lag:bandwidth_hz=1", r"bandwidth_hz: value 1 out of range: must be in "
     r"10\.\.100000"),
    ("time_delay:delay_s=-1e-5", "delay_s: value -1e-05 out of range"),
    ("sensor_gain:gain=abc", "gain: expected a number, got 'abc'"),
    ("sensor_gain:channel=Cz", "channel: value 'Cz' not one of Ax, Ay, Bx, By"),
    ("unbalance:disc=D3", "disc: value 'D3' not one of D1, D2"),
    ("actuator_lag:800", "expected key=value, got '800'"),
])
def test_parse_effect_errors(text, match):
    with pytest.raises(BayesAmbError, match=match):
        parse_effect(text)


def test_parse_effect_fills_defaults_and_converts():
    e = parse_effect("unbalance: u_kgm=1e-4 , disc=D2")
    assert e.params == {"u_kgm": 1e-4, "disc": "D2", "phase_deg": 0.0}
    assert parse_effect("flexible_mode:n_modes=3").params["n_modes"] == 3
    assert parse_effect("time_delay") == make_effect("time_delay")


@pytest.mark.parametrize("dt", [1e-3, 1e-4])
def test_default_multisine_fits_the_sample_rate(dt):
    """The default multisine band (5 Hz .. min(1 kHz, 0.8 Nyquist)) is valid at the paper's
    1 kHz too: peak = amplitude exactly, no power above 0.8 Nyquist (< 1e-20 of the total),
    and lines from 5 Hz on (power below 4 Hz < 1e-20 of the total)."""
    n = 2000
    x = excitation("multisine", n, 4, 0.5, np.random.default_rng(0), dt)
    assert np.max(np.abs(x), axis=0) == pytest.approx(0.5, rel=1e-12)
    P = np.abs(np.fft.rfft(x, axis=0)) ** 2
    f = np.fft.rfftfreq(n, dt)
    assert np.all(P[f > 0.4 / dt].sum(axis=0) < 1e-20 * P.sum(axis=0))
    assert np.all(P[f < 4.0].sum(axis=0) < 1e-20 * P.sum(axis=0))



def test_narrow_band_multisine_has_power_only_in_its_band():
    """excitation_band_hz=(95, 105) at 1 kHz over 1 s: every line on the record's 1 Hz grid
    inside [95, 105] Hz, nothing outside (< 1e-20 of the total)."""
    n, dt = 1000, 1e-3
    x = excitation("multisine", n, 4, 0.5, np.random.default_rng(1), dt, (95.0, 105.0))
    P = np.abs(np.fft.rfft(x, axis=0)) ** 2
    f = np.fft.rfftfreq(n, dt)
    inside = (f >= 95) & (f <= 105)
    assert np.all(P[~inside].sum(axis=0) < 1e-20 * P.sum(axis=0))
    assert np.all(P[inside] > 1e-3 * P.max())

# ---------------------------------------------------------------------------------------------
# reproducibility and truth isolation


def test_same_seed_same_bytes_api(rig, controllers, tmp_path):
    """simulate_recording + save_recording: same seed -> byte-identical NAME.csv and NAME.json
    (noise, r1, r2 and an effect all drawn); another seed -> different CSV and JSON."""
    cf = controllers[1e-3][1]
    kw = dict(truth="reduced", params={"k_By": 0.5}, dt=1e-3, duration=0.1, noise_rms=1e-7,
              r1_rms=1e-7, r2_rms=0.02, r1_band_hz=200.0,
              effects=(make_effect("sensor_gain"),))
    files = {}
    for tag, seed in (("a", 4), ("b", 4), ("c", 5)):
        rec, truth = simulate_recording(rig, cf, SimulationConfig(seed=seed, **kw))
        (tmp_path / tag).mkdir()
        csv, js = save_recording(tmp_path / tag / "run.csv", rec, truth=truth)
        files[tag] = (csv.read_bytes(), js.read_bytes())
    assert files["a"] == files["b"]
    assert files["a"][0] != files["c"][0] and files["a"][1] != files["c"][1]


def test_truth_never_reaches_the_identification(rig, controllers, tmp_path):
    """Removing the sidecar's truth changes nothing that load_recording returns (arrays and
    meta identical) and identify(map_only) gives the identical MAP (exact equality)."""
    cf = controllers[1e-3][1]
    cfg = SimulationConfig(truth="reduced", params={"k_By": 0.5}, dt=1e-3, duration=0.2,
                           noise_rms=1e-8, seed=9)
    rec, truth = simulate_recording(rig, cf, cfg)
    with_truth = tmp_path / "with.csv"
    csv, js = save_recording(with_truth, rec, truth=truth)
    assert load_truth(with_truth)["params"] == {"k_By": 0.5}
    side = json.loads(js.read_text())
    del side["truth"]
    without = tmp_path / "without.csv"
    without.write_bytes(csv.read_bytes())
    (tmp_path / "without.json").write_text(json.dumps(side, indent=2))
    assert load_truth(without) is None
    r1, r2 = load_recording(with_truth), load_recording(without)
    assert "truth" not in r1.meta
    assert r1.meta == r2.meta
    for a, b in ((r1.t, r2.t), (r1.y, r2.y), (r1.u, r2.u),
                 (r1.excitation["eta"], r2.excitation["eta"])):
        np.testing.assert_array_equal(a, b)
    opts = IdentifyOptions(map_only=True)
    m1 = identify(r1, "k_By", options=opts).map_result
    m2 = identify(r2, "k_By", options=opts).map_result
    np.testing.assert_array_equal(m1.theta, m2.theta)
    np.testing.assert_array_equal(m1.log10_sigma, m2.log10_sigma)
    assert abs(m1.theta[0] - 0.5) < 0.05                  # sanity: the MAP is near the truth
