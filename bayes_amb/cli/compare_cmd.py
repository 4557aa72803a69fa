"""`bayes-amb compare`: has a coefficient changed between two runs (records over time)?
A thin layer over :func:`bayes_amb.inference.compare.compare_runs`."""

from __future__ import annotations

import argparse

from bayes_amb.cli.common import emit
from bayes_amb.errors import BayesAmbError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("compare", help="how much each coefficient changed between two runs, "
                       "and the probability that it changed",
                       description="Compare two runs of identify (summary.json) or diagnose "
                       "(parameters_after of diagnosis.json), e.g. a record of today against "
                       "one of last month: per coefficient the change with its 90 %% "
                       "interval and the probability that it changed by a change of the "
                       "given size (Bayes factor, even prior odds).")
    p.add_argument("before", help="the earlier run: its directory or its JSON file")
    p.add_argument("after", help="the later run: its directory or its JSON file")
    p.add_argument("--change-scale", default="0.1", metavar="TAU or NAME=TAU,...",
                   help="size of a change that matters, in the parameters' units, one for "
                        "all or per parameter (default 0.1: 10 %% of ks, 100 N s/m)")
    p.add_argument("--out", default=None, metavar="FILE",
                   help="also write the comparison as JSON to FILE, atomically (default: "
                        "print only)")
    p.add_argument("--json", action="store_true", help="print JSON (default: text)")
    p.set_defaults(func=run)


def _scale(text: str) -> float | dict[str, float]:
    try:
        if "=" not in text:
            return float(text)
        return {k.strip(): float(v) for k, v in (t.split("=", 1) for t in text.split(","))}
    except ValueError:
        raise BayesAmbError(f"option --change-scale: value {text!r} is not TAU or "
                            "NAME=TAU,...") from None


def run(args: argparse.Namespace) -> int:
    from bayes_amb.inference.compare import compare_runs
    from bayes_amb.io.atomic import write_text_atomic
    from bayes_amb.io.nonfinite import result_json_text

    c = compare_runs(args.before, args.after, _scale(args.change_scale))
    if args.out:
        write_text_atomic(args.out, result_json_text(c.to_dict()))
    emit(c.to_dict(), f"before: {c.before}\nafter : {c.after}\n" + c.summary(), args.json)
    return 0
