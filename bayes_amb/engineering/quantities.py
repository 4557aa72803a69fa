"""Physical quantities from the posterior: :func:`physical_quantities`.

Every quantity q = f(theta) is a function of theta. Its value is the median of f over
(thinned) posterior draws; its 90 % interval is :func:`~bayes_amb.engineering.intervals.interval90`
(the equal-tailed interval widened to f over the posterior's central region; see
intervals.py for why).

The same function at theta = 0 is the nominal (as-designed) value, and at the true theta
(simulated data) the truth.

Sign convention (stated once, used everywhere): the bearing force on the rotor at an axis is

    f = ki i + ks s - c s'

with s the rotor displacement at the bearing. ks > 0 is the magnet's position stiffness (a
negative spring: it destabilises), c > 0 is passive damping (it stabilises). "ks" below is
ks as identified, ks (1 - theta_k); "c" is the identified damping theta_c c_ref
(:mod:`bayes_amb.uncertainty.parameters`).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar

from bayes_amb.engineering.intervals import CentralRegion, central_region, interval90
from bayes_amb.engineering.loop import (
    API617_LOGDEC,
    MODE_LABELS,
    closed_loop_modes,
    log_decrement,
)
from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.posterior import gaussian_draws
from bayes_amb.io.recording import Recording
from bayes_amb.results.engineering import EngineeringAnswers
from bayes_amb.results.identification import Identification
from bayes_amb.rig import CHANNELS
from bayes_amb.threads import limited_threads, pool_threads
from bayes_amb.uncertainty import get_spec, parse_param_list

__all__ = ["API617_LOGDEC", "Draws", "EngineeringResult", "Quantity", "draws_from",
           "physical_quantities", "required_separation_margin"]


@dataclass(frozen=True)
class Draws:
    """Posterior draws of theta: ``names`` (p,) and ``theta`` (n, p), dimensionless."""

    names: tuple[str, ...]
    theta: NDArray

    def __post_init__(self) -> None:
        names = parse_param_list(self.names)
        th = np.atleast_2d(np.asarray(self.theta, dtype=float))
        if th.shape[1] != len(names):
            raise BayesAmbError(f"draws: theta has {th.shape[1]} columns; expected "
                                f"{len(names)} for {list(names)}")
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "theta", th)

    def as_dicts(self) -> list[dict[str, float]]:
        return [dict(zip(self.names, (float(v) for v in row), strict=True))
                for row in self.theta]


def draws_from(source: Any, n_draws: int = 200, seed: int = 0) -> Draws:
    """Thinned posterior draws from an identification result, a report RunData or Draws.

    With emcee samples: ``n_draws`` evenly spaced draws of the flattened chains. Without
    (MAP-only runs): draws from the Laplace normal of summary.json, N(mean, C) with C its
    "laplace_cov" (with the correlations), or diag(sd^2) for a summary written before it
    was stored, with a numpy Generator seeded by ``seed``.
    """
    if isinstance(source, Draws):
        th = source.theta
        if th.shape[0] > n_draws:
            th = th[np.linspace(0, th.shape[0] - 1, n_draws).round().astype(int)]
        return Draws(source.names, th)
    names = tuple(getattr(source, "names", ()))
    flat = None
    samples = getattr(source, "samples", None)
    if samples is not None:                                  # an Identification
        flat = np.asarray(samples)[:, :, :len(names)].reshape(-1, len(names))
    elif getattr(source, "posterior", None) is not None and hasattr(source, "draws"):
        flat = np.stack([np.asarray(source.draws(n)).ravel() for n in names], axis=1)
    if flat is not None:
        idx = np.linspace(0, flat.shape[0] - 1, min(n_draws, flat.shape[0])).round()
        return Draws(names, flat[idx.astype(int)])
    ident = getattr(source, "summary", None) if hasattr(source, "run_dir") else source
    if not names or not isinstance(ident, Identification):
        raise BayesAmbError(f"draws: cannot take posterior draws from {type(source).__name__}")
    par = ident.parameters
    mean = np.array([float(par[n].mean) for n in names])
    sd = np.array([float(par[n].sd or 0.0) for n in names])
    sd = np.where(np.isfinite(sd), sd, 0.0)
    rng = np.random.default_rng(seed)
    lc = ident.laplace_cov
    if lc is not None and tuple(lc.names) == names:
        cov = np.asarray(lc.theta, dtype=float)
        return Draws(names, gaussian_draws(rng, mean, cov, n_draws))
    return Draws(names, mean + sd * rng.standard_normal((n_draws, len(names))))


@dataclass(frozen=True)
class Quantity:
    """One derived quantity: median and 90 % interval [lo, hi] over the draws
    (:func:`interval90`), the nominal value (theta = 0), the unit, the group it belongs to
    and how many draws gave a finite value."""

    name: str
    unit: str
    group: str
    value: float
    lo: float
    hi: float
    nominal: float
    n_valid: int
    estimated: bool = True

    def covers(self, truth: float) -> bool:
        return bool(self.lo <= truth <= self.hi)

    def to_dict(self) -> dict[str, Any]:
        return {"unit": self.unit, "group": self.group, "value": self.value,
                "interval90": [self.lo, self.hi], "nominal": self.nominal,
                "n_valid": self.n_valid, "estimated": self.estimated}


def required_separation_margin(zeta: NDArray, below: NDArray) -> NDArray:
    """API 617-style required separation margin (%) from the amplification factor.

    AF = 1/(2 zeta). AF < 2.5: no margin required (0). Otherwise, for a mode below the
    running speed SM = 17 (1 - 1/(AF - 1.5)); above it SM = min(10 + 17 (1 - 1/(AF - 1.5)),
    26).

    Examples
    --------
    >>> required_separation_margin(np.array([0.5, 0.01, 0.01]), np.array([True, True, False]))
    array([ 0.        , 16.64948454, 26.        ])
    """
    zeta = np.asarray(zeta, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        af = 1.0 / (2.0 * zeta)
        base = 17.0 * (1.0 - 1.0 / (af - 1.5))
    req = np.where(below, base, np.minimum(10.0 + base, 26.0))
    return np.where(af < 2.5, 0.0, req)


@dataclass(frozen=True)
class EngineeringResult:
    """What :func:`physical_quantities` found.

    quantities: name -> Quantity. speeds_rpm (n_s,); lam (n, n_s, 6) continuous closed-loop
    eigenvalues per draw, speed and mode (MODE_LABELS), rad/s; lam_nominal (n_s, 6);
    sens_freq_hz (n_f,), sens (n, n_f, 4) |S| per axis and sens_nominal (n_f, 4) at the
    recording's speed; draws the theta draws used; region their central region
    (:func:`central_region`), and lam_edge (n_e, n_s, 6) and sens_edge (n_e, n_f, 4) the
    same at its edge points; model "full" or "reduced".
    """

    quantities: dict[str, Quantity]
    speeds_rpm: NDArray
    running_speed_rpm: float
    lam: NDArray
    lam_nominal: NDArray
    sens_freq_hz: NDArray
    sens: NDArray
    sens_nominal: NDArray
    draws: Draws
    region: CentralRegion
    lam_edge: NDArray
    sens_edge: NDArray
    model: str
    notes: tuple[str, ...] = field(default_factory=tuple)

    def interval(self, values: NDArray, edge_values: NDArray) -> tuple[NDArray, NDArray]:
        """:func:`interval90` of values at the draws (n, ...) and at the edge points
        (n_e, ...): the interval every table, figure and JSON of these quantities shows."""
        return interval90(values, self.region.inside, edge_values)

    def to_dict(self) -> dict[str, Any]:
        return {"format": "bayes-amb-engineering/2", "model": self.model,
                "speeds_rpm": self.speeds_rpm.tolist(),
                "running_speed_rpm": self.running_speed_rpm,
                "n_draws": int(self.draws.theta.shape[0]),
                "n_edge_points": int(self.region.edge.shape[0]),
                "interval": INTERVAL_TEXT,
                "quantities": {k: q.to_dict() for k, q in self.quantities.items()},
                "notes": list(self.notes)}

    def answers(self, source: str | None = None) -> EngineeringAnswers:
        """The typed answers (results/engineering.py: what answers.json holds), with the
        posterior they came from."""
        data = self.to_dict()
        if source is not None:
            data["source"] = source
        return EngineeringAnswers.from_dict(data)


INTERVAL_TEXT = ("90 %: the 5 % and 95 % quantiles over the posterior draws, widened to the "
                 "quantity's range over the central region within 1.645 sd (Mahalanobis) "
                 "of the posterior mean")
"""How the intervals are made, in one line (JSON, CLI and report)."""


def _mode_key(label: str, what: str, speed: float) -> str:
    return f"{label}: {what} @ {speed:.0f} rpm"


def _bearing_values(names: tuple[str, ...], theta: NDArray, rec: Recording
                    ) -> dict[str, tuple[NDArray, str, bool]]:
    """Per axis: ks as identified (N/m) and c (N s/m); kxy (N/m) where estimated."""
    rig = rec.rig
    out = {}
    for ch in CHANNELS:
        for kind, unit in (("k", "N/m"), ("c", "N s/m")):
            n = f"{kind}_{ch}"
            th = theta[:, names.index(n)] if n in names else np.zeros(theta.shape[0])
            val = (rig.magnets[ch[0]].ks * (1.0 - th) if kind == "k"
                   else th * rig.c_ref)
            label = f"bearing {ch}: ks" if kind == "k" else f"bearing {ch}: c"
            out[label] = (val, unit, n in names)
    for n in names:
        spec = get_spec(n)
        if spec.kind == "kxy":
            out[f"{spec.location}: kxy"] = (theta[:, names.index(n)] * rig.k_ref, "N/m", True)
    return out


def _quantity(name: str, unit: str, group: str, values: NDArray, nominal: float,
              region: CentralRegion, estimated: bool = True) -> Quantity:
    """values (n + n_e,): at the draws, then at the region's edge points."""
    n = region.inside.size
    v = np.asarray(values, dtype=float)
    ok = np.isfinite(v[:n])
    if not ok.any():
        return Quantity(name, unit, group, float("nan"), float("nan"), float("nan"),
                        float(nominal), 0, estimated)
    lo, hi = interval90(v[:n], region.inside, v[n:])
    return Quantity(name, unit, group, float(np.median(v[:n][ok])), float(lo), float(hi),
                    float(nominal), int(ok.sum()), estimated)


