"""Benchmark cases: what is simulated (CaseSpec), drawn at random, run and written.

Bearing coefficients: all eight are off nominal in every drawn case, with the tool's own
parameter meaning: k_<axis> = theta in [-0.3, 0.3] (ks_true = (1 - theta) ks) and a
viscous damping c in [0, 300] N s/m per axis (theta c_<axis> = c / c_ref, c_ref = 1000).

Concealment of an effect: rms over channels and samples of (y_with - y_without), both
noise-free (eta only, no habits, start at rest, same bearings), divided by the sensor-noise
rms. Drawn effects are scaled (physically: bandwidth, delay, gain, kxy, unbalance, runout,
housing mass) until it lies in [0.2, 1): hidden below the noise of the raw y, yet not
vanishingly small. The value is kept in the truth.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bayes_amb.rig import Rig, load_rig
from tests.foreign.effects import EFFECT_PARAMS, HELD_OUT, Effect, build_plant
from tests.foreign.habits import Habits, draw_habits, habit_signals
from tests.foreign.loop import Controller, closed_loop, read_controller, run
from tests.foreign.plant import AXES, bearing_changes, rotor
from tests.foreign.write import write_recording

IN_FAMILY = tuple(n for n in EFFECT_PARAMS if n not in HELD_OUT)
"""Single effects the benchmark draws as kinds (besides 'control', 'pair', 'held_out',
'full_truth' and 'bending')."""

KINDS = ("control", *IN_FAMILY, "pair", "held_out", "full_truth", "bending")


@dataclass(frozen=True)
class CaseSpec:
    """Everything a foreign recording is made of (SI units).

    kind: the case kind (see KINDS); truth: 'reduced' or 'full'; n_bending: bending pairs
    kept in a reduced truth; static_correction: a reduced truth keeps the quasi-static
    deflection of the modes it leaves out (mode-acceleration method); speed_rpm: the
    nominal speed written in the sidecar;
    speed_rpm_true: the speed the rotor really runs at (gyroscopics, unbalance, runout);
    k_theta: ks reduction per axis (-); c_nsm: added damping per axis (N s/m); effects;
    habits; dt (s), duration_s (s, recorded part); controller_file: path of the controller
    JSON (may also be given to write_case).
    """

    kind: str = "control"
    truth: str = "reduced"
    n_bending: int = 0
    static_correction: bool = False
    speed_rpm: float = 31500.0
    speed_rpm_true: float = 31500.0
    k_theta: dict[str, float] = field(default_factory=lambda: dict.fromkeys(AXES, 0.0))
    c_nsm: dict[str, float] = field(default_factory=lambda: dict.fromkeys(AXES, 0.0))
    effects: tuple[Effect, ...] = ()
    habits: Habits = field(default_factory=Habits)
    dt: float = 1e-4
    duration_s: float = 2.0
    controller_file: str | None = None

    def theta(self, c_ref: float = 1000.0) -> dict[str, float]:
        """The tool's parameters: k_<axis> = theta, c_<axis> = c / c_ref."""
        return {**{f"k_{a}": self.k_theta[a] for a in AXES},
                **{f"c_{a}": self.c_nsm[a] / c_ref for a in AXES}}


@dataclass(frozen=True)
class Simulated:
    """A simulated record (recorded part only): y_m (N, 4) m, u (N, 4) A, eta (N, 4) A,
    eps (N, 4) m (the controller's innovation output), noise (N, 4) m, draws (dict)."""

    y: NDArray
    u: NDArray
    eta: NDArray
    eps: NDArray
    noise: NDArray
    draws: dict[str, Any]


def _controller(spec: CaseSpec, controller: Controller | str | os.PathLike | None
                ) -> Controller:
    if isinstance(controller, Controller):
        return controller
    src = controller if controller is not None else spec.controller_file
    if src is None:
        raise ValueError("no controller: give the file made by "
                         "`bayes-amb controller --dt 1e-4 --export FILE`")
    return read_controller(src)


def plant_of(spec: CaseSpec, rig: Rig, effects: tuple[Effect, ...] | None = None,
             truth: str | None = None):
    """The continuous plant of a case (optionally with other effects or another truth)."""
    R = rotor(rig, spec.speed_rpm_true, truth or spec.truth, spec.n_bending,
              spec.static_correction)
    R = bearing_changes(R, rig, spec.k_theta, spec.c_nsm)
    return build_plant(R, rig, spec.effects if effects is None else effects,
                       spec.speed_rpm_true, spec.k_theta)


