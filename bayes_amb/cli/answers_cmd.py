"""`bayes-amb answers`: engineering answers of an identification run, with 90 % intervals
(a thin layer over :func:`bayes_amb.engineering.physical_quantities`)."""

from __future__ import annotations

import argparse

from bayes_amb.cli.common import add_rig_option, check_rig_option, emit, to_jsonable
from bayes_amb.errors import BayesAmbError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "answers", help="bearing ks and c, closed-loop modes, log decrements, API 617 "
        "margins, ISO 14839-3 peak sensitivity, with 90%% intervals",
        description="Propagate the posterior of an identification run (RUN_DIR; after the "
        "diagnosis when RUN_DIR holds one that named physics) through the full FE plant "
        "closed with the recorded controller.")
    p.add_argument("run_dir", metavar="RUN_DIR", help="folder with summary.json (and "
                   "posterior.nc)")
    p.add_argument("--recording", default=None, help="the recording (default: the one "
                   "named in summary.json)")
    add_rig_option(p)
    p.add_argument("--draws", type=int, default=60, help="posterior draws used (default 60)")
    p.add_argument("--speeds", default=None, metavar="RPM,RPM,...", help="speeds of the "
                   "mode table (default 0.8, 0.9, 1.0, 1.05 x the recording's speed)")
    p.add_argument("--model", choices=("full", "reduced"), default="full",
                   help="plant the draws are put into: full (the FE model) or reduced "
                   "(default: full)")
    p.add_argument("--out", default=None, metavar="FILE.json", help="also write the result "
                   "as JSON, atomically (default: not written)")
    p.add_argument("--json", action="store_true", help="print JSON (default: text)")
    p.set_defaults(func=run)


def _speeds(text: str | None) -> list[float] | None:
    if text is None:
        return None
    try:
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise BayesAmbError(f"option --speeds: expected numbers in rpm separated by commas, "
                            f"got {text!r}") from None


def run(args: argparse.Namespace) -> int:
    from bayes_amb.engineering import physical_quantities
    from bayes_amb.engineering.quantities import INTERVAL_TEXT
    from bayes_amb.io.atomic import write_text_atomic
    from bayes_amb.io.nonfinite import result_json_text
    from bayes_amb.report.collect import collect_run

    if args.draws < 1:
        raise BayesAmbError(f"option --draws: expected a positive integer, got {args.draws}")
    run_data = collect_run(args.run_dir, recording=args.recording)
    check_rig_option(args, run_data.recording)
    if run_data.recording is None:
        raise BayesAmbError(f"run folder {args.run_dir}: field recording: "
                            f"{run_data.recording_note}")
    from bayes_amb.report.engineering import final_draws

    draws, source = final_draws(run_data, args.draws, 0)
    res = physical_quantities(draws, run_data.recording, _speeds(args.speeds),
                              n_draws=args.draws, model=args.model)
    answers = res.answers(source)
    data = answers.to_dict()
    if args.out:
        write_text_atomic(args.out, result_json_text(to_jsonable(data)))
    lines = [f"{k:<52} {q.value:>12.5g}  [{q.lo:.5g}, {q.hi:.5g}]  {q.unit}"
             + ("" if q.estimated else "  (not estimated)")
             for k, q in res.quantities.items()]
    head = [*res.notes, f"from {source}", f"interval {INTERVAL_TEXT}",
            "quantity  median  [90 % interval]  unit"]
    emit(data, "\n".join([*head, *lines]), args.json)
    return 0
