"""Several recordings, one posterior (issue 29): shared bearing coefficients, per-record
noise, speed, controller and sample time.

Each recording keeps its own forward model (the rig's model at its speed, gyroscopics
included; its controller; its dt) and its own Whittle likelihood, whose noise intensities
are fitted on that record (identify, MAP). The records are independent given theta, so the
joint log posterior of the coefficients is

    log p(theta | all) = sum_r log L_r(theta_r, sigma_r) + log p(theta),

theta_r the shared coefficients plus record r's own copies of any parameter declared per
record (``per_record``: e.g. a damping that may change with speed). The noise intensities
are held at each record's MAP: in the Whittle likelihood they are orthogonal to theta (the
noise spectrum does not depend on theta, so the expected information is block-diagonal),
and the posterior of theta conditional on them is its marginal to first order. The joint
MAP is searched from the precision-weighted combination of the records' own MAPs, the noise
filters refreshed at it, and the Laplace covariance is the inverse Hessian there.

When a record's model is not adequate (its adequacy test), its own reported posterior is
the one with the model error integrated out (doubted.with_model_error); the joint
posterior is then the product of the records' reported Gaussian posteriors (divided by the
prior counted R - 1 times too many), so that no record's doubt is lost in the combination.

Whether the records agree on what they share is tested (consistency.py: Cochran's Q on
each record's reported posterior); a parameter they disagree on gets the random-effects
interval, widened by their spread, and the adequacy line says so (summary['agreement']).
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize

from bayes_amb import __version__
from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.bounded import bounded_laplace, bounded_notes, bounded_summary
from bayes_amb.inference.consistency import agreement
from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.inference.joint_sampling import JointLogPosterior, sample_joint, sampled_summary
from bayes_amb.inference.laplace_rows import laplace_summary
from bayes_amb.inference.noise_check import (
    NoiseCheck,
    joint_check,
    record_check,
    sandwich_rows,
)
from bayes_amb.inference.priors import Prior, PriorSet
from bayes_amb.io.recording import Recording
from bayes_amb.results.identification import (
    FILE,
    Identification,
    NoisePosterior,
    RecordFit,
)
from bayes_amb.results.identification import NoiseCheck as NoiseCheckBlock
from bayes_amb.uncertainty import parse_param_list

STEP = 1e-4
"""Central-difference step of the joint Hessian (theta units)."""


def record_name(name: str, r: int) -> str:
    """A per-record copy of a parameter: 'c_Ax@2' (records counted from 1)."""
    return f"{name}@{r + 1}"


def _layout(names: tuple[str, ...], per_record: tuple[str, ...], n_rec: int
            ) -> tuple[list[str], list[NDArray]]:
    """The joint parameter names and, per record, the index of each of ``names`` in the
    joint vector."""
    joint = [n for n in names if n not in per_record]
    joint += [record_name(n, r) for r in range(n_rec) for n in names if n in per_record]
    idx = [np.array([joint.index(record_name(n, r) if n in per_record else n)
                     for n in names]) for r in range(n_rec)]
    return joint, idx


def identify_joint(recordings: list[Recording], params: str | tuple[str, ...] | list[str],
                   priors: dict[str, Prior] | None = None,
                   options: IdentifyOptions | None = None,
                   per_record: tuple[str, ...] | list[str] = ()) -> Identification:
    """One posterior of ``params`` from several recordings (module docstring): MAP and
    Laplace approximation; ``per_record`` names parameters estimated separately for each
    record. ``records`` holds each record's own fit (MAP, noise, adequacy)."""
    opt = options or IdentifyOptions()
    t0 = time.perf_counter()
    if len(recordings) < 2:
        raise BayesAmbError("identify: several recordings are needed for a joint posterior "
                            f"(got {len(recordings)})")
    names = parse_param_list(params)
    per = tuple(per_record)
    unknown = sorted(set(per) - set(names))
    if unknown:
        raise BayesAmbError(f"option --per-record: {unknown[0]} is not among the estimated "
                            f"parameters {list(names)}")
    rigs = {r.rig.name for r in recordings}
    if len({repr(r.rig.to_dict()) for r in recordings}) > 1:
        raise BayesAmbError("identify: the recordings come from different rigs "
                            f"({sorted(rigs)}); a joint posterior needs one rig")
    own = [identify(rec, names, priors, replace(opt, map_only=True)) for rec in recordings]
    joint_names, idx = _layout(names, per, len(recordings))
    base = PriorSet.build(names, priors)
    prior_of = dict(zip(names, base.priors, strict=True))
    prior_set = PriorSet(tuple(joint_names),
                         tuple(prior_of[n.split("@")[0]] for n in joint_names))
    likes = [res.likelihood for res in own]
    sigmas = [res.map_result.log10_sigma for res in own]

    def neg(z: NDArray) -> float:
        lp = float(prior_set.log_prior(z[None], np.zeros((1, 3)) + _NOISE_MID)[0])
        if not np.isfinite(lp):
            return np.inf
        total = lp
        for like, ls, ix in zip(likes, sigmas, idx, strict=True):
            v = float(like(z[ix][None], ls[None])[0])
            if not np.isfinite(v):
                return np.inf
            total += v
        return -total

    bounds = [(pr.lo if np.isfinite(pr.lo) else (pr.a if pr.kind == "uniform" else None),
               pr.hi if np.isfinite(pr.hi) else (pr.b if pr.kind == "uniform" else None))
              for pr in prior_set.priors]
    z0 = _combined_start(own, names, joint_names, idx)
    for _ in range(2):
        res = minimize(neg, z0, method="L-BFGS-B", bounds=bounds)
        z0 = res.x
        for like, ix in zip(likes, idx, strict=True):
            like.set_noise_reference(z0[ix])
    res = minimize(neg, z0, method="L-BFGS-B", bounds=bounds)
    z = res.x
    cov = _hessian_covariance(neg, z, bounds)
    rig = recordings[0].rig
    m = replace(own[0].map_result, theta=z, log_post=-float(res.fun))
    summary: dict[str, Any] = {
        "format": "bayes-amb-summary/1", "package_version": __version__,
        "recordings": [str(r.source) for r in recordings],
        "parameters_estimated": list(joint_names),
        "per_record_parameters": list(per),
        "priors": prior_set.to_dict(),
        "map": {n: float(v) for n, v in zip(joint_names, z, strict=True)},
        "inference": "joint MAP with Laplace approximation (each record's noise at its MAP)",
        "parameters": _summary(joint_names, m, cov, rig, prior_set, bounds),
        "records": [_record_block(rec, res) for rec, res in zip(recordings, own, strict=True)],
        "converged": bool(res.success and cov is not None),
        "seed": opt.seed,
    }
    # each record's check at the joint MAP, a learned spectrum's floored by its own scores
    checks = [record_check(like, z[ix], ls, names, like.spectrum is not None)
              for like, ls, ix in zip(likes, sigmas, idx, strict=True)]
    summary["records"] = [replace(block, noise_check=None if c is None else NoiseCheckBlock(
        **{**c.to_dict(), "line": c.finding + (
            ": its B - F enters the joint sandwich." if c.doubted else
            ": its learned spectrum's scores floor the joint sandwich." if c.widens else ".")}))
        for block, c in zip(summary["records"], checks, strict=True)]
    check = joint_check(checks, idx, joint_names)
    if check is not None and cov is not None:
        wide, check = check.sandwich(cov)
        summary["parameters_white_noise"] = summary["parameters"]
        summary["parameters"] = _summary(joint_names, m, wide, rig, prior_set, bounds)
    if any(_on_bound(v, b) for v, b in zip(z, bounds, strict=True)):
        _cut_at_bounds(summary, JointLogPosterior(likes, idx, prior_set), z, sigmas,
                       joint_names, rig, opt.seed)
    more: dict[str, Any] = {}
    if not opt.map_only:
        more = _sample(summary, likes, idx, prior_set, z, cov, sigmas, opt, recordings,
                       check, bounds)
    inadequate = [i for i, o in enumerate(own) if o.adequacy is not None
                  and not o.adequacy.adequate]
    summary["adequacy"] = _joint_adequacy(own, inadequate)
    if inadequate:
        _product_of_reported(summary, own, names, joint_names, idx, prior_set, rig)
    _check_agreement(summary, own, [n for n in names if n not in per], rig)
    summary["wall_s"] = time.perf_counter() - t0
    return replace(Identification.from_dict(summary, FILE), names=tuple(joint_names),
                   map_result=m, **more)


