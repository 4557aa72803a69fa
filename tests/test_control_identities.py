"""Identity tests of the coprime factors, Youla and dual-Youla parametrisations (eqs. 1-14).

References: Zhou, Doyle & Glover, Robust and Optimal Control (1996), ch. 5 and ch. 12
(doubly coprime factors of the observer-based controller, Youla parametrisation and the
closed-loop poles of K(Q)); Lauridsen et al. (the seed paper) eqs. 3, 4, 9-13 with the
corrections of ../shared/METHOD.md section 3. Each test states its tolerance.
"""

from __future__ import annotations

import control as ct
import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from bayes_amb.control import (
    bezout_residual,
    coprime_factors,
    design_observer_controller,
    freqresp,
)
from bayes_amb.control.coprime import CoprimeFactors, ss, unit_circle
from bayes_amb.control.discrete import spectral_radius, ss_freqresp, zoh
from bayes_amb.control.robustness import closed_loop_matrix, loop_spectral_radius
from bayes_amb.control.youla import (
    discrete_plant,
    g_of_s,
    g_of_s_left,
    gain,
    hcat,
    k_of_q,
    lft_transfer_blocks,
    s_theta,
    s_theta_exact,
    s_theta_lft,
    t_cl,
)
from bayes_amb.reduction import reduce_pseudo_modal
from bayes_amb.rig import load_rig
from bayes_amb.uncertainty import lft_reduced
from tests.helpers import dlsim, rel_freq, rel_signal

DT = 1e-4
ALL_KC = "k_Ax,k_Ay,k_Bx,k_By,c_Ax,c_Ay,c_Bx,c_By"
THETA_8 = np.array([0.3, -0.2, 0.5, 0.4, 0.2, -0.3, 0.1, 0.5])
PARAM_SETS = [("k_By", np.array([0.5])), ("k_By", np.array([-0.5])), (ALL_KC, THETA_8)]


# ---------------------------------------------------------------- fixtures and helpers
@pytest.fixture(scope="module")
def rig():
    return load_rig()


@pytest.fixture(scope="module")
def reduced(rig):
    return reduce_pseudo_modal(rig)


@pytest.fixture(scope="module")
def ctrls(reduced):
    """Observer-based controllers at dt = 1e-4 s (default) and 1e-3 s (the paper's case)."""
    return {dt: design_observer_controller(reduced, dt) for dt in (1e-4, 1e-3)}


@pytest.fixture(scope="module")
def ctrl(ctrls):
    return ctrls[DT]


@pytest.fixture(scope="module")
def factors(ctrl):
    return coprime_factors(ctrl)


@pytest.fixture(scope="module")
def z():
    return unit_circle(DT, 400)


# ---------------------------------------------------------------- eq. 3, factors of G and K
@pytest.mark.parametrize("dt", [1e-4, 1e-3])
def test_double_bezout_on_400_point_grid(ctrls, dt):
    """Eq. 3 [Vt -Ut; -Nt Mt][M U; N V] = I (both orders), relative residual < 1e-9 on the
    full 400-point grid from 0.1 Hz to Nyquist; reference: Zhou-Doyle-Glover thm 5.9."""
    f = coprime_factors(ctrls[dt])
    z = unit_circle(dt, 400)
    assert z.size == 400
    assert bezout_residual(f, z) < 1e-9


def test_bezout_check_detects_wrong_factors(factors):
    """The residual is not vacuous: a 1 % error in Mt's observer gain is detected (> 1e-4)."""
    f = factors
    Mt_bad = ss(np.asarray(f.Mt.A), 1.01 * np.asarray(f.Mt.B), np.asarray(f.Mt.C),
                np.asarray(f.Mt.D), f.dt)
    bad = CoprimeFactors(M=f.M, N=f.N, U=f.U, V=f.V, Mt=Mt_bad, Nt=f.Nt, Ut=f.Ut, Vt=f.Vt,
                         dt=f.dt)
    assert bezout_residual(bad) > 1e-4


@pytest.mark.parametrize("dt", [1e-4, 1e-3])
def test_plant_factors_give_nominal_plant(ctrls, dt):
    """G = N M^-1 = Mt^-1 Nt equals C (zI - A)^-1 B of the ZOH reduced plant (rel. 1e-9)."""
    c = ctrls[dt]
    f = coprime_factors(c)
    z = unit_circle(dt, 400)
    G = ss_freqresp(c.A, c.B, c.C, None, z)
    M, N, Mt, Nt = (freqresp(s, z) for s in (f.M, f.N, f.Mt, f.Nt))
    assert rel_freq(N @ np.linalg.inv(M), G) < 1e-9
    assert rel_freq(np.linalg.solve(Mt, Nt), G) < 1e-9


