"""The baselines the benchmarks compare against, and the timer.

The baselines are the plain way of doing the same computation with python-control: simulate
S(theta) x in the time domain with ``control.forced_response`` and score the residual with
an iid Gaussian likelihood; simulate the closed loop with ``forced_response`` on an
explicitly assembled discrete state-space system.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import control
import numpy as np
from numpy.typing import NDArray

from bayes_amb.control.discrete import zoh
from bayes_amb.inference.forward import ForwardModel
from bayes_amb.io.controller_file import ControllerFile


def median_time(fn: Callable[[], Any], repeats: int) -> float:
    """Median wall time of ``fn()`` over ``repeats`` calls, after one warm-up call.

    Parameters
    ----------
    fn : callable
        Called without arguments; its result is discarded.
    repeats : int
        Number of timed calls (``time.perf_counter``), at least 1.

    Returns
    -------
    float
        Median wall time of one call, in s.

    Examples
    --------
    >>> median_time(lambda: sum(range(100)), 3) >= 0.0
    True
    """
    fn()
    times = []
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def naive_log_likelihood(fm: ForwardModel, eps: NDArray, z: NDArray
                         ) -> tuple[float, NDArray]:
    """Baseline likelihood: S(theta) x by ``control.forced_response``, iid Gaussian residual.

    S(theta) is built exactly as the fast path builds it (``fm.excitation_system``, the
    dual-Youla map x -> eps, eq. 13) and simulated from rest in the time domain.

    Parameters
    ----------
    fm : ForwardModel
        Forward model of the recording (its excitation x, (N, 4)).
    eps : ndarray, shape (N, 4)
        Dual-Youla signal of the recording, in m.
    z : ndarray, shape (p + 3,)
        [theta (p), log10 sigma (3)]; sigma_noise = 10**z[p] (m) is the residual's
        standard deviation.

    Returns
    -------
    log_lik : float
        iid Gaussian log-likelihood of the residual.
    residual : ndarray, shape (N, 4)
        eps - S(theta) x, in m.
    """
    p = len(fm.params)
    A, B, C = (m[0] for m in fm.excitation_system(z[None, :p]))
    resp = control.forced_response(control.ss(A, B, C, 0, fm.dt), U=fm.x.T)
    r = eps - np.asarray(resp.outputs).T
    s2 = 10.0 ** (2 * z[p])
    return float(-0.5 * (np.sum(r * r) / s2 + r.size * np.log(2 * np.pi * s2))), r


def naive_eval_us(fm: ForwardModel, eps: NDArray, points: NDArray, repeats: int) -> float:
    """Median cost of one :func:`naive_log_likelihood` evaluation, in microseconds.

    Parameters
    ----------
    fm, eps
        As for :func:`naive_log_likelihood`.
    points : ndarray, shape (n, p + 3)
        Parameter vectors, used in turn (one per timed call).
    repeats : int
        Number of timed evaluations.

    Returns
    -------
    float
        Median time of one evaluation, in us.
    """
    order = iter(np.resize(np.arange(points.shape[0]), max(1, repeats) + 1))
    return 1e6 * median_time(lambda: naive_log_likelihood(fm, eps, points[next(order)]),
                             repeats)


def closed_loop_ss(A: NDArray, B: NDArray, C: NDArray, ctrl: ControllerFile,
                   dt: float) -> control.StateSpace:
    """Explicit discrete closed loop of a continuous plant (ZOH) and a controller file.

    Parameters
    ----------
    A, B, C : ndarray
        Continuous plant, shapes (n, n), (n, 4) and (4, n): currents in A to
        displacements in m, no feedthrough.
    ctrl : ControllerFile
        Controller with inputs [y (4); eta (4)] and outputs [u (4); eps (4)].
    dt : float
        Sample time, in s.

    Returns
    -------
    control.StateSpace
        Discrete system (n + n_k states) from eta (4) to [y (4); u (4)], with the plant
        input u = C_u x_k + D_uy y + D_ue eta.
    """
    Ad, Bd = zoh(A, B, dt)
    Ak, Bk, Ck, Dk = ctrl.A, ctrl.B, ctrl.C, ctrl.D
    Duy, Due, Cu = Dk[:4, :4], Dk[:4, 4:], Ck[:4]
    nk = Ak.shape[0]
    A_cl = np.block([[Ad + Bd @ Duy @ C, Bd @ Cu], [Bk[:, :4] @ C, Ak]])
    B_cl = np.vstack([Bd @ Due, Bk[:, 4:]])
    C_cl = np.block([[C, np.zeros((4, nk))], [Duy @ C, Cu]])
    D_cl = np.vstack([np.zeros((4, 4)), Due])
    return control.ss(A_cl, B_cl, C_cl, D_cl, dt)
