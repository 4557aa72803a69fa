"""`bayes-amb import-controller`: a MATLAB-style controller (.mat) into a controller file."""

from __future__ import annotations

import argparse

from bayes_amb.cli.common import emit
from bayes_amb.errors import DataImportError
from bayes_amb.io.controller_import import (
    DISCRETISATION_METHODS,
    ControllerImport,
    import_controller,
)
from bayes_amb.rig import load_rig


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("import-controller", help="import a MATLAB state-space or transfer-"
                       "function controller (.mat) as a controller file",
                       description="Read A, B, C, D, Ts (or num_Ax, den_Ax, ..., Ts) from a "
                       ".mat file (v5 or v7.3), discretise a continuous controller (Ts = 0) "
                       "at --dt, check that it stabilises the rig's full FE plant, report its "
                       "ISO 14839-3 zone and write a generic controller file.")
    p.add_argument("source", help="the .mat file (or, with --from-ross, a saved ROSS rotor)")
    p.add_argument("--from-ross", action="store_true",
                   help="source is a rotor saved with ross.Rotor.save: import its magnetic "
                   "bearings' controllers (PID gains; k_amp and k_sense), each bearing its "
                   "own, for the rig converted from it (--rig, required) (default: source "
                   "is a .mat file)")
    p.add_argument("--ross-scale", default=None, metavar="A=F[,B=F]",
                   help="with --from-ross: multiply a bearing's controller by F (default: "
                   "as ROSS has it)")
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
    if args.from_ross:
        imp = _from_ross(args)
    else:
        if args.ross_scale is not None:
            raise DataImportError("option --ross-scale: only with --from-ross")
        imp = import_controller(args.source, load_rig(args.rig), dt=args.dt,
                                method=args.method, prewarp_hz=args.prewarp_hz,
                                feedback=args.feedback, speed_rpm=args.speed_rpm)
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
        f"  full plant loop : stable (spectral radius {_rho(imp.spectral_radius)} at "
        f"{imp.speed_rpm:.0f} rpm)",
        f"  sensitivity     : {peaks}  -> ISO 14839-3 zone {imp.zone}"])
    emit(d, text, args.json)
    return 0


def _rho(rho: float) -> str:
    """0.992586, or '1 - 2e-10 (marginal: ...)' where six digits would print 1.000000."""
    if rho < 1 - 5e-7:
        return f"{rho:.6f}"
    return (f"1 - {1 - rho:.1e}, marginal: a pole on the unit circle to rounding, e.g. an "
            "integrator with a tiny gain")


def _from_ross(args: argparse.Namespace) -> ControllerImport:
    from bayes_amb.io.ross_controller import controller_from_ross
    from bayes_amb.rig.ross import load_ross_rotor

    if args.rig is None:
        raise DataImportError("option --rig: required with --from-ross (the rig converted "
                              "from the same rotor: bayes-amb rig from-ross)")
    if args.dt is None:
        raise DataImportError("option --dt: required with --from-ross (ROSS's controllers "
                              "are continuous)")
    if args.feedback != "negative":
        raise DataImportError("option --feedback: ROSS's controllers are negative feedback "
                              "(i = -k_amp C k_sense y); leave it out with --from-ross")
    scale = {}
    for item in (args.ross_scale or "").split(","):
        if not item:
            continue
        name, _, value = item.partition("=")
        try:
            scale[name.strip()] = float(value)
        except ValueError:
            raise DataImportError(f"option --ross-scale: expected BEARING=FACTOR, got "
                                  f"{item!r}") from None
    return controller_from_ross(load_ross_rotor(args.source), load_rig(args.rig), dt=args.dt,
                                method=args.method, prewarp_hz=args.prewarp_hz,
                                speed_rpm=args.speed_rpm, source=args.source, scale=scale)
