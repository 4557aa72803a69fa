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
    # Gyroscopic coupling from L = rho*J*Omega * int(theta_x' theta_y) dz, with
    # theta_y = N' q_x and theta_x = -N' q_y (see module docstring), signs folded into q_y.
    G = np.zeros((8, 8))
    gp = 2.0 * density * second_moment * P
    qy_as_slope = gp * _Y_SIGN[None, :]          # columns of q_y, expressed as slopes
    G[np.ix_(_X_DOFS, _Y_DOFS)] = qy_as_slope
    G[np.ix_(_Y_DOFS, _X_DOFS)] = -qy_as_slope.T
    return M, K, G


def disc_matrices(mass: float, ip: float, id_: float) -> tuple[NDArray, NDArray]:
    """Mass and gyroscopic matrices (4x4) of a rigid disc at one node.

    Id theta_x'' + Omega Ip theta_y' = M_x and Id theta_y'' - Omega Ip theta_x' = M_y.
    """
    M = np.diag([mass, mass, id_, id_])
    G = np.zeros((4, 4))
    G[2, 3] = ip
    G[3, 2] = -ip
    return M, G
