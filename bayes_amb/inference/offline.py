"""Dual-Youla signals from recorded data: eps = Mt y - Nt u (and x = Vt u - Ut y).

Computed with the nominal model and observer gain of the loop model (the controller's own
for an observer-based controller), exactly as the innovation the controller formed.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from bayes_amb.inference.loop_model import LoopParts


def dual_youla_eps(parts: LoopParts, y: NDArray, u: NDArray) -> NDArray:
    """eps[k] = y[k] - C xhat[k], xhat+ = A xhat + B u + L (C xhat - y), from rest; (N, 4)."""
    A_L = parts.A + parts.L @ parts.C
    xo = np.zeros(A_L.shape[0])
    eps = np.empty_like(y)
    drive = y @ parts.L.T - u @ parts.B.T                       # x_o+ = A_L x_o + L y - B u
    for k in range(y.shape[0]):
        eps[k] = parts.C @ xo + y[k]
        xo = A_L @ xo + drive[k]
    return eps


def dual_youla_x(parts: LoopParts, F: NDArray, y: NDArray, u: NDArray) -> NDArray:
    """x[k] = u[k] - F xhat[k] (= Vt u - Ut y), equal to eta for the observer-based loop."""
    A_L = parts.A + parts.L @ parts.C
    xo = np.zeros(A_L.shape[0])
    x = np.empty_like(u)
    drive = y @ parts.L.T - u @ parts.B.T
    for k in range(y.shape[0]):
        x[k] = u[k] + F @ xo                                      # x_o = -xhat
        xo = A_L @ xo + drive[k]
    return x
