"""Observer-based controller designed on the reduced model, in discrete time.

Design method (documented defaults)
-----------------------------------
The reduced model (8 states) is discretised exactly (ZOH) at the recording sample time dt.

* State feedback F: discrete LQR, cost sum(y'y / y_ref^2 + u'u / u_ref^2) with
  y_ref = 10 um and u_ref = 1 A, i.e. Q = C'C / y_ref^2, R = I / u_ref^2.
* Observer L: steady-state Kalman predictor for an input-current disturbance of
  w_ref = 1 A RMS per axis and sensor noise of v_ref = 0.316 um RMS per axis,
  W = w_ref^2 B B', V = v_ref^2 I.

Conventions (Zhou, Doyle & Glover ch. 5; ../shared/METHOD.md section 2): positive feedback
u = K y with A + BF and A + LC Schur stable, implemented as a rig would run it:

    xhat[k+1] = A xhat[k] + B u[k] + L (C xhat[k] - y[k])
    u[k]      = F xhat[k] + eta[k]        (eta: the Youla port, Q broken open)
    eps[k]    = y[k] - C xhat[k]          (the innovation)

so that K = [A+BF+LC | -L ; F | 0].
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray

from bayes_amb.control.discrete import zoh
from bayes_amb.errors import ControllerError
from bayes_amb.reduction import ReducedModel


@dataclass(frozen=True)
class DesignSettings:
    """LQG weights in physical units: y_ref in m, u_ref, w_ref in A, v_ref in m."""

    y_ref: float = 1.0e-5
    u_ref: float = 1.0
    w_ref: float = 1.0
    v_ref: float = 10 ** -6.5

    def validate(self) -> None:
        for k, v in asdict(self).items():
            if not (np.isfinite(v) and v > 0):
                raise ControllerError(f"design setting {k}: expected a positive number, got {v!r}")


@dataclass(frozen=True)
class ObserverController:
    """Discrete observer-based controller and the discrete nominal plant it was designed on.

    A (n, n), B (n, 4), C (4, n): ZOH-discretised reduced plant at ``dt`` seconds.
    F (4, n) state feedback and L (n, 4) observer gain, both in the positive-feedback
    convention (A + BF and A + LC Schur stable).
    """

    A: NDArray
    B: NDArray
    C: NDArray
    F: NDArray
    L: NDArray
    dt: float
    speed_rpm: float
    settings: DesignSettings = field(default_factory=DesignSettings)

    @property
    def n_states(self) -> int:
        return self.A.shape[0]

    def controller_matrices(self) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        """K = [A+BF+LC | -L ; F | 0] (u = K y)."""
        return (self.A + self.B @ self.F + self.L @ self.C, -self.L, self.F,
                np.zeros((self.F.shape[0], self.L.shape[1])))

    def youla_port_matrices(self) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        """J_K with inputs [y; eta] and outputs [u; eps] (eqs. 5-6, Fig. 2 with Q open).

        This is the exported controller: u = F xhat + eta, eps = y - C xhat.
        """
        _n, m = self.B.shape
        p = self.C.shape[0]
        Ak = self.A + self.B @ self.F + self.L @ self.C
        Bk = np.hstack([-self.L, self.B])
        Ck = np.vstack([self.F, -self.C])
        Dk = np.block([[np.zeros((m, p)), np.eye(m)], [np.eye(p), np.zeros((p, m))]])
        return Ak, Bk, Ck, Dk


def lqr_gain(A: NDArray, B: NDArray, Q: NDArray, R: NDArray) -> NDArray:
    """Discrete LQR gain F for u = F x (positive convention): A + BF is Schur."""
    P = sla.solve_discrete_are(A, B, Q, R)
    return -np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)


def kalman_predictor_gain(A: NDArray, C: NDArray, W: NDArray, V: NDArray) -> NDArray:
    """Steady-state Kalman predictor gain L (positive convention): A + LC is Schur."""
    P = sla.solve_discrete_are(A.T, C.T, W, V)
    return -A @ P @ C.T @ np.linalg.inv(C @ P @ C.T + V)


def design_observer_controller(reduced: ReducedModel, dt: float = 1e-4,
                               settings: DesignSettings | None = None) -> ObserverController:
    """LQR + Kalman observer-based controller on the ZOH-discretised reduced model.

    Examples
    --------
    >>> from bayes_amb.rig import load_rig
    >>> from bayes_amb.reduction import reduce_pseudo_modal
    >>> ctrl = design_observer_controller(reduce_pseudo_modal(load_rig()), dt=1e-4)
    >>> ctrl.F.shape, ctrl.L.shape
    ((4, 8), (8, 4))
    """
    if not (np.isfinite(dt) and 0 < dt <= 1e-2):
        raise ControllerError(f"option --dt: value {dt:g} out of range: must be > 0 and <= 0.01 s")
    s = settings or DesignSettings()
    s.validate()
    Ad, Bd = zoh(reduced.A, reduced.B, dt)
    C = reduced.C
    n = Ad.shape[0]
    # A tiny state weight keeps the Riccati problem well posed; output weighting dominates.
    Q = C.T @ C / s.y_ref**2
    Q = Q + 1e-6 * np.trace(Q) / n * np.eye(n)
    R = np.eye(Bd.shape[1]) / s.u_ref**2
    W = s.w_ref**2 * Bd @ Bd.T
    W = W + 1e-6 * np.trace(W) / n * np.eye(n)
    V = s.v_ref**2 * np.eye(C.shape[0])
    F = lqr_gain(Ad, Bd, Q, R)
    L = kalman_predictor_gain(Ad, C, W, V)
    return ObserverController(A=Ad, B=Bd, C=C, F=F, L=L, dt=float(dt),
                              speed_rpm=reduced.speed_rpm, settings=s)