def simulate(spec: CaseSpec, controller: Controller | str | None, rng: np.random.Generator,
             rig: Rig | None = None) -> Simulated:
    """Run a case: burn-in with everything running, then the recorded part."""
    rig = rig or load_rig()
    ctrl = _controller(spec, controller)
    if abs(ctrl.dt - spec.dt) > 1e-12 * spec.dt:
        raise ValueError(f"controller dt {ctrl.dt} differs from the case dt {spec.dt}")
    plant = plant_of(spec, rig)
    cl = closed_loop(plant, ctrl)
    n_rec = round(spec.duration_s / spec.dt)
    n_burn = round(spec.habits.burn_in_s / spec.dt)
    sig, draws = habit_signals(spec.habits, n_burn + n_rec, spec.dt, rng, -n_burn * spec.dt)
    e = np.hstack([sig["eta"], sig["w_add"], sig["m"]])
    # the simulation starts at t = -burn-in: the record starts at t = 0, where the line
    # phases of the truth refer; the first state is sampled sensor_delay_s earlier still
    x0 = plant.state_at(-n_burn * spec.dt - plant.sensor_delay_s)
    y, u, eps, _ = run(cl, e, cl.initial_state(x0))
    keep = slice(n_burn, None)
    draws["burn_in_samples"] = n_burn
    return Simulated(y[keep], u[keep], sig["eta"][keep], eps[keep], sig["noise"][keep], draws)


def clean_response(spec: CaseSpec, ctrl: Controller, eta: NDArray, rig: Rig,
                   effects: tuple[Effect, ...], truth: str | None = None) -> NDArray:
    """Noise-free y (N, 4) from rest with eta only (no habits) for a set of effects."""
    plant = plant_of(spec, rig, effects, truth)
    cl = closed_loop(plant, ctrl)
    z = np.zeros_like(eta)
    x0 = plant.state_at(-plant.sensor_delay_s)
    y, _, _, _ = run(cl, np.hstack([eta, z, z]), cl.initial_state(x0))
    return y


def concealment(spec: CaseSpec, ctrl: Controller, eta: NDArray, rig: Rig,
                effects: tuple[Effect, ...], truth: str | None = None,
                base: NDArray | None = None) -> float:
    """rms(y_with - y_without) / noise rms (noise-free responses, see module doc).

    ``truth`` overrides the truth of the 'with' run (the 'without' run is the reduced
    nominal family without effects); ``base`` a precomputed 'without' response.
    """
    if base is None:
        base = clean_response(replace(spec, truth="reduced", n_bending=0,
                                      static_correction=False), ctrl, eta, rig, ())
    y = clean_response(spec, ctrl, eta, rig, effects, truth)
    return float(np.sqrt(np.mean((y - base) ** 2)) / spec.habits.noise_rms_m)


# ------------------------------------------------------------------- drawing
_WHERE = ("A", "B", "all")


def _draw_effect(name: str, rng: np.random.Generator, noise: float) -> Effect:
    """A first draw of one effect (scaled later by :func:`conceal`)."""
    u = rng.uniform
    if name == "actuator_lag":
        p = {"bandwidth_hz": u(300, 2000), "where": str(rng.choice(_WHERE))}
    elif name == "actuator_2nd":
        p = {"natural_hz": u(600, 2500), "zeta": u(0.4, 0.9), "where": str(rng.choice(_WHERE))}
    elif name == "sensor_lag":
        p = {"bandwidth_hz": u(500, 3000), "where": str(rng.choice(_WHERE))}
    elif name in ("actuator_delay", "sensor_delay"):
        p = {"delay_s": u(0.2e-4, 2.5e-4)}
    elif name == "actuator_gain":
        p = {"axis": str(rng.choice(AXES)), "gain": float(rng.choice([-1, 1]) * u(0.03, 0.15))}
    elif name == "sensor_gain":
        p = {"channel": str(rng.choice(AXES)), "gain": float(rng.choice([-1, 1]) * u(0.02, 0.1))}
    elif name == "cross_coupling":
        p = {"where": str(rng.choice(["A", "B", "D1", "D2"])), "kxy_nm": u(2e4, 1e5)}
    elif name == "unbalance":
        n_planes = int(rng.integers(1, 3))
        nodes = rng.choice(np.arange(1, 41), size=n_planes, replace=False)
        p = {"planes": [{"node": int(nd), "u_kgm": u(5e-6, 5e-5), "phase_rad": u(0, 2 * np.pi)}
                        for nd in nodes]}
    elif name == "runout":
        p = {"channel": str(rng.choice(AXES)), "amplitude_m": u(0.5, 3.0) * noise,
             "phase_rad": u(0, 2 * np.pi)}
    elif name == "pedestal":
        p = {"bearing": "A", "mass_kg": u(40.0, 150.0), "natural_hz": u(150.0, 400.0),
             "zeta": u(0.02, 0.05)}
    else:
        raise ValueError(f"unknown effect {name!r}")
    return Effect(name, {k: (float(v) if isinstance(v, np.floating) else v)
                         for k, v in p.items()})