@pytest.mark.parametrize("dt", [1e-4, 1e-3])
def test_controller_factors_give_controller(ctrls, dt):
    """K = U V^-1 = Vt^-1 Ut equals controller_matrices() (rel. 1e-9)."""
    c = ctrls[dt]
    f = coprime_factors(c)
    z = unit_circle(dt, 400)
    K = ss_freqresp(*c.controller_matrices(), z)
    U, V, Ut, Vt = (freqresp(s, z) for s in (f.U, f.V, f.Ut, f.Vt))
    assert rel_freq(U @ np.linalg.inv(V), K) < 1e-9
    assert rel_freq(np.linalg.solve(Vt, Ut), K) < 1e-9


# ---------------------------------------------------------------- eq. 4, Youla
def random_stable_q(rng: np.random.Generator, n: int, scale: float, dt: float,
                    radius: float = 0.9) -> ct.StateSpace:
    """A random 4x4 discrete system with spectral radius ``radius`` and gain ~ ``scale``."""
    A = rng.standard_normal((n, n))
    A *= radius / spectral_radius(A)
    return ss(A, rng.standard_normal((n, 4)), scale * rng.standard_normal((4, n)),
              scale * rng.standard_normal((4, 4)), dt)


def test_k_of_zero_q_is_k(ctrl, factors, z):
    """Eq. 4 with Q = 0 gives K = [A+BF+LC | -L ; F | 0] (rel. 1e-9)."""
    K0 = k_of_q(factors, gain(np.zeros((4, 4)), DT))
    assert rel_freq(freqresp(K0, z), ss_freqresp(*ctrl.controller_matrices(), z)) < 1e-9


def test_k_of_random_stable_q_stabilises(ctrl, factors, z):
    """K(Q) for a stable random Q stabilises the nominal plant.

    Reference: Zhou-Doyle-Glover thm 12.8 / 12.17: the closed-loop poles of (A, B, C) with
    K(Q) realised as the LFT of the Youla port J_K with Q are eig(A+BF), eig(A+LC) and
    eig(A_Q) (matched to 1e-7 absolute). Eq. 4 (k_of_q) agrees with that LFT (rel. 1e-9).
    """
    rng = np.random.default_rng(20240603)
    Q = random_stable_q(rng, 6, 1e4, DT)        # |Q| ~ 1e4 A/m, the size of the PID's kp
    J = ss(*ctrl.youla_port_matrices(), DT)
    K_lft = J.lft(Q, nu=4, ny=4)
    assert rel_freq(freqresp(k_of_q(factors, Q), z), freqresp(K_lft, z)) < 1e-9
    Kmats = tuple(np.asarray(m) for m in (K_lft.A, K_lft.B, K_lft.C, K_lft.D))
    assert loop_spectral_radius(ctrl.A, ctrl.B, ctrl.C, Kmats) < 1.0
    closed = np.linalg.eigvals(closed_loop_matrix(ctrl.A, ctrl.B, ctrl.C, *Kmats))
    expected = np.concatenate([np.linalg.eigvals(ctrl.A + ctrl.B @ ctrl.F),
                               np.linalg.eigvals(ctrl.A + ctrl.L @ ctrl.C),
                               np.linalg.eigvals(np.asarray(Q.A))])
    rows, cols = linear_sum_assignment(np.abs(closed[:, None] - expected[None, :]))
    assert np.max(np.abs(closed[rows] - expected[cols])) < 1e-7


# ---------------------------------------------------------------- eq. 9, G(S)
def test_g_of_zero_s_is_g(ctrl, factors, z):
    """G(S = 0) equals the nominal plant in both forms (rel. 1e-12)."""
    S0 = gain(np.zeros((4, 4)), DT)
    G = ss_freqresp(ctrl.A, ctrl.B, ctrl.C, None, z)
    assert rel_freq(freqresp(g_of_s(factors, S0), z), G) < 1e-12
    assert rel_freq(freqresp(g_of_s_left(factors, S0), z), G) < 1e-12