def _minimum(name: str, modes: list[Quantity], nominal: float) -> Quantity:
    """The smallest log dec over the modes: value, lo and hi are the minima of the modes'
    medians, lower and upper ends.

    Not the interval of the per-draw minimum: where two modes' log decs nearly tie, the
    minimum of their draws lies below both, so its 95 % quantile hardly reaches the true
    minimum (rigid 3 and 4 differ by 0.03 on the reference rig: 25 of 30 intervals covered
    it in the coverage test, misses by 0.001). If every mode's interval covers its own
    truth, [min lo, min hi] covers the true minimum; away from a tie it is the interval of
    the weakest mode itself.
    """
    ok = [m for m in modes if m.n_valid > 0 and np.isfinite(m.value)]
    if not ok:
        return Quantity(name, "", "api617", float("nan"), float("nan"), float("nan"),
                        nominal, 0)
    return Quantity(name, "", "api617", min(m.value for m in ok), min(m.lo for m in ok),
                    min(m.hi for m in ok), nominal, min(m.n_valid for m in ok))


def _at_point(rig: Any, ctrl: Any, speed: float, theta: dict[str, float], model: str,
              freq: NDArray | None) -> tuple[NDArray, NDArray | None, NDArray | None]:
    """One plant's closed-loop modes at ``speed``, and where ``freq`` is given its
    sensitivity there and the peaks. Independent of every other point: the points run in
    a pool of threads (LAPACK releases the GIL; on ROSS's test rig, 452 closed-loop states,
    two threads took 1.22 s where one took 2.15 s for 16 points, the same eigenvalues to
    the bit)."""
    lm = closed_loop_modes(rig, ctrl, speed, theta, model)
    if freq is None:
        return lm.lam, None, None
    mag = lm.sensitivity_diag(freq)
    return lm.lam, mag, _peaks(lm, freq, mag)


