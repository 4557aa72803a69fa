"""Foreign recordings on ROSS's model of the real AMB test rig (the "real rotors" issue).

The plant is ROSS's own rotor (:mod:`benchmarks.foreign.ross_plant`: ROSS's M, K, C, G of
the full lateral FE model, 424 states, the magnets' ki and ks, ROSS's two bearing
controllers with their doubled constant taken out, discretised here by Tustin), run in the
foreign generator's exact sampled loop (:mod:`benchmarks.foreign.loop`) with its record
habits (:mod:`benchmarks.foreign.habits`). Written apart from the product: nothing of
bayes_amb.simulate, .discrepancy, .reduction, .uncertainty, .inference or .control, and not
bayes_amb.io either (the recording and the controller file are written here, in the
documented format).

Every record: the eight bearing coefficients as the product defines them, k_<axis> = theta
(ks_true = (1 - theta) ks of that axis' bearing) uniform in K_RANGE and c_<axis> = theta
(added viscous damping theta c_ref at the bearing node, c_ref the rig file's 1000 N s/m)
uniform in C_RANGE; the excitation r2 at the plant input, random binary +/- R2_AMPLITUDE_A
per channel and sample, recorded in the r2_* columns and included in u_* (u = K(y) + r2,
y the recorded displacements the controller saw: noise, offsets, drift, mains lines and r1
included); the habits of :func:`benchmarks.foreign.habits.draw_habits` (50 nm AR(1) or pink
sensor noise, offsets, drift, amplifier offset, 50/150 Hz lines, small unrecorded r1/r2, a
0.2-0.5 s burn-in), the amplifier offset and unrecorded r2 added after the recorded u.

Families (FAMILIES; HELD_OUT is not in the product's diagnosis library, do not tune to it):

- ``control``: the coefficients only;
- ``actuator_lag``: first-order amplifier lag, bandwidth uniform in LAG_HZ, on bearing A, B
  or all four channels;
- ``unbalance``: u Omega^2 at the central disc D1 (node 29), synchronous at 3000 rpm,
  random phase, u_kgm sized so that the 1x line at the larger probe is UNBALANCE_OVER_NOISE
  times the sensor-noise rms (the steady-state line of the case's own closed loop);
- ``probe_angle`` (held out): one bearing's probe pair turned by +/- ANGLE_DEG against the
  actuator axes (linear: the probes see R(a) [q_x, q_y]).

    PYTHONPATH=. .venv/bin/python -m benchmarks.foreign.ross_rig --out DIR \\
        --kinds control=3,actuator_lag=3,unbalance=3,probe_angle=2 --duration 1 --seed 1
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from benchmarks.foreign import ross_plant as rp
from benchmarks.foreign.effects import Effect
from benchmarks.foreign.habits import Habits, draw_habits, habit_signals
from benchmarks.foreign.loop import ClosedLoop, closed_loop, read_controller, run
from benchmarks.foreign.write import _plain

FAMILIES = ("control", "actuator_lag", "unbalance", "probe_angle")
HELD_OUT = ("probe_angle",)
K_RANGE = (-0.2, 0.2)
C_RANGE = (0.0, 0.3)
R2_AMPLITUDE_A = 0.05
"""5 % of the 1 A bias: peak control currents about 0.1 A, rotor excursions up to about
6 um at the probes (1.4 % of the 0.432 mm gap), y 20-40 x the noise rms."""
LAG_HZ = (300.0, 1500.0)
UNBALANCE_OVER_NOISE = (3.0, 10.0)
ANGLE_DEG = (1.0, 5.0)
UNBALANCE_DISC = "D1"
DEFAULT_KINDS = {"control": 3, "actuator_lag": 3, "unbalance": 3, "probe_angle": 2}
AXES = rp.AXES


def one_thread() -> contextlib.AbstractContextManager:
    """BLAS single-threaded (a 460-state loop is 20-50 x slower with threads contending on
    a loaded machine); a no-op without threadpoolctl."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:            # pragma: no cover
        return contextlib.nullcontext()
    return threadpool_limits(limits=1)


@dataclass(frozen=True)
class RigCase:
    """A record to simulate (SI): family ``kind``; ``k_theta``, ``c_theta`` the eight
    coefficients in the product's units (c_nsm = c_theta c_ref); effects; habits (its
    ``eta_amplitude_a`` is the r2 excitation amplitude, A); the controller's discretisation
    ``method`` and ``scale``."""

    kind: str
    k_theta: dict[str, float]
    c_theta: dict[str, float]
    effects: tuple[Effect, ...] = ()
    habits: Habits = field(default_factory=Habits)
    dt: float = 1e-4
    duration_s: float = 1.0
    speed_rpm: float = rp.SPEED_RPM
    method: str = "tustin"
    scale: dict[str, float] = field(default_factory=lambda: dict(rp.SCALE))

    def theta(self) -> dict[str, float]:
        return {**{f"k_{a}": self.k_theta[a] for a in AXES},
                **{f"c_{a}": self.c_theta[a] for a in AXES}}


