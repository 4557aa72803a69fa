"""Finite-element matrices: Euler-Bernoulli shaft element and rigid disc.

Each node has 4 DOF ordered [x, y, theta_x, theta_y]: translations in m and rotations in rad
about the x and y axes (right-hand rule, spin about +z). For small angles
theta_y = dx/dz and theta_x = -dy/dz. Equations of motion:

    M q'' + (C + Omega*G) q' + K q = f

with G skew-symmetric (gyroscopic). Forward whirl is in the direction of spin (x -> y).

References
----------
Nelson & McVaugh (1976), "The dynamics of rotor-bearing systems using finite elements";
Friswell et al. (2010), Dynamics of Rotating Machines, ch. 5.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

# Within a plane, Hermite beam DOFs are [w1, w1', w2, w2'] (w' = dw/dz).
# Node DOF k of a plane: x-plane (x, theta_y = x'), y-plane (y, theta_x = -y').
_X_DOFS = (0, 3, 4, 7)            # element DOFs of [x1, x1', x2, x2']
_Y_DOFS = (1, 2, 5, 6)            # element DOFs of [y1, -y1', y2, -y2']
_Y_SIGN = np.array([1.0, -1.0, 1.0, -1.0])


def _beam_stiffness(l: float) -> NDArray:
    return np.array([[12, 6 * l, -12, 6 * l],
                     [6 * l, 4 * l**2, -6 * l, 2 * l**2],
                     [-12, -6 * l, 12, -6 * l],
                     [6 * l, 2 * l**2, -6 * l, 4 * l**2]]) / l**3


def _beam_translational_mass(l: float) -> NDArray:
    return np.array([[156, 22 * l, 54, -13 * l],
                     [22 * l, 4 * l**2, 13 * l, -3 * l**2],
                     [54, 13 * l, 156, -22 * l],
                     [-13 * l, -3 * l**2, -22 * l, 4 * l**2]]) * (l / 420.0)


def _beam_slope_integral(l: float) -> NDArray:
    """P = integral of N'^T N' dz over the element (rotary inertia and gyroscopics)."""
    return np.array([[36, 3 * l, -36, 3 * l],
                     [3 * l, 4 * l**2, -3 * l, -(l**2)],
                     [-36, -3 * l, 36, -3 * l],
                     [3 * l, -(l**2), -3 * l, 4 * l**2]]) / (30.0 * l)


def _both_planes(planar: NDArray) -> NDArray:
    """Place a symmetric 4x4 planar matrix into both planes of the 8x8 element matrix."""
    out = np.zeros((8, 8))
    out[np.ix_(_X_DOFS, _X_DOFS)] = planar
    out[np.ix_(_Y_DOFS, _Y_DOFS)] = planar * np.outer(_Y_SIGN, _Y_SIGN)
    return out


def shaft_element(length: float, youngs_modulus: float, density: float, area: float,
                  second_moment: float) -> tuple[NDArray, NDArray, NDArray]:
    """Mass, stiffness and gyroscopic matrices (8x8) of a uniform Euler-Bernoulli element.

    The mass includes rotary inertia. The gyroscopic matrix G is per unit spin speed
    (multiply by Omega in rad/s), polar inertia per length rho*J = 2*rho*I.

    Examples
    --------
    >>> M, K, G = shaft_element(0.1, 2e11, 7800.0, 1e-3, 1e-7)
    >>> bool(np.allclose(M, M.T) and np.allclose(K, K.T) and np.allclose(G, -G.T))
    True
    """
    P = _beam_slope_integral(length)
    M = _both_planes(density * area * _beam_translational_mass(length)
                     + density * second_moment * P)
    K = _both_planes(youngs_modulus * second_moment * _beam_stiffness(length))
    return M, K, _gyroscopic(2.0 * density * second_moment * P)


def _gyroscopic(gp: NDArray) -> NDArray:
    """The 8x8 gyroscopic matrix (per rad/s of spin) from the planar polar-inertia integral
    gp = int rho J Psi^T Psi dz (J = 2 I). From L = rho*J*Omega * int(theta_x' theta_y) dz,
    with theta_y = Psi q_x and theta_x = -Psi q_y (module docstring), signs folded into q_y."""
    G = np.zeros((8, 8))
    qy_as_slope = gp * _Y_SIGN[None, :]          # columns of q_y, expressed as slopes
    G[np.ix_(_X_DOFS, _Y_DOFS)] = qy_as_slope
    G[np.ix_(_Y_DOFS, _X_DOFS)] = -qy_as_slope.T
    return G


def disc_matrices(mass: float, ip: float, id_: float) -> tuple[NDArray, NDArray]:
    """Mass and gyroscopic matrices (4x4) of a rigid disc at one node.

    Id theta_x'' + Omega Ip theta_y' = M_x and Id theta_y'' - Omega Ip theta_x' = M_y.
    """
    M = np.diag([mass, mass, id_, id_])
    G = np.zeros((4, 4))
    G[2, 3] = ip
    G[3, 2] = -ip
    return M, G


_GAUSS_Z, _GAUSS_W = np.polynomial.legendre.leggauss(6)
_GAUSS_Z = 0.5 * (_GAUSS_Z + 1.0)          # on [0, 1]
_GAUSS_W = 0.5 * _GAUSS_W


def cowper_shear_factor(poisson: float, inner_over_outer: float = 0.0) -> float:
    """Timoshenko shear coefficient kappa of a (hollow) circular section (Cowper 1966).

    >>> round(cowper_shear_factor(0.3), 4)
    0.8864
    """
    r2 = inner_over_outer**2
    a = (1.0 + r2) ** 2
    return 6.0 * (1.0 + poisson) * a / ((7.0 + 6.0 * poisson) * a + (20.0 + 12.0 * poisson) * r2)


def _timoshenko_shapes(xi: float, length: float, phi: float) -> tuple[NDArray, ...]:
    """Interpolation of one plane of a Timoshenko beam (Friedman & Kosmatka 1993), DOFs
    [w1, psi1, w2, psi2] with psi the section's rotation: N (deflection), dN/dz, Psi
    (rotation) and dPsi/dz at xi = z / L. With phi = 0 they are the Hermite cubics, psi = w'.
    The shear strain dN/dz - Psi is constant along the element."""
    L, p, d = length, phi, 1.0 / (1.0 + phi)
    N = d * np.array([2 * xi**3 - 3 * xi**2 - p * xi + 1 + p,
                      L * (xi**3 - (2 + p / 2) * xi**2 + (1 + p / 2) * xi),
                      -(2 * xi**3 - 3 * xi**2 - p * xi),
                      L * (xi**3 - (1 - p / 2) * xi**2 - (p / 2) * xi)])
    dN = d / L * np.array([6 * xi**2 - 6 * xi - p,
                           L * (3 * xi**2 - (4 + p) * xi + 1 + p / 2),
                           -(6 * xi**2 - 6 * xi - p),
                           L * (3 * xi**2 - (2 - p) * xi - p / 2)])
    Psi = d * np.array([6 / L * (xi**2 - xi),
                        3 * xi**2 - (4 + p) * xi + 1 + p,
                        -6 / L * (xi**2 - xi),
                        3 * xi**2 - (2 - p) * xi])
    dPsi = d / L * np.array([6 / L * (2 * xi - 1),
                             6 * xi - (4 + p),
                             -6 / L * (2 * xi - 1),
                             6 * xi - (2 - p)])
    return N, dN, Psi, dPsi


def section_element(length: float, od: tuple[float, float], id_: tuple[float, float],
                    youngs_modulus: float, density: float, poisson: float, *,
                    shear: bool = False, rotary_inertia: bool = True, gyroscopic: bool = True
                    ) -> tuple[NDArray, NDArray, NDArray]:
    """Mass, stiffness and gyroscopic matrices (8x8) of a shaft element with its own outer
    and inner diameter at each end (m), linear in between: stepped, hollow or tapered.

    Timoshenko (``shear=True``: shear deformation, Cowper's kappa of the element's mean
    section) or Euler-Bernoulli; rotary inertia and gyroscopics (G per rad/s of spin) from
    the section rotation. The section's area and second moment vary along the element and
    are integrated by Gauss quadrature (exact for these polynomials); the shear parameter
    phi = 12 E I / (kappa G A L^2) is taken at mid-element. A uniform solid element with
    ``shear=False`` gives :func:`shaft_element`'s matrices.

    References
    ----------
    Friedman & Kosmatka (1993), "An improved two-node Timoshenko beam finite element";
    Friswell et al. (2010), Dynamics of Rotating Machines, sections 5.4-5.5.

    Examples
    --------
    >>> a = section_element(0.1, (0.05, 0.05), (0.0, 0.0), 2e11, 7800.0, 0.3)
    >>> b = shaft_element(0.1, 2e11, 7800.0, np.pi * 0.05**2 / 4, np.pi * 0.05**4 / 64)
    >>> all(bool(np.allclose(x, y, rtol=1e-12, atol=1e-12)) for x, y in zip(a, b))
    True
    """
    L = float(length)
    ro = np.array(od, dtype=float) / 2.0
    ri = np.array(id_, dtype=float) / 2.0

    def radii(xi: float) -> tuple[float, float]:
        return ro[0] + (ro[1] - ro[0]) * xi, ri[0] + (ri[1] - ri[0]) * xi

    def area(xi: float) -> float:
        o, i = radii(xi)
        return np.pi * (o**2 - i**2)

    def second_moment(xi: float) -> float:
        o, i = radii(xi)
        return np.pi * (o**4 - i**4) / 4.0

    phi = 0.0
    if shear:
        o_m, i_m = radii(0.5)
        kappa = cowper_shear_factor(poisson, i_m / o_m)
        g_s = youngs_modulus / (2.0 * (1.0 + poisson))
        phi = 12.0 * youngs_modulus * second_moment(0.5) / (kappa * g_s * area(0.5) * L**2)
    planar_m = np.zeros((4, 4))
    planar_k = np.zeros((4, 4))
    planar_r = np.zeros((4, 4))           # integral of I Psi^T Psi dz
    for xi, w in zip(_GAUSS_Z, _GAUSS_W, strict=True):
        N, dN, Psi, dPsi = _timoshenko_shapes(xi, L, phi)
        A, I = area(xi), second_moment(xi)
        planar_m += w * L * density * A * np.outer(N, N)
        planar_r += w * L * I * np.outer(Psi, Psi)
        planar_k += w * L * youngs_modulus * I * np.outer(dPsi, dPsi)
        if shear:
            gamma = dN - Psi                 # constant: the element's shear strain
            planar_k += w * L * kappa * g_s * A * np.outer(gamma, gamma)
    if rotary_inertia:
        planar_m = planar_m + density * planar_r
    M = _both_planes(planar_m)
    K = _both_planes(planar_k)
    G = _gyroscopic(2.0 * density * planar_r) if gyroscopic else np.zeros((8, 8))
    return M, K, G


def disc_from_geometry(density: float, width: float, od: float, id_: float = 0.0
                       ) -> tuple[float, float, float]:
    """(mass kg, polar Ip, diametral Id kg m^2) of a rigid disc: a ring of width (m), outer
    and inner diameter (m). Id about a diameter through its centre.

    >>> m, ip, id_ = disc_from_geometry(7850.0, 0.02, 0.2)
    >>> round(m, 4), round(ip / (m * 0.2**2 / 8), 12), round(id_, 6)
    (4.9323, 1.0, 0.012495)
    """
    m = density * np.pi / 4.0 * (od**2 - id_**2) * width
    ip = m * (od**2 + id_**2) / 8.0
    return float(m), float(ip), float(ip / 2.0 + m * width**2 / 12.0)