def _cut_at_bounds(summary: dict[str, Any], post: JointLogPosterior, z: NDArray,
                   sigmas: list[NDArray], joint_names: list[str], rig: Any, seed: int) -> None:
    """A joint MAP with a coefficient on a prior bound: the Laplace approximation cut at the
    prior (bounded.py, as identify reports a record's) when every bound one is informed
    and near it; else the held ones keep their prior's interval (_summary). The note says
    which."""
    bl = bounded_laplace(post, np.concatenate([z, *sigmas]))
    if bl is None or not bl.bound.any():
        return
    names = tuple(joint_names)
    cut = not bl.to_prior(post.priors).any()
    if cut:
        summary["parameters"] = bounded_summary(names, bl, rig, seed)
    summary["identifiability"] = bounded_notes(names, bl, post.priors, cut)


def _sample(summary: dict[str, Any], likes: list, idx: list[NDArray], prior_set: PriorSet,
            z: NDArray, cov: NDArray | None, sigmas: list[NDArray], opt: IdentifyOptions,
            recordings: list[Recording], check: NoiseCheck | None = None,
            bounds: list | None = None) -> dict[str, Any]:
    """emcee on the joint posterior (joint_sampling.py): its summary entries replace the
    Laplace ones (the draws stretched to the records' noise sandwich where ``check`` has
    one, noise_check.py); returns the draws for the result."""
    post = JointLogPosterior(likes, idx, prior_set)
    run, n_walkers, used = sample_joint(post, z, cov, sigmas, opt.walkers, opt.steps,
                                        opt.max_steps, opt.seed, opt.progress)
    attrs = {"package_version": __version__, "recordings": ", ".join(
        str(r.source) for r in recordings), "n_steps": run.n_steps, "burn": run.burn,
        "thin": run.thin, "seed": opt.seed, "inference": "joint emcee ensemble"}
    found, noise, dt = sampled_summary(summary["parameters_estimated"], run, n_walkers, used,
                                       post, recordings[0].rig, attrs)
    summary.update(found)
    if check is not None:
        rows, _, _ = sandwich_rows(check, run, bounds, recordings[0].rig, found["parameters"])
        summary["parameters_white_noise"] = found["parameters"]
        summary["parameters"] = rows
    summary["records"] = [replace(block, noise_posterior={k: NoisePosterior(**v)
                                                          for k, v in rows.items()})
                          for block, rows in zip(summary["records"], noise, strict=True)]
    return {"posterior": dt, "samples": run.samples}


