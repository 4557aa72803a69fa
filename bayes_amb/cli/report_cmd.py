"""`bayes-amb report`: an HTML and a PDF report of an identification run."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from bayes_amb.cli.common import add_rig_option, check_rig_option, emit
from bayes_amb.report import PDF_BACKENDS, ReportOptions, collect_run, write_report


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("report", help="write an HTML and a PDF report of a run",
                       description="Read RUN_DIR (summary.json, posterior.nc, optional "
                       "diagnosis.json), the recording it was identified on and any study "
                       "folders, and write OUT/report.html (one self-contained file) and "
                       "OUT/report.pdf. Nothing estimated is recomputed.")
    p.add_argument("run_dir", metavar="RUN_DIR")
    p.add_argument("--recording", default=None, metavar="NAME.csv",
                   help="the recording (default: the path in summary.json, tried as given, "
                   "then next to RUN_DIR)")
    add_rig_option(p)
    p.add_argument("--study", action="append", default=[], metavar="DIR",
                   help="a finished study folder to include (repeatable; default none)")
    p.add_argument("--out", default=None, metavar="DIR", help="output folder (default RUN_DIR)")
    p.add_argument("--no-pdf", action="store_true",
                   help="write the HTML only (default: HTML and PDF)")
    p.add_argument("--pdf-backend", choices=PDF_BACKENDS, default="auto",
                   help=f"PDF writer, one of {', '.join(PDF_BACKENDS)}; auto: WeasyPrint, "
                   "else matplotlib (default auto)")
    p.add_argument("--json", action="store_true",
                   help="print what was written as JSON (default: text)")
    p.set_defaults(func=run)


def command_line(args: argparse.Namespace) -> list[str]:
    """sys.argv when run as the bayes-amb script, else the command rebuilt from ``args``."""
    if Path(sys.argv[0]).name == "bayes-amb":
        return ["bayes-amb", *sys.argv[1:]]
    cmd = ["bayes-amb", "report", str(args.run_dir)]
    if args.recording:
        cmd += ["--recording", str(args.recording)]
    if args.rig:
        cmd += ["--rig", str(args.rig)]
    for s in args.study:
        cmd += ["--study", str(s)]
    if args.out:
        cmd += ["--out", str(args.out)]
    cmd += ["--no-pdf"] * args.no_pdf + ["--json"] * args.json
    if args.pdf_backend != "auto":
        cmd += ["--pdf-backend", args.pdf_backend]
    return cmd


def run(args: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    quiet = args.json

    def progress(msg: str) -> None:
        if not quiet:
            sys.stderr.write(f"[{time.perf_counter() - t0:5.1f} s] {msg}\n")

    from bayes_amb.report.joint import is_joint_run, write_joint_report
    if is_joint_run(args.run_dir):            # identify REC1 REC2 ... --out RUN_DIR
        path = write_joint_report(args.run_dir, args.out,
                                  None if args.no_pdf else args.pdf_backend)
        pdf = None if args.no_pdf else path.with_suffix(".pdf")
        emit({"html": str(path), "pdf": None if pdf is None else str(pdf)},
             f"wrote {path}" + ("" if pdf is None else f" and {pdf}") + " (a joint "
             "identification of several recordings: one page; report each record's own "
             "run for the full report)", args.json)
        return 0
    data = collect_run(args.run_dir, recording=args.recording, studies=args.study)
    check_rig_option(args, data.recording)
    progress(f"read {args.run_dir}")
    result = write_report(data, args.out or args.run_dir, argv=command_line(args),
                          options=ReportOptions(), pdf=not args.no_pdf,
                          pdf_backend=args.pdf_backend, progress=progress)
    lines = [f"wrote {result.html}"]
    if result.pdf is not None:
        lines.append(f"wrote {result.pdf} (PDF made with {result.pdf_backend})")
    lines += [f"note: {n}" for n in result.notes]
    lines.append(f"{len(result.sections)} sections, {result.n_figures} figures, "
                 f"{result.wall_s:.1f} s")
    emit(result.to_dict(), "\n".join(lines), args.json)
    return 0
