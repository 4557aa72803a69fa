"""Numbers that describe one fitted model: predictions, fit quality, parameter summaries.

Parameter summaries come from posterior draws: emcee samples when the model was sampled,
otherwise draws from its Laplace approximation (stated in the output). Physical values of
the candidates' parameters are computed draw by draw (e.g. bandwidth = 1/(2 pi tau)).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from scipy.signal import welch

from bayes_amb.discrepancy.fitting import FittedModel
from bayes_amb.discrepancy.locate import (
    ljung_box,
    noise_cholesky,
    whiten,
    whitened_series,
)
from bayes_amb.inference.posterior import gaussian_draws, stretch_draws
from bayes_amb.rig import CHANNELS
from bayes_amb.uncertainty import get_spec

if TYPE_CHECKING:     # xarray (with pandas) takes half a second to import: only where written
    import xarray as xr


def hdi(values: NDArray, prob: float = 0.9) -> list[float]:
    """Shortest interval holding a fraction prob of the draws.

    Examples
    --------
    >>> hdi(np.arange(101.0), 0.9)
    [0.0, 90.0]
    """
    v = np.sort(np.asarray(values, dtype=float))
    n = v.size
    k = max(1, int(np.floor(prob * n)))
    if k >= n:
        return [float(v[0]), float(v[-1])]
    widths = v[k:] - v[:n - k]
    i = int(np.argmin(widths))
    return [float(v[i]), float(v[i + k])]


PINNED = 0.5
"""A parameter with more than this share of its draws at a prior bound is pinned there."""

NEAR_BOUND = 0.01
"""... and so is one whose MAP lies within this share of the prior's width of a bound with
any of its draws at it: the data push it to the wall. (With the share alone, only a MAP on
the wall was: on a foreign record with an amplifier limit and an unmodelled sensor gain at
Bx, k_Bx stood 0.005 inside its bound of -0.8 with an sd of 0.005, and its 90 % interval
[-0.8, -0.785] said -0.8 with confidence where the truth was 0.26.)"""

AT_BOUND = 1e-6
"""Draws within this share of the prior's width of a bound count as at it: a curvature
taken on the bound (the stencil meets the prior's wall) leaves the Laplace draws a spread of
1e-10, half of them clipped and half a hair inside, which no record measures."""


def draws(fitted: FittedModel, n: int = 4000, seed: int = 0) -> NDArray:
    """Posterior draws of the parameters (n, p): emcee samples if present, else Laplace
    draws clipped to the prior support (without a covariance: uniform over the prior).

    When the model's error has been assessed (``fitted.model_error``, model_error.py) the
    draws are those of the posterior with the band-wise discrepancy integrated out: the
    Laplace draws from its shifted mean and widened covariance; emcee draws moved by the
    same shift and stretched about the MAP by the map taking one covariance to the other
    (the open-faced sandwich adjustment of Shaby 2014), then clipped to the prior. A
    fit's ``extra_cov`` (a modelled clip's uncertainty, clip_model.py) is added last."""
    me = fitted.model_error
    p = fitted.p
    bounds = fitted.post.bounds()[:p]
    extra = fitted.extra_cov
    if fitted.samples is not None:
        d = fitted.samples.reshape(-1, fitted.samples.shape[-1])[:, :p].copy()
        if (me is not None or extra is not None) and fitted.cov is not None:
            target = (me.cov[:p, :p] if me is not None else fitted.cov[:p, :p]) + (
                0.0 if extra is None else extra)
            d = stretch_draws(d, fitted.params, fitted.cov[:p, :p], target) + (
                me.shift if me is not None else 0.0)
    else:
        rng = np.random.default_rng(seed)
        if fitted.cov is None:
            # no usable curvature (a coefficient at its prior bound, a record that does not
            # inform it): the data allow the prior, never a zero-width interval
            d = np.tile(fitted.params, (n, 1)).astype(float)
            for j, (lo, hi) in enumerate(bounds):
                if lo is not None and hi is not None:
                    d[:, j] = rng.uniform(lo, hi, n)
            return d
        mean, cov = fitted.params, fitted.cov[:p, :p]
        if me is not None:
            mean, cov = mean + me.shift, me.cov[:p, :p]
        if extra is not None:
            cov = cov + extra
        d = gaussian_draws(rng, mean, cov, n)
    rng = np.random.default_rng(seed + 1)
    for j, (lo, hi) in enumerate(bounds):
        d[:, j] = np.clip(d[:, j], -np.inf if lo is None else lo, np.inf if hi is None else hi)
        if lo is None or hi is None:
            continue
        tol = AT_BOUND * (hi - lo)
        at_lo, at_hi = np.mean(d[:, j] <= lo + tol), np.mean(d[:, j] >= hi - tol)
        near = NEAR_BOUND * (hi - lo)
        pushed = ((at_lo > 0 and fitted.params[j] <= lo + near)
                  or (at_hi > 0 and fitted.params[j] >= hi - near))
        if max(at_lo, at_hi) > PINNED or pushed:
            # the data push it beyond its prior (a model that lacks something): an interval
            # of zero width at the bound would claim a precision nobody has; the data allow
            # the prior
            d[:, j] = rng.uniform(lo, hi, d.shape[0])
    return d


def _at_bound(value: float, lo: float | None, hi: float | None, v: NDArray) -> bool:
    """On its prior bound (to 1e-6), or reported as pinned there (:func:`draws`: its draws
    the prior's, its MAP within NEAR_BOUND of the prior's width of a bound)."""
    if any(b is not None and abs(value - b) < 1e-6 for b in (lo, hi)):
        return True
    if lo is None or hi is None:
        return False
    near = NEAR_BOUND * (hi - lo)
    return bool((value <= lo + near or value >= hi - near) and np.std(v) > 0.25 * (hi - lo))


def theta_summary(fitted: FittedModel, samples: NDArray,
                  truth: dict[str, float] | None = None) -> dict[str, dict[str, Any]]:
    """Stiffness/damping parameters: mean, sd, hdi90 and the same in physical units."""
    rig = fitted.forward.recording.rig
    out: dict[str, dict[str, Any]] = {}
    bounds = fitted.post.bounds()
    for j, name in enumerate(fitted.forward.theta_names):
        spec = get_spec(name)
        lo_b, hi_b = bounds[j]
        scale = spec.physical_scale(rig)
        v = samples[:, j]
        lo, hi = hdi(v)
        out[name] = {"map": float(fitted.params[j]), "mean": float(np.mean(v)),
                     "sd": float(np.std(v)), "hdi90": [lo, hi], "unit": spec.unit,
                     "physical_mean": float(np.mean(v)) * scale,
                     "physical_hdi90": sorted([lo * scale, hi * scale]),
                     "at_prior_bound": _at_bound(fitted.params[j], lo_b, hi_b, v)}
        if truth is not None and name in truth:
            out[name]["true"] = truth[name]
    return out


def effect_summaries(fitted: FittedModel, samples: NDArray) -> list[dict[str, Any]]:
    """Per candidate of the model: its physical parameters (mean, hdi90, unit)."""
    fwd = fitted.forward
    out = []
    for c, sl in zip(fwd.candidates, fwd.slices, strict=True):
        phys = c.physical(samples[:, sl], fwd.ctx)
        at_map = c.physical(fitted.params[None, sl], fwd.ctx)
        params = {}
        for k, (vals, unit) in phys.items():
            params[k] = {"mean": float(np.mean(vals)), "map": float(at_map[k][0][0]),
                         "hdi90": hdi(vals), "unit": unit}
        out.append({"effect": c.effect, "location": c.location, "params": params,
                    "description": c.describe({k: v["map"] for k, v in params.items()}),
                    "sampled": {n: float(fitted.x[fwd.params.index(n)])
                                for n in fwd.params[sl]}})
    return out


def nominal_physical(fitted: FittedModel) -> dict[tuple[str, str], dict[str, float]]:
    """Per candidate (effect, location): its physical quantities with its sampled
    parameters at zero, the rig's own model (a bending pair's FE frequency and damping)."""
    fwd = fitted.forward
    out = {}
    for c, sl in zip(fwd.candidates, fwd.slices, strict=True):
        width = len(fwd.params[sl])
        phys = c.physical(np.zeros((1, width)), fwd.ctx)
        out[(c.effect, c.location)] = {k: float(np.ravel(v)[0]) for k, (v, _) in phys.items()}
    return out


def predict(fitted: FittedModel) -> NDArray:
    """Time-domain eps_pred (N, 4) at the MAP: S(theta) x plus any synchronous lines."""
    fwd = fitted.forward
    pred = fwd.simulate(fitted.params[None])
    for c, basis in zip(fwd.line_candidates, fwd.line_responses(fitted.params[None]),
                        strict=True):
        pred = pred + basis @ fitted.params[fwd.slices[fwd.candidates.index(c)]]
    return pred


def fit_quality(fitted: FittedModel, eps: NDArray) -> dict[str, Any]:
    """Per channel: NRMSE = RMS(eps - eps_pred) / RMS(eps), and the Ljung-Box p-value of the
    residual whitened by the model's own fitted noise spectrum."""
    r = eps - predict(fitted)
    like = fitted.like
    w = slice(getattr(like, "start", 0), None)          # the compared window
    nrmse = np.sqrt(np.mean(r[w] ** 2, axis=0) / np.mean(eps[w] ** 2, axis=0))
    like.set_noise_reference(fitted.params)
    R = like.residual_dft(fitted.params[None])[0][0]
    W = whiten(noise_cholesky(like, fitted.log10_sigma), R)
    _, lb = ljung_box(whitened_series(W, like.k, like.n), 20)
    return {"nrmse": {ch: float(v) for ch, v in zip(CHANNELS, nrmse, strict=True)},
            "whiteness_p": {ch: float(v) for ch, v in zip(CHANNELS, lb, strict=True)},
            "residual": r}


def posterior_dataset(fm: FittedModel, n: int = 2000) -> xr.Dataset:
    """``n`` posterior draws of a fitted model (emcee or Laplace, as its attrs say): a run
    folder's models/<model>.nc."""
    import xarray as xr
    s = draws(fm, n)
    kind = "emcee" if fm.samples is not None else "Laplace approximation at the MAP"
    return xr.Dataset({name: (("draw",), s[:, j]) for j, name in enumerate(fm.names)},
                      attrs={"inference": kind,
                             "effects": ",".join(c.key for c in fm.candidates) or "none",
                             "log_post_map": fm.log_post,
                             "log_bayes_factor": np.nan if fm.log_bf is None else fm.log_bf})


def residual_spectrum(r: NDArray, dt: float) -> tuple[NDArray, NDArray]:
    """Welch PSD of a residual (f in Hz, PSD (nf, 4) in m^2/Hz)."""
    nper = int(min(1024, max(64, r.shape[0] // 8)))
    return welch(r, fs=1.0 / dt, nperseg=nper, axis=0)
