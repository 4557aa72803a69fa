"""`bayes-amb library`: the physics library of the diagnosis, from its registry."""

from __future__ import annotations

import argparse
import textwrap

from bayes_amb.cli.common import emit


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("library", help="list the candidate physics of the diagnosis",
                       description="List every effect `bayes-amb diagnose` can name: where "
                       "it acts, its physical parameters and units, its sampled parameters "
                       "with priors and null values, its fingerprint in the residual and the "
                       "effects it cannot be told apart from with u, y and the excitation.")
    p.add_argument("--all", action="store_true",
                   help="also list the nominal model's own coefficients, tried first "
                        "(default: physics only)")
    p.add_argument("--markdown", action="store_true",
                   help="print the library's Markdown table, as docs/diagnose.md has it "
                   "(default: plain text)")
    p.add_argument("--json", action="store_true", help="print JSON (default: text)")
    p.set_defaults(func=run)


def format_library(rows: list[dict]) -> str:
    out = []
    for r in rows:
        out.append(f"{r['effect']} ({r['title']}, {r['side']} side"
                   f"{', repeatable' if r['repeatable'] else ''})")
        wrap = textwrap.TextWrapper(width=92, initial_indent="  ", subsequent_indent="    ")
        out += wrap.wrap(r["description"])
        out.append("  at          : " + ", ".join(r["locations"]))
        out.append("  reports     : " + ", ".join(f"{p['name']} ({p['unit']})"
                                                  for p in r["parameters"]))
        for q in r["parameters"]:
            if q["plausible"] is not None:
                out += textwrap.wrap(f"{q['name']} within {q['plausible'][0]:g} .. "
                                     f"{q['plausible'][1]:g}: {q['why']} (outside: a stand-in)",
                                     width=92, initial_indent="  plausible   : ",
                                     subsequent_indent="                ")
        out.append("  sampled     : " + ", ".join(f"{s['name']} {s['prior']} [{s['unit']}], "
                                                  f"null {s['null']:g}" for s in r["sampled"]))
        out += textwrap.wrap(r["fingerprint"], width=92, initial_indent="  fingerprint : ",
                             subsequent_indent="                ")
        for e in r["equivalences"] or ["-"]:
            out += textwrap.wrap(e, width=92, initial_indent="  same as     : ",
                                 subsequent_indent="                ")
    return "\n".join(out)


def run(args: argparse.Namespace) -> int:
    from bayes_amb.discrepancy.library import library_table, markdown_table

    rows = library_table(with_nominal=args.all)
    text = markdown_table() if args.markdown else format_library(rows)
    emit({"effects": rows}, text, args.json)
    return 0
