"""`bayes-amb identify`: MAP and emcee posterior of named parameters from a recording."""

from __future__ import annotations

import argparse
import sys

from bayes_amb.cli.common import (
    add_prior_options,
    add_rig_option,
    check_rig_option,
    emit,
    read_priors,
    to_jsonable,
)
from bayes_amb.cli.options import integer, seed
from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.io.recording import load_recording
from bayes_amb.results.identification import Identification


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("identify", help="identify parameters from a recording",
                       description="Fit S(theta) to a closed-loop recording: MAP, then an "
                       "emcee posterior run to 50 autocorrelation times. Writes "
                       "RUN_DIR/posterior.nc and RUN_DIR/summary.json.")
    p.add_argument("recording", metavar="NAME.csv", nargs="+",
                   help="the recording (NAME.json beside it); several give one joint "
                   "posterior of the shared coefficients (each record's own noise, speed, "
                   "controller and dt; sampled as one record is, or MAP and Laplace with "
                   "--map-only; RUN_DIR/joint.html too)")
    p.add_argument("--per-record", default="", metavar="NAMES",
                   help="with several recordings: parameters estimated per record, e.g. "
                   "c_Ax (reported as c_Ax@1, c_Ax@2, ...) (default: none, all shared)")
    add_rig_option(p)
    p.add_argument("--params", required=True, metavar="NAMES",
                   help="comma-separated parameter names, e.g. k_By,c_By (required; names: "
                   "bayes-amb params)")
    add_prior_options(p)
    p.add_argument("--walkers", type=integer(4), default=None, metavar="N",
                   help="emcee walkers, >= 4 and >= 2 x the sampled dimensions (default: "
                   "max(24, 2 x dimensions + 2))")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--steps", type=integer(10), default=None, metavar="N",
                   help="fixed number of emcee steps, >= 10 (default: run to 50 "
                   "autocorrelation times, at most 20000 steps)")
    g.add_argument("--auto", action="store_true",
                   help="run to 50 autocorrelation times (default: on)")
    p.add_argument("--map-only", action="store_true",
                   help="MAP + Laplace only, fast (default: MAP, then emcee)")
    p.add_argument("--initial-state", action=argparse.BooleanOptionalAction, default=None,
                   help="fit the transient of the record's start, or not (default: fitted "
                   "when the data check finds that the record starts mid-operation, as a "
                   "rig's records do)")
    p.add_argument("--white-noise", action="store_true",
                   help="keep the three white noise sources (the noise check's sandwich "
                   "where the record's noise is not white) instead of learning the noise "
                   "spectrum from the record (default: learned where the residual is not "
                   "white)")
    p.add_argument("--keep-lines", action="store_true",
                   help="keep the record's narrowband lines (mains pick-up, a pump, the "
                   "unbalance) in the likelihood (default: their bins are left out before "
                   "the fit and listed under noise.lines_left_out)")
    p.add_argument("--map-method", choices=("lbfgs", "nelder-mead"), default="lbfgs",
                   help="MAP optimiser, one of lbfgs (L-BFGS-B, multi-start), nelder-mead "
                   "(the paper's fminsearch) (default lbfgs)")
    p.add_argument("--seed", type=seed, default=0,
                   help="sampler seed, 0..4294967295 (default 0)")
    p.add_argument("--out", required=True, metavar="RUN_DIR",
                   help="folder for posterior.nc and summary.json (required)")
    p.add_argument("--no-progress", action="store_true",
                   help="no progress bar (default: a bar on stderr)")
    p.add_argument("--json", action="store_true",
                   help="print summary.json to stdout (default: a table)")
    p.set_defaults(func=run)


def _progress_bar(enabled: bool):
    if not enabled:
        return None, None
    from tqdm import tqdm

    bar = tqdm(total=None, unit="step", file=sys.stderr, desc="sampling", leave=False)

    def update(done: int, target: int, tau_max: float) -> None:
        bar.total = target
        bar.set_postfix_str(f"tau_max {tau_max:.0f}, {done / max(tau_max, 1):.0f} tau",
                            refresh=False)
        bar.update(done - bar.n)

    return update, bar


