"""`bayes-amb diagnose`: locate the model mismatch, name the missing physics, model it."""

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
from bayes_amb.cli.options import integer, real, seed
from bayes_amb.discrepancy import (
    VOCABULARY,
    DiagnoseOptions,
    all_candidates,
    diagnose,
    node_scan,
)
from bayes_amb.discrepancy.balancing import check_planes
from bayes_amb.discrepancy.library.registry import scanned_effects
from bayes_amb.errors import BayesAmbError
from bayes_amb.io.recording import load_recording
from bayes_amb.results.diagnosis import Diagnosis


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("diagnose", help="locate and explain model discrepancy",
                       description="Fit the nominal model over the whole band, locate where "
                       "its residual fails (channels, bands, time), try the library of "
                       "candidate physics (" + ", ".join(VOCABULARY) + "; `bayes-amb "
                       "library` lists them with parameters, units, priors and "
                       "equivalences), accept effects greedily by Bayes factor and compare "
                       "the fit before and after. Writes DIR/diagnosis.json, "
                       "DIR/residuals.nc and DIR/models/*.nc.")
    p.add_argument("recording", metavar="NAME.csv", nargs="+",
                   help="the recording (NAME.json beside it); several: each diagnosed, and "
                   "every effect named in one tested in all (DIR/record_<i>/, "
                   "DIR/records.json)")
    add_rig_option(p)
    p.add_argument("--params", default=None, metavar="NAMES",
                   help="stiffness/damping parameters kept in every model, comma-separated "
                        "(default: all eight bearing coefficients k_Ax,k_Ay,k_Bx,k_By,c_Ax,"
                        "c_Ay,c_Bx,c_By; any left out is tried as an explanation before any "
                        "physics)")
    add_prior_options(p)
    p.add_argument("--effects", default=",".join(VOCABULARY), metavar="NAMES",
                   help="effects to try, comma-separated (default " + ",".join(VOCABULARY)
                   + ", i.e. all)")
    p.add_argument("--scan", default="", metavar="NAMES",
                   help="effects to try also at every shaft node, comma-separated ("
                   + ", ".join(scanned_effects()) + "; default none: "
                   "their default locations only). Each scan costs one linearisation "
                   "per round; more candidates raise the bar for each")
    p.add_argument("--planes", default=None, metavar="P1,P2",
                   help="the two correction planes of the balancing answer when unbalance "
                   "is named: discs, bearings or shaft nodes n<j> (default: the two discs "
                   "furthest apart)")
    p.add_argument("--threshold", type=real(0), default=3.0, metavar="LOGBF",
                   help="log posterior odds (log Bayes factor - log of the number of "
                   "candidates tried) above which an effect is accepted, >= 0 (default 3)")
    p.add_argument("--max-effects", type=integer(0), default=4, metavar="N",
                   help="most effects to accept, >= 0 (default 4)")
    p.add_argument("--sample", action="store_true",
                   help="emcee posteriors of the nominal and final models (default: Laplace)")
    p.add_argument("--steps", type=integer(10), default=2000, metavar="N",
                   help="emcee steps with --sample, >= 10 (default 2000)")
    p.add_argument("--seed", type=seed, default=0, help="seed, 0..4294967295 (default 0)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="folder for diagnosis.json, residuals.nc and models/ (required)")
    p.add_argument("--no-progress", action="store_true",
                   help="no progress messages (default: progress on stderr)")
    p.add_argument("--json", action="store_true",
                   help="print diagnosis.json to stdout (default: text)")
    p.set_defaults(func=run)


def format_report(d: Diagnosis) -> str:
    """The terminal table of a diagnosis."""
    mm = d.mismatch
    wall = f", {d.wall_s:.0f} s" if d.wall_s is not None else ""
    lines = [f"Diagnosis of {d.recording} ({d.inference}{wall})"]
    lines += [f"check         : {c.line}" for c in d.checks]
    lines += [f"verdict       : {d.verdict}",
              f"mismatch      : {'DETECTED' if mm.detected else 'none'}"
              + (f" on {', '.join(mm.channels)}" if mm.channels else "")
              + (f"; bands {', '.join(f'{a:.0f}-{b:.0f} Hz' for a, b in mm.bands_hz)}"
                 if mm.bands_hz else "")
              + (f"; time {mm.time_s[0]:.2f}-{mm.time_s[1]:.2f} s" if mm.time_s else "")
              + f" (evidence {mm.evidence.strength})"]
    noise = sorted({f.test for f in mm.noise_findings})
    if noise:
        lines.append(f"noise         : {' and '.join(noise)} tests fail (the noise is not the "
                     "loop noise model's: a habit, not a mismatch)")
    for e in d.explanations:
        ps = ", ".join(f"{k} {v.map:.4g} [{v.hdi90[0]:.4g}, {v.hdi90[1]:.4g}] {v.unit}"
                       for k, v in e.params.items())
        cls = e.equivalence_class
        same = f"; cannot be told from {', '.join(cls[1:])}" if len(cls) > 1 else ""
        if e.node_range and e.node_range[0] != e.node_range[1]:
            same += f"; nodes {e.node_range[0]}-{e.node_range[1]} fit as well"
        lines.append(f"explanation   : {e.effect} at {e.location}: {ps} "
                     f"(log BF {e.score:.1f}, {e.confidence}{same})")
    if not d.explanations:
        lines.append("explanation   : none named")
    nl = d.nonlinearity
    if nl is not None:
        ps = "; ".join(f"{loc} {v:.4g} [{nl.hdi90[loc][0]:.4g}, {nl.hdi90[loc][1]:.4g}] "
                       f"{'Hz' if loc == 'bandwidth_hz' else nl.unit}"
                       for loc, v in nl.estimate.items())
        lines.append(f"nonlinearity  : {nl.title}" + (f": {nl.parameter} {ps}" if ps else "")
                     + (f"; {nl.linear_range}" if nl.linear_range else ""))
    lines += [f"stand-in      : {s.line}" for s in d.stand_ins]
    for pl in d.balancing.planes if d.balancing is not None else []:
        u, ph = pl.u_kgm, pl.phase_deg
        lines.append(f"balancing     : plane {pl.plane}: {u.map:.3g} [{u.hdi90[0]:.3g}, "
                     f"{u.hdi90[1]:.3g}] kg m at {ph.map:.0f} [{ph.hdi90[0]:.0f}, "
                     f"{ph.hdi90[1]:.0f}] deg"
                     + (" (correction mass opposite)" if pl.nonzero
                        else " (not told from 0: no correction needed)"))
    un = d.unexplained
    if un.present:
        lines.append(f"unexplained   : structure on {', '.join(un.channels)}"
                     + (f" in {', '.join(f'{a:.0f}-{b:.0f} Hz' for a, b in un.bands_hz)}"
                        if un.bands_hz else ""))
    fb, fa = d.fit.before, d.fit.after
    lines.append("NRMSE         : " + ", ".join(f"{c} {fb.nrmse[c]:.4f} -> {fa.nrmse[c]:.4f}"
                                              for c in fb.nrmse))
    lines.append("whiteness p   : " + ", ".join(
        f"{c} {fb.whiteness_p[c]:.2g} -> {fa.whiteness_p[c]:.2g}" for c in fb.nrmse))
    for n, v in d.parameters_before.items():
        a = d.parameters_after[n]
        lines.append(f"{n:<14}: {v.mean:+.4f} [{v.hdi90[0]:+.4f}, {v.hdi90[1]:+.4f}]"
                     f" -> {a.mean:+.4f} [{a.hdi90[0]:+.4f}, {a.hdi90[1]:+.4f}]")
    lines.append(d.story)
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    priors = read_priors(args)
    wanted = [e.strip() for e in args.effects.split(",") if e.strip()]
    unknown = [e for e in wanted if e not in VOCABULARY]
    if unknown or not wanted:
        raise BayesAmbError(f"option --effects: unknown effect {unknown[0] if unknown else ''!r};"
                            f" known: {', '.join(VOCABULARY)}")
    scan = [e.strip() for e in args.scan.split(",") if e.strip()]
    bad = [e for e in scan if e not in scanned_effects()]
    if bad:
        raise BayesAmbError(f"option --scan: effect {bad[0]!r} has no node scan; known: "
                            + ", ".join(scanned_effects()))
    recs = [load_recording(r) for r in args.recording]
    for r in recs:
        check_rig_option(args, r)
    rec = recs[0]
    planes = None
    if args.planes is not None:
        planes = tuple(p.strip() for p in args.planes.split(","))
        try:
            check_planes(rec.rig, planes)
        except BayesAmbError as exc:
            raise BayesAmbError(f"option --planes: {exc}") from None
    cands = all_candidates(wanted, rig=rec.rig)
    cands += node_scan(scan, rec.rig.n_nodes, cands)
    quiet = args.no_progress or args.json

    def say(text: str) -> None:
        if not quiet:
            sys.stderr.write(f"  {text}\n")

    opt = DiagnoseOptions(
        log_bf_threshold=args.threshold, max_effects=args.max_effects, candidates=cands,
        sample=args.sample, steps=args.steps, seed=args.seed, progress=say, planes=planes)
    if len(recs) > 1:
        return _run_records(args, recs, priors, opt)
    d = diagnose(rec, args.params, priors, opt)
    d.save(args.out)
    emit(to_jsonable(d.to_dict()), format_report(d) + f"\nwrote {args.out}/diagnosis.json, "
         f"{args.out}/residuals.nc and {args.out}/models/", args.json)
    return 0


def _run_records(args: argparse.Namespace, recs, priors, opt: DiagnoseOptions) -> int:
    from bayes_amb.discrepancy.records import diagnose_records
    from bayes_amb.report.records import write_records_report
    r = diagnose_records(recs, args.params, priors, opt)
    r.save(args.out)
    write_records_report(args.out)
    d = to_jsonable(r.to_dict())
    lines = [f"record {i}: {v} ({s})" for i, (v, s) in
             enumerate(zip(r.verdicts, r.recordings, strict=True), 1)]
    for row in r.across:
        bf = ", ".join(f"record {k}: " + (f"{v:.1f}" if v is not None else
                                           "no gain" if row.present[k] is False
                                           else "not tested")
                       for k, v in row.log_bayes_factor.items())
        if row.named_in:
            where = f"named in record(s) {','.join(map(str, row.named_in))}"
        else:
            odds = row.joint_log_posterior_odds
            where = (("named by the records together" if row.named_jointly else
                      "not named, even by the records together")
                     + " (joint log posterior odds "
                     + (f"{odds:.1f})" if odds is not None else "not computed)"))
        lines.append(f"{row.effect}: {where}; log Bayes factor {bf}; "
                     + ("present in every record" if row.in_every_record
                        else "NOT in every record")
                     + (f"; size: {row.size.reading}" if row.size else "")
                     + (f"; the records prefer {row.preferred_location} (by "
                        f"{row.weaker_by:.1f} nats)" if row.weaker_by is not None else ""))
    if r.force_law:
        lines.append(r.force_law["line"])
    emit(d, "\n".join(lines) + f"\nwrote {args.out}/records.json, {args.out}/records.html "
         f"and {args.out}/record_<i>/", args.json)
    return 0
