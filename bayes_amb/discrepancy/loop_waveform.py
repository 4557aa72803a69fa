"""The current an amplifier's current loop delivers, as held samples: the waveform behind
the capped current loop (current_loop.py) and, in its limits, the plain lag and the slew
limit's ramp-then-hold (nonlinear.slew_defect).

    di/dt = clip(wb (w - i), -S, S),       w the held command (the recorded current u).

Over each sample the coil current is solved exactly from where the previous sample left
it: a ramp at S while wb |w - i| > S, then an exponential approach to w. The plant is
given the held sample with the waveform's mean and its first moment in place: the current
is its end value held plus a pulse that decays to zero at the sample's end, and a share
1/2 - centroid / dt of the pulse's mean is held a sample earlier (a held sample's centroid
is the sample's middle).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray
from scipy.signal import lfilter


def _pulse_share(Q: NDArray, M1: NDArray, dt: float) -> NDArray:
    """The share of a pulse's mean held a sample earlier: 1/2 - centroid / dt (the
    centroid M1 / Q of a pulse that decays to zero at the sample's end)."""
    safe = np.where(Q > 0, Q, 1.0)
    return np.where(Q > 0, 0.5 - M1 / safe / dt, 0.0)


def loop_defect(u: NDArray, rates: NDArray, bandwidths_hz: NDArray, dt: float,
                first_moment: bool = True) -> NDArray:
    """Delivered minus commanded current (G, N, 4) for G loops (rate S A/s, bandwidth Hz;
    np.inf allowed for either), driven by the held command u (N, 4), as held samples (the
    module docstring). The loop starts at the first command. first_moment=False holds
    each pulse's mean in its own sample (the cruder form). Compiled (_loop_kernel; the
    numpy form, loop_defect_numpy, took 0.9 s of a 2 s record's screen)."""
    u = np.ascontiguousarray(u, dtype=float)
    S = np.asarray(rates, dtype=float).ravel()
    wb = 2.0 * np.pi * np.asarray(bandwidths_hz, dtype=float).ravel()
    S = np.ascontiguousarray(np.where(np.isfinite(S), S, 1e150))   # no cap / ideal loop
    wb = np.ascontiguousarray(np.where(np.isfinite(wb), wb, 1e150))
    d = np.zeros((S.size, u.shape[0], u.shape[1]))
    _loop_kernel(u, S, wb, float(dt), bool(first_moment), d)
    return d


@njit(cache=True, nogil=True)
def _loop_kernel(u, S, wb, dt, first_moment, d):  # pragma: no cover - compiled
    # loop_defect_numpy's arithmetic, one loop and channel at a time in sample order
    n, nc = u.shape
    for j in range(S.size):
        s_j, w_j = S[j], wb[j]
        e_free = s_j / w_j                       # |w - i| below which the lag is free
        for c in range(nc):
            i = u[0, c]
            for k in range(n):
                e0 = u[k, c] - i
                sg = 1.0 if e0 > 0 else (-1.0 if e0 < 0 else 0.0)
                a = abs(e0)
                t1 = min(max((a - e_free) / s_j, 0.0), dt)    # the ramp's end
                g1 = a - s_j * t1                             # the error it leaves
                L = dt - t1
                x = np.exp(-w_j * L)
                g_end = g1 * x
                q_exp = g1 * (1.0 - x) / w_j
                Q = a * t1 - 0.5 * s_j * t1 * t1 + q_exp - g_end * dt
                pulse = -sg * Q / dt
                end = -sg * g_end
                if first_moment:
                    M1 = (0.5 * a * t1 * t1 - s_j * t1 ** 3 / 3.0 + t1 * q_exp
                          + g1 * ((1.0 - x) / w_j ** 2 - L * x / w_j) - 0.5 * g_end * dt * dt)
                    share = 0.5 - M1 / Q / dt if Q > 0 else 0.0
                    d[j, k, c] += end + (1.0 - share) * pulse
                    if k:
                        d[j, k - 1, c] += share * pulse
                else:
                    d[j, k, c] += end + pulse
                i = u[k, c] - sg * g_end


