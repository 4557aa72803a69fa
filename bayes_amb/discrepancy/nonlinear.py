"""The magnets' force law and the amplifier's slew-rate limit: looked for on every record,
named and modelled where found, never absorbed into the linear coefficients.

Both act on signals the DAQ records, so they enter the S(theta) likelihood as a transform
of the data, not as a nonlinear simulation. The plant received the recorded current u plus
a defect d that is a known function of the record (given one physical parameter), and d
enters the loop where r2 does: the residual of the fitted linear model then holds
T_r2(theta) d, T_r2 the model's own r2 -> eps filter with a gain of exactly one (the
clipping test's reasoning, linearity.py). Modelling it is refitting on eps - T_r2 d.

magnet force law   A differential pair with bias current i0 and air gap g0 pulls with
                   f = F0 [(1 + i/i0)^2 / (1 - x/g0)^2 - (1 - i/i0)^2 / (1 + x/g0)^2].
                   Its linearisation at the centre is the rig's ki and ks exactly when
                   i0 = g0 ks / ki and F0 = ki i0 / 4, so one parameter per bearing (the
                   gap g0; the bias follows) fixes the law. The force beyond ki i + ks x,
                   divided by ki, is the current defect d = N(u, x; g0) / ki, x the rotor
                   displacement at the actuator (from the probes by rigid-body kinematics
                   along the shaft, rig.force_law.actuator_displacement). To third order
                   d = beta h with h = x u^2 / rho + 3 u x^2 + 2 rho x^3, rho = ks / ki
                   and beta = 1 / g0^2: linear in beta, so the screen is a regression of
                   the whitened residual on T_r2 h (one column per bearing) beside the
                   coefficients' Jacobian.
                   The mean of u^2 times x is a stiffness (a linear fit absorbs it: ks
                   looks (1 + <(u/i0)^2>) times larger); the rest is not linear and names
                   the law.
slew-rate limit    The amplifier's voltage limit caps di/dt at S. Within a sample the
                   current ramps from where it ended toward the held command at rate S at
                   most, then holds; the current the plant integrates over the sample is
                   the ramp-then-hold's mean (slew_defect). The screen runs the regression
                   over a grid of S (quantiles of |du/dt|), as the clipping test does over
                   limits, with the gain checked against one.

A finding needs a z above the Bonferroni threshold both beside the Jacobian and after the
residual and the regressor are freed of their fit on the DFTs of u and the excitation in
narrow bands (the linear-free z: a linear misfit the model lacks, a lag, a seal, is linear
in the loop's signals and cannot fake it). Its parameter is then profiled with the exact
law and the gain fixed at one (least residual sum of squares with the coefficients free),
and its 90 % interval is where that sum rises by chi2_1(0.9) = 2.71 (the rows are whitened
with band-wise variances, so a unit rise is one unit of log likelihood times two).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray
from scipy import optimize, stats

from bayes_amb.discrepancy.linearity import Regression
from bayes_amb.rig import Rig
from bayes_amb.rig.force_law import (
    actuator_displacement,
    bias_per_gap,
    law_current,
    rig_gaps,
    rig_saturation,
)

FORCE_LAW = "magnet_force_law"
RIG_FORCE_LAW = "rig_force_law"
"""How a fit took the force law in when the rig file's bias gave it (not the record)."""
SLEW = "slew_limit"
LOOP = "amp_current_loop"
"""The amplifier's current loop with its rate capped (current_loop.py)."""
TITLES = {FORCE_LAW: "magnet force law (gap and bias beyond the linearisation)",
          SLEW: "amplifier slew-rate limit (voltage limit)",
          LOOP: "amplifier current loop with its rate capped (supply voltage limit)",
          "current_limit": "amplifier current limit"}