def _weaker(e: Effect, f: float = 0.7) -> Effect:
    """The same effect made weaker by a factor f (physical direction of 'weaker');
    f > 1 makes it stronger."""
    p = dict(e.params)
    if e.name in ("actuator_lag", "sensor_lag"):
        p["bandwidth_hz"] /= f
    elif e.name == "actuator_2nd":
        p["natural_hz"] /= f
    elif e.name in ("actuator_delay", "sensor_delay"):
        p["delay_s"] *= f
    elif e.name in ("actuator_gain", "sensor_gain"):
        p["gain"] *= f
    elif e.name == "cross_coupling":
        p["kxy_nm"] *= f
    elif e.name == "unbalance":
        p["planes"] = [{**q, "u_kgm": q["u_kgm"] * f} for q in p["planes"]]
    elif e.name == "runout":
        p["amplitude_m"] *= f
    elif e.name == "pedestal":
        p["mass_kg"] /= f
    return Effect(e.name, p)


def draw_case(kind: str, rng: np.random.Generator, *, controller_file: str | None = None,
              duration_s: float = 2.0, dt: float = 1e-4, noise_rms_m: float = 5e-8,
              habits: bool = True) -> CaseSpec:
    """Draw a case of a kind (KINDS, or 'pair:<a>+<b>'): bearings off nominal, habits drawn,
    effects drawn at a first guess (scaled to concealment in [0.2, 1) by :func:`conceal`)."""
    k_theta = {a: float(rng.uniform(-0.3, 0.3)) for a in AXES}
    c_nsm = {a: float(rng.uniform(0.0, 300.0)) for a in AXES}
    hab = draw_habits(rng, noise_rms_m) if habits else Habits(noise_rms_m=noise_rms_m)
    truth, n_bending, effects = "reduced", 0, ()
    if kind == "control":
        pass
    elif kind in IN_FAMILY:
        effects = (_draw_effect(kind, rng, noise_rms_m),)
    elif kind == "pair" or kind.startswith("pair:"):
        names = (kind[5:].split("+") if ":" in kind
                 else list(rng.choice(IN_FAMILY, size=2, replace=False)))
        effects = tuple(_draw_effect(str(n), rng, noise_rms_m) for n in names)
    elif kind == "held_out":
        effects = (_draw_effect("pedestal", rng, noise_rms_m),)
    elif kind == "full_truth":
        truth = "full"
    elif kind == "bending":
        n_bending = int(rng.integers(1, 3))
    else:
        raise ValueError(f"unknown case kind {kind!r}; known: {KINDS} or 'pair:<a>+<b>'")
    speed = 31500.0
    lines = any(e.name in ("unbalance", "runout") for e in effects)
    speed_true = speed * (1.0 + rng.uniform(-0.005, 0.005)) if lines else speed
    return CaseSpec(kind=kind, truth=truth, n_bending=n_bending, speed_rpm=speed,
                    speed_rpm_true=float(speed_true), k_theta=k_theta, c_nsm=c_nsm,
                    effects=effects, habits=hab, dt=dt, duration_s=duration_s,
                    controller_file=controller_file)


def conceal(spec: CaseSpec, ctrl: Controller, rng: np.random.Generator, rig: Rig,
            band: tuple[float, float] = (0.2, 1.0), max_tries: int = 40
            ) -> tuple[CaseSpec, dict[str, float]]:
    """Bring each effect's concealment into ``band`` (default [0.2, 1)): weaken it by steps
    of 0.7 while it is >= band[1]; if its first draw is below band[0], strengthen it by
    1/0.7 while the stronger version stays below band[1]. Returns the case and the
    concealments per effect (index:name), of all effects together ('all') and of the
    flexible modes of a full or bending truth ('flexible', never changed)."""
    n = round(spec.duration_s / spec.dt)
    eta = spec.habits.eta_amplitude_a * rng.choice([-1.0, 1.0], size=(n, 4))
    base = clean_response(replace(spec, truth="reduced", n_bending=0, static_correction=False,
                                  effects=()), ctrl, eta,
                          rig, ())
    out: dict[str, float] = {}
    effects = list(spec.effects)
    ref = replace(spec, truth="reduced", n_bending=0, static_correction=False)

    def conc(e: Effect) -> float:
        c = concealment(ref, ctrl, eta, rig, (e,), base=base)
        return c if np.isfinite(c) else np.inf

    for i, e in enumerate(effects):
        c = conc(e)
        for _ in range(max_tries):
            if c < band[1]:
                break
            e = _weaker(e)
            c = conc(e)
        for _ in range(max_tries if c < band[0] else 0):
            stronger = _weaker(e, 1 / 0.7)
            c_s = conc(stronger)
            if c_s >= band[1]:
                break
            e, c = stronger, c_s
            if c >= band[0]:
                break
        effects[i] = e
        out[f"{i}:{e.name}"] = c
    spec = replace(spec, effects=tuple(effects))
    if spec.truth == "full" or spec.n_bending or spec.static_correction:
        out["flexible"] = concealment(spec, ctrl, eta, rig, (), base=base)
    out["all"] = concealment(spec, ctrl, eta, rig, spec.effects, base=base)
    return spec, out


