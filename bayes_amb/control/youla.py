"""Youla and dual-Youla parametrisations and the stable S(theta) (eqs. 4-14).

Correct forms used here (the paper's eqs. 9 and 11 are misprinted; METHOD.md section 3):

* K(Q) = (Vt + Q Nt)^-1 (Ut + Q Mt)                                  (eq. 4)
* G(S) = (N + V S)(M + U S)^-1 = (Mt + S Ut)^-1 (Nt + S Vt)          (eq. 9, corrected:
  the paper has a second inverse on the first factor)
* T_cl(S), inputs [r1; r2; eta] with r1 added to y at the controller input and r2 to the
  plant input, outputs [y; u; eps] with u the plant input (eqs. 10-11):

      y   = (N + V S) (Ut r1 + Vt r2 + eta)
      u   = (M + U S) (Ut r1 + Vt r2 + eta)
      eps = (Mt + S Ut) r1 + (Nt + S Vt) r2 + S eta

  The paper's third row has Vt and Ut swapped (its S*Vt + Mt does not even conform).
* S(theta) = F_l([[0, Mt G_yw], [G_zu M, G_zw + G_zu U Mt G_yw]], theta)   (eq. 13)

In discrete time the exactly sampled perturbed plant, ZOH(A + B_w Theta C_z), is not an
LFT in theta. The identification therefore uses :func:`s_theta_exact` (the eta -> eps map of
the loop with the exactly sampled plant), and eq. 13 is checked on LFT plants.
"""

from __future__ import annotations

import control as ct
import numpy as np
from numpy.typing import NDArray

from bayes_amb.control.coprime import CoprimeFactors, ss, ss_inv
from bayes_amb.control.design import ObserverController
from bayes_amb.control.discrete import zoh
from bayes_amb.uncertainty import UncertainPlant


def discrete_plant(plant: UncertainPlant, theta: NDArray | list[float], dt: float
                   ) -> tuple[NDArray, NDArray, NDArray]:
    """Exact ZOH samples of the perturbed plant: (Ad(theta), Bd(theta), C)."""
    Ad, Bd = zoh(plant.A_theta(theta), plant.B, dt)
    return Ad, Bd, plant.C


