"""`bayes-amb simulate`: simulate a closed-loop recording (NAME.csv + NAME.json)."""

from __future__ import annotations

import argparse

import numpy as np

from bayes_amb.cli.common import emit
from bayes_amb.cli.options import real, seed
from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.errors import ParameterError
from bayes_amb.io.controller_file import load_controller
from bayes_amb.io.recording import save_recording
from bayes_amb.rig import load_rig
from bayes_amb.simulate import EXCITATIONS, SimulationConfig, parse_effect, simulate_recording
from bayes_amb.simulate.effects import describe_effects
from bayes_amb.uncertainty import get_spec


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="simulate a closed-loop recording",
                       description="Simulate the truth plant (full FE or reduced) in closed "
                       "loop with a controller and write NAME.csv and NAME.json. The paper's "
                       "case: --truth reduced --set k_By=0.5 --dt 1e-3 --duration 0.5.")
    p.add_argument("--rig", default=None, metavar="FILE",
                   help="rig TOML file (default: the reference rig)")
    p.add_argument("--controller", default=None, metavar="FILE", help="controller JSON "
                   "(default: the reference controller designed for the rig and --dt)")
    p.add_argument("--truth", choices=("full", "reduced"), default="full",
                   help="truth plant: full (the rig's full-order FE model) or reduced (the "
                   "8-state identification model) (default full)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=THETA",
                   help="true parameter value, theta in -0.95..0.95, e.g. k_By=0.5 "
                   "(repeatable; default: every parameter 0; names: bayes-amb params)")
    p.add_argument("--effect", action="append", default=[], metavar="NAME[:k=v,...]",
                   help="hidden physics, e.g. actuator_lag:bandwidth_hz=600 (repeatable; "
                   "default none). Effects and parameters (default, allowed): "
                   + "; ".join(describe_effects()))
    p.add_argument("--excitation", choices=EXCITATIONS, default="random-binary",
                   help=f"excitation signal, one of {', '.join(EXCITATIONS)} "
                   "(default random-binary)")
    p.add_argument("--amplitude", type=real(0, lo_open=True, unit="A"), default=0.5,
                   metavar="A", help="excitation amplitude, A, > 0 (default 0.5, about 10 %% "
                   "of a 5 A saturation current)")
    p.add_argument("--port", choices=("eta", "r2"), default=None,
                   help="where the excitation enters: eta (the Youla port of an "
                   "observer-based controller, column group eta_*) or r2 (added to the coil "
                   "current after the controller, any controller, column group r2_*; the "
                   "recorded u_* includes it) (default: eta for an observer controller, r2 "
                   "otherwise)")
    p.add_argument("--band", default=None, metavar="LO,HI", help="multisine band, Hz, "
                   "0 < LO < HI <= Nyquist (default 5 Hz to min(1 kHz, 0.8 Nyquist)); a "
                   "narrow band informs only a combination of parameters")
    p.add_argument("--channels", default=None, metavar="CH,...",
                   help="excited channels, e.g. Bx or Ax,By (default: all four)")
    p.add_argument("--r1-rms", type=real(0, unit="m"), default=0.0, metavar="M",
                   help="sensor-side disturbance r1, RMS in m, >= 0 (default 0)")
    p.add_argument("--r2-rms", type=real(0, unit="A"), default=0.0, metavar="A",
                   help="actuator-side disturbance r2 (unknown, not recorded, not in u_*), "
                   "RMS in A, >= 0 (default 0)")
    p.add_argument("--r1-band-hz", type=real(0, lo_open=True, unit="Hz"), default=None,
                   metavar="HZ", help="low-pass band of r1, Hz, > 0 (default: white)")
    p.add_argument("--r2-band-hz", type=real(0, lo_open=True, unit="Hz"), default=None,
                   metavar="HZ", help="low-pass band of r2, Hz, > 0 (default: white)")
    p.add_argument("--noise-rms", type=real(0, unit="m"), default=0.0, metavar="M",
                   help="sensor noise RMS, m, >= 0 (default 0)")
    p.add_argument("--duration", type=real(0, 600, lo_open=True, unit="s"), default=0.5,
                   metavar="S", help="record length, s, > 0 and <= 600 (default 0.5)")
    p.add_argument("--dt", type=real(0, 0.01, lo_open=True, unit="s"), default=1e-4,
                   metavar="S", help="sample time, s, > 0 and <= 0.01 (default 1e-4)")
    p.add_argument("--speed-rpm", type=real(0, unit="rpm"), default=None, metavar="RPM",
                   help="rotor speed, rpm, 0..2 x the rig's nominal speed (default: nominal, "
                   "31500 on the reference rig)")
    p.add_argument("--seed", type=seed, default=0, help="random seed, 0..4294967295 "
                   "(default 0)")
    p.add_argument("-o", "--output", required=True, metavar="NAME.csv",
                   help="recording to write: NAME.csv and its sidecar NAME.json (required)")
    p.add_argument("--json", action="store_true", help="print JSON (default: text)")
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
    cfg = SimulationConfig(truth=args.truth, params=parse_assignments(args.set),
                           effects=tuple(parse_effect(e) for e in args.effect),
                           excitation=args.excitation, amplitude=args.amplitude,
                           excitation_band_hz=parse_band(args.band),
                           noise_rms=args.noise_rms, r1_rms=args.r1_rms, r2_rms=args.r2_rms,
                           r1_band_hz=args.r1_band_hz, r2_band_hz=args.r2_band_hz,
                           duration=args.duration, dt=args.dt, speed_rpm=args.speed_rpm,
                           seed=args.seed, port=args.port,
                           channels=(None if args.channels is None else
                                     tuple(c.strip() for c in args.channels.split(","))))
    cfg.validate()                          # the options first, before any expensive work
    rig = load_rig(args.rig)
    if args.controller:
        ctrl = load_controller(args.controller)
    else:
        ctrl = export_controller(reference_controller(rig, args.dt, args.speed_rpm), rig)
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
