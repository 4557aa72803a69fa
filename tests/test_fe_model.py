"""FE rotor model (eq. 17): reference tests against analytic beam and rigid-rotor results.

Beam constants: free-free (beta_n L) = 4.730040745, 7.853204624, 10.995607838 and
pinned-pinned n*pi (Blevins, Formulas for Natural Frequency and Mode Shape, table 8-1);
omega_n = (beta_n L)^2 / L^2 * sqrt(EI / (rho A)) for an Euler-Bernoulli beam.
Rayleigh beam (rotary inertia, spinning), pinned-pinned with k = n pi / L:
rho (A + I k^2) w^2 -/+ 2 rho I Omega k^2 w - EI k^4 = 0 (Genta, Dynamics of Rotating
Systems, 2005, sec. 5.5; the upper sign is forward whirl).
Rigid rotor, tilt: Id w^2 -/+ Ip Omega w - k_t = 0 (Friswell et al. 2010, sec. 3.5).
Forward whirl is counterclockwise x -> y, the direction of spin about +z.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from bayes_amb.rig import load_rig, rig_from_dict
from bayes_amb.rotor import (
    assemble,
    bending_frequencies_hz,
    channel_dofs,
    disc_matrices,
    dof_index,
    full_model,
    rpm_to_rad_s,
    shaft_element,
    state_matrices,
    unstable_poles,
)
from bayes_amb.rotor.assembly import shaft_matrices

FREE_FREE_BETA_L = np.array([4.730040745, 7.853204624, 10.995607838])
PINNED_BETA_L = np.pi * np.arange(1, 4)


def beam_rig(n_el: int, length: float = 0.45, diameter: float = 0.09):
    """Bare uniform steel shaft, no discs, ks = 0, no damping (reference material)."""
    n = n_el + 1
    return rig_from_dict({
        "shaft": {"youngs_modulus": 211e9, "density": 7810.0, "poisson": 0.3,
                  "diameter": diameter, "length": length, "n_nodes": n},
        "bearings": {"ki": 1.0, "ks": 0.0, "A": {"node": 1}, "B": {"node": n}},
        "sensors": {"A": {"node": 1}, "B": {"node": n}},
        "damping": {"first_mode_zeta": 0.0},
        "operation": {"nominal_speed_rpm": 0.0},
    }, source="beam")


def rotary_mass(rig) -> np.ndarray:
    """The rho*I (rotary-inertia) part of the shaft mass matrix (element built with A = 0)."""
    s = rig.shaft
    le = s.length / (s.n_nodes - 1)
    Me = shaft_element(le, s.youngs_modulus, s.density, 0.0, s.second_moment)[0]
    M = np.zeros((4 * s.n_nodes, 4 * s.n_nodes))
    for e in range(s.n_nodes - 1):
        M[4 * e:4 * e + 8, 4 * e:4 * e + 8] += Me
    return M


def x_plane(n_nodes: int) -> list[int]:
    return sorted([dof_index(i, "x") for i in range(1, n_nodes + 1)]
                  + [dof_index(i, "ty") for i in range(1, n_nodes + 1)])


def beam_frequencies(n_el: int, support: str, rotary: bool, length=0.45, diameter=0.09):
    """First three x-plane bending frequencies divided by sqrt(EI/(rho A))/L^2."""
    rig = beam_rig(n_el, length, diameter)
    M, K, _ = shaft_matrices(rig)
    if not rotary:
        M = M - rotary_mass(rig)
    keep = x_plane(rig.n_nodes)
    if support == "pinned":
        keep = [j for j in keep if j not in (dof_index(1, "x"), dof_index(rig.n_nodes, "x"))]
    w2 = sla.eigh(K[np.ix_(keep, keep)], M[np.ix_(keep, keep)], eigvals_only=True)
    flexible = w2[2:5] if support == "free" else w2[:3]
    s = rig.shaft
    scale = np.sqrt(s.youngs_modulus * s.second_moment / (s.density * s.area)) / s.length**2
    return np.sqrt(flexible) / scale


@pytest.mark.parametrize(("support", "beta_l"), [("free", FREE_FREE_BETA_L),
                                                 ("pinned", PINNED_BETA_L)])
def test_euler_bernoulli_frequencies_39_elements(support, beta_l):
    """Reference shaft (L = 0.45 m, d = 0.09 m), 39 elements, rotary inertia removed
    (M minus its rho*I part), so the model is a pure Euler-Bernoulli beam.
    Tolerance 0.5 %; measured errors are below 3e-6."""
    err = beam_frequencies(39, support, rotary=False) / beta_l**2 - 1.0
    assert np.all(np.abs(err) < 5e-3), err


@pytest.mark.parametrize(("support", "beta_l"), [("free", FREE_FREE_BETA_L),
                                                 ("pinned", PINNED_BETA_L)])
def test_slender_beam_with_rotary_inertia(support, beta_l):
    """Slender shaft (L/d = 100) with the element's rotary inertia left in: Euler-Bernoulli
    values within 0.5 % (rotary inertia shifts them by ~(n pi d / 4L)^2/2 < 0.02 %)."""
    err = beam_frequencies(39, support, rotary=True, length=1.0, diameter=0.01) / beta_l**2 - 1
    assert np.all(np.abs(err) < 5e-3), err


@pytest.mark.parametrize(("support", "beta_l"), [("free", FREE_FREE_BETA_L),
                                                 ("pinned", PINNED_BETA_L)])
def test_error_decreases_with_mesh(support, beta_l):
    """Convergence: |error| of each of the first three modes falls strictly from 4 to 8 to 16
    elements (Euler-Bernoulli, rotary inertia removed); at 4 elements modes 2-3 are off
    by more than 0.3 %, so the comparison is not within round-off."""
    errs = np.array([np.abs(beam_frequencies(n, support, rotary=False) / beta_l**2 - 1)
                     for n in (4, 8, 16)])
    assert np.all(np.diff(errs, axis=0) < 0), errs
    assert errs[0, 2] > 3e-3


def test_rayleigh_beam_pinned_pinned_rotary_inertia():
    """Stubby reference shaft (L/d = 5), rotary inertia in: pinned-pinned Rayleigh-beam
    frequencies w^2 = EI k^4 / (rho (A + I k^2)) within 1e-4 relative (39 elements)."""
    rig = beam_rig(39)
    s = rig.shaft
    k = PINNED_BETA_L / s.length
    w_exact = np.sqrt(s.youngs_modulus * s.second_moment * k**4
                      / (s.density * (s.area + s.second_moment * k**2)))
    scale = np.sqrt(s.youngs_modulus * s.second_moment / (s.density * s.area)) / s.length**2
    w_fe = beam_frequencies(39, "pinned", rotary=True) * scale
    assert np.allclose(w_fe, w_exact, rtol=1e-4, atol=0)
    # and rotary inertia matters here: more than 1 % below Euler-Bernoulli for mode 3
    assert w_exact[2] < 0.99 * PINNED_BETA_L[2] ** 2 * scale


def whirl_direction(v: np.ndarray, jx: int, jy: int) -> float:
    """angle(Y / X) of a mode at x and y DOFs: -pi/2 forward (x -> y), +pi/2 backward."""
    return float(np.angle(v[jy] / v[jx]))


def first_order(M, G, K, omega):
    n = M.shape[0]
    Mi = np.linalg.inv(M)
    return np.block([[np.zeros((n, n)), np.eye(n)], [-Mi @ K, -Mi @ (omega * G)]])


def positive_modes(A):
    lam, V = np.linalg.eig(A)
    sel = lam.imag > 1e-6
    order = np.argsort(lam[sel].imag)
    return lam[sel][order], V[:, sel][:, order]


@pytest.mark.parametrize("rpm", [10000.0, 31500.0, 100000.0])
def test_spinning_pinned_pinned_shaft_whirl(rpm):
    """Pinned-pinned spinning Rayleigh beam (x and y pinned at both ends), first mode:
    backward/forward whirl frequencies within 1e-6 relative of the analytic roots; the
    rising (forward) root whirls x -> y at midspan (angle(Y/X) = -pi/2 to 1e-6), the
    falling one y -> x. This checks sign and size of the shaft gyroscopic matrix."""
    rig = beam_rig(40)
    s = rig.shaft
    M, K, G = shaft_matrices(rig)
    n = rig.n_nodes
    pinned = {dof_index(1, "x"), dof_index(1, "y"), dof_index(n, "x"), dof_index(n, "y")}
    keep = [j for j in range(M.shape[0]) if j not in pinned]
    Om = rpm_to_rad_s(rpm)
    lam, V = positive_modes(first_order(*(X[np.ix_(keep, keep)] for X in (M, G, K)), Om))
    k = np.pi / s.length
    a = s.density * (s.area + s.second_moment * k**2)
    b = 2 * s.density * s.second_moment * Om * k**2
    c = s.youngs_modulus * s.second_moment * k**4
    w_b = (-b + np.sqrt(b * b + 4 * a * c)) / (2 * a)
    w_f = (b + np.sqrt(b * b + 4 * a * c)) / (2 * a)
    assert np.allclose(lam[:2].imag, [w_b, w_f], rtol=1e-6, atol=0)
    assert np.all(np.abs(lam[:2].real) < 1e-9 * np.abs(lam[:2]))
    mid = keep.index(dof_index(n // 2 + 1, "x"))     # midspan node of 40 elements
    assert whirl_direction(V[:, 0], mid, mid + 1) == pytest.approx(np.pi / 2, abs=1e-6)
    assert whirl_direction(V[:, 1], mid, mid + 1) == pytest.approx(-np.pi / 2, abs=1e-6)


def test_spinning_free_free_shaft_forward_whirl_rises():
    """Free-free bare reference shaft at 31500 rpm: the first bending pair splits around
    its 0-rpm frequency; the higher member whirls forward (x -> y at node 1), the lower
    backward (angles to 1e-6)."""
    rig = beam_rig(39)
    M, K, G = shaft_matrices(rig)
    w0 = positive_modes(first_order(M, G, K, 0.0))[0]
    w0 = w0[w0.imag > 100.0][0].imag
    lam, V = positive_modes(first_order(M, G, K, rpm_to_rad_s(31500.0)))
    pair = np.argsort(np.abs(lam.imag - w0))[:2]
    low, high = pair[np.argsort(lam[pair].imag)]
    assert lam[low].imag < w0 * (1 - 1e-3) and lam[high].imag > w0 * (1 + 1e-3)
    jx, jy = dof_index(1, "x"), dof_index(1, "y")
    assert whirl_direction(V[:, high], jx, jy) == pytest.approx(-np.pi / 2, abs=1e-6)
    assert whirl_direction(V[:, low], jx, jy) == pytest.approx(np.pi / 2, abs=1e-6)


def test_disc_on_springs_whirl():
    """One rigid disc on springs k (translation) and k_t (tilt), 4 DOF: frequencies
    sqrt(k/m) and the roots of Id w^2 -/+ Ip Omega w - k_t = 0 to 1e-6 relative at several
    speeds; the rising tilt root whirls forward (spin axis n = (theta_y, -theta_x) turns
    x -> y)."""
    m, ip, id_, k, kt = 6.0, 0.030, 0.017, 2.0e7, 4.0e5
    Md, Gd = disc_matrices(m, ip, id_)
    K = np.diag([k, k, kt, kt])
    for rpm in (0.0, 5000.0, 31500.0, 60000.0):
        Om = rpm_to_rad_s(rpm)
        lam, V = positive_modes(first_order(Md, Gd, K, Om))
        disc = np.sqrt((ip * Om) ** 2 + 4 * id_ * kt)
        expected = np.sort([np.sqrt(k / m)] * 2 + [(disc - ip * Om) / (2 * id_),
                                                   (disc + ip * Om) / (2 * id_)])
        assert np.allclose(lam.imag, expected, rtol=1e-6, atol=0)
        if rpm > 0:
            w_f = (disc + ip * Om) / (2 * id_)
            v = V[:, np.argmin(np.abs(lam.imag - w_f))]
            n_x, n_y = v[3], -v[2]                    # tilt of the spin axis
            assert np.angle(n_y / n_x) == pytest.approx(-np.pi / 2, abs=1e-6)


def rigid_projection(length: float) -> np.ndarray:
    """T (8, 4): element DOFs of a rigid motion [x_c, y_c, theta_x, theta_y] about midspan."""
    T = np.zeros((8, 4))
    for node, z in ((0, -length / 2), (1, length / 2)):
        T[4 * node + 0, [0, 3]] = [1.0, z]            # x = x_c + z theta_y
        T[4 * node + 1, [1, 2]] = [1.0, -z]           # y = y_c - z theta_x
        T[4 * node + 2, 2] = 1.0
        T[4 * node + 3, 3] = 1.0
    return T


def test_rigid_shaft_element_is_a_disc():
    """Identity (1e-12): one shaft element moved rigidly has m = rho A L,
    Id = rho A L^3/12 + rho I L, Ip = 2 rho I L and no strain energy; T^T G T equals the
    disc's G with that Ip, so beam and disc gyroscopic signs agree."""
    L, E, rho, d = 0.3, 211e9, 7810.0, 0.09
    A, I = np.pi * d**2 / 4, np.pi * d**4 / 64
    Me, Ke, Ge = shaft_element(L, E, rho, A, I)
    T = rigid_projection(L)
    Md, Gd = disc_matrices(rho * A * L, 2 * rho * I * L, rho * A * L**3 / 12 + rho * I * L)
    assert np.allclose(T.T @ Me @ T, Md, rtol=0, atol=1e-12 * np.abs(Md).max())
    assert np.allclose(T.T @ Ge @ T, Gd, rtol=0, atol=1e-12 * np.abs(Gd).max())
    assert np.abs(T.T @ Ke @ T).max() < 1e-12 * np.abs(Ke).max()