ALPHA = 1e-4
"""Family-wise level of each screen (Bonferroni over its bearings or its grid)."""
SLEW_QUANTILES = (0.995, 0.99, 0.98, 0.97, 0.95, 0.92, 0.88, 0.84, 0.8, 0.75)
"""Candidate slew rates: these quantiles of |du/dt| pooled over the channels (0.5 .. 25 %
of the samples ramp-limited)."""
GAIN_RANGE = (0.5, 2.0)
"""A slew limit's gain must reach 1 within this range: its path through the loop is known."""
CHI2_90 = float(stats.chi2.ppf(0.9, 1))
SLEW_REL_SD = 0.005
"""Least relative sd of an estimated slew rate: the sample-mean ramp is this model's, not
the amplifier's (whose ramp passes through the plant within the sample); on the first
three foreign slew records the estimates were off by -0.2 .. +0.1 %, against profile
intervals of +-0.1 %."""
GAP_RANGE = (1e-5, 0.05)
"""Gaps (m) the force law's profile searches: 10 um .. 50 mm."""


def centred(v: NDArray) -> NDArray:
    v = np.asarray(v, dtype=float)
    return v - np.median(v, axis=0)


def nonlinear_part(d: NDArray, u: NDArray, x: NDArray) -> NDArray:
    """d (N, 4) freed, per channel, of its least-squares fit on [1, u, x]: the part no
    linear coefficient can take. What is left is not linear in the probes' noise either
    (x u^2 holds <u^2> times the noise, which the residual holds too: a regression on it
    would find the noise, not the law)."""
    out = np.empty_like(d)
    for c in range(d.shape[1]):
        Z = np.column_stack([np.ones(d.shape[0]), u[:, c], x[:, c]])
        coef = np.linalg.lstsq(Z, d[:, c], rcond=None)[0]
        out[:, c] = d[:, c] - Z @ coef
    return out


def force_law_regressors(rig: Rig, u: NDArray, x: NDArray) -> dict[str, NDArray]:
    """Per bearing, h (N, 4) with d ~ h / g0^2 to third order (module docstring), zero on
    the other bearing's channels, freed of its linear part (nonlinear_part)."""
    u, x, rho = centred(u), centred(x), bias_per_gap(rig)
    h = nonlinear_part(x * u ** 2 / rho + 3.0 * u * x ** 2 + 2.0 * rho * x ** 3, u, x)
    out = {}
    for j, b in enumerate("AB"):
        hb = np.zeros_like(h)
        hb[:, 2 * j:2 * j + 2] = h[:, 2 * j:2 * j + 2]
        out[b] = hb
    return out


def force_law_defect(rig: Rig, u: NDArray, x: NDArray, gaps: dict[str, float],
                     saturation: dict[str, float] | None = None) -> NDArray:
    """d = (f - ki i - ks x) / ki (N, 4) of the exact differential law, per bearing gap
    (m; a bearing not in ``gaps`` is linear), for the record's currents and displacements
    about their medians (rig.force_law.law_current; the iron saturating at the rig file's
    ratios unless ``saturation`` gives others)."""
    return law_current(rig, centred(u), centred(x), gaps, saturation)


def slew_defect(u: NDArray, rate: float, dt: float, first_moment: bool = True) -> NDArray:
    """The current a ramp-then-hold amplifier (slew rate ``rate`` A/s) delivers, driven by
    the held command u, minus u (N, 4), as held samples. The ramp starts where the previous
    sample's ended (at the first command for the first sample).

    Over a sample the delivered current is its end value (held: the command, or short of
    it when the ramp takes the whole sample) minus a triangle of height rate tau and length
    tau (tau <= dt, the ramp's time). The triangle's mean, rate tau^2 / (2 dt), sits at
    tau / 3 from the sample's start, not at its middle where a held sample sits; so a share
    delta = 1/2 - tau / (3 dt) of it is held in the sample before, which puts the pulse's
    first moment where it is (its phase right up to a few hundred Hz). first_moment=False
    holds the whole mean in its own sample (the cruder form: their difference is the
    scale of what the held form leaves out, clip_model._parameter_spread)."""
    u = np.require(u, np.float64, ("C", "W"))     # one compiled signature (eigen.modal_batch)
    d = np.zeros_like(u)
    _ramp_defect(u, float(rate), float(dt), bool(first_moment), d)
    return d


