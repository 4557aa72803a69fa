"""The diagnosis' Gauss-Newton MAP search (bayes_amb.discrepancy.gauss_newton).

Identity tests: the linear model at its own point is the exact log posterior, its gradient
is the exact gradient (up to the forward-difference step of J), and it is exact in the
noise intensities. Search tests: from the same start it reaches the optimum that L-BFGS-B
with central-difference gradients reaches (a stationary point of the exact posterior), and
the eq. 15 estimate (Gauss-Newton) reaches the L-BFGS-B minimum.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.optimize as so

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.discrepancy import ActuatorLag, SensorGain
from bayes_amb.discrepancy import gauss_newton as gn
from bayes_amb.discrepancy.fitting import build, extend, fit_nominal
from bayes_amb.inference.estimate import LogPosterior, least_squares_theta, local_search
from bayes_amb.inference.forward import ForwardModel
from bayes_amb.inference.offline import dual_youla_eps
from bayes_amb.inference.priors import PriorSet
from bayes_amb.inference.whittle import WhittleLikelihood
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, parse_effect, simulate_recording

NAMES = ("k_Ax", "k_By", "c_Bx", "c_By")


def _case(effects):
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, 1e-4), rig)
    cfg = SimulationConfig(truth="reduced", params={"k_By": 0.3, "c_Bx": 0.1}, dt=1e-4,
                           duration=0.3, noise_rms=1e-7, r2_rms=0.02, seed=7,
                           effects=tuple(parse_effect(e) for e in effects))
    rec = simulate_recording(rig, ctrl, cfg)[0]
    fm = ForwardModel(rec, NAMES)
    eps = dual_youla_eps(fm.parts, np.asarray(rec.y), np.asarray(rec.u))
    return rec, eps


@pytest.fixture(scope="module")
def case():
    """A hidden 1500 Hz actuator lag."""
    return _case(["actuator_lag:bandwidth_hz=1500"])


@pytest.fixture(scope="module")
def clean():
    return _case(["sensor_gain:channel=By,gain=0.05"])


def _fd_gradient(post, x, h):
    g = np.empty(x.size)
    for j in range(x.size):
        e = np.zeros(x.size)
        e[j] = h[j]
        g[j] = (post((x + e)[None])[0] - post((x - e)[None])[0]) / (2 * h[j])
    return g


def test_linear_model_is_exact_at_its_point(case):
    rec, eps = case
    _, like, post = build(rec, NAMES, eps)
    x = np.array([0.05, 0.2, 0.05, -0.05, -7.0, -9.0, -1.7])
    like.set_noise_reference(x[:4])
    lin = gn.linearise(post, x, np.arange(4))
    f, g_theta, g_ls = lin.value_grad(np.zeros(4), x[4:])
    exact = post(x[None])[0]
    assert abs(f - exact) <= 1e-9 * abs(exact)
    # exact in the noise intensities: the model away from x along log10 sigma only
    ls = x[4:] + np.array([0.3, -0.5, 0.2])
    f_ls = lin.value_grad(np.zeros(4), ls)[0]
    exact_ls = post(np.r_[x[:4], ls][None])[0]
    assert abs(f_ls - exact_ls) <= 1e-9 * abs(exact_ls)
    h = np.r_[np.full(4, 1e-5), np.full(3, 1e-4)]
    g_fd = _fd_gradient(post, x, h)
    # J by forward differences (step 1e-5) against central differences of log p: both
    # carry an O(h) or O(h^2) error, small against the gradient itself
    g = np.r_[g_theta, g_ls]
    assert np.all(np.abs(g - g_fd) <= 1e-4 * np.abs(g_fd) + 1e-2), (g, g_fd)
    # a wrong Jacobian column is seen
    lin.MT[1] *= 1.01
    assert abs(lin.value_grad(np.zeros(4), x[4:])[1][0] - g_fd[0]) > 1e-3 * abs(g_fd[0])


def test_compiled_band_algebra_is_the_numpy_one(case):
    """value_grad's compiled band algebra (inference/hermitian_kernels.py) gives the numpy
    path's value and gradients away from the linear model's point too, and refuses the
    same points (a noise spectrum that is not positive definite)."""
    rec, eps = case
    _, like, post = build(rec, NAMES, eps)
    x = np.array([0.05, 0.2, 0.05, -0.05, -7.0, -9.0, -1.7])
    like.set_noise_reference(x[:4])
    lin = gn.linearise(post, x, np.arange(4))
    _, Psi, *_ = lin._noise_terms(x[4:])
    wt = like.nu + like.counts
    rng = np.random.default_rng(3)
    for _ in range(5):
        w = np.r_[1.0, 0.05 * rng.standard_normal(4)]
        ok, ld, gq, gs = gn.linear_terms(lin.MT, w, Psi, lin.phi, wt)
        ok_np, ld_np, gq_np, gs_np = lin._terms_numpy(w, Psi, wt)
        assert ok and ok_np
        assert abs(ld - ld_np) <= 1e-11 * abs(ld_np)
        assert np.allclose(gq, gq_np, rtol=1e-9, atol=1e-9 * np.abs(gq_np).max())
        assert np.allclose(gs, gs_np, rtol=1e-9, atol=1e-9 * np.abs(gs_np).max())
    bad = Psi.copy()
    bad[0] = np.diag([-1e30, 1.0, 1.0, 1.0])
    w = np.r_[1.0, np.zeros(4)]
    assert not gn.linear_terms(lin.MT, w, bad, lin.phi, wt)[0]
    assert not lin._terms_numpy(w, bad, wt)[0]


def test_analytic_curvatures_are_the_gradients_differences(case):
    """LinearModel.hessian (its diagonal: the trust region's scales; the whole: the Newton
    start of the linear model's search) equals central differences of the linear
    model's own analytic gradient, prior included; a wrong M_jj is seen."""
    rec, eps = case
    _, like, post = build(rec, NAMES, eps)
    x = np.array([0.05, 0.2, 0.05, -0.05, -7.0, -9.0, -1.7])
    like.set_noise_reference(x[:4])
    lin = gn.linearise(post, x, np.arange(4))
    curv = np.diag(lin.hessian(x[4:]))
    fd = np.empty(4)
    for j in range(4):
        dv = np.zeros(4)
        dv[j] = 1e-6
        fd[j] = -(lin.value_grad(dv, x[4:])[1][j] - lin.value_grad(-dv, x[4:])[1][j]) / 2e-6
    assert np.all(fd > 0)
    assert np.allclose(curv, fd, rtol=1e-6), (curv, fd)
    MT = lin.MT.copy()
    MT[2, :, 2] *= 1.5                          # M[2, 2]: column 1's own block
    wrong = gn.LinearModel(post, lin.x0, lin.cols, MT)
    assert abs(wrong.hessian(x[4:])[1, 1] / fd[1] - 1) > 1e-3
    # the off-diagonal entries: differences of the gradient along another column
    H = lin.hessian(x[4:])
    dv = np.zeros(4)
    dv[3] = 1e-6
    col = -(lin.value_grad(dv, x[4:])[1] - lin.value_grad(-dv, x[4:])[1]) / 2e-6
    assert np.allclose(H[:, 3], col, rtol=1e-5, atol=1e-6 * np.abs(col).max()), (H[:, 3], col)
    assert np.allclose(H, H.T, rtol=1e-12, atol=1e-12 * np.abs(H).max())


def test_a_family_members_hessian_is_its_gradients_differences(case):
    """A scan member's linear model (family._Restricted: the member's priors in place of the
    basis' wide ones) has the Hessian of its own value_grad, lognormal prior included."""
    from bayes_amb.discrepancy.family import _Restricted
    from bayes_amb.inference.priors import Prior

    rec, eps = case
    _, like, post = build(rec, NAMES, eps)
    x = np.array([0.05, 0.2, 0.05, -0.05, -7.0, -9.0, -1.7])
    like.set_noise_reference(x[:4])
    lin = gn.linearise(post, x, np.arange(4))
    pri = [Prior("normal", 0.0, 0.02), Prior("lognormal", 0.0, 0.5),
           Prior("normal", 0.1, 0.3), Prior("uniform", -1.0, 1.0)]
    r = _Restricted(lin, pri, np.array([0.0, 1.0, 0.0, 0.0]))
    H = r.hessian(x[4:])
    for j in range(4):
        dv = np.zeros(4)
        dv[j] = 1e-6
        col = -(r.value_grad(dv, x[4:])[1] - r.value_grad(-dv, x[4:])[1]) / 2e-6
        assert np.allclose(H[:, j], col, rtol=1e-5, atol=1e-6 * np.abs(col).max()), (j, H, col)
    # the member's priors are in it: the normal one's 1/sd^2 on its diagonal
    assert H[0, 0] - lin.hessian(x[4:])[0, 0] == pytest.approx(1 / 0.02**2, rel=1e-4)


def test_search_reaches_the_lbfgs_optimum(clean):
    rec, eps = clean
    nominal = fit_nominal(rec, NAMES, eps)
    _, like, post = extend(nominal, SensorGain("sensor_gain", "By"))
    x0 = np.r_[np.zeros(4), 0.0, nominal.log10_sigma]
    like.set_noise_reference(x0[:post.p])
    x_lb, _ = local_search(post, "lbfgs", x0)
    f_lb = post(x_lb[None])[0]
    x_gn, f_gn = gn.gauss_newton(post, x0)
    assert f_gn >= f_lb - 1e-5
    assert np.allclose(x_gn, x_lb, rtol=0, atol=2e-4), (x_gn, x_lb)
    # stationary: no coordinate gains more than 1e-4 nats in one curvature step
    h = np.r_[np.full(post.p, 1e-5), np.full(3, 1e-4)]
    g = _fd_gradient(post, x_gn, h)
    H = np.array([(post((x_gn + e)[None])[0] - 2 * f_gn + post((x_gn - e)[None])[0])
                  for e in np.diag(h * 10)]) / (h * 10) ** 2
    assert np.all(0.5 * g**2 / np.abs(H) < 1e-4)


def test_search_leaves_a_bound_the_nominal_fit_absorbed_the_lag_on(case):
    """The nominal fit takes the lag as negative damping (c_Bx, c_By on the -0.8 bound).
    The Gauss-Newton step of the linear model leaves it, as high as from a neutral start;
    so does L-BFGS-B now that its gradient on a bound is one-sided towards the inside
    (estimate._grad; with a zero there it stayed on the bound, many nats lower)."""
    rec, eps = case
    nominal = fit_nominal(rec, NAMES, eps)
    assert nominal.value("c_By") == pytest.approx(-0.8)
    _, like, post = extend(nominal, ActuatorLag("actuator_lag", "both"))
    x0 = np.r_[nominal.params, 0.05, nominal.log10_sigma]
    like.set_noise_reference(x0[:post.p])
    x_lb, _ = local_search(post, "lbfgs", x0)
    x_gn, f_gn = gn.gauss_newton(post, x0)
    _, f_ref = gn.gauss_newton(post, np.r_[np.zeros(4), x0[4:]])
    assert f_gn >= f_ref - 1e-5 and x_gn[3] > -0.5     # as high as from a neutral start
    assert x_lb[3] > -0.5 and post(x_lb[None])[0] > f_gn - 0.1


def _eq15_lbfgs(like, theta0, bounds):
    """The eq. 15 cost minimised by L-BFGS-B with central differences (the search both
    MAPs started from before the Gauss-Newton one): the reference."""
    h = np.full(theta0.size, 1e-6)

    def fun(th):
        v = like.sum_squares(np.vstack([th, th + np.diag(h), th - np.diag(h)]))
        return float(v[0]), (v[1:th.size + 1] - v[th.size + 1:]) / (2 * h)

    return so.minimize(fun, theta0, jac=True, method="L-BFGS-B", bounds=bounds,
                       options={"maxiter": 500, "ftol": 1e-15, "gtol": 1e-10}).x


def test_least_squares_start_reaches_the_lbfgs_minimum(case):
    """The diagnosis' eq. 15 start and identify's first stage (both Gauss-Newton,
    inference/least_squares.py) reach the minimum L-BFGS-B reaches, in a few batches."""
    rec, eps = case
    _, _, post = build(rec, NAMES, eps)
    n0 = post.n_evals
    theta_gn = gn.least_squares_start(post, np.zeros(4))
    assert post.n_evals - n0 <= 8 * (4 + 2) + 1
    ipost = LogPosterior(WhittleLikelihood(ForwardModel(rec, NAMES), eps),
                         PriorSet.build(NAMES))
    theta_id = least_squares_theta(ipost, "lbfgs", np.zeros(4))
    theta_lb = _eq15_lbfgs(post.likelihood, np.zeros(4), post.bounds()[:4])
    cost_gn, cost_lb = post.likelihood.sum_squares(np.vstack([theta_gn, theta_lb]))
    assert cost_gn <= cost_lb * (1 + 1e-10)
    assert np.allclose(theta_gn, theta_lb, rtol=0, atol=1e-5)
    theta_ilb = _eq15_lbfgs(ipost.likelihood, np.zeros(4), ipost.bounds()[:4])
    cost_id, cost_ilb = ipost.likelihood.sum_squares(np.vstack([theta_id, theta_ilb]))
    assert cost_id <= cost_ilb * (1 + 1e-10)
    assert np.allclose(theta_id, theta_ilb, rtol=0, atol=1e-5)