def test_two_node_rigid_rotor_whirl():
    """2-node rigid rotor (one shaft element projected on rigid motions) on springs k at
    both nodes: translation sqrt(2k/m) and tilt roots of Id w^2 -/+ Ip Omega w - k L^2/2 = 0
    to 1e-6; the rising tilt root whirls forward at node 2 (x -> y)."""
    L, E, rho, d, k = 0.3, 211e9, 7810.0, 0.09, 1.0e6
    A, I = np.pi * d**2 / 4, np.pi * d**4 / 64
    Me, Ke, Ge = shaft_element(L, E, rho, A, I)
    T = rigid_projection(L)
    Ks = np.zeros((8, 8))
    for j in (0, 1, 4, 5):
        Ks[j, j] = k
    Mr, Gr, Kr = T.T @ Me @ T, T.T @ Ge @ T, T.T @ (Ke + Ks) @ T
    m, ip, id_, kt = rho * A * L, 2 * rho * I * L, rho * A * L**3 / 12 + rho * I * L, k * L**2 / 2
    for rpm in (1000.0, 31500.0, 90000.0):
        Om = rpm_to_rad_s(rpm)
        lam, V = positive_modes(first_order(Mr, Gr, Kr, Om))
        disc = np.sqrt((ip * Om) ** 2 + 4 * id_ * kt)
        w_f = (disc + ip * Om) / (2 * id_)
        expected = np.sort([np.sqrt(2 * k / m)] * 2 + [(disc - ip * Om) / (2 * id_), w_f])
        assert np.allclose(lam.imag, expected, rtol=1e-6, atol=0)
        node2 = T[4:6] @ V[:4, np.argmin(np.abs(lam.imag - w_f))]   # x2, y2 of the mode
        assert np.angle(node2[1] / node2[0]) == pytest.approx(-np.pi / 2, abs=1e-6)


