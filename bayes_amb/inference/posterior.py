"""ArviZ 1.x DataTree of a posterior, its summary in theta and physical units, and the
identifiability statement."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from bayes_amb.inference.priors import PriorSet
from bayes_amb.inference.whittle import NOISE_SOURCES, WhittleLikelihood
from bayes_amb.io.atomic import write_netcdf_atomic
from bayes_amb.rig import Rig
from bayes_amb.uncertainty import get_spec

if TYPE_CHECKING:     # ArviZ and xarray (with pandas) take 0.8 s to import: only where drawn
    import xarray as xr

CHAINS_OVER_DRAWS = "Found chain dimension to be longer than draw dimension"
"""ArviZ's warning where the walkers (the chains) outnumber the draws kept: normal for an
ensemble sampler's short run (``--steps``), not a mislabelled array, so not shown."""


def walkers_datatree(data: dict, **kwargs) -> xr.DataTree:
    """az.from_dict for an ensemble's draws, the walkers as the chains (CHAINS_OVER_DRAWS
    not raised to the user)."""
    import arviz as az
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=CHAINS_OVER_DRAWS, category=UserWarning)
        return az.from_dict(data, **kwargs)


def pointwise_log_likelihood(like: WhittleLikelihood, samples: NDArray, p: int,
                             batch: int = 256) -> NDArray:
    """Per-band log-likelihood for every retained draw: (n_walkers, n_draws, n_bands)."""
    flat = samples.reshape(-1, samples.shape[-1])
    out = np.empty((flat.shape[0], like.n_bands))
    for i in range(0, flat.shape[0], batch):
        out[i:i + batch] = like.pointwise(flat[i:i + batch, :p], flat[i:i + batch, p:])
    return out.reshape(*samples.shape[:2], like.n_bands)


def to_datatree(names: tuple[str, ...], samples: NDArray, log_post: NDArray,
                log_lik: NDArray, like: WhittleLikelihood, eps: NDArray, x: NDArray,
                tau: NDArray, attrs: dict[str, Any]) -> xr.DataTree:
    """Groups posterior, log_likelihood (per frequency band), sample_stats, observed_data and
    constant_data. Walkers are the chains (they are not independent: see attrs tau)."""
    p = len(names)
    post = {n: samples[:, :, j] for j, n in enumerate(names)}
    post.update({s: 10.0 ** samples[:, :, p + j] for j, s in enumerate(NOISE_SOURCES)})
    band = {"band": np.arange(like.n_bands)}
    t = np.arange(eps.shape[0]) * like.forward.dt
    data = {
        "posterior": post,
        "log_likelihood": {"eps": log_lik},
        "sample_stats": {"lp": log_post},
        "observed_data": {"eps": eps},
        "constant_data": {"x": x, "t": t, "band_freq_hz": like.band_freq_hz,
                          "band_bins": like.counts},
    }
    dims = {"eps": ["time", "channel"], "x": ["time", "channel"], "t": ["time"],
            "band_freq_hz": ["band"], "band_bins": ["band"]}
    coords = {"channel": ["Ax", "Ay", "Bx", "By"], "time": np.arange(eps.shape[0]), **band}
    import xarray as xr
    dt = walkers_datatree(data, dims=dims, coords=coords)
    dt["log_likelihood"] = xr.DataTree(xr.Dataset(
        {"eps": (("chain", "draw", "band"), log_lik)},
        coords={"chain": np.arange(log_lik.shape[0]), "draw": np.arange(log_lik.shape[1]),
                "band": np.arange(like.n_bands)}))
    dt.attrs.update({k: (v if isinstance(v, (str, int, float)) else str(v))
                     for k, v in attrs.items()})
    dt.attrs["tau"] = ",".join(f"{v:.3f}" for v in tau)
    return dt


def save_datatree(dt: xr.DataTree, path: str | Path) -> None:
    """Write NetCDF atomically (temporary file in the same folder, then rename)."""
    write_netcdf_atomic(dt, path)


def summarise(dt: xr.DataTree, names: tuple[str, ...], tau: NDArray, rig: Rig,
              truth: dict[str, float] | None = None) -> dict[str, dict[str, Any]]:
    """Per parameter: mean, sd, hdi90, ess_bulk, ess_tail, r_hat, tau, unit, physical."""
    import arviz as az
    s = az.summary(dt, var_names=list(names), ci_prob=0.9, ci_kind="hdi", round_to="none")
    out: dict[str, dict[str, Any]] = {}
    for j, n in enumerate(names):
        row = s.loc[n]
        spec = get_spec(n.split("@")[0])          # a per-record copy 'c_Ax@2'
        scale = spec.physical_scale(rig)
        lo, hi = float(row["hdi90_lb"]), float(row["hdi90_ub"])
        phys = sorted([lo * scale, hi * scale])
        out[n] = {"mean": float(row["mean"]), "sd": float(row["sd"]), "hdi90": [lo, hi],
                  "ess_bulk": float(row["ess_bulk"]), "ess_tail": float(row["ess_tail"]),
                  "r_hat": float(row["r_hat"]), "tau": float(tau[j]), "unit": spec.unit,
                  "physical": spec.physical_label,
                  "physical_mean": float(row["mean"]) * scale,
                  "physical_sd": float(row["sd"]) * abs(scale), "physical_hdi90": phys}
        if truth is not None and n in truth:
            out[n]["true"] = truth[n]
    return out