@dataclass
class World:
    """ROSS's rotor, the rig file and the controller files (by method), built once."""

    rr: rp.RossRig
    rig: Any
    controllers: dict[tuple, dict[str, Any]] = field(default_factory=dict)

    def controller(self, case: RigCase) -> dict[str, Any]:
        key = (case.method, case.dt, tuple(sorted(case.scale.items())))
        if key not in self.controllers:
            self.controllers[key] = rp.controller_file(self.rr, self.rig, case.dt,
                                                       case.method, case.scale)
        return self.controllers[key]

    def loop(self, case: RigCase, effects: tuple[Effect, ...] | None = None
             ) -> tuple[ClosedLoop, Any]:
        c_nsm = {a: case.c_theta[a] * self.rig.c_ref for a in AXES}
        plant = rp.build(self.rr, case.speed_rpm, case.k_theta, c_nsm,
                         case.effects if effects is None else effects)
        return closed_loop(plant, read_controller(self.controller(case))), plant


_WORLD: list[World] = []


def world() -> World:
    if not _WORLD:
        w = World(rp.ross_rig(), rp.rig())
        rp.check_against_rig(w.rr, w.rig)
        _WORLD.append(w)
    return _WORLD[0]


def spectral_radius(cl: ClosedLoop, plant: Any = None) -> float:
    """Largest |eigenvalue| of the sampled loop, an unbalance oscillator left out (it runs
    free on the unit circle; the loop is block triangular with it)."""
    keep = [i for i in range(cl.Acl.shape[0])
            if plant is None or plant.osc < 0 or i not in (plant.osc, plant.osc + 1)]
    return float(np.max(np.abs(np.linalg.eigvals(cl.Acl[np.ix_(keep, keep)]))))


def line_amplitude(cl: ClosedLoop, plant: Any, dt: float) -> NDArray:
    """Steady-state amplitude (m, per channel) of the 1x line at the probes of a plant with
    an unbalance oscillator: the oscillator runs free as Re(w e^{j Omega t}), w = [1, -j],
    and the rest of the loop follows as Re(v z^k), (z I - A_ss) v = A_so w."""
    o = [plant.osc, plant.osc + 1]
    s = [i for i in range(cl.Acl.shape[0]) if i not in o]
    z, w = np.exp(1j * plant.omega * dt), np.array([1.0, -1j])
    A = cl.Acl
    v = np.linalg.solve(z * np.eye(len(s)) - A[np.ix_(s, s)], A[np.ix_(s, o)] @ w)
    return np.abs(cl.Cy[:, s] @ v + cl.Cy[:, o] @ w)


def draw_rig_case(kind: str, rng: np.random.Generator, *, duration_s: float = 1.0,
                  r2_amplitude_a: float = R2_AMPLITUDE_A, noise_rms_m: float = 5e-8,
                  method: str = "tustin", w: World | None = None) -> RigCase:
    """Draw a record of a family (FAMILIES): coefficients, habits, then the effect."""
    if kind not in FAMILIES:
        raise ValueError(f"unknown family {kind!r}; known: {list(FAMILIES)}")
    k_theta = {a: float(rng.uniform(*K_RANGE)) for a in AXES}
    c_theta = {a: float(rng.uniform(*C_RANGE)) for a in AXES}
    habits = replace(draw_habits(rng, noise_rms_m), eta_amplitude_a=float(r2_amplitude_a))
    case = RigCase(kind, k_theta, c_theta, habits=habits, duration_s=float(duration_s),
                   method=method)
    where = ("A", "B", "all")[int(rng.integers(3))]
    if kind == "actuator_lag":
        eff = Effect("actuator_lag", {"bandwidth_hz": float(rng.uniform(*LAG_HZ)),
                                      "where": where})
    elif kind == "unbalance":
        w = w or world()
        node = w.rig.disc(UNBALANCE_DISC).node
        target = float(rng.uniform(*UNBALANCE_OVER_NOISE)) * noise_rms_m
        plane = {"node": node, "u_kgm": 1e-6, "phase_rad": float(rng.uniform(0, 2 * np.pi))}
        cl, plant = w.loop(case, (Effect("unbalance", {"planes": [plane]}),))
        unit = float(np.max(line_amplitude(cl, plant, case.dt)))
        plane["u_kgm"] = 1e-6 * target / unit
        eff = Effect("unbalance", {"planes": [plane]})
    elif kind == "probe_angle":
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        eff = Effect("probe_angle", {"bearing": "AB"[int(rng.integers(2))],
                                     "angle_deg": sign * float(rng.uniform(*ANGLE_DEG))})
    else:
        return case
    return replace(case, effects=(eff,))


