"""The paper's eq. 15 estimate by Gauss-Newton: argmin sum_k |eps_k - S(theta) x_k|^2.

The residual DFT R_k(theta) is close to linear in theta (S(theta) enters through a
low-rank LFT, METHOD.md section 2), so one batch of p + 1 kernel rows (R and its forward
differences, G = (R, dR/dtheta_1, ..., dR/dtheta_p)) gives the cost of the linear model as a
quadratic form, sum_k |R_k + J_k delta|^2 = w^T T w with w = (1, delta) and
T[a, c] = Re sum_k,ch G_a conj(G_c). Its minimum over the prior box is a step; the step is
halved until the exact cost falls (Nocedal & Wright, Numerical Optimization, 10.3). A few
steps reach what L-BFGS-B with central differences (2 p + 1 rows per gradient, some fifty
gradients) reaches. Used by identify's MAP (estimate.find_map, its first stage) and by the
diagnosis' (discrepancy/gauss_newton.least_squares_start).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
import scipy.optimize as so
from numpy.typing import NDArray

STEP = 1e-5
"""Forward-difference step of the Jacobian (theta is dimensionless, of order 0.01-10)."""


class ResidualModel(Protocol):
    """What the search needs of a likelihood: R for a batch of theta rows, and its cost."""

    def residual_dft(self, theta: NDArray) -> tuple[NDArray, NDArray]: ...

    def sum_squares(self, theta: NDArray) -> NDArray: ...


def _quadratic(d: NDArray, H: NDArray, g: NDArray) -> tuple[float, NDArray]:
    return float(d @ H @ d + 2 * g @ d), 2 * (H @ d + g)


def gauss_newton_least_squares(like: ResidualModel, lo: NDArray, hi: NDArray,
                               theta0: NDArray, max_iter: int = 8, step: float = STEP
                               ) -> tuple[NDArray, float, int]:
    """Minimise sum_k |R_k(theta)|^2 over the box [lo, hi] from theta0 (module docstring).

    Returns theta, its cost and the number of theta rows evaluated. Stops when a step
    lowers the cost by less than 1e-10 of it, when no halved step lowers it, or where a
    row of the Jacobian's batch is not stabilised.

    Examples
    --------
    >>> import numpy as np
    >>> class Line:                     # R(theta) = a + B theta, minimised at B^-1 (-a)
    ...     a = np.array([[1.0 + 0j, -2.0]]); B = np.array([[[2.0, 0], [0, 1.0]]])
    ...     def residual_dft(self, th):
    ...         R = self.a + np.einsum("kcj,bj->bkc", self.B, th)
    ...         return R, np.ones(len(th), bool)
    ...     def sum_squares(self, th):
    ...         return np.sum(np.abs(self.residual_dft(th)[0]) ** 2, axis=(1, 2))
    >>> th, cost, _ = gauss_newton_least_squares(Line(), np.full(2, -5.0), np.full(2, 5.0),
    ...                                          np.zeros(2))
    >>> np.round(th, 6).tolist(), round(cost, 12)
    ([-0.5, 2.0], 0.0)
    """
    theta = np.clip(np.asarray(theta0, dtype=float), lo, hi)
    p = theta.size
    cost = float(like.sum_squares(theta[None])[0])
    rows_used = 1
    for _ in range(max_iter):
        h = np.where(theta + step > hi, -step, step)       # inward at an upper bound
        rows = np.tile(theta, (p + 1, 1))
        rows[1 + np.arange(p), np.arange(p)] += h
        R, stable = like.residual_dft(rows)
        rows_used += p + 1
        if not np.all(stable):
            break
        G = np.concatenate([R[:1], (R[1:] - R[:1]) / h[:, None, None]]).reshape(p + 1, -1)
        T = (G @ G.conj().T).real                                       # (p + 1, p + 1)
        res = so.minimize(_quadratic, np.zeros(p), args=(T[1:, 1:], T[1:, 0]), jac=True,
                          method="L-BFGS-B", bounds=list(zip(lo - theta, hi - theta,
                                                             strict=True)),
                          options={"maxiter": 500, "ftol": 1e-15, "gtol": 1e-12})
        d = res.x
        for _ in range(10):
            new = float(like.sum_squares((theta + d)[None])[0])
            rows_used += 1
            if new < cost:
                break
            d = 0.5 * d
        else:
            break
        converged = cost - new < 1e-10 * cost
        theta, cost = theta + d, new
        if converged:
            break
    return theta, cost, rows_used