def format_summary(s: Identification) -> str:
    """The terminal table of one recording's identification."""
    wall = f", {s.wall_s:.1f} s" if s.wall_s is not None else ""
    lines = [f"Identification of {s.recording} ({s.inference}, "
             f"{'converged' if s.converged else 'NOT converged'}{wall})",
             f"{'param':<7} {'MAP':>9} {'mean':>9} {'sd':>9} {'90% HDI':>21} "
             f"{'physical mean':>16} {'R-hat':>6} {'ESS':>6} {'tau':>6}"]
    for n, v in s.parameters.items():
        lo, hi = v.hdi90
        rh = f"{v.r_hat:.3f}" if v.r_hat is not None else "-"
        ess = f"{v.ess_bulk:.0f}" if v.ess_bulk is not None else "-"
        tau = f"{v.tau:.1f}" if v.tau is not None else "-"
        lines.append(f"{n:<7} {s.map[n]:>9.4f} {v.mean:>9.4f} {v.sd:>9.3g} "
                     f"[{lo:>8.4f}, {hi:>8.4f}] {v.physical_mean:>11.4g} {v.unit:<4} "
                     f"{rh:>6} {ess:>6} {tau:>6}")
    if s.noise is not None:
        lines.append("noise (MAP): " + ", ".join(f"{k} {v.value:.3g} {v.unit}"
                                                  for k, v in s.noise.map.items()))
    for note in (s.identifiability or {}).get("notes", []):
        lines.append(f"warning: {note}")
    if s.noise is not None and s.noise.lines_line:
        lines.append(s.noise.lines_line)
    if s.noise is not None and s.noise.spectrum is not None:
        lines.append(s.noise.spectrum.line)
    check = s.noise.check if s.noise is not None else None
    if check is not None and (check.doubted or check.sd_ratio):
        lines.append(f"noise: {check.line}")
    if s.model is not None:
        lines.append(s.model.line)
    if s.adequacy is not None:
        lines.append(f"adequacy: {s.adequacy.line}")
    return "\n".join(lines)


def format_joint(s: Identification) -> str:
    """The terminal table of a joint identification of several recordings."""
    wall = f", {s.wall_s:.1f} s" if s.wall_s is not None else ""
    lines = [f"Joint identification of {len(s.recordings or [])} recordings ({s.inference}, "
             f"{'converged' if s.converged else 'NOT converged'}{wall})",
             f"{'param':<9} {'mean':>9} {'sd':>9} {'90% HDI':>21} {'physical mean':>16}"
             + (f" {'R-hat':>6} {'ESS':>6}" if s.sampler is not None else "")]
    for n, v in s.parameters.items():
        lo, hi = v.hdi90
        mix = (f" {v.r_hat:>6.3f} {v.ess_bulk:>6.0f}"
               if s.sampler is not None and v.r_hat is not None else "")
        lines.append(f"{n:<9} {v.mean:>9.4f} {v.sd:>9.3g} [{lo:>8.4f}, {hi:>8.4f}] "
                     f"{v.physical_mean:>11.4g} {v.unit:<5}{mix}")
    for i, r in enumerate(s.records or [], 1):
        noise = ", ".join(f"{k} {v.value:.3g} {v.unit}" for k, v in r.noise.items())
        lines.append(f"record {i}: {r.recording}, {r.speed_rpm:g} rpm, dt {r.dt:g} s; "
                     f"noise (MAP) {noise}")
        if r.noise_check is not None and r.noise_check.doubted:
            lines.append(f"record {i} noise: {r.noise_check.line}")
    for note in (s.identifiability or {}).get("notes", []):
        lines.append(f"warning: {note}")
    if s.agreement is not None and not s.agreement.disagree:
        lines.append(f"agreement: {s.agreement.line}")
    if s.adequacy is not None:
        lines.append(f"adequacy: {s.adequacy.line}")
    return "\n".join(lines)


def _run_joint(args: argparse.Namespace, priors) -> int:
    from bayes_amb.inference.joint import identify_joint
    recs = [load_recording(r) for r in args.recording]
    for rec in recs:
        check_rig_option(args, rec)
    per = tuple(n.strip() for n in args.per_record.split(",") if n.strip())
    update, bar = _progress_bar(not (args.no_progress or args.json or args.map_only))
    try:
        result = identify_joint(recs, args.params, priors, IdentifyOptions(
            walkers=args.walkers, steps=args.steps, map_only=args.map_only,
            map_method=args.map_method, seed=args.seed, progress=update,
            initial_state=args.initial_state, learn_spectrum=not args.white_noise,
            leave_out_lines=not args.keep_lines),
            per_record=per)
    finally:
        if bar is not None:
            bar.close()
    result.save(args.out)
    from bayes_amb.report.joint import write_joint_report
    page = write_joint_report(args.out)
    emit(to_jsonable(result.to_dict()), format_joint(result)
         + f"\nwrote {args.out}/summary.json"
         + ("" if args.map_only else f", {args.out}/posterior.nc")
         + f" and {page}", args.json)
    return 0


def run(args: argparse.Namespace) -> int:
    priors = read_priors(args)
    if len(args.recording) > 1:
        return _run_joint(args, priors)
    if args.per_record:
        raise BayesAmbError("option --per-record: needs several recordings")
    rec = load_recording(args.recording[0])
    check_rig_option(args, rec)
    update, bar = _progress_bar(not (args.no_progress or args.json or args.map_only))
    try:
        result = identify(rec, args.params, priors, IdentifyOptions(
            walkers=args.walkers, steps=args.steps, map_only=args.map_only,
            map_method=args.map_method, seed=args.seed, progress=update,
            initial_state=args.initial_state, learn_spectrum=not args.white_noise,
            leave_out_lines=not args.keep_lines))
    finally:
        if bar is not None:
            bar.close()
    result.save(args.out)
    text = format_summary(result) + f"\nwrote {args.out}/summary.json" + \
        ("" if args.map_only else f" and {args.out}/posterior.nc")
    emit(to_jsonable(result.to_dict()), text, args.json)
    return 0