def s_theta_exact(ctrl: ObserverController, Ap: NDArray, Bp: NDArray, Cp: NDArray
                  ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """S: eta -> eps of the observer-based loop around a discrete plant (Ap, Bp, Cp).

    When the plant has the order of the nominal model, the realisation is in error
    coordinates e = x_p - xhat, so that S is exactly zero at the nominal plant:

        e+  = (A + LC - dB F) e + (dA + dB F) x_p + dB eta
        x_p+ = -Bp F e + (Ap + Bp F) x_p + Bp eta
        eps = C e + dC x_p

    with dA = Ap - A, dB = Bp - B, dC = Cp - C. Otherwise states are [x_p; xhat].
    Returns (A_S, B_S, C_S, D_S) with D_S = 0.
    """
    A, B, C, F, L = ctrl.A, ctrl.B, ctrl.C, ctrl.F, ctrl.L
    p, m = C.shape[0], B.shape[1]
    if Ap.shape == A.shape:
        dA, dB, dC = Ap - A, Bp - B, Cp - C
        A_S = np.block([[A + L @ C - dB @ F, dA + dB @ F], [-Bp @ F, Ap + Bp @ F]])
        B_S = np.vstack([dB, Bp])
        C_S = np.hstack([C, dC])
    else:
        A_S = np.block([[Ap, Bp @ F], [-L @ Cp, A + B @ F + L @ C]])
        B_S = np.vstack([Bp, B])
        C_S = np.hstack([Cp, -C])
    return A_S, B_S, C_S, np.zeros((p, m))


def s_theta(ctrl: ObserverController, plant: UncertainPlant, theta: NDArray | list[float]
            ) -> ct.StateSpace:
    """S(theta) for the exactly sampled LFT plant, as a python-control system."""
    return ss(*s_theta_exact(ctrl, *discrete_plant(plant, theta, ctrl.dt)), ctrl.dt)


def lft_transfer_blocks(A: NDArray, B: NDArray, C: NDArray, B_w: NDArray, C_z: NDArray,
                        dt: float) -> tuple[ct.StateSpace, ct.StateSpace, ct.StateSpace]:
    """Transfer matrices G_yw, G_zu, G_zw of the LFT plant (A, [B, B_w], [C; C_z], 0)."""
    r = B_w.shape[1]
    return (ss(A, B_w, C, np.zeros((C.shape[0], r)), dt),
            ss(A, B, C_z, np.zeros((r, B.shape[1])), dt),
            ss(A, B_w, C_z, np.zeros((r, r)), dt))


def s_theta_lft(f: CoprimeFactors, G_yw: ct.StateSpace, G_zu: ct.StateSpace,
                G_zw: ct.StateSpace, theta_diag: NDArray) -> ct.StateSpace:
    """Eq. 13: S = F_l([[0, Mt G_yw], [G_zu M, G_zw + G_zu U Mt G_yw]], Theta)."""
    P12 = f.Mt * G_yw
    P21 = G_zu * f.M
    P22 = G_zw + G_zu * f.U * f.Mt * G_yw
    P11 = gain(np.zeros((P12.noutputs, P21.ninputs)), f.dt)
    P = vcat(hcat(P11, P12), hcat(P21, P22))
    r = P12.ninputs
    return P.lft(gain(np.diag(theta_diag), f.dt), nu=r, ny=r)


def k_of_q(f: CoprimeFactors, Q: ct.StateSpace) -> ct.StateSpace:
    """Eq. 4: K(Q) = (Vt + Q Nt)^-1 (Ut + Q Mt)."""
    return ss_inv(f.Vt + Q * f.Nt) * (f.Ut + Q * f.Mt)


def g_of_s(f: CoprimeFactors, S: ct.StateSpace) -> ct.StateSpace:
    """Eq. 9, corrected: G(S) = (N + V S)(M + U S)^-1."""
    return (f.N + f.V * S) * ss_inv(f.M + f.U * S)


def g_of_s_left(f: CoprimeFactors, S: ct.StateSpace) -> ct.StateSpace:
    """Left form of the corrected eq. 9: G(S) = (Mt + S Ut)^-1 (Nt + S Vt)."""
    return ss_inv(f.Mt + S * f.Ut) * (f.Nt + S * f.Vt)


def t_cl(f: CoprimeFactors, S: ct.StateSpace) -> ct.StateSpace:
    """Eqs. 10-11 (third row corrected): [y; u; eps] = T_cl(S) [r1; r2; eta]."""
    z_in = hcat(f.Ut, f.Vt, gain(np.eye(f.M.ninputs), f.dt))
    return vcat((f.N + f.V * S) * z_in, (f.M + f.U * S) * z_in,
                hcat(f.Mt + S * f.Ut, f.Nt + S * f.Vt, S))


def gain(D: NDArray, dt: float) -> ct.StateSpace:
    """A static gain as a (state-less) discrete system."""
    D = np.atleast_2d(D)
    return ss(np.zeros((0, 0)), np.zeros((0, D.shape[1])), np.zeros((D.shape[0], 0)), D, dt)


def hcat(*systems: ct.StateSpace) -> ct.StateSpace:
    """[S1, S2, ...]: inputs stacked, outputs summed."""
    return ss(_blkdiag(*[np.asarray(s.A) for s in systems]),
              _blkdiag(*[np.asarray(s.B) for s in systems]),
              np.hstack([np.asarray(s.C) for s in systems]),
              np.hstack([np.asarray(s.D) for s in systems]), systems[0].dt)


def vcat(*systems: ct.StateSpace) -> ct.StateSpace:
    """[S1; S2; ...]: same inputs, outputs stacked."""
    return ss(_blkdiag(*[np.asarray(s.A) for s in systems]),
              np.vstack([np.asarray(s.B) for s in systems]),
              _blkdiag(*[np.asarray(s.C) for s in systems]),
              np.vstack([np.asarray(s.D) for s in systems]), systems[0].dt)


def _blkdiag(*mats: NDArray) -> NDArray:
    rows = sum(m.shape[0] for m in mats)
    cols = sum(m.shape[1] for m in mats)
    out = np.zeros((rows, cols))
    r = c = 0
    for m in mats:
        out[r:r + m.shape[0], c:c + m.shape[1]] = m
        r += m.shape[0]
        c += m.shape[1]
    return out
