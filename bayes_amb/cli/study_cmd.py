"""`bayes-amb study`: run a study file (grid of simulated experiments)."""

from __future__ import annotations

import argparse
import shlex
import sys

from bayes_amb.cli.common import emit, one_line
from bayes_amb.cli.options import integer
from bayes_amb.errors import StudyInterrupted
from bayes_amb.studies import finalise, load_study, run_study


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("study", help="run a sensitivity or calibration study",
                       description="Run the replicates of a study TOML file (see studies/), "
                       "resumably, on a process pool or Dask; write DIR/results.csv, "
                       "DIR/summary.csv, DIR/results.nc, DIR/figures/ and DIR/study.json.")
    p.add_argument("study", metavar="studies/NAME.toml", help="the study file")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="results folder (required; holds results.jsonl for resuming)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--workers", type=integer(1), default=2, metavar="N",
                   help="local worker processes, >= 1 (default 2; 1 runs in this process)")
    g.add_argument("--dask-local", type=integer(1), default=None, metavar="N",
                   help="run on a local Dask cluster of N >= 1 workers (default: the process "
                   "pool)")
    g.add_argument("--scheduler", default=None, metavar="ADDR",
                   help="run on the Dask scheduler at ADDR (default: the process pool)")
    p.add_argument("--resume", action="store_true",
                   help="continue a stopped study in DIR (default: also on; finished "
                   "replicates are always skipped). Ctrl-C or kill stops a study cleanly")
    p.add_argument("--no-figures", action="store_true",
                   help="do not draw DIR/figures/ (default: draw them)")
    p.add_argument("--no-progress", action="store_true",
                   help="no progress bar on stderr (default: a bar)")
    p.add_argument("--json", action="store_true", help="print the outcome as JSON "
                   "(default: text)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    spec = load_study(args.study)
    try:
        rows = run_study(spec, args.out, workers=args.workers, dask_local=args.dask_local,
                         scheduler=args.scheduler,
                         progress=not (args.no_progress or args.json))
    except StudyInterrupted as exc:
        sys.stderr.write(one_line(f"bayes-amb study: {exc}; resume with: bayes-amb study "
                                  f"{shlex.quote(args.study)} --out "
                                  f"{shlex.quote(args.out)} --resume") + "\n")
        return exc.exit_status
    study = finalise(spec, rows, args.out)
    figures = []
    if not args.no_figures:
        from bayes_amb.plots.studies import study_figures
        figures = [str(p) for p in study_figures(spec, args.out, study)]
    d = {"study": spec.name, "out": args.out, "rows": len(rows),
         "failures": study.failures, "conclusions": study.conclusions,
         "sbc": study.sbc, "benchmark": study.benchmark, "figures": figures}
    text = [f"study '{spec.name}': {len(rows)} replicates ({study.failures} failed), "
            f"results in {args.out}/"]
    text += [f"  - {c}" for c in study.conclusions or []]
    emit(d, "\n".join(text), args.json)
    return 0
