"""The rotor of the foreign generator: its own state space, bearing changes and truncation.

Only the rig description (bayes_amb.rig) and the FE matrices (bayes_amb.rotor.assemble)
are borrowed from the package, as a drawing of the machine. Everything else here is written
again from the physics:

    M q'' + (C + Omega G) q' + (K_shaft - ks P_b) q = f,     x = [q; q'] (m, m/s; rad)

with f the external forces (N) on the translational DOFs. Spin is about +z, so a mass
unbalance m e at angle Omega t + phi pulls with m e Omega^2 [cos, sin] (N) in (x, y). An
AMB pulls with f = ki i + ks s (i in A, s the air gap in m); the ks term is the destabilising
negative spring -ks P_b (N/m) already inside the stiffness above.

Bearing coefficient changes (the tool's parameters, applied physically here):
- k_<axis> = theta: ks_true = (1 - theta) ks, i.e. an extra restoring force -theta ks q_j;
- c_<axis> (N s/m): extra viscous force -c q'_j;
- kxy at a node (N/m): f_x = -kxy q_y, f_y = +kxy q_x.

The rotor is a :class:`RotorBlock`: a state matrix A and maps from forces at DOFs to the
state derivative and from the state to displacements and velocities at DOFs. ``truth="full"``
keeps all 2 n_q states; ``truth="reduced"`` truncates the *nominal* model to its 8 suspended
rigid-body modes (+ 4 per kept bending pair) by eigenvectors, and every change made later
(bearing coefficients, cross-coupling, forces, sensors) acts through the projected maps
T_L (.) and (.) T_R, so that the bearing changes are T_L dA T_R.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray

from bayes_amb.rig import Rig
from bayes_amb.rotor import assemble

AXES = ("Ax", "Ay", "Bx", "By")
_AX_OFF = {"x": 0, "y": 1}


def dof(node: int, axis: str) -> int:
    """0-based translational DOF index of a 1-based node; axis 'x' or 'y' (4 DOFs a node)."""
    return 4 * (node - 1) + _AX_OFF[axis]


def node_of(rig: Rig, where: str) -> int:
    """Node of a bearing ('A', 'B') or disc ('D1', 'D2'); an int is a node already."""
    if where in rig.bearing_nodes:
        return rig.bearing_nodes[where]
    for d in rig.discs:
        if d.name == where:
            return d.node
    return int(where)


@dataclass(frozen=True)
class RotorBlock:
    """A rotor in state-space form. A (n, n) in 1/s; ``force`` (n, n_q) maps a force vector
    in N on all DOFs to x'; ``disp`` and ``vel`` (n_q, n) give all DOF displacements (m) and
    velocities (m/s) from the state. Full: n = 2 n_q; reduced: n = 8 + 4 n_bending.
    ``residual`` (n_q, n_q), m/N, or None: the quasi-static deflection at every DOF per
    force at every DOF of the modes a reduced block leaves out (its static correction)."""

    A: NDArray
    force: NDArray
    disp: NDArray
    vel: NDArray
    truth: str
    speed_rpm: float
    residual: NDArray | None = None

    @property
    def n(self) -> int:
        return self.A.shape[0]

    def add_spring(self, dof_out: int, dof_in: int, k: float, velocity: bool = False
                   ) -> RotorBlock:
        """A new block with an extra force -k q_in (or -k q'_in) at dof_out (k in N/m or N s/m)."""
        src = self.vel if velocity else self.disp
        A = self.A - k * np.outer(self.force[:, dof_out], src[dof_in])
        return RotorBlock(A, self.force, self.disp, self.vel, self.truth, self.speed_rpm,
                          self.residual)


def full_rotor(rig: Rig, speed_rpm: float) -> RotorBlock:
    """All 2 n_q states of the FE rotor at a speed (rpm), nominal bearings."""
    m = assemble(rig)
    n_q = m.M.shape[0]
    K = np.array(m.K_shaft, dtype=float)
    for b in ("A", "B"):
        for ax in ("x", "y"):
            j = dof(rig.bearing_nodes[b], ax)
            K[j, j] -= rig.ks
    omega = float(speed_rpm) * np.pi / 30.0
    Minv = np.linalg.inv(m.M)
    A = np.block([[np.zeros((n_q, n_q)), np.eye(n_q)],
                  [-Minv @ K, -Minv @ (m.C + omega * m.G)]])
    force = np.vstack([np.zeros((n_q, n_q)), Minv])
    disp = np.hstack([np.eye(n_q), np.zeros((n_q, n_q))])
    vel = np.hstack([np.zeros((n_q, n_q)), np.eye(n_q)])
    return RotorBlock(A, force, disp, vel, "full", float(speed_rpm))


def modal_truncation(block: RotorBlock, n_bending: int = 0, static: bool = False
                     ) -> RotorBlock:
    """Keep the 8 + 4 n_bending eigenvalues of smallest modulus of a full block.

    T_R is a real basis of the kept right invariant subspace (Re v, Im v of each pair); the
    oblique projector P = V W^T onto it along the left-out modes (w^T v = 1) is real, and
    T_L = pinv(T_R) P, so that T_L T_R = I and T_L kills the left-out modes. The reduced
    block is (T_L A T_R, T_L force, disp T_R, vel T_R).

    ``static``: also keep the static correction of the left-out modes (mode-acceleration
    method). Far below their own frequencies they follow the force quasi-statically, so
    they add ``residual`` = disp (-A^-1)(I - P) force, the static compliance of the
    left-out modes, to the displacements. It is summed over them, disp v (-1/lambda) w^T
    force, not taken as (full static) - (kept static): on the reference rig those two are
    ~1e4 times the difference, and a solve with the full A (condition ~7e14) loses ~2e-4 of
    it, where the sum agrees with an 80-bit (long double) reference to ~1e-8.
    """
    lam, vl, vr = sla.eig(block.A, left=True, right=True)
    order = np.argsort(np.abs(lam), kind="stable")
    n_keep = 8 + 4 * n_bending
    if abs(abs(lam[order[n_keep]]) - abs(lam[order[n_keep - 1]])) < 1e-9 * abs(lam[order[n_keep]]):
        raise ValueError(f"modal truncation at {n_keep} would split a pair")
    keep = order[:n_keep]
    V = vr[:, keep]
    W = np.conj(vl[:, keep])                       # w^T A = lambda w^T
    W = W / np.sum(W * V, axis=0)                  # w^T v = 1
    P = np.real(V @ W.T)
    cols = []
    done = np.zeros(n_keep, dtype=bool)
    for i in range(n_keep):
        if done[i]:
            continue
        v = V[:, i]
        if abs(lam[keep[i]].imag) < 1e-9 * abs(lam[keep[i]]):
            v = v * np.exp(-1j * np.angle(v[np.argmax(np.abs(v))]))
            cols.append(v.real)
            done[i] = True
        else:
            j = np.argmin(np.abs(lam[keep] - np.conj(lam[keep[i]])) + done * 1e300)
            done[i] = done[j] = True
            cols += [v.real, v.imag]
    T_R = np.column_stack(cols)
    T_R = T_R / np.linalg.norm(T_R, axis=0)
    T_L = np.linalg.pinv(T_R) @ P
    T_L = np.linalg.solve(T_L @ T_R, T_L)
    A_r, force_r, disp_r = T_L @ block.A @ T_R, T_L @ block.force, block.disp @ T_R
    residual = None
    if static:
        out = order[n_keep:]
        w_out = np.conj(vl[:, out])
        w_out = w_out / np.sum(w_out * vr[:, out], axis=0)
        residual = np.real((block.disp @ vr[:, out] / -lam[out])
                           @ (w_out.T @ block.force))
    return RotorBlock(A_r, force_r, disp_r, block.vel @ T_R, f"reduced+{n_bending}",
                      block.speed_rpm, residual)


def bearing_changes(block: RotorBlock, rig: Rig, k_theta: dict[str, float],
                    c_nsm: dict[str, float], kxy_nm: dict[str, float] | None = None
                    ) -> RotorBlock:
    """Apply the eight bearing coefficients and cross-couplings to a (full or reduced) block.

    k_theta: relative ks reduction per axis Ax..By; c_nsm: viscous damping per axis, N s/m;
    kxy_nm: cross-coupled stiffness (N/m) at 'A', 'B', 'D1', 'D2' or a node number.
    """
    out = block
    for ax in AXES:
        j = dof(rig.bearing_nodes[ax[0]], ax[1])
        if k_theta.get(ax, 0.0):
            out = out.add_spring(j, j, k_theta[ax] * rig.ks)
        if c_nsm.get(ax, 0.0):
            out = out.add_spring(j, j, c_nsm[ax], velocity=True)
    for where, kxy in (kxy_nm or {}).items():
        n = node_of(rig, where)
        out = out.add_spring(dof(n, "x"), dof(n, "y"), kxy)       # f_x = -kxy y
        out = out.add_spring(dof(n, "y"), dof(n, "x"), -kxy)      # f_y = +kxy x
    return out


_CACHE: dict[tuple, RotorBlock] = {}


def rotor(rig: Rig, speed_rpm: float, truth: str = "reduced", n_bending: int = 0,
          static: bool = False) -> RotorBlock:
    """Nominal rotor block: ``truth`` 'full' (2 n_q states) or 'reduced' (8 + 4 n_bending,
    with the static correction of the left-out modes if ``static``).

    Blocks are cached per (rig, speed, truth, n_bending, static); they are immutable.
    """
    if truth not in ("full", "reduced"):
        raise ValueError(f"truth must be 'full' or 'reduced', got {truth!r}")
    reduced = truth == "reduced"
    key = (repr(rig.to_dict()), float(speed_rpm), truth, n_bending if reduced else 0,
           static and reduced)
    if key not in _CACHE:
        full = full_rotor(rig, speed_rpm)
        _CACHE[key] = full if not reduced else modal_truncation(full, n_bending, static)
    return _CACHE[key]
