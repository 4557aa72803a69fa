"""The amplifier's current loop with its rate capped by the supply voltage: looked for on
every record where the residual holds a lag, named and modelled where found.

A switching amplifier closes a current loop of finite bandwidth wb, and its supply voltage
caps how fast the coil current can change:

    di/dt = clip(wb (w - i), -S, S),       w the held command (the recorded current u).

Below the cap it is a first-order lag (the library's actuator_lag: linear physics). Above
it, on the large steps of a random binary excitation, the current ramps at S: a lag whose
size depends on the step's. Named as a lag, the cap's part bends the coefficients (on the
foreign generator's held-out capped loops, 4 of 24 coefficients inside their intervals with
a confident linear name). Like the slew limit (nonlinear.py), the loop acts on a recorded
signal, so it enters the S(theta) likelihood as a transform of the data: over each sample
the coil current is solved exactly from where the previous sample left it (a ramp at S
while wb |w - i| > S, then an exponential approach), and the plant is given the held
sample that has the waveform's mean with its first moment in place (a share of the
pulse's mean held a sample earlier, as slew_defect does). With S infinite this is a linear
filter of u (lag_defect), with wb infinite the slew limit's ramp-then-hold.

The screen (loop_screen), on a fitted model's residual:
1. lag stage (cheap: a linear filter per bandwidth): the residual regressed on the lag's
   defect at each bearing over a grid of bandwidths, beside the coefficients' Jacobian.
   Without a lag (z below the threshold) there is no loop to cap and the screen ends.
2. cap stage: at the best bandwidth, the cap's own part (the capped loop minus the lag)
   over a grid of rates, S = ratio x the rms rate the uncapped loop asks on this record,
   regressed beside the lag columns and the Jacobian. Found when its z passes the
   Bonferroni threshold over the grid, both beside the Jacobian and after the residual
   and the regressor are freed of the loop's linear signals (Regression.linear_free: a
   linear misfit, the lag itself included, cannot fake it), with a gain near one.
3. profile: the bandwidth and the rate with the gain fixed at one (the whole loop, lag
   and cap, taken out of the residual; least residual sum of squares with the
   coefficients free), on a local grid in log parameters with a quadratic surface through
   it. Its 90 % intervals are where that sum rises by chi2_1(0.9) with the other
   parameter profiled, floored at LOOP_REL_SD.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from bayes_amb.discrepancy.linearity import Regression
from bayes_amb.discrepancy.loop_waveform import asked_rate, lag_defect, loop_defect
from bayes_amb.discrepancy.nonlinear import LOOP, Nonlinearity, rss_fn

BANDWIDTHS_HZ = (500.0, 750.0, 1000.0, 1500.0, 2000.0, 3000.0, 4000.0, 6000.0, 8000.0)
"""The lag stage's grid of current-loop bandwidths."""
RATE_RATIOS = (0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.1, 1.2, 1.35, 1.5, 1.7, 2.0)
"""The cap stage's grid: S over the rms rate wb |u - i| the uncapped loop asks."""
ALPHA = 1e-4
GAIN_RANGE = (0.5, 2.0)
CHI2_90 = float(stats.chi2.ppf(0.9, 1))
CAP_Z_GATE = 2.0
"""The z the cap must reach, in the first screen's cap stage (beside the lag) and on a
named lag's residual, for the model comparison to be run (loop_alternative.py): on a
foreign record whose weak cap moved five coefficients past their intervals they were 2.1
and 2.6, with gains of 0.94 and 0.93; on two plain-lag records 1.7 and 0.8 in the first
screen, and 1.8 and 0.5 with gains of 0.13 and 0.01 on the named lag's residual (the gain
must also lie in GAIN_RANGE)."""
LOOP_REL_SD = 0.01
"""Least relative sd of an estimated rate or bandwidth: the held sample with its first
moment is this model's, not the amplifier's (whose waveform passes through the plant
within the sample)."""
_COARSE = np.log(np.array([0.8, 0.9, 1.0, 1.1, 1.25]))
"""The profile's coarse local grid (log steps about the best point, each parameter)."""
_FINE = np.array([-0.04, -0.02, 0.0, 0.02, 0.04])
"""Its fine grid about the coarse surface's minimum, where the intervals are read."""


def _per_bearing(d: NDArray) -> list[NDArray]:
    """d split into bearing A's channels and bearing B's (zeros elsewhere)."""
    a, b = np.zeros_like(d), np.zeros_like(d)
    a[:, :2], b[:, 2:] = d[:, :2], d[:, 2:]
    return [a, b]