@pytest.mark.parametrize(("params", "theta"), PARAM_SETS, ids=["k_By+", "k_By-", "8 k/c"])
def test_g_of_s_theta_is_sampled_plant(ctrl, factors, reduced, rig, z, params, theta):
    """G(S(theta)) (corrected eq. 9, both forms) equals the exactly sampled G(theta)
    (discrete_plant) to rel. 1e-9."""
    up = lft_reduced(reduced, rig, params)
    S = s_theta(ctrl, up, theta)
    G_theta = ss_freqresp(*discrete_plant(up, theta, DT), None, z)
    G_nom = ss_freqresp(ctrl.A, ctrl.B, ctrl.C, None, z)
    assert rel_freq(G_nom, G_theta) > 1e-3          # the perturbation is not negligible
    assert rel_freq(freqresp(g_of_s(factors, S), z), G_theta) < 1e-9
    assert rel_freq(freqresp(g_of_s_left(factors, S), z), G_theta) < 1e-9


# ---------------------------------------------------------------- S(theta)
def test_s_of_nominal_plant_is_exactly_zero(ctrl, reduced, rig):
    """S(0) = 0 exactly: zero B rows on the error states, zero C columns on x_p, and a
    dlsim response to random input that is exactly 0 (no tolerance). Not vacuous: at
    theta = 0.3 on k_By the same response exceeds 1e-5 of the plant factor N's response."""
    A_S, B_S, C_S, D_S = s_theta_exact(ctrl, ctrl.A, ctrl.B, ctrl.C)
    n = ctrl.n_states
    assert not np.any(B_S[:n]) and not np.any(C_S[:, n:]) and not np.any(D_S)
    u = np.random.default_rng(1).standard_normal((500, 4))
    y = dlsim(ss(A_S, B_S, C_S, D_S, DT), u)
    assert np.all(y == 0.0)
    y_pert = dlsim(s_theta(ctrl, lft_reduced(reduced, rig, "k_By"), [0.3]), u)
    y_N = dlsim(coprime_factors(ctrl).N, u)
    assert np.max(np.abs(y_pert)) > 1e-5 * np.max(np.abs(y_N))


def theta_grid() -> list[tuple[str, np.ndarray]]:
    """Each k_* and c_* alone at +-0.25, +-0.5; 6 corners and 4 interior points of the box."""
    names = ALL_KC.split(",")
    out = [(nm, np.array([v])) for nm in names for v in (-0.5, -0.25, 0.25, 0.5)]
    rng = np.random.default_rng(7)
    out += [(ALL_KC, 0.5 * rng.choice([-1.0, 1.0], 8)) for _ in range(6)]
    out += [(ALL_KC, rng.uniform(-0.5, 0.5, 8)) for _ in range(4)]
    return out


def test_s_theta_stable_while_open_loop_unstable(ctrl, reduced, rig):
    """Figs. 6/7: over |theta| <= 0.5 on each k_* and c_* (alone, and 10 points of the
    8-dim box) S(theta) is Schur stable although the continuous G(theta) has RHP poles."""
    worst_s, least_rhp = 0.0, np.inf
    cache = {}
    for params, theta in theta_grid():
        up = cache.setdefault(params, lft_reduced(reduced, rig, params))
        A_S = s_theta_exact(ctrl, *discrete_plant(up, theta, DT))[0]
        worst_s = max(worst_s, spectral_radius(A_S))
        least_rhp = min(least_rhp, float(np.max(np.linalg.eigvals(up.A_theta(theta)).real)))
    assert worst_s < 1.0
    assert least_rhp > 0.0


# ---------------------------------------------------------------- eq. 13
@pytest.mark.parametrize(("params", "theta"),
                         [*PARAM_SETS, ("k_By,c_Ax,kxy_A", np.array([0.4, 0.3, 0.5]))],
                         ids=["k_By+", "k_By-", "8 k/c", "k,c,kxy"])
