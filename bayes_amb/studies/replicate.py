"""One replicate of a study: simulate a recording, identify, and report one tidy row.

The seed of every replicate derives from the study seed and its (cell, replicate) index
(numpy SeedSequence spawn keys), so any single replicate can be re-run alone and gives the
same numbers.
"""

from __future__ import annotations

import time
import traceback
from typing import Any

import numpy as np

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.inference.priors import parse_prior
from bayes_amb.results.identification import Posterior
from bayes_amb.rig import load_rig
from bayes_amb.simulate import simulate_recording
from bayes_amb.studies.concealed import run_case
from bayes_amb.studies.spec import StudySpec, cell_estimate, simulation_config
from bayes_amb.threads import limited_threads

N_RANK_DRAWS = 99
"""Posterior draws against which the rank of the true value is taken (SBC)."""

_CONTROLLERS: dict[tuple[str, float, float | None], Any] = {}


def replicate_seeds(spec: StudySpec, cell: int, rep: int) -> tuple[int, int, int]:
    """(simulation seed, theta-draw seed, sampler seed) of one replicate."""
    ss = np.random.SeedSequence(spec.seed, spawn_key=(cell, rep))
    a, b, c = ss.generate_state(3, dtype=np.uint32)
    return int(a), int(b), int(c)


def replicate_id(cell: int, rep: int) -> str:
    return f"c{cell:03d}r{rep:04d}"


def true_values(spec: StudySpec, cell: dict[str, Any], estimate: tuple[str, ...],
                seed: int) -> dict[str, float]:
    """True theta: fixed values, cell overrides, or a draw from the estimation priors."""
    vals = dict(spec.true_params)
    vals.update({k[5:]: float(v) for k, v in cell.items() if k.startswith("true.")})
    if spec.draw_from_prior:
        rng = np.random.default_rng(seed)
        for n in estimate:
            vals[n] = float(parse_prior(spec.priors[n], n).sample(rng, 1)[0])
    for n in estimate:
        vals.setdefault(n, 0.0)
    return vals


def _controller(spec: StudySpec, rig: Any, dt: float, speed: float | None) -> Any:
    key = (spec.rig, dt, speed)
    if key not in _CONTROLLERS:
        _CONTROLLERS[key] = export_controller(reference_controller(rig, dt, speed), rig)
    return _CONTROLLERS[key]


@limited_threads
def run_replicate(spec: StudySpec, cell_index: int, rep: int) -> dict[str, Any]:
    """Simulate and identify one replicate; returns a flat row (never raises for numerical
    failures: they are recorded in ``error``)."""
    t0 = time.perf_counter()
    cell = spec.cells[cell_index]
    estimate = cell_estimate(spec, cell)
    sim_seed, draw_seed, samp_seed = replicate_seeds(spec, cell_index, rep)
    truth = true_values(spec, cell, estimate, draw_seed)
    row: dict[str, Any] = {"study": spec.name, "id": replicate_id(cell_index, rep),
                           "cell": cell_index, "rep": rep, "seed": sim_seed,
                           "inference": spec.inference, "estimate": ",".join(estimate)}
    row.update({f"f_{k}": v for k, v in cell.items()})
    row.update({f"true_{k}": v for k, v in truth.items()})
    if spec.inference == "diagnose":
        rig = load_rig(spec.rig)
        cfg = simulation_config(spec, cell, sim_seed, truth)
        ctrl = _controller(spec, rig, cfg.dt, cfg.speed_rpm)
        row.update(run_case(rig, ctrl, cfg, cell.get("case", "none"), estimate, sim_seed,
                            draw_seed))
        row["wall_s"] = time.perf_counter() - t0
        return row
    try:
        rig = load_rig(spec.rig)
        cfg = simulation_config(spec, cell, sim_seed, truth)
        ctrl = _controller(spec, rig, cfg.dt, cfg.speed_rpm)
        rec, _ = simulate_recording(rig, ctrl, cfg)
        priors = {n: parse_prior(spec.priors[n], n) for n in estimate if n in spec.priors}
        res = identify(rec, estimate, priors, IdentifyOptions(
            walkers=spec.walkers, steps=spec.steps, map_only=spec.inference == "laplace",
            seed=samp_seed))
        row["converged"] = bool(res.converged)
        for j, n in enumerate(estimate):
            v = res.parameters[n]
            lo, hi = v.hdi90
            row.update({f"{n}_map": res.map[n], f"{n}_mean": v.mean, f"{n}_sd": v.sd,
                        f"{n}_hdi_lo": lo, f"{n}_hdi_hi": hi,
                        f"{n}_covered": bool(lo <= truth[n] <= hi),
                        f"{n}_rhat": v.r_hat, f"{n}_ess": v.ess_bulk})
            row.update(_rank_stats(res, j, truth[n], v))
            row[f"{n}_q"] = row.pop("_q")
            row[f"{n}_rank"] = row.pop("_rank")
        row["error"] = ""
    except Exception as exc:
        row["converged"] = False
        row["error"] = f"{type(exc).__name__}: {exc}"
        row["traceback"] = traceback.format_exc(limit=3)
    row["wall_s"] = time.perf_counter() - t0
    return row


def _rank_stats(res: Any, j: int, true: float, v: Posterior) -> dict[str, Any]:
    """Posterior quantile q of the true value, and its rank among N_RANK_DRAWS draws."""
    if res.samples is not None:
        flat = res.samples.reshape(-1, res.samples.shape[-1])[:, j]
        q = float(np.mean(flat < true))
        idx = np.linspace(0, flat.size - 1, N_RANK_DRAWS).astype(int)
        rank = int(np.sum(flat[idx] < true))
    else:                                   # Laplace: normal quantile
        from scipy.stats import norm
        sd = v.sd if v.sd and np.isfinite(v.sd) and v.sd > 0 else np.inf
        q = float(norm.cdf((true - v.mean) / sd))
        rank = round(q * N_RANK_DRAWS)
    return {"_q": q, "_rank": rank}