def simulate_case(case: RigCase, rng: np.random.Generator, w: World | None = None
                  ) -> dict[str, Any]:
    """Burn-in and record: y (m), u (A: controller output + r2), r2 (A), each (N, 4), the
    draws worth keeping and the loop's spectral radius. ValueError on an unstable loop."""
    w = w or world()
    cl, plant = w.loop(case)
    rho = spectral_radius(cl, plant)
    if rho >= 1.0:
        raise ValueError(f"{case.kind}: the closed loop is unstable (spectral radius {rho})")
    n_burn = round(case.habits.burn_in_s / case.dt)
    n_rec = round(case.duration_s / case.dt)
    sigs, draws = habit_signals(case.habits, n_burn + n_rec, case.dt, rng,
                                t0=-n_burn * case.dt)
    r2 = sigs["eta"]                     # random binary +/- amplitude: the r2 excitation
    e = np.zeros((n_burn + n_rec, 12))
    e[:, 4:8] = r2 + sigs["w_add"]       # amplifier input: excitation, offset, unrecorded r2
    e[:, 8:] = sigs["m"]
    X0 = cl.initial_state(plant.state_at(-n_burn * case.dt))
    y, u, _, _ = run(cl, e, X0)
    k = slice(n_burn, None)
    rec = {"y": y[k], "u": u[k] + r2[k], "r2": r2[k]}
    coil = u[k] + e[k, 4:8]
    draws.update(burn_in_samples=n_burn, spectral_radius=rho,
                 coil_current_rms_a=coil.std(axis=0).tolist(),
                 coil_current_peak_a=np.abs(coil).max(axis=0).tolist(),
                 y_rms_m=rec["y"].std(axis=0).tolist())
    if plant.osc >= 0:
        draws["unbalance_line_m"] = line_amplitude(cl, plant, case.dt).tolist()
    return {**rec, "draws": draws, "spectral_radius": rho}


def effect_change(case: RigCase, r2: NDArray, w: World | None = None) -> float:
    """rms over channels and samples of (y with - y without the effects) / noise rms, both
    noise-free: the record's r2 only, from rest, no habits."""
    w = w or world()
    e = np.zeros((r2.shape[0], 12))
    e[:, 4:8] = r2
    ys = []
    for effects in (case.effects, ()):
        cl, plant = w.loop(case, effects)
        ys.append(run(cl, e, cl.initial_state(plant.x0))[0])
    return float(np.sqrt(np.mean((ys[0] - ys[1]) ** 2)) / case.habits.noise_rms_m)


def truth_block(case: RigCase, sim: dict[str, Any], w: World, change: float | None
                ) -> dict[str, Any]:
    """What was simulated (never read by the product)."""
    rr = w.rr
    return {
        "format": "foreign-ross-truth/1",
        "generator": "benchmarks.foreign.ross_rig",
        "kind": case.kind,
        "plant": "ROSS rotor_example_amb_complex_controllers: full lateral FE model "
                 f"({2 * rr.n_q} states), ROSS's M, K, C (Rayleigh), G",
        "speed_rpm": case.speed_rpm,
        "speed_rpm_true": case.speed_rpm,
        "dt": case.dt,
        "duration_s": case.duration_s,
        "theta": case.theta(),
        "c_ref": w.rig.c_ref,
        "bearings": {a: {"ks_nominal_n_per_m": rr.ks[a[0]],
                         "ks_n_per_m": (1 - case.k_theta[a]) * rr.ks[a[0]],
                         "ki_n_per_a": rr.ki[a[0]],
                         "c_ns_per_m": case.c_theta[a] * w.rig.c_ref} for a in AXES},
        "effects": [{"name": e.name, "params": e.params} for e in case.effects],
        "held_out": [e.name for e in case.effects if e.name in HELD_OUT],
        "excitation": {"port": "r2", "kind": "random_binary",
                       "amplitude_a": case.habits.eta_amplitude_a},
        "controller": {"method": case.method, "scale": case.scale,
                       "spectral_radius": sim["spectral_radius"]},
        "habits": case.habits.to_dict(),
        "draws": sim["draws"],
        "noise_rms_m": case.habits.noise_rms_m,
        "effect_y_change_over_noise": change,
    }


