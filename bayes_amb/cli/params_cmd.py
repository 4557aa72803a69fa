"""`bayes-amb params`: the parameter vocabulary with meaning, scale and unit."""

from __future__ import annotations

import argparse

from bayes_amb.cli.common import emit
from bayes_amb.rig import load_rig
from bayes_amb.uncertainty import PARAMETERS


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("params", help="list the uncertain-parameter names",
                       description="List every parameter name with its meaning, physical "
                       "scale (value per unit theta) and unit.")
    p.add_argument("--rig", default=None, metavar="FILE",
                   help="rig TOML file (default: the reference rig)")
    p.add_argument("--json", action="store_true", help="print JSON (default: text)")
    p.set_defaults(func=run)


def parameter_table(rig_path: str | None = None) -> list[dict]:
    rig = load_rig(rig_path)
    return [{"name": s.name, "kind": s.kind, "location": s.location, "meaning": s.meaning,
             "scale": s.physical_scale(rig), "unit": s.unit, "physical": s.physical_label}
            for s in PARAMETERS.values()]


def run(args: argparse.Namespace) -> int:
    rows = parameter_table(args.rig)
    text = ["name     physical per unit theta   meaning"]
    for r in rows:
        text.append(f"{r['name']:<8} {r['physical']:>8} {r['scale']:>+11.4g} {r['unit']:<6}  "
                    f"{r['meaning']}")
    emit({"parameters": rows}, "\n".join(text), args.json)
    return 0
