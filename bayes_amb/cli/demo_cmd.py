"""`bayes-amb demo`: the end-to-end demonstration (model, paper's case, realistic case,
reports). Progress goes to stderr, the results to stdout."""

from __future__ import annotations

import argparse
import sys
import time

from bayes_amb.cli.common import emit, to_jsonable
from bayes_amb.cli.options import seed
from bayes_amb.demo import PAPER_THETA, DemoConfig, run_demo


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="run the end-to-end demonstration and write a report",
                       description="Build and reduce the reference rig, export its "
                       "controllers, reproduce the paper's case (k_By = 0.5), identify "
                       "k_By and c_By on a realistic 10 kHz recording with noise and a "
                       "concealed actuator lag, and write OUT/report.html and "
                       "OUT/report.pdf. About 2-4 minutes on two cores.")
    p.add_argument("--out", default="reports/demo", metavar="DIR",
                   help="output folder (default reports/demo)")
    p.add_argument("--seed", type=seed, default=0, help="seed of simulations and samplers, "
                   "0..4294967295 (default 0)")
    p.add_argument("--quick", action="store_true", help="a smoke test: short records and few "
                   "sampler steps (seconds; default: the full demo)")
    p.add_argument("--import-formats", action="store_true",
                   help="only the import step: export a simulated recording to .mat v5, "
                   ".mat v7.3, TDMS, HDF5 and CSV with a channel map in volts, import and "
                   "identify each, import a MATLAB-style PID (OUT/import_demo.json; default: the "
                   "full demo)")
    p.add_argument("--json", action="store_true",
                   help="print the results as JSON (default: text)")
    p.set_defaults(func=run)


def run_import_formats(args: argparse.Namespace) -> int:
    from bayes_amb.demo_import import TRUTH, run_import_demo

    res = run_import_demo(args.out, args.seed)
    lines = ["Import demo: one simulated recording written as a rig's DAQ would (volts, "
             "offsets, an inverted probe), imported back and identified (MAP + Laplace):"]
    can = res.canonical
    lines.append("  canonical CSV : " + ", ".join(
        f"{n} {can[n]['mean']:.4f} +- {can[n]['sd']:.4f}" for n in TRUTH))
    for fmt, r in res.formats.items():
        post = r["posterior"]
        lines.append(f"  {fmt:<13} : " + ", ".join(
            f"{n} {post[n]['mean']:.4f} +- {post[n]['sd']:.4f}" for n in TRUTH)
            + f"  (largest shift {r['max_shift_in_sd']:.1e} sd)")
    c = res.controller
    lines.append(f"MATLAB PID (continuous, negative feedback) imported: {c['discretisation']}; "
                 f"full-plant spectral radius {c['spectral_radius_full']:.6f}, ISO 14839-3 "
                 f"zone {c['iso14839_zone']}")
    lines.append(f"Files and numbers: {res.summary_path} ({res.wall_s:.0f} s)")
    emit(to_jsonable({"formats": res.formats, "canonical": res.canonical,
                      "controller": res.controller, "summary": str(res.summary_path),
                      "wall_s": res.wall_s}), "\n".join(lines), args.json)
    return 0


def run(args: argparse.Namespace) -> int:
    if args.import_formats:
        return run_import_formats(args)
    t0 = time.perf_counter()

    def progress(msg: str) -> None:
        sys.stderr.write(f"[{time.perf_counter() - t0:6.1f} s] {msg}\n")
        sys.stderr.flush()

    res = run_demo(args.out, DemoConfig(seed=args.seed, quick=args.quick), progress)
    k = res.paper["k_By"]
    lines = [f"Paper's case (reduced truth, k_By = 0.5, dt = 1e-3 s): MAP {k['map']:.6f}, "
             f"posterior mean {k['mean']:.6f}, 90 % HDI [{k['hdi90'][0]:.6f}, "
             f"{k['hdi90'][1]:.6f}]; true 0.5 (error {abs(k['mean'] - 0.5):.1e}), the paper "
             f"found {PAPER_THETA}"]
    lines.append("Realistic case (full truth, 10 kHz, noise, concealed actuator lag):")
    for n, e in res.realistic.items():
        if n == "converged":
            continue
        lines.append(f"  {n}: mean {e['mean']:.4f} ({e['physical_mean']:.4g} {e['unit']}), "
                     f"90 % HDI [{e['hdi90'][0]:.4f}, {e['hdi90'][1]:.4f}], "
                     f"true {e['true']:g}")
    lines.append(f"  sampler {'converged' if res.realistic['converged'] else 'NOT converged'};"
                 f" diagnosis {res.diagnosis}")
    lines.append(f"Report: {res.report_html}")
    if res.report_pdf is not None:
        lines.append(f"        {res.report_pdf} (PDF made with {res.pdf_backend})")
    if res.paper_report is not None:
        lines.append(f"Paper case report: {res.paper_report}")
    lines.append("Timings: " + ", ".join(f"{k} {v:.0f} s" for k, v in res.timings.items()))
    emit(to_jsonable({"out": str(res.out), "paper": res.paper, "realistic": res.realistic,
                      "report_html": str(res.report_html),
                      "report_pdf": None if res.report_pdf is None else str(res.report_pdf),
                      "pdf_backend": res.pdf_backend,
                      "paper_report": None if res.paper_report is None
                      else str(res.paper_report),
                      "diagnosis": res.diagnosis, "timings": res.timings}),
         "\n".join(lines), args.json)
    return 0