def gaussian_draws(rng: np.random.Generator, mean: NDArray, cov: NDArray, n: int
                   ) -> NDArray:
    """n draws (n, p) of N(mean, cov), as mean + L z with L the Cholesky factor of cov.

    The Cholesky factor is a continuous function of cov, so the same seed gives the same
    draws, up to rounding, on any CPU. An eigendecomposition (numpy's default) is not: where
    two eigenvalues are close, rounding can turn their eigenvectors, and every draw with
    them. A cov that is only semi-definite (a direction with no variance) falls back to the
    eigendecomposition."""
    mean = np.asarray(mean, dtype=float)
    cov = np.asarray(cov, dtype=float)
    try:
        L = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        return rng.multivariate_normal(mean, cov, size=n, method="eigh")
    return mean + rng.standard_normal((n, mean.size)) @ L.T


def stretch_draws(d: NDArray, centre: NDArray, cov: NDArray, cov_new: NDArray) -> NDArray:
    """Draws d (..., p) moved so that their spread about centre goes from cov to cov_new
    (the open-faced sandwich adjustment of Shaby 2014; free dimensions only: those with
    positive variance in cov). Any leading shape (walkers, draws) is kept."""
    free = np.flatnonzero(np.diag(cov) > 0)
    if free.size == 0:
        return d
    try:
        K = np.linalg.cholesky(cov[np.ix_(free, free)])
        Kw = np.linalg.cholesky(cov_new[np.ix_(free, free)])
    except np.linalg.LinAlgError:
        return d
    out = np.array(d, dtype=float, copy=True)
    dev = (d[..., free] - centre[free]).reshape(-1, free.size)
    out[..., free] = (centre[free] + np.linalg.solve(K, dev.T).T @ Kw.T).reshape(
        *d.shape[:-1], free.size)
    return out


def approximate_row(name: str, rig: Rig, mean: float, sd: float, lo: float, hi: float
                    ) -> dict[str, Any]:
    """A parameter's summary row from an approximation (no chains, so no ESS, R-hat or tau):
    mean, sd and 90 % interval in theta units and physical ('c_Ax@2' in c_Ax's units)."""
    spec = get_spec(name.split("@")[0])
    scale = spec.physical_scale(rig)
    return {"mean": mean, "sd": sd, "hdi90": [lo, hi], "ess_bulk": None, "ess_tail": None,
            "r_hat": None, "tau": None, "unit": spec.unit, "physical": spec.physical_label,
            "physical_mean": mean * scale, "physical_sd": sd * abs(scale),
            "physical_hdi90": sorted([lo * scale, hi * scale])}


def draws_row(name: str, rig: Rig, v: NDArray) -> dict[str, Any]:
    """approximate_row of independent draws: their mean, sd and central 90 % interval."""
    lo, hi = (float(q) for q in np.quantile(v, [0.05, 0.95]))
    return approximate_row(name, rig, float(v.mean()), float(v.std()), lo, hi)


def identifiability(samples: NDArray, names: tuple[str, ...], priors: PriorSet,
                    corr_limit: float = 0.9, shrink_limit: float = 0.5) -> dict[str, Any]:
    """Posterior correlations and plain-language warnings where the data do not pin a
    parameter (posterior sd above shrink_limit times prior sd) or only a combination
    (|correlation| above corr_limit)."""
    p = len(names)
    flat = samples.reshape(-1, samples.shape[-1])[:, :p]
    corr = np.corrcoef(flat.T) if p > 1 else np.ones((1, 1))
    notes = []
    for j, n in enumerate(names):
        ratio = float(np.std(flat[:, j]) / priors.priors[j].sd)
        if ratio > shrink_limit:
            notes.append(f"{n} is not identified by these data: its posterior sd is "
                         f"{ratio:.0%} of the prior sd, so the estimate mostly restates the "
                         "prior.")
    for i in range(p):
        for j in range(i + 1, p):
            if abs(corr[i, j]) > corr_limit:
                notes.append(f"{names[i]} and {names[j]} are strongly correlated "
                             f"(rho = {corr[i, j]:+.2f}): the data pin a combination of the "
                             "two, not each one; widen the excitation band or fix one.")
    return {"correlation": {"names": list(names), "matrix": np.round(corr, 4).tolist()},
            "identifiable": not notes, "notes": notes}