def loop_defect_numpy(u: NDArray, rates: NDArray, bandwidths_hz: NDArray, dt: float,
                      first_moment: bool = True) -> NDArray:
    """:func:`loop_defect` in numpy, the G loops side by side in each sample's step (the
    compiled kernel's reference, held to it by a test)."""
    u = np.asarray(u, dtype=float)
    n = u.shape[0]
    S = np.asarray(rates, dtype=float).reshape(-1, 1)
    wb = 2.0 * np.pi * np.asarray(bandwidths_hz, dtype=float).reshape(-1, 1)
    S = np.where(np.isfinite(S), S, 1e150)       # no cap / an ideal loop
    wb = np.where(np.isfinite(wb), wb, 1e150)
    g = S.shape[0]
    E = S / wb                                   # |w - i| below which the lag is free
    i = np.broadcast_to(u[0], (g, 4)).copy()
    d = np.zeros((g, n, 4))
    for k in range(n):
        e0 = u[k] - i
        s = np.sign(e0)
        a = np.abs(e0)
        t1 = np.minimum(np.maximum((a - E) / S, 0.0), dt)     # the ramp's end
        g1 = a - S * t1                                       # the error it leaves
        L = dt - t1
        x = np.exp(-wb * L)
        g_end = g1 * x
        q_exp = g1 * (1.0 - x) / wb
        Q = a * t1 - 0.5 * S * t1 * t1 + q_exp - g_end * dt   # the pulse above the end
        pulse = -s * Q / dt
        end = -s * g_end
        if first_moment:
            M1 = (0.5 * a * t1 * t1 - S * t1 ** 3 / 3.0 + t1 * q_exp
                  + g1 * ((1.0 - x) / wb ** 2 - L * x / wb) - 0.5 * g_end * dt * dt)
            share = _pulse_share(Q, M1, dt)
            d[:, k] += end + (1.0 - share) * pulse
            if k:
                d[:, k - 1] += share * pulse
        else:
            d[:, k] += end + pulse
        i = u[k] - s * g_end
    return d


def lag_defect(u: NDArray, bandwidth_hz: float, dt: float) -> NDArray:
    """loop_defect with no cap (N, 4), as a linear filter of u: the end current follows
    i[k] = x i[k-1] + (1 - x) u[k], x = exp(-wb dt), and the pulse of every sample has the
    same shape, so its mean and first moment are fixed multiples of u[k] - i[k-1]."""
    u = np.asarray(u, dtype=float)
    wb = 2.0 * np.pi * bandwidth_hz
    x = float(np.exp(-wb * dt))
    i_end = lfilter([1.0 - x], [1.0, -x], u, axis=0, zi=x * u[:1])[0]
    e0 = u - np.vstack([u[:1], i_end[:-1]])
    Q = (1.0 - x) / wb - x * dt
    M1 = (1.0 - x) / wb ** 2 - dt * x / wb - 0.5 * x * dt * dt
    share = float(_pulse_share(np.array(Q), np.array(M1), dt))
    pulse = -e0 * Q / dt
    d = -e0 * x + (1.0 - share) * pulse
    d[:-1] += share * pulse[1:]
    return d


def asked_rate(u: NDArray, bandwidth_hz: float, dt: float) -> float:
    """The rms rate wb |u[k] - i[k-1]| the uncapped loop asks at the start of each sample
    (A/s): the scale of the cap stage's grid."""
    u = np.asarray(u, dtype=float)
    x = float(np.exp(-2.0 * np.pi * bandwidth_hz * dt))
    i_end = lfilter([1.0 - x], [1.0, -x], u, axis=0, zi=x * u[:1])[0]
    e0 = u[1:] - i_end[:-1]
    return float(2.0 * np.pi * bandwidth_hz * np.sqrt(np.mean(e0 ** 2)))


def loop_substeps(u: NDArray, rate: float, bandwidth_hz: float, dt: float, m: int = 8
                  ) -> NDArray:
    """Delivered minus commanded current of one loop as exact means over m equal
    sub-intervals of each sample (N, m, 4): within a sample the current ramps at the cap
    while wb |w - i| > S, then approaches w exponentially (module docstring); its integral
    is read at the sub-interval ends. np.inf is allowed for the rate (the plain lag)."""
    u = np.asarray(u, dtype=float)
    n = u.shape[0]
    S = float(rate) if np.isfinite(rate) else 1e150
    wb = 2.0 * np.pi * float(bandwidth_hz)
    E = S / wb
    t = np.linspace(0.0, dt, m + 1)[None, :]           # (1, m + 1)
    h = dt / m
    out = np.empty((n, m, 4))
    i = u[0].copy()
    for k in range(n):
        e0 = u[k] - i
        s = np.sign(e0)
        a = np.abs(e0)
        t1 = np.minimum(np.maximum((a - E) / S, 0.0), dt)[:, None]       # (4, 1)
        g1 = a[:, None] - S * t1
        tt = np.minimum(t, t1)
        F = a[:, None] * tt - 0.5 * S * tt * tt + np.where(
            t > t1, g1 * -np.expm1(-wb * np.maximum(t - t1, 0.0)) / wb, 0.0)
        out[k] = (-s[:, None] * np.diff(F, axis=1) / h).T
        i = u[k] - s * g1[:, 0] * np.exp(-wb * (dt - t1[:, 0]))
    return out
