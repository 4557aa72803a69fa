"""`bayes-amb import-controller`: a MATLAB-style controller (.mat) into a controller file."""

from __future__ import annotations

import argparse

from bayes_amb.cli.common import emit
from bayes_amb.io.controller_import import DISCRETISATION_METHODS, import_controller
from bayes_amb.rig import load_rig


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("import-controller", help="import a MATLAB state-space or transfer-"
                       "function controller (.mat) as a controller file",
                       description="Read A, B, C, D, Ts (or num_Ax, den_Ax, ..., Ts) from a "
                       ".mat file (v5 or v7.3), discretise a continuous controller (Ts = 0) "
                       "at --dt, check that it stabilises the rig's full FE plant, report its "
                       "ISO 14839-3 zone and write a generic controller file.")
    p.add_argument("source", help="the .mat file")
    p.add_argument("--dt", type=float, default=None,
                   help="sample time in s (required for Ts = 0; else must equal Ts; "
                   "default: Ts)")
    p.add_argument("--method", choices=DISCRETISATION_METHODS, default="tustin",
                   help="discretisation of a continuous controller: "
                   + ", ".join(DISCRETISATION_METHODS)
                   + " (default tustin)")
    p.add_argument("--prewarp-hz", type=float, default=None,
                   help="Tustin prewarp frequency in Hz (default: none)")
    p.add_argument("--feedback", choices=("negative", "positive"), default="negative",
                   help="negative: u = -K y (MATLAB convention) or positive: u = +K y (default "
                   "negative)")
    p.add_argument("--rig", default=None, help="rig TOML file (default: the reference rig)")
    p.add_argument("--speed-rpm", type=float, default=None,
                   help="speed of the stability check (default: nominal)")
    p.add_argument("-o", "--output", required=True, metavar="CONTROLLER.json",
                   help="the controller file to write")
    p.add_argument("--json", action="store_true", help="print JSON (default: text)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    imp = import_controller(args.source, load_rig(args.rig), dt=args.dt, method=args.method,
                            prewarp_hz=args.prewarp_hz, feedback=args.feedback,
                            speed_rpm=args.speed_rpm)
    imp.controller.save(args.output)
    d = {"output": args.output, "dt": imp.controller.dt, "states": imp.controller.n_states,
         "form": imp.form, "feedback": args.feedback, "discretisation": imp.discretisation,
         "speed_rpm": imp.speed_rpm, "spectral_radius_full": imp.spectral_radius,
         "stable": bool(imp.spectral_radius < 1), "sensitivity_peak_db": imp.sensitivity_peak_db,
         "iso14839_zone": imp.zone}
    peaks = ", ".join(f"{k} {v:.2f} dB" for k, v in imp.sensitivity_peak_db.items())
    text = "\n".join([
        f"wrote {args.output}: generic controller, {imp.controller.n_states} states, "
        f"dt = {imp.controller.dt:g} s, from {imp.form} ({args.feedback} feedback)",
        f"  discretisation  : {imp.discretisation}",
        f"  full plant loop : stable (spectral radius {imp.spectral_radius:.6f} at "
        f"{imp.speed_rpm:.0f} rpm)",
        f"  sensitivity     : {peaks}  -> ISO 14839-3 zone {imp.zone}"])
    emit(d, text, args.json)
    return 0