def test_eq13_equals_exact_s_on_discrete_lft_plant(ctrl, factors, reduced, rig, z, params,
                                                    theta):
    """Eq. 13 (s_theta_lft) equals s_theta_exact on the discrete LFT plant
    A_d + B_wd Theta C_z (B_wd from the ZOH of B_w): relative to the peak of |S| over the
    grid (H-infinity sense) < 1e-9, and pointwise relative < 1e-6 (at the Nyquist frequency
    |S| is 1e-6 of its peak and the LFT form loses digits there).

    Not vacuous: |S| peaks above 1e-4 of |N|, and S of the *exactly* sampled plant (not an
    LFT in theta) differs from this one by more than 1 % of the peak."""
    up = lft_reduced(reduced, rig, params)
    Ad, Bd = zoh(up.A, up.B, DT)
    _, B_wd = zoh(up.A, up.B_w, DT)
    td = up.theta_diag(theta)
    Ap = Ad + (B_wd * td) @ up.C_z
    S_exact = freqresp(ss(*s_theta_exact(ctrl, Ap, Bd, up.C), DT), z)
    S_lft = freqresp(s_theta_lft(factors, *lft_transfer_blocks(Ad, Bd, up.C, B_wd, up.C_z,
                                                               DT), td), z)
    peak = np.linalg.norm(S_exact, axis=(1, 2)).max()
    assert peak > 1e-4 * np.linalg.norm(freqresp(factors.N, z), axis=(1, 2)).max()
    assert np.linalg.norm(S_lft - S_exact, axis=(1, 2)).max() / peak < 1e-9
    assert rel_freq(S_lft, S_exact) < 1e-6
    S_sampled = freqresp(s_theta(ctrl, up, theta), z)
    assert np.linalg.norm(S_sampled - S_exact, axis=(1, 2)).max() / peak > 1e-2


# ---------------------------------------------------------------- eqs. 10-11, time domain
def simulate_fig2_loop(ctrl, Ap, Bp, Cp, r1, r2, eta):
    """Fig. 2 loop by hand: the plant (Ap, Bp, Cp), the observer-based controller fed with
    y + r1, u_c = F xhat + eta, plant input u = u_c + r2. Returns y, u (plant input), eps."""
    A, B, C, F, L = ctrl.A, ctrl.B, ctrl.C, ctrl.F, ctrl.L
    n = r1.shape[0]
    xp, xh = np.zeros(Ap.shape[0]), np.zeros(A.shape[0])
    Y, U, E = np.empty((n, 4)), np.empty((n, 4)), np.empty((n, 4))
    for k in range(n):
        y = Cp @ xp
        y_c = y + r1[k]
        u_c = F @ xh + eta[k]
        u = u_c + r2[k]
        E[k] = y_c - C @ xh
        Y[k], U[k] = y, u
        xp = Ap @ xp + Bp @ u
        xh = A @ xh + B @ u_c + L @ (C @ xh - y_c)
    return Y, U, E


@pytest.fixture(scope="module")
def loop_case(ctrl, reduced, rig):
    """G(theta) for all 8 k/c parameters, exactly sampled."""
    up = lft_reduced(reduced, rig, ALL_KC)
    return up, discrete_plant(up, THETA_8, DT)


def test_t_cl_matches_loop_simulation(ctrl, factors, loop_case):
    """T_cl(S(theta)) (eqs. 10-11, third row corrected) driven by random r1, r2, eta equals
    the hand-written time-domain loop for y, u and eps (rel. 1e-8 per channel)."""
    up, (Ap, Bp, Cp) = loop_case
    rng = np.random.default_rng(11)
    n = 2000
    r1 = 1e-6 * rng.standard_normal((n, 4))        # m, sensor-side injection
    r2 = 0.1 * rng.standard_normal((n, 4))         # A, plant-input injection
    eta = 0.1 * rng.standard_normal((n, 4))        # A, Youla port
    Y, U, E = simulate_fig2_loop(ctrl, Ap, Bp, Cp, r1, r2, eta)
    out = dlsim(t_cl(factors, s_theta(ctrl, up, THETA_8)), np.hstack([r1, r2, eta]))
    assert rel_signal(out[:, :4], Y) < 1e-8
    assert rel_signal(out[:, 4:8], U) < 1e-8
    assert rel_signal(out[:, 8:], E) < 1e-8


def test_dual_youla_signals_noise_free(ctrl, factors, loop_case):
    """With r1 = r2 = 0: eps = Mt y - Nt u equals S(theta) eta and the loop's innovation,
    and x = Vt u - Ut y equals eta (rel. 1e-8 per channel); METHOD.md section 3."""
    up, (Ap, Bp, Cp) = loop_case
    rng = np.random.default_rng(12)
    n = 2000
    zero = np.zeros((n, 4))
    eta = 0.1 * rng.standard_normal((n, 4))
    Y, U, E = simulate_fig2_loop(ctrl, Ap, Bp, Cp, zero, zero, eta)
    yu = np.hstack([Y, U])
    eps = dlsim(hcat(factors.Mt, -factors.Nt), yu)
    x = dlsim(hcat(-factors.Ut, factors.Vt), yu)
    assert rel_signal(eps, dlsim(s_theta(ctrl, up, THETA_8), eta)) < 1e-8
    assert rel_signal(eps, E) < 1e-8
    assert rel_signal(x, eta) < 1e-8