_NOISE_MID = np.array([-7.0, -7.0, -3.0])
"""A point inside the noise priors: the joint objective holds the noise fixed per record,
so only theta's prior counts (the noise prior's constant is the same everywhere)."""


def _combined_start(own: list[Identification], names: tuple[str, ...],
                    joint_names: list[str], idx: list[NDArray]) -> NDArray:
    """Shared parameters: the precision-weighted mean of the records' MAPs; per-record
    ones: the record's own MAP."""
    z = np.zeros(len(joint_names))
    w = np.zeros(len(joint_names))
    for res, ix in zip(own, idx, strict=True):
        for j, n in enumerate(names):
            sd = res.parameters[n].sd
            prec = 1.0 / sd ** 2 if np.isfinite(sd) and sd > 0 else 1e-6
            z[ix[j]] += prec * res.map_result.theta[j]
            w[ix[j]] += prec
    return z / np.where(w > 0, w, 1.0)


def _hessian_covariance(neg: Any, z: NDArray, bounds: list) -> NDArray | None:
    """Inverse of the central-difference Hessian of neg at z (None if not positive
    definite); a parameter on a prior bound is held (zero variance here; _summary gives it
    its prior's interval)."""
    p = z.size
    free = [j for j, b in enumerate(bounds) if not _on_bound(z[j], b)]
    H = np.zeros((p, p))
    f0 = neg(z)
    for a in free:
        for b in free:
            if b < a:
                continue
            e_a, e_b = np.eye(p)[a] * STEP, np.eye(p)[b] * STEP
            if a == b:
                H[a, a] = (neg(z + e_a) - 2 * f0 + neg(z - e_a)) / STEP ** 2
            else:
                H[a, b] = H[b, a] = (neg(z + e_a + e_b) - neg(z + e_a - e_b)
                                     - neg(z - e_a + e_b) + neg(z - e_a - e_b)) / (4 * STEP ** 2)
    sub = H[np.ix_(free, free)]
    try:
        np.linalg.cholesky(sub)
    except np.linalg.LinAlgError:
        return None
    cov = np.zeros((p, p))
    cov[np.ix_(free, free)] = np.linalg.inv(sub)
    return cov


