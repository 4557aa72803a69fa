"""Global FE matrices and the full state-space model of eq. 17.

    x_f' = A_f x_f + B_f u,   y = C_f x_f,   x_f = [q; q'] (positions, then velocities)

    A_f = [[0, I], [-M^-1 (K_shaft - ks*P_b), -M^-1 (C + Omega*G)]]

u are the control currents [Ax, Ay, Bx, By] in A (bearing force ki*u) and y the sensor
displacements [Ax, Ay, Bx, By] in m. P_b puts ks on the bearing translational DOFs (eq. 16:
f = ki*i + ks*s, a spring of negative stiffness -ks).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray

from bayes_amb.rig import CHANNELS, Rig
from bayes_amb.rotor.elements import disc_matrices, section_element, shaft_element

_AXIS_OFFSET = {"x": 0, "y": 1, "tx": 2, "ty": 3}
DOF_PER_NODE = 4


def dof_index(node: int, axis: str) -> int:
    """Global DOF index (0-based) of a 1-based node and an axis in {x, y, tx, ty}."""
    return DOF_PER_NODE * (node - 1) + _AXIS_OFFSET[axis]


def channel_dofs(nodes: dict[str, int]) -> list[int]:
    """DOF indices of the channels Ax, Ay, Bx, By at the given bearing or sensor nodes."""
    return [dof_index(nodes[ch[0]], ch[1]) for ch in CHANNELS]


@dataclass(frozen=True)
class RotorMatrices:
    """Global second-order matrices, each (n_q, n_q) with n_q = 4 * n_nodes.

    M in kg (kg m^2 on rotations), K_shaft in N/m, C in N s/m (C = beta*K_shaft on a
    uniform shaft; the elements' Rayleigh damping alpha M_e + beta K_e plus beta*K_shaft on
    a stepped one), G gyroscopic per rad/s of spin (multiply by Omega), K_bearing = -ks on
    each bearing's DOFs, Bq (n_q, 4) maps currents to forces (each bearing's ki), Cq (4, n_q)
    picks sensor displacements. A rig's fixed supports (fluid-film bearings, seals;
    rig/supports.py) are in K_shaft, C and M at their nodes' x and y DOFs (the shaft's
    damping beta is set from the bare shaft before).
    """

    M: NDArray
    K_shaft: NDArray
    C: NDArray
    G: NDArray
    K_bearing: NDArray
    Bq: NDArray
    Cq: NDArray
    beta: float

    @property
    def n_q(self) -> int:
        return self.M.shape[0]

    @cached_property
    def M_inv(self) -> NDArray:
        return np.linalg.inv(self.M)

    @property
    def K(self) -> NDArray:
        """Total stiffness K_shaft + K_bearing (bearing negative stiffness included)."""
        return self.K_shaft + self.K_bearing


def shaft_matrices(rig: Rig) -> tuple[NDArray, NDArray, NDArray]:
    """Bare-shaft M, K and G (no discs, no bearings), each (4 n_nodes, 4 n_nodes)."""
    M, K, G, _ = _shaft_with_damping(rig)
    return M, K, G


def _shaft_with_damping(rig: Rig) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Bare-shaft M, K, G and the elements' own Rayleigh damping sum(alpha M_e + beta K_e)
    (zero on a uniform shaft, whose damping is set by first_mode_zeta)."""
    s = rig.shaft
    n_q = DOF_PER_NODE * s.n_nodes
    M = np.zeros((n_q, n_q))
    K = np.zeros((n_q, n_q))
    G = np.zeros((n_q, n_q))
    C = np.zeros((n_q, n_q))
    if s.uniform:
        le = s.length / (s.n_nodes - 1)
        Me, Ke, Ge = shaft_element(le, s.youngs_modulus, s.density, s.area, s.second_moment)
        elements = [(Me, Ke, Ge, 0.0, 0.0)] * (s.n_nodes - 1)
    else:
        elements = [(*section_element(e.length, e.od, e.id, e.material.youngs_modulus,
                                      e.material.density, e.material.poisson,
                                      shear=s.shear), e.alpha, e.beta)
                    for e in s.elements]
    for j, (Me, Ke, Ge, alpha, beta) in enumerate(elements):
        idx = slice(DOF_PER_NODE * j, DOF_PER_NODE * (j + 2))
        M[idx, idx] += Me
        K[idx, idx] += Ke
        G[idx, idx] += Ge
        if alpha or beta:
            C[idx, idx] += alpha * Me + beta * Ke
    return M, K, G, C