@njit(cache=True, nogil=True)
def _ramp_defect(u, rate, dt, first_moment, d):  # pragma: no cover - compiled
    # slew_defect's loop, per channel in sample order (it was Python: 36 ms a call)
    step = rate * dt
    half = rate / (2.0 * dt)
    n = u.shape[0]
    pulse = np.zeros(n)                          # the triangle's mean (signed), per sample
    share = np.zeros(n)                          # delta: its share held a sample earlier
    for c in range(u.shape[1]):
        prev = u[0, c]
        pulse[:] = 0.0
        share[:] = 0.0
        for k in range(n):
            target = u[k, c]
            delta = target - prev
            if delta == 0:
                continue
            up = delta > 0
            if -step <= delta <= step:
                tau = abs(delta) / rate
                prev = target
            else:
                tau = dt
                prev += step if up else -step
                d[k, c] = prev - target          # held short of the command
            pulse[k] = -(half * tau * tau) if up else half * tau * tau
            share[k] = 0.5 - tau / (3.0 * dt) if first_moment else 0.0
        for k in range(n):
            if pulse[k] != 0.0:
                d[k, c] += (1.0 - share[k]) * pulse[k]
                if k:
                    d[k - 1, c] += share[k] * pulse[k]


@dataclass(frozen=True)
class Nonlinearity:
    """A nonlinearity the screen found (or its strongest candidate when none was found).

    name: 'magnet_force_law' or 'slew_limit'; where: the bearings (force law) or 'all';
    parameter: 'gap_m' or 'slew_a_per_s'; estimate and interval90 per location; z and
    z_linear_free: the screen's statistics against their threshold z_crit; gain, gain_sd:
    the regression coefficient (the force law's 1/g0^2 per bearing, the slew's gain);
    rss_drop: how much the modelled law lowers the whitened residual sum of squares."""

    name: str
    found: bool
    z: float
    z_linear_free: float
    z_crit: float
    where: tuple[str, ...] = ()
    parameter: str = ""
    estimate: dict[str, float] = field(default_factory=dict)
    interval90: dict[str, tuple[float, float]] = field(default_factory=dict)
    gain: float = 0.0
    gain_sd: float = 0.0
    rss_drop: float = 0.0
    source: str = "record"
    saturation: dict[str, float] = field(default_factory=dict)
    """The force law's iron saturation ratio per bearing where the rig file gives one."""

    @property
    def title(self) -> str:
        return TITLES[self.name]

    def defect(self, rig: Rig, u: NDArray, y: NDArray, dt: float,
               at: dict[str, float] | None = None,
               saturation: dict[str, float] | None = None) -> NDArray:
        """The current defect d (N, 4) at the estimate (or at ``at``; the force law's
        saturation ratios at ``saturation`` instead of its own)."""
        v = self.estimate if at is None else at
        if self.name == FORCE_LAW:
            sat = saturation if saturation is not None else (self.saturation or None)
            return force_law_defect(rig, u, actuator_displacement(rig, y), v, sat)
        return slew_defect(u, v["all"], dt)

    def ends(self) -> list[dict[str, float]]:
        """The parameter one sd (from the 90 % interval) below and above its estimate, per
        location in turn: the refits that carry its uncertainty into the coefficients."""
        out = []
        for loc, (lo, hi) in self.interval90.items():
            sd = (hi - lo) / (2 * 1.645)
            for s in (-1.0, 1.0):
                v = dict(self.estimate)
                v[loc] = max(v[loc] + s * sd, 1e-12)
                out.append(v)
        return out

    def saturation_ends(self) -> list[dict[str, float]]:
        """The saturation ratios with one bearing's SATURATION_REL_SD below and above it,
        in turn (the refits that carry the ratio's uncertainty into the coefficients)."""
        out = []
        for b, r in self.saturation.items():
            for s in (-1.0, 1.0):
                out.append({**self.saturation, b: max(r * (1.0 + s * SATURATION_REL_SD),
                                                       1.0 + 1e-6)})
        return out

    def text(self) -> str:
        """One phrase: what, where, the parameter with its interval."""
        if self.name == LOOP:
            (blo, bhi), (lo, hi) = self.interval90["bandwidth_hz"], self.interval90["all"]
            return (f"{self.title}: bandwidth {self.estimate['bandwidth_hz']:.4g} Hz (90 % "
                    f"{blo:.4g} .. {bhi:.4g}), rate capped at {self.estimate['all']:.4g} "
                    f"A/s (90 % {lo:.4g} .. {hi:.4g})")
        parts = []
        for loc in self.where:
            e, (lo, hi) = self.estimate[loc], self.interval90[loc]
            if self.name == FORCE_LAW:
                sat = (f", the iron saturating at {self.saturation[loc]:.3g} times the bias "
                       "flux density" if loc in self.saturation else "")
                parts.append(f"bearing {loc}: gap {1e3 * e:.3g} mm (90 % {1e3 * lo:.3g} .. "
                             f"{1e3 * hi:.3g} mm){sat}")
            else:
                parts.append(f"{e:.4g} A/s (90 % {lo:.4g} .. {hi:.4g})")
        src = ((" (from the rig file's bias current and saturation ratio)" if self.saturation
                else " (from the rig file's bias current)") if self.source == "rig file"
               else "")
        return f"{self.title}{src}: " + "; ".join(parts)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "found": self.found, "z": self.z,
                "z_linear_free": self.z_linear_free, "z_crit": self.z_crit,
                "where": list(self.where), "parameter": self.parameter,
                "estimate": dict(self.estimate),
                "interval90": {k: list(v) for k, v in self.interval90.items()},
                "gain": self.gain, "gain_sd": self.gain_sd, "rss_drop": self.rss_drop,
                "source": self.source,
                **({"saturation": dict(self.saturation)} if self.saturation else {})}