def _summary(joint_names: list[str], m: Any, cov: NDArray | None, rig: Any,
             prior_set: PriorSet | None = None, bounds: list | None = None
             ) -> dict[str, dict[str, Any]]:
    """identify's Laplace summary per joint parameter (a per-record copy 'c_Ax@2' in the
    units of c_Ax); one held on its prior bound (_hessian_covariance) gets its prior's
    interval, as in identify, never the zero width of a held parameter."""
    out = {}
    for j, n in enumerate(joint_names):
        one = np.array([m.theta[j]])
        c = None if cov is None else np.array([[cov[j, j]]])
        base = n.split("@")[0]
        if prior_set is None or bounds is None:
            out[n] = laplace_summary((base,), one, c, rig)[base]
            continue
        held = np.array([_on_bound(m.theta[j], bounds[j])])
        out[n] = laplace_summary((base,), one, c, rig,
                                  PriorSet((base,), (prior_set.priors[j],)), held)[base]
    return out


def _on_bound(v: float, bound: tuple[float | None, float | None]) -> bool:
    """Within two Hessian steps of a prior bound (_hessian_covariance holds it there)."""
    lo, hi = bound
    return bool((lo is not None and v - lo < 2 * STEP) or (hi is not None and hi - v < 2 * STEP))


def _record_block(rec: Recording, res: Identification) -> RecordFit:
    return RecordFit(recording=str(rec.source), speed_rpm=rec.speed_rpm, dt=rec.dt,
                     excitation_port=res.excitation_port, map=res.map,
                     noise=res.noise.map, adequacy=res.adequacy, parameters=res.parameters,
                     start_transient=res.start_transient)


def _joint_adequacy(own: list[Identification], bad: list[int]) -> dict[str, Any]:
    if not bad:
        return {"adequate": True, "line": f"model adequate on every one of the {len(own)} "
                                          "records", "records": []}
    lines = [f"record {i + 1}: {own[i].adequacy.line}" for i in bad]
    return {"adequate": False, "records": [i + 1 for i in bad],
            "line": (f"model NOT adequate on {len(bad)} of {len(own)} records; the joint "
                     "intervals combine each record's reported posterior, with its model "
                     "error integrated out. " + " | ".join(lines))}


def _check_agreement(summary: dict[str, Any], own: list[Identification],
                     shared: list[str], rig: Any) -> None:
    """Whether the records agree on the shared parameters (consistency.py); where they do
    not, the joint interval becomes the random-effects one and the adequacy says so."""
    found = agreement({n: [o.parameters[n].mean for o in own] for n in shared},
                      {n: [o.parameters[n].sd for o in own] for n in shared})
    summary["agreement"] = found
    if not found["disagree"]:
        return
    for n in found["disagree"]:
        row = found["parameters"][n]
        one = replace(own[0].map_result, theta=np.array([row["random_effects_mean"]]))
        summary["parameters"][n] = _summary(
            [n], one, np.array([[row["random_effects_sd"] ** 2]]), rig)[n]
    ad = summary["adequacy"]
    ad["adequate"] = False
    ad["line"] = ("model NOT adequate for one shared posterior: " + found["line"]
                  if not ad.get("records") else ad["line"] + " | " + found["line"])


def _product_of_reported(summary: dict[str, Any], own: list[Identification],
                         names: tuple[str, ...], joint_names: list[str], idx: list[NDArray],
                         prior_set: PriorSet, rig: Any) -> None:
    """Replace the joint Laplace intervals by the product of the records' reported
    Gaussian posteriors (each record's model error kept); the prior's precision counted
    once (a normal prior; a flat one has none)."""
    p = len(joint_names)
    P = np.zeros((p, p))
    b = np.zeros(p)
    for res, ix in zip(own, idx, strict=True):
        for j, n in enumerate(names):
            v = res.parameters[n]
            if not (np.isfinite(v.sd) and v.sd > 0):
                continue
            P[ix[j], ix[j]] += 1.0 / v.sd ** 2
            b[ix[j]] += v.mean / v.sd ** 2
    for j, pr in enumerate(prior_set.priors):
        if pr.kind == "normal":
            P[j, j] -= (len(own) - 1) / pr.b ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        sd = np.where(np.diag(P) > 0, 1.0 / np.sqrt(np.diag(P)), np.nan)
        mean = np.where(np.diag(P) > 0, b / np.diag(P), np.nan)
    m = replace(own[0].map_result, theta=mean)
    summary["parameters_model_only"] = summary["parameters"]
    summary["parameters"] = _summary(joint_names, m, np.diag(sd ** 2), rig)
    summary["parameters_from"] = ("the product of each record's reported posterior (its "
                                  "model error integrated out where its model is not "
                                  "adequate); the joint Laplace in parameters_model_only")
