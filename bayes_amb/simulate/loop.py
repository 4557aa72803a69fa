"""Closed-loop simulation of a continuous truth plant under a discrete controller.

Signals (Fig. 2 of the paper) at sample k:

    y_meas = sensor_gain * C x + n          recorded displacement (sensor noise n)
    y_c    = y_meas + r1                    what the controller sees (r1: sensor-side)
    [k; eps_c] = controller([y_c; eta])     eta: the controller's excitation port
    u      = k + e2                         e2: excitation added after the controller
    u_plant = u + r2                        r2: actuator-side disturbance (not recorded)
    x+      = exact ZOH of the plant over one sample, with the input delayed by delay_s

The recorded current u is the current at the plant input and includes any injected
excitation (the convention of io/recording.py): e2 when the excitation is injected after
the controller (port ``r2``), and eta when the controller adds it at its output, as a
generic controller's exported form does. Only the unknown disturbance r2 is not in u.
The delay tau = m dt + phi (0 <= phi < dt) is exact under ZOH:
x[k+1] = Ad x[k] + Gamma(dt - phi) u[k-m] + e^{A(dt-phi)} Gamma(phi) u[k-m-1].
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bayes_amb.control.discrete import zoh
from bayes_amb.simulate.truth import TruthPlant


@dataclass(frozen=True)
class LoopSignals:
    """Simulated signals, each (n, 4): recorded y (m) and u (A), controller eps (m).

    ``unstable`` is True when the sampled closed loop has a pole on or outside the unit circle
    (checked by eigenvalues, see :func:`closed_loop_spectral_radius`) or the signals diverged.
    """

    y: NDArray
    u: NDArray
    eps: NDArray
    unstable: bool


def delayed_input_matrices(A: NDArray, B: NDArray, dt: float, delay_s: float
                           ) -> tuple[NDArray, int, NDArray, NDArray]:
    """(Ad, m, G_now, G_prev): u[k-m] enters through G_now and u[k-m-1] through G_prev."""
    m = int(np.floor(delay_s / dt + 1e-12))
    phi = delay_s - m * dt
    Ad, G_full = zoh(A, B, dt)
    if phi <= 1e-15 * dt:
        return Ad, m, G_full, np.zeros_like(G_full)
    E1, G_rest = zoh(A, B, dt - phi)
    _, G_phi = zoh(A, B, phi)
    return Ad, m, G_rest, E1 @ G_phi


_EIG_LIMIT = 1500   # largest closed-loop order whose eigenvalues are computed (dense eig)


def closed_loop_spectral_radius(truth: TruthPlant,
                                controller: tuple[NDArray, NDArray, NDArray, NDArray],
                                dt: float,
                                discrete: tuple[NDArray, int, NDArray, NDArray] | None = None
                                ) -> float:
    """Spectral radius of the sampled closed loop that :func:`simulate_loop` runs.

    ``discrete`` is the result of :func:`delayed_input_matrices` when the caller has it.

    States [x; x_k; u_p[k-1]; ...; u_p[k-m-1]] (plant, controller, held past plant inputs of
    the delay line). Returns nan when the order exceeds an internal limit (1500).
    """
    Ak, Bk, Ck, Dk = (np.asarray(m, dtype=float) for m in controller)
    Ad, m_del, G_now, G_prev = discrete or delayed_input_matrices(truth.A, truth.B, dt,
                                                                   truth.delay_s)
    Cg = truth.sensor_gain[:, None] * truth.C
    n, nk, nu = Ad.shape[0], Ak.shape[0], truth.B.shape[1]
    size = n + nk + nu * (m_del + 1)
    if size > _EIG_LIMIT:
        return float("nan")
    M = np.zeros((size, size))
    sx, sk = slice(0, n), slice(n, n + nk)

    def hist(j: int) -> slice:                      # u_p[k - j], j = 1..m_del+1
        return slice(n + nk + (j - 1) * nu, n + nk + j * nu)

    u_x, u_k = Dk[:nu, :nu] @ Cg, Ck[:nu]           # u_p[k] = u_x x + u_k x_k (inputs off)
    M[sx, sx] = Ad
    M[sk, sx] = Bk[:, :nu] @ Cg
    M[sk, sk] = Ak
    if m_del == 0:
        M[sx, sx] += G_now @ u_x
        M[sx, sk] += G_now @ u_k
    else:
        M[sx, hist(m_del)] += G_now
    M[sx, hist(m_del + 1)] += G_prev
    M[hist(1), sx], M[hist(1), sk] = u_x, u_k
    for j in range(2, m_del + 2):
        M[hist(j), hist(j - 1)] = np.eye(nu)
    return float(np.max(np.abs(np.linalg.eigvals(M))))


def simulate_loop(truth: TruthPlant, controller: tuple[NDArray, NDArray, NDArray, NDArray],
                  dt: float, eta: NDArray, noise: NDArray | None = None,
                  r1: NDArray | None = None, r2: NDArray | None = None,
                  port: str = "eta", law: Callable[[NDArray, NDArray], NDArray] | None = None
                  ) -> LoopSignals:
    """Run the loop for len(eta) samples from rest. controller = (Ak, Bk, Ck, Dk) with
    inputs [y (4); eta (4)] and outputs [u (4); eps (4)].

    port: where the excitation ``eta`` (n, 4) enters: ``"eta"``, the controller's eta
    port; ``"r2"``, added to the controller's output current (the eta port stays zero).
    Either way the recorded u includes what the excitation adds to the plant current.
    law: the magnets' force law as a current d(u_plant, y) (4,) added to the plant's input
    on each sample (rig.force_law.law_current at the rig file's bias), from the plant
    current and the noise-free probe signal of that sample; None: linear magnets.
    """
    if port not in ("eta", "r2"):
        raise ValueError(f"port: expected 'eta' or 'r2' instead of {port!r}")
    n = eta.shape[0]
    zeros = np.zeros_like(eta)
    e2 = eta if port == "r2" else zeros
    eta = zeros if port == "r2" else eta
    noise = zeros if noise is None else noise
    r1 = zeros if r1 is None else r1
    r2 = zeros if r2 is None else r2
    Ak, Bk, Ck, Dk = (np.asarray(m, dtype=float) for m in controller)
    Ad, m_del, G_now, G_prev = delayed_input_matrices(truth.A, truth.B, dt, truth.delay_s)
    Cg = truth.sensor_gain[:, None] * truth.C
    # unbalance: the continuous forward-whirl force amp [cos, sin](w t + ph), integrated
    # exactly over each sample: x+ = Ad x + Re((A - j w I)^-1 (Ad - e^{j w dt} I) B_f
    # [1, -j] amp e^{j (w t_k + ph)})
    force_term = np.zeros((n, truth.n_states))
    if truth.B_f is not None and truth.unbalance is not None:
        amp, ph = truth.unbalance
        omega = truth.speed_rpm * 2 * np.pi / 60
        Ad_f, _ = zoh(truth.A, truth.B_f, dt)
        eye = np.eye(truth.n_states)
        Gw = np.linalg.solve(truth.A - 1j * omega * eye,
                             (Ad_f - np.exp(1j * omega * dt) * eye) @ truth.B_f)
        t = np.arange(n) * dt
        force_term = np.real(np.exp(1j * (omega * t + ph))[:, None]
                             * (Gw @ np.array([1.0, -1j]))[None, :]) * amp
    x = np.zeros(truth.n_states)
    xk = np.zeros(Ak.shape[0])
    u_hist = np.zeros((n + m_del + 1, truth.B.shape[1]))   # u_hist[k + m_del + 1] = u_plant[k]
    y_rec = np.empty((n, 4))
    u_rec = np.empty((n, 4))
    eps = np.empty((n, 4))
    v = np.empty(8)
    unstable = False
    off = m_del + 1
    for k in range(n):
        y = Cg @ x + noise[k]
        v[:4] = y + r1[k]
        v[4:] = eta[k]
        out = Ck @ xk + Dk @ v
        xk = Ak @ xk + Bk @ v
        y_rec[k] = y
        u_rec[k] = out[:4] + e2[k]
        eps[k] = out[4:]
        u_hist[k + off] = u_rec[k] + r2[k]
        if law is not None:
            u_hist[k + off] += law(u_hist[k + off], y - noise[k])
        x = Ad @ x + G_now @ u_hist[k + off - m_del] + G_prev @ u_hist[k + off - m_del - 1] \
            + force_term[k]
        if k % 256 == 0 and not np.all(np.isfinite(x)):
            unstable = True
            break
    if unstable or not np.all(np.isfinite(y_rec)):
        unstable = True
    elif closed_loop_spectral_radius(truth, (Ak, Bk, Ck, Dk), dt,
                                     (Ad, m_del, G_now, G_prev)) >= 1.0:
        unstable = True   # a growing but still finite response is no rig recording either
    return LoopSignals(y=y_rec, u=u_rec, eps=eps, unstable=unstable)