def test_reference_matrices_structure():
    """Identities (1e-12 relative): M, K_shaft, C symmetric; M positive definite; K_shaft
    positive semidefinite with 4 rigid-body zeros; G skew; total mass = rho A L + discs."""
    rig = load_rig()
    m = assemble(rig)
    for X in (m.M, m.K_shaft, m.C):
        assert np.abs(X - X.T).max() <= 1e-12 * np.abs(X).max()
    assert np.abs(m.G + m.G.T).max() <= 1e-12 * np.abs(m.G).max()
    assert np.linalg.eigvalsh(m.M).min() > 0
    kk = sla.eigh(m.K_shaft, m.M, eigvals_only=True)
    assert np.sum(np.abs(kk) < 1e-6 * kk.max()) == 4 and kk.min() > -1e-6 * kk.max()
    ex = np.zeros(m.n_q)
    ex[[dof_index(i, "x") for i in range(1, rig.n_nodes + 1)]] = 1.0
    s = rig.shaft
    total = s.density * s.area * s.length + sum(d.mass for d in rig.discs)
    assert ex @ m.M @ ex == pytest.approx(total, rel=1e-12)
    assert np.count_nonzero(m.K_bearing) == 4 and np.all(np.diag(m.K_bearing)[
        channel_dofs(rig.bearing_nodes)] == -rig.ks)