def _flexible(w2: NDArray) -> NDArray:
    """Which of the ascending squared natural frequencies w2 of an unsupported structure
    are flexible modes (the rigid-body ones are zero to rounding)."""
    return w2 > 1e-9 * max(abs(w2[-1]), 1.0)


def first_free_free_bending(M: NDArray, K: NDArray) -> float:
    """First non-rigid natural frequency (rad/s) of an unsupported structure (M, K)."""
    w2 = np.sort(sla.eigh(K, M, eigvals_only=True))
    return float(np.sqrt(w2[_flexible(w2)][0]))


def modal_damping(M: NDArray, K: NDArray, zeta: float) -> NDArray:
    """The damping matrix that gives every flexible mode of (M, K) the ratio zeta, and its
    rigid-body modes none: C = M Phi diag(2 zeta w) Phi^T M, Phi the mass-normalised modes
    (classical damping, so the modes stay (M, K)'s; ROSS's modal_damping_ratio builds its
    C the same way, but from the rotor with its bearings).

    >>> M, K = np.diag([2.0, 1.0]), np.array([[6.0, -2.0], [-2.0, 4.0]])
    >>> C = modal_damping(M, K, 0.05)
    >>> lam = np.linalg.eigvals(np.block([[np.zeros((2, 2)), np.eye(2)],
    ...                                   [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]]))
    >>> bool(np.allclose(-lam.real / abs(lam), 0.05))
    True
    """
    w2, phi = sla.eigh(K, M)
    w = np.where(_flexible(w2), np.sqrt(np.clip(w2, 0.0, None)), 0.0)
    Mphi = M @ phi
    return (Mphi * (2.0 * zeta * w)) @ Mphi.T


def assemble(rig: Rig) -> RotorMatrices:
    """Assemble the global matrices of a rig (discs and bearings included).

    Examples
    --------
    >>> from bayes_amb.rig import load_rig
    >>> m = assemble(load_rig())
    >>> m.n_q
    160
    """
    M, K, G, C_el = _shaft_with_damping(rig)
    beta = (2.0 * rig.first_mode_zeta / first_free_free_bending(M, K)
            if rig.first_mode_zeta else 0.0)
    C = beta * K + C_el
    for d in rig.discs:
        Md, Gd = disc_matrices(d.mass, d.ip, d.id)
        idx = slice(dof_index(d.node, "x"), dof_index(d.node, "x") + DOF_PER_NODE)
        M[idx, idx] += Md
        G[idx, idx] += Gd
    if rig.modal_zeta:
        C = C + modal_damping(M, K, rig.modal_zeta)
    for s in rig.supports:          # fluid-film bearings, seals: fixed, on x and y
        xy = [dof_index(s.node, "x"), dof_index(s.node, "y")]
        K[np.ix_(xy, xy)] += s.matrix("k")
        C[np.ix_(xy, xy)] += s.matrix("c")
        M[np.ix_(xy, xy)] += s.matrix("m")
    n_q = M.shape[0]
    K_b = np.zeros((n_q, n_q))
    b_dofs = channel_dofs(rig.bearing_nodes)
    mags = rig.channel_magnets
    for m, j in zip(mags, b_dofs, strict=True):
        K_b[j, j] -= m.ks
    Bq = np.zeros((n_q, len(CHANNELS)))
    for k, (m, j) in enumerate(zip(mags, b_dofs, strict=True)):
        Bq[j, k] = m.ki
    Cq = np.zeros((len(CHANNELS), n_q))
    for k, j in enumerate(channel_dofs(rig.sensor_nodes)):
        Cq[k, j] = 1.0
    return RotorMatrices(M=M, K_shaft=K, C=C, G=G, K_bearing=K_b, Bq=Bq, Cq=Cq, beta=beta)