def _joint(reg: Regression, cols: list[NDArray]) -> tuple[NDArray, NDArray, NDArray]:
    """Regression of the residual on regressor rows ``cols`` beside the Jacobian, with
    band-wise weights: coefficients, their z, the row weights."""
    X = np.column_stack([*cols, reg.J])
    b, wt = reg.band_weights(X, reg.y)
    Xw = X * wt[:, None]
    sd = np.sqrt(np.maximum(np.diag(np.linalg.pinv(Xw.T @ Xw))[:len(cols)], 1e-300))
    return b[:len(cols)], b[:len(cols)] / sd, wt


def _quadratic_min(p: NDArray, f: NDArray) -> tuple[NDArray, NDArray] | None:
    """Least-squares quadratic surface through values f at points p (m, 2): its minimiser
    and Hessian, or None when it has no minimum."""
    x, y = p[:, 0], p[:, 1]
    A = np.column_stack([np.ones_like(x), x, y, x * x, x * y, y * y])
    c = np.linalg.lstsq(A, f, rcond=None)[0]
    H = np.array([[2 * c[3], c[4]], [c[4], 2 * c[5]]])
    if np.any(np.linalg.eigvalsh(H) <= 0):
        return None
    return np.linalg.solve(H, -c[1:3]), H


def _lag_stage(reg: Regression, u: NDArray, dt: float) -> tuple[float, float]:
    """The lag regression over BANDWIDTHS_HZ: the largest z of a bearing's lag and its
    bandwidth (u centred)."""
    fits = []
    for bw in BANDWIDTHS_HZ:
        cols = [reg.rows(reg.defect_dft(c)) for c in _per_bearing(lag_defect(u, bw, dt))]
        fits.append((float(np.max(_joint(reg, cols)[1])), bw))
    return max(fits)


def _cap_stage(reg: Regression, u: NDArray, dt: float, bw: float,
               lag_cols: list[NDArray], linear_free: bool = True,
               z_crit: float | None = None) -> tuple[bool, float, dict]:
    """The cap's own part (the capped loop minus its lag) at bandwidth bw over the rate
    grid, regressed beside lag_cols and the Jacobian, and freed of the loop's linear
    signals: found, the best grid rate, and the statistics (Nonlinearity's fields).
    linear_free=False does not ask the linear-free z to pass (cap_stage_at); z_crit
    (default: Bonferroni over the grid at ALPHA) is the z the best rate must pass."""
    n_grid = len(RATE_RATIOS)
    if z_crit is None:
        z_crit = float(stats.norm.isf(ALPHA / n_grid))
    lag = lag_defect(u, bw, dt)
    rates = np.array(RATE_RATIOS) * asked_rate(u, bw, dt)
    D = loop_defect(u, rates, np.full(n_grid, bw), dt)
    zs, zfs, gains = [], [], []
    for j in range(n_grid):
        cap = D[j] - lag
        if not np.any(np.abs(cap) > 1e-12):
            zs.append(0.0), zfs.append(0.0), gains.append(0.0)
            continue
        Cd = reg.defect_dft(cap)
        b, z, _ = _joint(reg, [reg.rows(Cd), *lag_cols])
        zs.append(float(z[0])), gains.append(float(b[0]))
        zfs.append(reg.linear_free_z(Cd))
    j = int(np.argmax(zs))
    near = [gains[k] for k in range(n_grid) if zs[k] > z_crit]
    found = bool(zs[j] > z_crit and (max(zfs) > z_crit or not linear_free) and near
                 and max(near) >= GAIN_RANGE[0] and min(near) <= GAIN_RANGE[1])
    common = dict(z=zs[j], z_linear_free=float(max(zfs)), z_crit=z_crit, gain=gains[j],
                  gain_sd=abs(gains[j] / zs[j]) if zs[j] else 0.0)
    return found, float(rates[j]), common


def loop_screen(reg: Regression, u: NDArray, dt: float) -> Nonlinearity:
    """The capped current loop's screen on a fitted model's residual (module docstring):
    a nonlinear.Nonlinearity named LOOP, parameter 'slew_a_per_s' with the bandwidth
    beside it (estimate and interval90 keys 'all' and 'bandwidth_hz')."""
    u = np.asarray(u, dtype=float) - np.median(u, axis=0)
    z_lag, bw = _lag_stage(reg, u, dt)
    z_crit = float(stats.norm.isf(ALPHA / len(RATE_RATIOS)))
    if not z_lag > z_crit:
        return Nonlinearity(LOOP, False, 0.0, 0.0, z_crit)
    lag_cols = [reg.rows(reg.defect_dft(c)) for c in _per_bearing(lag_defect(u, bw, dt))]
    found, rate, common = _cap_stage(reg, u, dt, bw, lag_cols)
    if not found:
        return Nonlinearity(LOOP, False, **common)
    _, _, wt = _joint(reg, lag_cols)
    return _profiled(reg, wt, u, dt, (bw, rate), common)


