"""`bayes-amb simulate`: simulate a closed-loop recording (NAME.csv + NAME.json)."""

from __future__ import annotations

import argparse

import numpy as np

from bayes_amb.cli.common import emit
from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.errors import ParameterError
from bayes_amb.io.controller_file import load_controller
from bayes_amb.io.recording import save_recording
from bayes_amb.rig import load_rig
from bayes_amb.simulate import EXCITATIONS, SimulationConfig, parse_effect, simulate_recording
from bayes_amb.uncertainty import get_spec


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="simulate a closed-loop recording",
                       description="Simulate the truth plant (full FE or reduced) in closed "
                       "loop with a controller and write NAME.csv and NAME.json. The paper's "
                       "case: --truth reduced --set k_By=0.5 --dt 1e-3 --duration 0.5.")
    p.add_argument("--rig", default=None, help="rig TOML file (default: the reference rig)")
    p.add_argument("--controller", default=None, help="controller JSON (default: the "
                   "reference controller designed for the rig and dt)")
    p.add_argument("--truth", choices=("full", "reduced"), default="full")
    p.add_argument("--set", action="append", default=[], metavar="NAME=THETA",
                   help="true parameter value, e.g. k_By=0.5 (repeatable)")
    p.add_argument("--effect", action="append", default=[], metavar="NAME[:k=v,...]",
                   help="hidden physics, e.g. actuator_lag:bandwidth_hz=600 (repeatable)")
    p.add_argument("--excitation", choices=EXCITATIONS, default="random-binary")
    p.add_argument("--amplitude", type=float, default=0.5, help="excitation amplitude, A")
    p.add_argument("--band", default=None, metavar="LO,HI", help="multisine band, Hz "
                   "(default 5 Hz to min(1 kHz, 0.8 Nyquist)); a narrow band informs only a "
                   "combination of parameters")
    p.add_argument("--r1-rms", type=float, default=0.0, help="sensor-side disturbance RMS, m")
    p.add_argument("--r2-rms", type=float, default=0.0, help="actuator-side disturbance RMS, A")
    p.add_argument("--r1-band-hz", type=float, default=None, help="r1 low-pass band, Hz")
    p.add_argument("--r2-band-hz", type=float, default=None, help="r2 low-pass band, Hz")
    p.add_argument("--noise-rms", type=float, default=0.0, help="sensor noise RMS, m")
    p.add_argument("--duration", type=float, default=0.5, help="record length, s")
    p.add_argument("--dt", type=float, default=1e-4, help="sample time, s")
    p.add_argument("--speed-rpm", type=float, default=None, help="rotor speed (default nominal)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("-o", "--output", required=True, metavar="NAME.csv")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=run)


def parse_assignments(items: list[str]) -> dict[str, float]:
    out: dict[str, float] = {}
    for it in items:
        name, eq, val = it.partition("=")
        if not eq:
            raise ParameterError(f"option --set: expected NAME=THETA, got {it!r}")
        get_spec(name.strip())
        try:
            out[name.strip()] = float(val)
        except ValueError:
            raise ParameterError(f"option --set: {name.strip()}: value {val!r} is not a "
                                 "number") from None
    return out


def parse_band(text: str | None) -> tuple[float, float] | None:
    """'95,105' -> (95.0, 105.0)."""
    if text is None:
        return None
    parts = text.split(",")
    try:
        lo, hi = (float(v) for v in parts)
    except ValueError:
        raise ParameterError(f"option --band: expected LO,HI in Hz, got {text!r}") from None
    return lo, hi


def run(args: argparse.Namespace) -> int:
    rig = load_rig(args.rig)
    if args.controller:
        ctrl = load_controller(args.controller)
    else:
        ctrl = export_controller(reference_controller(rig, args.dt, args.speed_rpm), rig)
    cfg = SimulationConfig(truth=args.truth, params=parse_assignments(args.set),
                           effects=tuple(parse_effect(e) for e in args.effect),
                           excitation=args.excitation, amplitude=args.amplitude,
                           excitation_band_hz=parse_band(args.band),
                           noise_rms=args.noise_rms, r1_rms=args.r1_rms, r2_rms=args.r2_rms,
                           r1_band_hz=args.r1_band_hz, r2_band_hz=args.r2_band_hz,
                           duration=args.duration, dt=args.dt, speed_rpm=args.speed_rpm,
                           seed=args.seed)
    rec, truth = simulate_recording(rig, ctrl, cfg)
    csv_path, json_path = save_recording(args.output, rec, truth=truth)
    rms_y = np.sqrt(np.mean(np.asarray(rec.y) ** 2, axis=0))
    d = {"csv": str(csv_path), "json": str(json_path), "samples": rec.n_samples,
         "dt": rec.dt, "speed_rpm": rec.speed_rpm, "truth": args.truth,
         "y_rms_m": dict(zip(("Ax", "Ay", "Bx", "By"), rms_y.tolist(), strict=True))}
    text = (f"wrote {csv_path} and {json_path}: {rec.n_samples} samples at dt = {rec.dt:g} s, "
            f"{rec.speed_rpm:.0f} rpm, {args.truth} truth; y RMS "
            + ", ".join(f"{k} {v * 1e6:.2f} um" for k, v in d["y_rms_m"].items()))
    emit(d, text, args.json)
    return 0