@dataclass(frozen=True)
class FullModel:
    """The full-order state-space model of eq. 17 at one speed.

    A (2 n_q, 2 n_q) in 1/s, B (2 n_q, 4) per A, C (4, 2 n_q) in m per state unit.
    """

    A: NDArray
    B: NDArray
    C: NDArray
    speed_rpm: float
    matrices: RotorMatrices

    @property
    def n_states(self) -> int:
        return self.A.shape[0]

    @cached_property
    def modes(self) -> tuple[NDArray, NDArray, NDArray]:
        """(lambda, W, V): the eigenvalues of A in rad/s sorted by modulus (ties by imaginary
        part), with left (w^T A = lambda w^T) and right eigenvectors as columns, not
        normalised. Computed once per model: the reductions and the residual flexibility
        share it."""
        lam, wl, vr = sla.eig(self.A, left=True, right=True)
        order = np.lexsort((np.imag(lam), np.abs(lam)))
        # scipy's left vectors satisfy vl^H A = lambda vl^H; w = conj(vl) gives w^T A = lambda w^T
        return lam[order], np.conj(wl[:, order]), vr[:, order]

    @cached_property
    def mode_inputs(self) -> NDArray:
        """w_i^T B_f per mode (rows in the order of :attr:`modes`), with w_i^T v_i = 1, so
        that mode i's residue from the inputs to outputs C is C v_i w_i^T B_f. Computed
        once: every model that holds the left-out modes' compliance uses it."""
        _, W, V = self.modes
        return (W / np.sum(W * V, axis=0)).T @ self.B

    @cached_property
    def poles(self) -> NDArray:
        """Open-loop poles, rad/s, sorted by modulus."""
        lam = np.linalg.eigvals(self.A)
        return lam[np.argsort(np.abs(lam), kind="stable")]


def rpm_to_rad_s(rpm: float) -> float:
    return float(rpm) * 2.0 * np.pi / 60.0


def state_matrices(mats: RotorMatrices, speed_rpm: float, dK: NDArray | None = None,
                   dC: NDArray | None = None) -> tuple[NDArray, NDArray, NDArray]:
    """(A_f, B_f, C_f) of eq. 17, optionally with extra stiffness dK and damping dC (n_q x n_q)."""
    n_q = mats.n_q
    K = mats.K if dK is None else mats.K + dK
    Cd = mats.C + rpm_to_rad_s(speed_rpm) * mats.G
    if dC is not None:
        Cd = Cd + dC
    Mi = mats.M_inv
    A = np.zeros((2 * n_q, 2 * n_q))
    A[:n_q, n_q:] = np.eye(n_q)
    A[n_q:, :n_q] = -Mi @ K
    A[n_q:, n_q:] = -Mi @ Cd
    B = np.vstack([np.zeros((n_q, mats.Bq.shape[1])), Mi @ mats.Bq])
    C = np.hstack([mats.Cq, np.zeros_like(mats.Cq)])
    return A, B, C


def full_model(rig: Rig, speed_rpm: float | None = None, mats: RotorMatrices | None = None,
               ) -> FullModel:
    """Full FE state-space model (eq. 17) of a rig at a speed (default: nominal speed).

    Examples
    --------
    >>> from bayes_amb.rig import load_rig
    >>> fm = full_model(load_rig())
    >>> fm.n_states, fm.B.shape, fm.C.shape
    (320, (320, 4), (4, 320))
    """
    speed = rig.nominal_speed_rpm if speed_rpm is None else float(speed_rpm)
    mats = assemble(rig) if mats is None else mats
    A, B, C = state_matrices(mats, speed)
    return FullModel(A=A, B=B, C=C, speed_rpm=speed, matrices=mats)