def write_record(stem: str | Path, dt: float, y: NDArray, u: NDArray, r2: NDArray,
                 speed_rpm: float, rig: Any, controller: dict[str, Any], truth: dict,
                 notes: str = "") -> dict[str, Path]:
    """NAME.csv (t, y_*, u_*, r2_*; full precision) and NAME.json (the sidecar of
    docs/guide.md "Recording format", the rig embedded, ``truth`` inside)."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    t = np.arange(y.shape[0]) * float(dt)
    header = ["t", *(f"{g}_{c}" for g in ("y", "u", "r2") for c in AXES)]
    rows = np.column_stack([t, y, u, r2]).tolist()
    paths = {"csv": Path(f"{stem}.csv"), "json": Path(f"{stem}.json")}
    paths["csv"].write_text("\n".join([",".join(header),
                                       *(",".join(map(repr, r)) for r in rows)]) + "\n",
                            encoding="ascii")
    side = {"format": "bayes-amb-recording/1", "dt": float(dt), "speed_rpm": float(speed_rpm),
            "rig": rig.to_dict(), "controller": controller,
            "excitation": {"columns": ["r2"], "injected_at": {"r2": "plant_input"}},
            "units": {"t": "s", "y": "m", "u": "A", "r2": "A"}, "notes": notes,
            "provenance": {"generator": "benchmarks.foreign.ross_rig (independent of "
                                        "bayes_amb.simulate)",
                           "ross": getattr(sys.modules.get("ross"), "__version__", None)},
            "truth": truth}
    paths["json"].write_text(json.dumps(side, indent=1, default=_plain), encoding="utf-8")
    return paths


def write_case(case: RigCase, out_dir: str | Path, name: str, rng: np.random.Generator,
               w: World | None = None) -> dict[str, Path]:
    """Simulate a drawn case and write NAME.csv + NAME.json into out_dir."""
    w = w or world()
    with one_thread():
        sim = simulate_case(case, rng, w)
        change = effect_change(case, sim["r2"], w) if case.effects else None
    truth = truth_block(case, sim, w, change)
    return write_record(Path(out_dir) / name, case.dt, sim["y"], sim["u"], sim["r2"],
                        case.speed_rpm, w.rig, w.controller(case), truth,
                        notes=f"foreign generator on ROSS's test rig, family {case.kind}")


def write_records(out_dir: str | Path, kinds: dict[str, int], seed: int = 1,
                  duration_s: float = 1.0, **draw: Any) -> list[dict[str, Any]]:
    """Write ``kinds`` (family -> count) records named <family>_<i>; each has its own rng
    (seed, family, i), so one family's records do not depend on the others'. OUT/index.json
    lists them with their truth summary and the seconds each took."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    w = world()
    index = []
    for kind, count in kinds.items():
        for i in range(count):
            t0 = time.perf_counter()
            rng = np.random.default_rng([seed, FAMILIES.index(kind), i])
            with one_thread():
                case = draw_rig_case(kind, rng, duration_s=duration_s, w=w, **draw)
            name = f"{kind}_{i:03d}"
            paths = write_case(case, out, name, rng, w)
            truth = json.loads(paths["json"].read_text())["truth"]
            index.append({"name": name, "kind": kind, "csv": paths["csv"].name,
                          "theta": truth["theta"], "effects": truth["effects"],
                          "held_out": truth["held_out"],
                          "effect_y_change_over_noise": truth["effect_y_change_over_noise"],
                          "seconds": round(time.perf_counter() - t0, 2)})
    (out / "index.json").write_text(json.dumps(index, indent=1))
    return index


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.foreign.ross_rig",
                                 description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--kinds", default="", help="family=count,... (default "
                    + ",".join(f"{k}={v}" for k, v in DEFAULT_KINDS.items()) + ")")
    ap.add_argument("--duration", type=float, default=1.0, help="record length, s")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--r2", type=float, default=R2_AMPLITUDE_A, help="r2 amplitude, A")
    ap.add_argument("--method", choices=("tustin", "zoh"), default="tustin",
                    help="controller discretisation")
    a = ap.parse_args(argv)
    kinds = dict(DEFAULT_KINDS) if not a.kinds else {}
    for item in (c for c in a.kinds.split(",") if c):
        k, v = item.split("=")
        if k not in FAMILIES:
            ap.error(f"unknown family {k!r} (known: {', '.join(FAMILIES)})")
        kinds[k] = int(v)
    index = write_records(a.out, kinds, a.seed, a.duration, r2_amplitude_a=a.r2,
                          method=a.method)
    for r in index:
        print(f"{r['name']}: {r['seconds']} s")
    print(f"{len(index)} recordings in {a.out} (index.json)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