def truth_record(spec: CaseSpec, rig: Rig, concealments: dict[str, float],
                 draws: dict[str, Any]) -> dict[str, Any]:
    """The truth file's content (see README.md of this package for the keys)."""
    return {
        "format": "foreign-truth/1",
        "kind": spec.kind,
        "truth": spec.truth,
        "n_bending": spec.n_bending,
        "static_correction": spec.static_correction,
        "speed_rpm": spec.speed_rpm,
        "speed_rpm_true": spec.speed_rpm_true,
        "dt": spec.dt,
        "duration_s": spec.duration_s,
        "theta": spec.theta(rig.c_ref),
        "bearings": {a: {"ks_n_per_m": (1 - spec.k_theta[a]) * rig.ks,
                         "c_ns_per_m": spec.c_nsm[a]} for a in AXES},
        "effects": [{"name": e.name, "params": e.params} for e in spec.effects],
        "held_out": [e.name for e in spec.effects if e.name in HELD_OUT],
        "habits": spec.habits.to_dict(),
        "draws": draws,
        "concealment": concealments,
        "noise_rms_m": spec.habits.noise_rms_m,
    }


def write_case(spec: CaseSpec, out_dir: str | os.PathLike, name: str,
               rng: np.random.Generator, *, controller: Controller | str | None = None,
               conceal_effects: bool = True) -> dict[str, Path]:
    """Conceal (unless told not to), simulate and write NAME.csv, NAME.json and
    NAME.truth.json into out_dir; returns the paths ('csv', 'json', 'truth')."""
    rig = load_rig()
    ctrl = _controller(spec, controller)
    conc: dict[str, float] = {}
    if conceal_effects and (spec.effects or spec.truth == "full" or spec.n_bending
                            or spec.static_correction):
        spec, conc = conceal(spec, ctrl, rng, rig)
    sim = simulate(spec, ctrl, rng, rig)
    truth = truth_record(spec, rig, conc, sim.draws)
    return write_recording(Path(out_dir) / name, spec.dt, sim.y, sim.u, sim.eta,
                           spec.speed_rpm, ctrl.raw,
                           notes=f"foreign generator, case kind {spec.kind}", truth=truth)


def write_suite(out_dir: str | os.PathLike, kinds: dict[str, int], seed: int,
                controller_file: str, **draw: Any) -> list[dict[str, Any]]:
    """Write a benchmark suite: ``kinds`` maps a kind to how many recordings. Names are
    ``<kind>_<i>`` (':' and '+' replaced by '_'); an ``index.json`` lists every recording
    with its kind, paths, effects and concealment. ``draw`` goes to :func:`draw_case`
    (e.g. duration_s). Each recording has its own rng, spawned from ``seed``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ctrl = read_controller(controller_file)
    seeds = np.random.SeedSequence(seed).spawn(sum(kinds.values()))
    index, i = [], 0
    for kind, count in kinds.items():
        for j in range(count):
            rng = np.random.default_rng(seeds[i])
            i += 1
            name = f"{kind.replace(':', '_').replace('+', '_')}_{j:03d}"
            spec = draw_case(kind, rng, controller_file=str(controller_file), **draw)
            paths = write_case(spec, out, name, rng, controller=ctrl)
            truth = json.loads(paths["truth"].read_text())
            index.append({"name": name, "kind": kind, "csv": paths["csv"].name,
                          "truth": paths["truth"].name, "effects": truth["effects"],
                          "concealment": truth["concealment"]})
    (out / "index.json").write_text(json.dumps(index, indent=1))
    return index