def undamped(rig_dict_changes: dict):
    d = load_rig().to_dict()
    d["damping"]["first_mode_zeta"] = 0.0
    d["bearings"]["ks"] = 0.0
    d.update(rig_dict_changes)
    rig = rig_from_dict(d)
    return rig, assemble(rig)


@pytest.mark.parametrize("rpm", [0.0, 31500.0])
def test_undamped_supported_model_is_conservative(rpm):
    """C = 0, ks = 0, positive springs 1e6 N/m on the bearing DOFs: every eigenvalue
    imaginary, |Re| <= 1e-7 |lambda| (conservative, also with gyroscopics)."""
    rig, m = undamped({})
    assert not np.any(m.C) and not np.any(m.K_bearing)
    dK = np.zeros((m.n_q, m.n_q))
    for j in channel_dofs(rig.bearing_nodes):
        dK[j, j] = 1.0e6
    lam = np.linalg.eigvals(state_matrices(m, rpm, dK=dK)[0])
    assert np.all(np.abs(lam.real) <= 1e-7 * np.abs(lam))
    assert np.abs(lam).min() > 100.0


def test_undamped_free_free_model_at_rest():
    """C = 0, ks = 0, no support, 0 rpm: 8 (near-)zero eigenvalues (4 rigid DOF, Jordan
    pairs: |lambda| < 0.1 rad/s from round-off), the rest imaginary to 1e-7."""
    _, m = undamped({})
    lam = np.linalg.eigvals(state_matrices(m, 0.0)[0])
    rigid = np.abs(lam) < 0.1
    assert rigid.sum() == 8
    assert np.all(np.abs(lam[~rigid].real) <= 1e-7 * np.abs(lam[~rigid]))


@pytest.mark.parametrize("rpm", [0.0, 31500.0])
def test_reference_rig_has_four_rhp_poles(rpm):
    """Reference rig (ks = 1e6 N/m at two bearings, two axes): exactly 4 right-half-plane
    poles (one per bearing axis), real part > 100 rad/s, at 0 and at 31500 rpm."""
    fm = full_model(load_rig(), rpm)
    rhp = unstable_poles(fm)
    assert rhp.size == 4
    assert np.all(rhp.real > 100.0)
    assert np.sum(fm.poles.real > -1e-6 * np.abs(fm.poles)) == 4


def test_bending_frequencies_ascending():
    """At 31500 rpm: >= 4 bending frequencies, ascending, between 500 Hz and 10 kHz, the
    lowest above the 525 Hz running frequency."""
    f = bending_frequencies_hz(full_model(load_rig(), 31500.0), 8)
    assert f.size >= 4
    assert np.all(np.diff(f) > 0)
    assert 31500.0 / 60 < f[0] and f[-1] < 1e4