def _sens_grid(rec: Recording, n_freq: int) -> NDArray:
    return np.logspace(0.0, np.log10(0.5 / rec.dt), n_freq)


@limited_threads
def physical_quantities(source: Any, recording: Recording,
                        speeds_rpm: NDArray | list[float] | None = None, n_draws: int = 200,
                        model: str = "full", n_freq: int = 400, seed: int = 0
                        ) -> EngineeringResult:
    """Bearing coefficients, closed-loop modes, API 617-style margins and ISO 14839-3 peak
    sensitivities, with 90 % intervals propagated from posterior draws.

    Each quantity's value is its median over the draws and its interval
    :func:`interval90` (the equal-tailed interval, widened to the quantity's range over
    the posterior's central region; module docstring). The quantities are evaluated at the
    draws and at the central region's edge points (:func:`central_region`; about a quarter
    more points with two parameters). The rigid-body modes are labelled
    rigid 1-4 in ascending order of frequency in every draw, as API 617 mode tables number
    them; on the reference rig that is the labelling eigenvalue continuation gives over the
    posterior, and each frequency is a continuous function of theta.

    Parameters
    ----------
    source : Identification, RunData or Draws
        Where the posterior draws come from (see :func:`draws_from`).
    recording : Recording
        Gives the rig, the controller that ran and the running speed.
    speeds_rpm : array of float, optional
        Speeds (rpm) of the mode table; default 0.8, 0.9, 1.0 and 1.05 times the
        recording's speed. Modes are computed with the recorded controller at every speed.
    n_draws : int
        Draws used (evenly thinned).
    model : {"full", "reduced"}
        Plant the draws are put into: the full FE model (default) or the 8-state reduction.
    n_freq : int
        Frequencies of the sensitivity (log-spaced 1 Hz to Nyquist); each peak is refined
        by a bounded search between the neighbours of the grid maximum.

    Returns
    -------
    EngineeringResult

    Examples
    --------
    >>> from bayes_amb.rig import load_rig
    >>> from bayes_amb.control.export import export_controller, reference_controller
    >>> from bayes_amb.io.recording import make_recording
    >>> rig = load_rig()
    >>> k = export_controller(reference_controller(rig, 1e-3), rig)
    >>> z = np.zeros((4, 4))
    >>> rec = make_recording(z, z, {"eta": z}, 1e-3, k, speed_rpm=31500.0, rig=rig)
    >>> r = physical_quantities(Draws(("k_By",), [[0.5]]), rec, [31500.0], model="reduced")
    >>> r.quantities["bearing By: ks"].value
    500000.0
    """
    draws = draws_from(source, n_draws, seed)
    region = central_region(draws.theta)
    run = float(recording.speed_rpm)
    speeds = np.array([0.8, 0.9, 1.0, 1.05]) * run if speeds_rpm is None \
        else np.atleast_1d(np.asarray(speeds_rpm, dtype=float))
    if speeds.size == 0 or np.any(~np.isfinite(speeds)) or np.any(speeds < 0):
        raise BayesAmbError(f"option speeds: expected speeds >= 0 rpm, got {speeds.tolist()}")
    rig, ctrl = recording.rig, recording.controller
    i_run = int(np.argmin(np.abs(speeds - run)))
    base_f = _sens_grid(recording, n_freq)
    n = draws.theta.shape[0]
    points = Draws(draws.names, np.vstack([draws.theta, region.edge]))   # draws, then edge
    n_pts = points.theta.shape[0]
    lam = np.full((n_pts, speeds.size, len(MODE_LABELS)), np.nan + 0j)
    lam_nom = np.full((speeds.size, len(MODE_LABELS)), np.nan + 0j)
    peaks = np.full((n_pts, 4), np.nan)
    sens = np.full((n_pts, base_f.size, 4), np.nan)
    thetas = [{}, *points.as_dicts()]              # the nominal plant, then the points
    with ThreadPoolExecutor(pool_threads()) as pool:
        for j, s in enumerate(speeds):
            rows = list(pool.map(lambda th, s=s, j=j: _at_point(
                rig, ctrl, s, th, model, base_f if j == i_run else None), thetas))
            lam_nom[j] = rows[0][0]
            lam[:, j] = [r[0] for r in rows[1:]]
            if j == i_run:
                sens_nom, peak_nom = rows[0][1], rows[0][2]
                sens[:] = [r[1] for r in rows[1:]]
                peaks[:] = [r[2] for r in rows[1:]]
    q: dict[str, Quantity] = {}

    def _summarise(name: str, unit: str, group: str, values: NDArray, nominal: float,
                   estimated: bool = True) -> Quantity:
        return _quantity(name, unit, group, values, nominal, region, estimated)

    nominal_theta = np.zeros((1, len(draws.names)))
    bear = _bearing_values(draws.names, points.theta, recording)
    bear_nom = _bearing_values(draws.names, nominal_theta, recording)
    for k, (v, unit, est) in bear.items():
        q[k] = _summarise(k, unit, "bearing", v, float(bear_nom[k][0][0]), est)
    f_run = run / 60.0
    for j, s in enumerate(speeds):
        for m, label in enumerate(MODE_LABELS):
            lm, ln = lam[:, j, m], lam_nom[j, m]
            f, fn = lm.imag / (2 * np.pi), ln.imag / (2 * np.pi)
            z, zn = -lm.real / np.abs(lm), -ln.real / np.abs(ln)
            q[_mode_key(label, "frequency", s)] = _summarise(
                _mode_key(label, "frequency", s), "Hz", "modes", f, fn)
            q[_mode_key(label, "damping ratio", s)] = _summarise(
                _mode_key(label, "damping ratio", s), "", "modes", z, zn)
            q[_mode_key(label, "log dec", s)] = _summarise(
                _mode_key(label, "log dec", s), "", "modes", log_decrement(lm),
                float(log_decrement(np.array([ln]))[0]))
            if j == i_run:
                fr = s / 60.0
                sm = 100 * np.abs(f - fr) / fr
                smn = 100 * abs(fn - fr) / fr
                q[f"{label}: separation margin"] = _summarise(
                    f"{label}: separation margin", "%", "api617", sm, smn)
                req = required_separation_margin(z, f < fr)
                reqn = float(required_separation_margin(np.array([zn]),
                                                        np.array([fn < fr]))[0])
                q[f"{label}: required separation margin"] = _summarise(
                    f"{label}: required separation margin", "%", "api617", req, reqn)
        ldn = log_decrement(lam_nom[j])
        q[f"minimum log dec @ {s:.0f} rpm"] = _minimum(
            f"minimum log dec @ {s:.0f} rpm",
            [q[_mode_key(label, "log dec", s)] for label in MODE_LABELS],
            float(np.nanmin(ldn)) if np.any(np.isfinite(ldn)) else float("nan"))
    for c, ch in enumerate(CHANNELS):
        q[f"peak sensitivity {ch}"] = _summarise(
            f"peak sensitivity {ch}", "dB", "iso14839", 20 * np.log10(peaks[:, c]),
            float(20 * np.log10(peak_nom[c])))
    notes = (f"running speed {run:.0f} rpm ({f_run:.1f} Hz)",
             f"{n} posterior draws (and {n_pts - n} edge points of their central region), "
             f"plant model '{model}', controller from the recording")
    return EngineeringResult(quantities=q, speeds_rpm=speeds, running_speed_rpm=run,
                             lam=lam[:n], lam_nominal=lam_nom, sens_freq_hz=base_f,
                             sens=sens[:n], sens_nominal=sens_nom, draws=draws, region=region,
                             lam_edge=lam[n:], sens_edge=sens[n:], model=model, notes=notes)


def _peaks(lm: Any, f: NDArray, mag: NDArray) -> NDArray:
    """Peak |S_jj| per axis: the grid maximum refined by a bounded scalar search between
    its neighbours (so that the peak is a smooth function of the plant, not of the grid)."""
    out = np.empty(mag.shape[1])
    for c in range(mag.shape[1]):
        k = int(np.argmax(mag[:, c]))
        lo, hi = f[max(k - 1, 0)], f[min(k + 1, f.size - 1)]
        res = minimize_scalar(lambda x, c=c: -lm.sensitivity_diag(np.array([x]))[0, c],
                              bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-6 * f[k]})
        out[c] = max(mag[k, c], -float(res.fun))
    return out
