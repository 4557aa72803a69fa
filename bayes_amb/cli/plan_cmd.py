"""`bayes-amb plan`: the posterior sd a test will give, before it is run (issue 30)."""

from __future__ import annotations

import argparse

import numpy as np

from bayes_amb.cli.common import emit
from bayes_amb.cli.options import real, seed
from bayes_amb.cli.simulate_cmd import parse_assignments, parse_band
from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.errors import BayesAmbError
from bayes_amb.io.controller_file import load_controller
from bayes_amb.io.recording import load_recording
from bayes_amb.planning import Design, Noise, plan
from bayes_amb.planning.optimise import optimise
from bayes_amb.planning.plan import BEARING_COEFFICIENTS, recorded
from bayes_amb.rig import load_rig
from bayes_amb.simulate import EXCITATIONS
from bayes_amb.uncertainty import parse_param_list


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("plan", help="predict what a test will tell before it is run",
                       description="Predict the posterior sd that identify will report on a "
                       "record of the given design, from the Fisher information of its "
                       "likelihood (first order; seconds, no study). The noise is given "
                       "(--noise-rms, --r1-rms, --r2-rms and their bands) or fitted on an "
                       "earlier recording (--noise-from, which also gives the rig, "
                       "controller and speed).")
    p.add_argument("--rig", default=None, metavar="FILE",
                   help="rig TOML file (default: the reference rig)")
    p.add_argument("--controller", default=None, metavar="FILE", help="controller JSON "
                   "(default: the reference controller designed for the rig and --dt)")
    p.add_argument("--initial-state", action=argparse.BooleanOptionalAction, default=None,
                   help="with --noise-from: fit that record's start transient, or not, as "
                   "identify does (default: as identify decides, fitted when the record "
                   "starts mid-operation)")
    p.add_argument("--noise-from", default=None, metavar="REC.csv",
                   help="take the noise, rig, controller and speed from an earlier recording "
                   "(the noise intensities identify fits on it and the colour of its "
                   "residual), and plan at identify's estimate on it (--set overrides) "
                   "(default: none, the noise options are used)")
    p.add_argument("--excitation", choices=EXCITATIONS, default="random-binary",
                   help=f"excitation signal, one of {', '.join(EXCITATIONS)} "
                   "(default random-binary)")
    p.add_argument("--amplitude", type=real(0, lo_open=True, unit="A"), default=0.5,
                   metavar="A", help="excitation amplitude, A (default 0.5)")
    p.add_argument("--band", default=None, metavar="LO,HI",
                   help="multisine band, Hz (default 5 Hz to min(1 kHz, 0.8 Nyquist))")
    p.add_argument("--channels", default=None, metavar="CH,...",
                   help="excited channels, e.g. Bx or Ax,By (default: all four)")
    p.add_argument("--duration", type=real(0, 600, lo_open=True, unit="s"), default=2.0,
                   metavar="S", help="record length, s (default 2)")
    p.add_argument("--dt", type=real(0, 0.01, lo_open=True, unit="s"), default=1e-4,
                   metavar="S", help="sample time, s (default 1e-4)")
    p.add_argument("--port", choices=("eta", "r2"), default=None,
                   help="where the excitation enters (default: eta for an observer "
                   "controller, r2 otherwise)")
    p.add_argument("--noise-rms", type=real(0, unit="m"), default=5e-8, metavar="M",
                   help="sensor noise RMS, m (default 5e-8)")
    p.add_argument("--r1-rms", type=real(0, unit="m"), default=0.0, metavar="M",
                   help="sensor-side disturbance RMS, m (default 0)")
    p.add_argument("--r2-rms", type=real(0, unit="A"), default=0.0, metavar="A",
                   help="actuator-side (force) disturbance RMS, A (default 0)")
    p.add_argument("--r1-band-hz", type=real(0, lo_open=True, unit="Hz"), default=None,
                   metavar="HZ", help="low-pass band of r1, Hz (default: white)")
    p.add_argument("--r2-band-hz", type=real(0, lo_open=True, unit="Hz"), default=None,
                   metavar="HZ", help="low-pass band of r2, Hz (default: white)")
    p.add_argument("--params", default=None, metavar="NAMES",
                   help="parameters, comma-separated (default: the eight bearing "
                   "coefficients)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=THETA",
                   help="parameter value the prediction is made at (default 0: nominal; with "
                   "--noise-from: identify's estimate on that record)")
    p.add_argument("--speed-rpm", type=real(0, unit="rpm"), default=None, metavar="RPM",
                   help="rotor speed, rpm (default: the rig's nominal)")
    p.add_argument("--target", action="append", default=[], metavar="NAME=SD",
                   help="target posterior sd in theta units, e.g. k_By=0.005 (repeatable): "
                   "find the shortest design that reaches every target within the rig "
                   "file's [limits] (excitation kind, band and channels; --amplitude is the "
                   "amplitude used) (default: none, predict the given design)")
    p.add_argument("--effect", action="append", default=[], metavar="NAME[:k=v,...]",
                   help="a hidden effect whose detectability to predict, as simulate "
                   "takes it, e.g. actuator_lag:bandwidth_hz=2000 (repeatable; of "
                   "actuator_lag, time_delay, cross_coupling, sensor_gain) (default: none)")
    p.add_argument("--smallest", action="store_true",
                   help="with --effect: also search the weakest detectable size (about 15 s "
                   "per effect) (default: off)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="also write DIR/plan.json and DIR/plan.html (the design, the "
                   "prediction, sd against length and amplitude) (default: none)")
    p.add_argument("--seed", type=seed, default=0, help="seed of the design's excitation "
                   "(default 0)")
    p.add_argument("--json", action="store_true", help="print JSON (default: a table)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    design = Design(excitation=args.excitation, amplitude=args.amplitude,
                    band_hz=parse_band(args.band),
                    channels=(None if args.channels is None else
                              tuple(c.strip() for c in args.channels.split(","))),
                    duration=args.duration, dt=args.dt, port=args.port)
    speed = args.speed_rpm
    estimate: dict[str, float] = {}
    if args.noise_from:
        rec = load_recording(args.noise_from)
        noise, estimate = recorded(rec, args.initial_state)
        rig, ctrl = rec.rig, rec.controller
        speed = rec.speed_rpm if speed is None else speed
        design = Design(**{**design.__dict__, "dt": rec.dt})
    else:
        rig = load_rig(args.rig)
        ctrl = (load_controller(args.controller) if args.controller else
                export_controller(reference_controller(rig, args.dt, speed), rig))
        noise = Noise(noise_rms=args.noise_rms, r1_rms=args.r1_rms, r2_rms=args.r2_rms,
                      r1_band_hz=args.r1_band_hz, r2_band_hz=args.r2_band_hz)
    if args.target:
        return _optimise(args, rig, ctrl, design, noise, speed)
    planned = parse_param_list(",".join(BEARING_COEFFICIENTS) if args.params is None
                               else args.params)
    at = {**{k: v for k, v in estimate.items() if k in planned},
          **parse_assignments(args.set)}    # --noise-from: at that record's estimate
    result = plan(rig, ctrl, design, noise, args.params, at, speed, seed=args.seed)
    d = result.to_dict()
    extra = ""
    if args.effect:
        d["detectability"] = _detect(args, rig, ctrl, design, noise, speed,
                                     tuple(result.parameters))
        extra = "\n" + "\n".join(_detect_line(r) for r in d["detectability"])
    head = (f"plan: {design.excitation} {design.amplitude:g} A on "
            f"{','.join(design.channels or ('Ax', 'Ay', 'Bx', 'By'))}, {design.duration:g} s "
            f"at dt {design.dt:g} s; noise {noise.noise_rms:.3g} m, r1 {noise.r1_rms:.3g} m, "
            f"r2 {noise.r2_rms:.3g} A; predicted posterior sd (first order, "
            f"{result.n_bins} bins up to {result.f_max_hz:.0f} Hz):")
    if args.out:
        from bayes_amb.planning.page import write_plan_page
        extra += f"\nwrote {write_plan_page(args.out, d)}"
    emit(d, head + "\n" + result.table() + extra, args.json)
    return 0


def _detect(args: argparse.Namespace, rig, ctrl, design: Design, noise: Noise,
            speed: float | None, params: tuple[str, ...]) -> list[dict]:
    from bayes_amb.planning.detect import detectability, smallest_detectable
    from bayes_amb.simulate.effects import parse_effect
    out = []
    for text in args.effect:
        e = parse_effect(text)
        if args.smallest:
            out.append(smallest_detectable(rig, ctrl, design, noise, e, params,
                                           speed_rpm=speed, seed=args.seed))
        else:
            out.append(detectability(rig, ctrl, design, noise, e, params, speed_rpm=speed,
                                     seed=args.seed))
    return out


def _detect_line(r: dict) -> str:
    size = ", ".join(f"{k}={v:g}" for k, v in r["params"].items() if isinstance(v, float))
    line = (f"{r['effect']} ({size}): expected log Bayes factor "
            f"{r['expected_log_bayes_factor']:.1f} +- {r['scatter_of_log_bf']:.1f}, log "
            f"posterior odds {r['expected_log_posterior_odds']:.1f} (threshold "
            f"{r['threshold']:g}): {'detected' if r['detected'] else 'NOT detected'} "
            f"(probability {r['probability_detected']:.2f})")
    if "smallest_detectable" in r:
        sm = r["smallest_detectable"]
        line += ("; " + r.get("note", "") if sm is None else
                 "; weakest detectable: " + ", ".join(f"{k}={v:.3g}" for k, v in sm.items()))
    return line


def _optimise(args: argparse.Namespace, rig, ctrl, design: Design, noise: Noise,
              speed: float | None) -> int:
    targets = parse_targets(args.target)
    o = optimise(rig, ctrl, targets, noise, design, speed, seed=args.seed)
    d = o.design
    def band_of(r):
        return "-" if r["band_hz"] is None else f"{r['band_hz'][0]:g}-{r['band_hz'][1]:g} Hz"

    rows = [f"  {r['excitation']:<13} {band_of(r):<15} "
            f"{','.join(r['channels']):<12} {r['duration_s']:>8.2f} s  "
            f"peak {r['peak_current_a']:.2f} A, {r['peak_displacement_m'] * 1e6:.1f} um"
            + (f"  REFUSED: {r['refused']}" if r["refused"] else "") for r in o.candidates]
    goal = ", ".join(f"{k} sd {v:g}" for k, v in targets.items())
    band = "" if d.band_hz is None else f" band {d.band_hz[0]:g}-{d.band_hz[1]:g} Hz"
    text = (f"plan: the shortest design reaching {goal}: {d.excitation}{band}"
            f" {d.amplitude:g} A on {','.join(d.channels or ('Ax', 'Ay', 'Bx', 'By'))}, "
            f"{d.duration:g} s (the default random binary needs {o.default_s:.2f} s: "
            f"{o.gain:.1f}x longer)\n{o.plan.table()}\ncandidates (length that reaches the "
            "targets):\n" + "\n".join(rows))
    if args.out:
        from bayes_amb.planning.page import write_plan_page
        text += f"\nwrote {write_plan_page(args.out, o.plan.to_dict(), o.to_dict())}"
    emit(o.to_dict(), text, args.json)
    return 0


def parse_targets(items: list[str]) -> dict[str, float]:
    """['k_By=0.005'] -> {'k_By': 0.005}."""
    out = {}
    for it in items:
        name, eq, val = it.partition("=")
        try:
            out[name.strip()] = float(val) if eq else float("nan")
        except ValueError:
            out[name.strip()] = float("nan")
        if not eq or not np.isfinite(out[name.strip()]):
            raise BayesAmbError(f"option --target: expected NAME=SD with a number, got {it!r}")
    return out