BIAS_REL_SD = 0.05
"""Relative sd of a bias current the rig file gives (a design value: the amplifiers' bias
setting and the gap's machining tolerance)."""
SATURATION_REL_SD = 0.05
"""Relative sd of a saturation ratio the rig file gives (the iron's saturation flux
density from its data sheet over the design's bias flux density)."""


def rig_force_law(rig: Rig) -> Nonlinearity | None:
    """The magnets' force law at the bias currents the rig file states (rig.force_law.
    rig_gaps), with BIAS_REL_SD as its uncertainty; None when it states none. One record
    at one excitation level cannot tell this law from a stiffness change (its mean part is
    one, and the rest, spread over the whole band by a random binary excitation, hardly
    moves the rotor), so where the rig file knows the bias the law is modelled from it."""
    gaps = rig_gaps(rig)
    where = sorted(gaps)
    if not gaps:
        return None
    k = 1.645 * BIAS_REL_SD
    return Nonlinearity(FORCE_LAW, False, 0.0, 0.0, 0.0, where=tuple(where),
                        parameter="gap_m", estimate=gaps,
                        interval90={b: (g * (1 - k), g * (1 + k)) for b, g in gaps.items()},
                        source="rig file", saturation=rig_saturation(rig))


def rss_fn(reg: Regression, wt: NDArray) -> Callable[[NDArray], float]:
    """Whitened residual sum of squares after a defect's bins are taken out, with the
    coefficients free (their Jacobian projected out) and fixed band weights."""
    Q, _ = np.linalg.qr(reg.J * wt[:, None])

    def rss(bins: NDArray | None) -> float:
        """None: no defect taken out (the linear model's own sum)."""
        r = (reg.y if bins is None else reg.y - reg.rows(bins)) * wt
        return float(np.sum((r - Q @ (Q.T @ r)) ** 2))
    return rss


