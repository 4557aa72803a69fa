"""`bayes-amb rig from-ross`: convert a ROSS rotor file into a rig file (optional extra)."""

from __future__ import annotations

import argparse

from bayes_amb.cli.common import emit
from bayes_amb.cli.options import real
from bayes_amb.io.atomic import write_text_atomic


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("rig", help="rig files: convert from ROSS",
                       description="Rig-file tools. `rig from-ross ROTOR.toml -o RIG.toml` "
                       "converts a saved ross.Rotor (needs the optional extra "
                       "bayes-amb[ross]).")
    rs = p.add_subparsers(dest="rig_command", metavar="RIG_COMMAND", required=True,
                          parser_class=type(p))
    q = rs.add_parser("from-ross", help="convert a saved ROSS rotor into a rig file")
    q.add_argument("rotor", help="a rotor saved with ross.Rotor.save")
    q.add_argument("-o", "--output", required=True, metavar="RIG.toml")
    q.add_argument("--name", default=None, help="rig name (default: the output file's stem)")
    q.add_argument("--speed-rpm", type=float, default=None,
                   help="nominal speed (default: the rotor's rated_w)")
    q.add_argument("--zeta", type=real(0, 1), default=None,
                   help="first_mode_zeta of the rig, 0..1, replacing the ROSS shaft's "
                   "material damping (default: from the shaft elements' beta, zeta = beta "
                   "w1 / 2 with w1 the bare shaft's first free-free bending frequency)")
    q.add_argument("--json", action="store_true", help="print JSON")
    q.set_defaults(func=run_from_ross)


def run_from_ross(args: argparse.Namespace) -> int:
    from pathlib import Path

    from bayes_amb.rig.ross import load_ross_rotor, rig_from_ross, rig_to_toml

    rotor = load_ross_rotor(args.rotor)
    conv = rig_from_ross(rotor, name=args.name or Path(args.output).stem, source=args.rotor,
                         nominal_speed_rpm=args.speed_rpm, first_mode_zeta=args.zeta)
    write_text_atomic(args.output, rig_to_toml(conv.data))
    r = conv.rig
    d = {"output": args.output, "rig": conv.data, "notes": list(conv.notes)}
    text = [f"wrote {args.output}: rig '{r.name}', {r.n_nodes} nodes, {r.shaft.text()}, "
            f"{len(r.discs)} discs, bearings at nodes {r.bearing_nodes['A']} and "
            f"{r.bearing_nodes['B']} ({r.magnet_text()}), sensors at {r.sensor_nodes['A']} "
            f"and {r.sensor_nodes['B']}, {r.nominal_speed_rpm:g} rpm"]
    text += [f"  note: {n}" for n in conv.notes]
    emit(d, "\n".join(text), args.json)
    return 0