def cap_stage_at(reg: Regression, u: NDArray, dt: float, bandwidth_hz: float
                 ) -> tuple[bool, float, dict]:
    """The cap stage on the residual of a model that holds the loop's lag (a named
    actuator lag of this bandwidth): found, the best grid rate, the statistics. The
    linear-free test is not asked: under a random binary excitation most steps are the
    same size, so a cap acts on them alike and is nearly linear in u; what tells it from
    the lag is then the model comparison (loop_alternative.py), which this only gates:
    so its z must pass CAP_Z_GATE, not a detection threshold, with the gain near one."""
    u = np.asarray(u, dtype=float) - np.median(u, axis=0)
    return _cap_stage(reg, u, dt, bandwidth_hz, [], linear_free=False, z_crit=CAP_Z_GATE)


def _profiled(reg: Regression, wt: NDArray, u: NDArray, dt: float,
              centre: tuple[float, float], common: dict) -> Nonlinearity:
    """The loop found, its bandwidth and rate profiled from ``centre`` with the gain fixed
    at one (the whole loop taken out of the residual, the coefficients free). The
    estimate starts the modelling (loop_model.py), which fits the bandwidth and the rate
    again with the lag exact."""
    rss_bins = rss_fn(reg, wt)

    def rss(d: NDArray) -> float:
        return rss_bins(reg.defect_dft(d))

    rss_lin = rss_bins(None)

    def surface(centre: tuple[float, float], steps: NDArray) -> tuple[NDArray, NDArray]:
        """rss on a grid of log steps about centre (bandwidth, rate): points, values."""
        pts = np.array([(lb, ls) for lb in steps for ls in steps])
        F = loop_defect(u, centre[1] * np.exp(pts[:, 1]), centre[0] * np.exp(pts[:, 0]), dt)
        return pts, np.array([rss(F[k]) for k in range(len(pts))])

    for steps in (_COARSE, _FINE):
        for _ in range(3):              # grids until the best is inside one
            pts, vals = surface(centre, steps)
            k = int(np.argmin(vals))
            if np.all((pts[k] > steps[0]) & (pts[k] < steps[-1])):
                break
            centre = (centre[0] * float(np.exp(pts[k, 0])),
                      centre[1] * float(np.exp(pts[k, 1])))
        if steps is _COARSE:            # the fine grid about the coarse surface's minimum
            quad = _quadratic_min(pts - pts[k], vals - vals[k])
            at = pts[k] + (quad[0] if quad is not None and np.all(
                np.abs(quad[0]) < _COARSE[-1]) else 0.0)
            centre = (centre[0] * float(np.exp(at[0])), centre[1] * float(np.exp(at[1])))
    rss0 = float(vals[k])
    bw, rate = centre[0] * float(np.exp(pts[k, 0])), centre[1] * float(np.exp(pts[k, 1]))
    quad = _quadratic_min(pts, vals - rss0)
    sd = np.array([LOOP_REL_SD, LOOP_REL_SD])
    if quad is not None:
        at, H = quad
        b_q, s_q = centre[0] * float(np.exp(at[0])), centre[1] * float(np.exp(at[1]))
        if np.all(np.abs(at) <= _FINE[-1]) and (
                r_q := rss(loop_defect(u, [s_q], [b_q], dt)[0])) < rss0:
            bw, rate, rss0 = b_q, s_q, r_q
        cov = 2.0 * np.linalg.inv(H)        # rss rises by p' H p / 2: one sd at a rise of 1
        sd = np.maximum(np.sqrt(np.maximum(np.diag(cov), 0.0)), LOOP_REL_SD)
    half = np.sqrt(CHI2_90) * sd            # log half-widths of the 90 % intervals
    return Nonlinearity(LOOP, True, where=("all",), parameter="slew_a_per_s",
                        estimate={"all": rate, "bandwidth_hz": bw},
                        interval90={"all": (rate * np.exp(-half[1]), rate * np.exp(half[1])),
                                    "bandwidth_hz": (bw * np.exp(-half[0]),
                                                     bw * np.exp(half[0]))},
                        rss_drop=float(rss_lin - rss0), **common)