def _argmin_log(f: Callable[[float], float], centre: float, half: float,
                n: int = 13) -> float:
    """The minimiser of f over [centre - half, centre + half]: a grid of n points, then a
    bounded search between the best one's neighbours."""
    grid = np.linspace(centre - half, centre + half, n)
    vals = [f(float(v)) for v in grid]
    j = int(np.argmin(vals))
    a, b = grid[max(j - 1, 0)], grid[min(j + 1, n - 1)]
    res = optimize.minimize_scalar(f, bounds=(a, b), method="bounded",
                                   options={"xatol": 1e-4})
    return float(res.x if res.fun <= vals[j] else grid[j])


def _interval(f: Callable[[float], float], best: float, lo: float, hi: float,
              rss0: float) -> tuple[float, float]:
    """Where f (a profiled residual sum of squares) rises by CHI2_90 on either side of
    best, within [lo, hi] (a side that never rises that far ends at the bound)."""
    def side(end: float) -> float:
        if f(end) - rss0 < CHI2_90:
            return end
        return float(optimize.brentq(lambda v: f(v) - rss0 - CHI2_90, *sorted((best, end)),
                                     xtol=1e-6 * abs(best)))
    return side(lo), side(hi)


def force_law_screen(reg: Regression, rig: Rig, u: NDArray, y: NDArray) -> Nonlinearity:
    """The force-law regression (module docstring): z per bearing, and where found the
    gap profiled with the exact law."""
    x = actuator_displacement(rig, y)
    hs = force_law_regressors(rig, u, x)
    scale = {b: 1.0 / max(float(np.sqrt(np.mean(hs[b] ** 2))), 1e-300) for b in "AB"}
    hs = {b: hs[b] * scale[b] for b in "AB"}            # unit rms: a conditioned regression
    cols = [reg.rows(reg.defect_dft(hs[b])) for b in "AB"]
    X = np.column_stack([*cols, reg.J])
    b, wt = reg.band_weights(X, reg.y)
    Xw = X * wt[:, None]
    cov = np.linalg.pinv(Xw.T @ Xw)
    z = np.array([b[j] / np.sqrt(cov[j, j]) for j in range(2)])
    # linear-free z: both the regressors and the residual freed of the loop's signals
    free = [reg.linear_free(reg.defect_dft(hs[c])) for c in "AB"]
    Xf = np.column_stack(free)
    bf, wf = reg.band_weights(Xf, reg.y_linear_free)
    Xfw = Xf * wf[:, None]
    covf = np.linalg.pinv(Xfw.T @ Xfw)
    zf = np.array([bf[j] / np.sqrt(covf[j, j]) for j in range(2)])
    z_crit = float(stats.norm.isf(ALPHA / 2))
    hit = tuple(c for j, c in enumerate("AB") if z[j] > z_crit and zf[j] > z_crit)
    j_best = int(np.argmax(z))
    sb = scale["AB"[j_best]]
    common = dict(z=float(z[j_best]), z_linear_free=float(zf[j_best]), z_crit=z_crit,
                  gain=float(b[j_best] * sb), gain_sd=float(np.sqrt(cov[j_best, j_best]) * sb))
    if not hit:
        return Nonlinearity(FORCE_LAW, False, **common)
    rss = rss_fn(reg, wt)
    gaps = {c: float((b["AB".index(c)] * scale[c]) ** -0.5) for c in hit}
    rss_lin = rss(None)
    uc, xc = centred(u), centred(x)

    def total(g: dict[str, float]) -> float:
        return rss(reg.defect_dft(nonlinear_part(force_law_defect(rig, u, x, g), uc, xc)))

    for _ in range(2):                         # coordinate profile, log gap, per bearing
        for c in hit:
            def one(lg: float, c: str = c) -> float:
                return total({**gaps, c: float(np.exp(lg))})
            gaps[c] = float(np.clip(np.exp(_argmin_log(one, np.log(gaps[c]), 1.2)),
                                    *GAP_RANGE))
    rss0 = total(gaps)
    intervals = {c: _interval(lambda g, c=c: total({**gaps, c: g}), gaps[c],
                              gaps[c] / 3.0, gaps[c] * 3.0, rss0) for c in hit}
    return Nonlinearity(FORCE_LAW, True, where=hit, parameter="gap_m", estimate=gaps,
                        interval90=intervals, rss_drop=float(rss_lin - rss0), **common)


def slew_screen(reg: Regression, u: NDArray, dt: float) -> Nonlinearity:
    """The slew-limit regression over a grid of rates (module docstring)."""
    u = np.asarray(u, dtype=float)
    du = np.abs(np.diff(u, axis=0)).ravel() / dt
    rates = np.quantile(du[du > 0], SLEW_QUANTILES) if np.any(du > 0) else np.array([])
    z_crit = float(stats.norm.isf(ALPHA / max(len(rates), 1)))
    if rates.size == 0:
        return Nonlinearity(SLEW, False, 0.0, 0.0, z_crit)
    best = None
    zs, zfs, betas = [], [], []
    for r in rates:
        D = reg.defect_dft(slew_defect(u, float(r), dt))
        X = np.column_stack([reg.rows(D), reg.J])
        b, wt = reg.band_weights(X, reg.y)
        Xw = X * wt[:, None]
        sd = float(np.sqrt(np.linalg.pinv(Xw.T @ Xw)[0, 0]))
        zs.append(b[0] / sd)
        zfs.append(reg.linear_free_z(D))
        betas.append(float(b[0]))
        if best is None or zs[-1] > best[0]:
            best = (zs[-1], float(r), float(b[0]), sd, wt)
    zmax, _, beta, sd, wt = best
    zf = float(max(zfs))
    found = bool(zmax > z_crit and zf > z_crit and max(betas) >= GAIN_RANGE[0]
                 and min(betas) <= GAIN_RANGE[1])
    common = dict(z=float(zmax), z_linear_free=zf, z_crit=z_crit, gain=beta, gain_sd=sd)
    if not found:
        return Nonlinearity(SLEW, False, **common)
    rss = rss_fn(reg, wt)

    def f(rate: float) -> float:
        return rss(reg.defect_dft(slew_defect(u, rate, dt)))

    lo, hi = float(rates.min()), float(rates.max())
    rate = float(np.exp(_argmin_log(lambda lr: f(float(np.exp(lr))),
                                    0.5 * np.log(lo * hi), 0.5 * np.log(hi / lo) + 0.1)))
    rss0 = f(rate)
    rss_lin = rss(None)
    lo90, hi90 = _interval(f, rate, rate / 2.0, rate * 2.0, rss0)
    floor = 1.645 * SLEW_REL_SD * rate
    interval = (min(lo90, rate - floor), max(hi90, rate + floor))
    return Nonlinearity(SLEW, True, where=("all",), parameter="slew_a_per_s",
                        estimate={"all": rate}, interval90={"all": interval},
                        rss_drop=float(rss_lin - rss0), **common)


def better_fit(reg: Regression, a: NDArray, b: NDArray) -> bool:
    """Whether current defect a (N, 4) explains the residual better than b: the smaller
    whitened residual sum of squares with the coefficients free, under one set of band
    weights (those of the residual on the Jacobian alone)."""
    _, wt = reg.band_weights(reg.J, reg.y)
    rss = rss_fn(reg, wt)
    return rss(reg.defect_dft(a)) < rss(reg.defect_dft(b))


def screen(like, params: NDArray, log10_sigma: NDArray, u: NDArray, y: NDArray,
           rig: Rig, reg: Regression | None = None) -> list[Nonlinearity]:
    """Both screens on a fitted model's residual: the force law and the slew limit, the
    found ones first, the larger drop of the residual sum of squares first (ranked)."""
    reg = reg or Regression(like, params, log10_sigma, u)
    return ranked([force_law_screen(reg, rig, u, y), slew_screen(reg, u, like.forward.dt)])


def ranked(found: list[Nonlinearity]) -> list[Nonlinearity]:
    """Screens' results, the found ones first, the larger drop of the residual sum of
    squares first."""
    return sorted(found, key=lambda n: (not n.found, -n.rss_drop))

