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
from benchmarks.foreign.disturbances import KINDS as DISTURBANCE_KINDS
from benchmarks.foreign.disturbances import Disturbance, disturbance_signals, draw_disturbance
from benchmarks.foreign.effects import (
    EFFECT_PARAMS,
    HELD_OUT,
    MAGNET_LAWS,
    NONLINEAR,
    NONLINEAR_SEEN,
    Effect,
    build_plant,
)
from benchmarks.foreign.habits import Habits, draw_force, draw_habits, habit_signals
from benchmarks.foreign.loop import (
    ClosedLoop,
    Controller,
    closed_loop,
    read_controller,
    run_segments,
)
from benchmarks.foreign.plant import AXES, bearing_changes, rotor
from benchmarks.foreign.write import write_recording

IN_FAMILY = tuple(n for n in EFFECT_PARAMS if n not in HELD_OUT and n not in NONLINEAR_SEEN)
"""Single effects the benchmark draws as kinds (besides 'control', 'control_force', 'pair',
the held-out effects, 'held_out' (= 'pedestal'), 'full_truth' and 'bending'); what a random
'pair' draws from."""

KIND_EFFECT = {"force_law": "magnet_force_law"}
"""Case kinds (and names in 'pair:<a>+<b>') that stand for an effect of another name."""

KINDS = ("control", "control_force", *IN_FAMILY, "pair", "held_out", *HELD_OUT,
         "full_truth", "bending", "control_one_channel", "force_law", "slew_limit",
         *DISTURBANCE_KINDS)


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
    JSON (may also be given to write_case); disturbance: the coloured disturbances
    (disturbances.Disturbance) or None.
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
    disturbance: Disturbance | None = None

    def theta(self, c_ref: float = 1000.0) -> dict[str, float]:
        """The tool's parameters: k_<axis> = theta, c_<axis> = c / c_ref."""
        return {**{f"k_{a}": self.k_theta[a] for a in AXES},
                **{f"c_{a}": self.c_nsm[a] / c_ref for a in AXES}}


@dataclass(frozen=True)
class Simulated:
    """A simulated record (recorded part only): y_m (N, 4) m, u (N, 4) A (what the DAQ
    records: the controller's command, or with a ``current_limit`` recording 'coil' the
    coil current), eta (N, 4) A, eps (N, 4) m (the controller's innovation output), noise
    (N, 4) m, draws (dict; with a current limit 'clipped_share', the share of samples and
    channels at the limit), w (N, 4) A the total commanded current (command + r2 + offset),
    coil (N, 4) A the current the amplifiers deliver (held over the sample; with a slew or
    voltage limit its value at the end of the sample)."""

    y: NDArray
    u: NDArray
    eta: NDArray
    eps: NDArray
    noise: NDArray
    draws: dict[str, Any]
    w: NDArray | None = None
    coil: NDArray | None = None


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


def loops(spec: CaseSpec, rig: Rig, ctrl: Controller, k0: int, n: int,
          effects: tuple[Effect, ...] | None = None, truth: str | None = None
          ) -> tuple[list[tuple[int, ClosedLoop]], Any]:
    """The closed loop(s) of a case over n samples whose first is at t = k0 dt, and the
    plant (of the first step). One loop, unless a ``ks_drift`` makes the plant vary: then
    a staircase, step j covering t in [j, j + 1) segment_s with ks_true at its mid-point,
    (1 - theta - rate ((j + 1/2) segment_s - t_ref)) ks on the drifting axes."""
    effects = spec.effects if effects is None else effects
    drift = [e for e in effects if e.name == "ks_drift"]
    if not drift:
        plant = plant_of(spec, rig, effects, truth)
        return [(0, closed_loop(plant, ctrl))], plant
    if len(drift) > 1:
        raise ValueError(f"one ks_drift per case, got {len(drift)}")
    p = drift[0].params
    t = (k0 + np.arange(n)) * spec.dt
    step = np.floor(t / p["segment_s"] + 1e-9).astype(int)
    starts = np.flatnonzero(np.diff(step, prepend=step[0] - 1))
    out, plant0 = [], None
    for k in starts:
        mid = (step[k] + 0.5) * p["segment_s"]
        shift = p["rate_per_s"] * (mid - p["t_ref_s"])
        k_theta = {a: v + (shift if a in _axes(p["where"]) else 0.0)
                   for a, v in spec.k_theta.items()}
        plant = plant_of(replace(spec, k_theta=k_theta), rig, effects, truth)
        plant0 = plant0 or plant
        out.append((int(k), closed_loop(plant, ctrl)))
    return out, plant0


def _axes(where: str) -> tuple[str, ...]:
    return AXES if where == "all" else tuple(a for a in AXES if a[0] == where)


def simulate(spec: CaseSpec, controller: Controller | str | None, rng: np.random.Generator,
             rig: Rig | None = None) -> Simulated:
    """Run a case: burn-in with everything running, then the recorded part."""
    rig = rig or load_rig()
    ctrl = _controller(spec, controller)
    if abs(ctrl.dt - spec.dt) > 1e-12 * spec.dt:
        raise ValueError(f"controller dt {ctrl.dt} differs from the case dt {spec.dt}")
    n_rec = round(spec.duration_s / spec.dt)
    n_burn = round(spec.habits.burn_in_s / spec.dt)
    segs, plant = loops(spec, rig, ctrl, -n_burn, n_burn + n_rec)
    sig, draws = habit_signals(spec.habits, n_burn + n_rec, spec.dt, rng, -n_burn * spec.dt)
    if spec.disturbance is not None:    # drawn after every habit signal
        w_d, m_d, draws["disturbance"] = disturbance_signals(
            spec.disturbance, n_burn + n_rec, spec.dt, rng, -n_burn * spec.dt)
        draws["disturbance"].update(
            w_rms_a=np.sqrt(np.mean(w_d[n_burn:] ** 2, axis=0)).tolist(),
            m_rms_m=np.sqrt(np.mean(m_d[n_burn:] ** 2, axis=0)).tolist())
        sig["w_add"], sig["m"] = sig["w_add"] + w_d, sig["m"] + m_d
    e = np.hstack([sig["eta"], sig["w_add"], sig["m"]])
    # the simulation starts at t = -burn-in: the record starts at t = 0, where the line
    # phases of the truth refer; the first state is sampled sensor_delay_s earlier still
    x0 = plant.state_at(-n_burn * spec.dt - plant.sensor_delay_s)
    r = run_segments(segs, e, segs[0][1].initial_state(x0), force=sig["force"],
                     i_max_a=plant.i_max_a)
    keep = slice(n_burn, None)
    draws["burn_in_samples"] = n_burn
    u = r.u
    limit = [e for e in spec.effects if e.name == "current_limit"]
    if np.isfinite(plant.i_max_a):
        draws["clipped_share"] = float(np.mean(np.abs(r.w[keep]) > plant.i_max_a))
        if limit and limit[0].params["recorded"] == "coil":
            u = r.coil
    if r.limited is not None:
        draws["slew_limited_share"] = float(np.mean(r.limited[keep]))
        draws["slew_ramp_time_share"] = float(np.mean(r.ramp[keep]))
    if r.i_mag is not None:
        draws["magnets"] = magnet_draws(spec, plant, r.i_mag[keep], r.x_mag[keep])
    if sig["force"] is not None:
        f = sig["force"][keep]
        on = np.any(f != 0, axis=0)
        draws["force_rms_n"] = np.sqrt(np.mean(f[:, on] ** 2, axis=0)).tolist()
        draws["force_equivalent_current_a"] = (np.array(draws["force_rms_n"]) / rig.ki).tolist()
    return Simulated(r.y[keep], u[keep], sig["eta"][keep], r.eps[keep], sig["noise"][keep],
                     draws, r.w[keep], r.coil[keep])


def magnet_draws(spec: CaseSpec, plant: Any, i_mag: NDArray, x_mag: NDArray
                 ) -> list[dict[str, Any]]:
    """What a magnet law did on the record (i_mag, x_mag: the current in force (A) and the
    air gap at the bearing node (m), (N, 4), recorded part), one dict per law: its
    ``effect``, ``axes``, ``gap_m``, ``i0_a``, ``f0_n``, the ``excitation_level``
    eta / i0, the true small-signal slopes at (0, 0) (``ki_true_at_0`` N/A,
    ``ks_true_at_0`` N/m) and per axis: ``i_rms_over_i0``, ``x_max_over_gap``,
    ``ks_shift_n_per_m`` (the linear-equivalent stiffness shift, an estimate: the mean
    over the samples of df/dx at (i, 0) minus the rig's ks; for the force law exactly
    ks mean((i / i0)^2), with 'unsaturated' slopes it includes their drop at 0),
    ``ki_shift_n_per_a`` (likewise df/di at (i, 0) minus ki: zero for the force law) and
    ``k_theta_linear_equivalent`` = theta - ks_shift / ks (the tool's k_<axis> a linear
    fit would approach, an estimate that ignores how the fit weights the samples)."""
    out = []
    for law in plant.magnets:
        axes = [AXES[c] for c in law.channels]
        ki0, ks0 = law.slopes_at_zero()
        d: dict[str, Any] = {
            "effect": law.effect, "axes": axes, "gap_m": law.gap_m, "i0_a": law.i0_a,
            "f0_n": law.f0_n, "excitation_level": spec.habits.eta_amplitude_a / law.i0_a,
            "ki_true_at_0": ki0, "ks_true_at_0": ks0,
            "i_rms_over_i0": {}, "x_max_over_gap": {}, "ks_shift_n_per_m": {},
            "ki_shift_n_per_a": {}, "k_theta_linear_equivalent": {}}
        for c, ax in zip(law.channels, axes, strict=True):
            i, x = i_mag[:, c], x_mag[:, c]
            shift = float(np.mean(law.stiffness_at(i)) - law.ks)
            d["i_rms_over_i0"][ax] = float(np.sqrt(np.mean(i**2)) / law.i0_a)
            d["x_max_over_gap"][ax] = float(np.max(np.abs(x)) / law.gap_m)
            d["ks_shift_n_per_m"][ax] = shift
            d["ki_shift_n_per_a"][ax] = float(np.mean(law.gain_at(i)) - law.ki)
            d["k_theta_linear_equivalent"][ax] = spec.k_theta[ax] - shift / law.ks
        out.append(d)
    return out


def clean_response(spec: CaseSpec, ctrl: Controller, eta: NDArray, rig: Rig,
                   effects: tuple[Effect, ...], truth: str | None = None) -> NDArray:
    """Noise-free y (N, 4) from rest with eta only (no habits) for a set of effects."""
    segs, plant = loops(spec, rig, ctrl, 0, eta.shape[0], effects, truth)
    z = np.zeros_like(eta)
    x0 = plant.state_at(-plant.sensor_delay_s)
    r = run_segments(segs, np.hstack([eta, z, z]), segs[0][1].initial_state(x0),
                     i_max_a=plant.i_max_a)
    return r.y


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


SEAL_NODES = ("D1", "D2", "mid")
"""Where a seal is drawn: at a wheel (impeller-eye seal) or mid-span (nodes 15-26: a shaft
or balance-piston seal between the bearings at nodes 8 and 33 of the reference rig)."""


EXCITATION_LEVEL = (0.1, 0.4)
"""The range a magnet law's excitation level eta / i0 is drawn from (its gap follows:
g0 = i0 ki / ks, i0 = eta / level)."""


def _draw_effect(name: str, rng: np.random.Generator, noise: float,
                 duration_s: float = 2.0, speed_rpm: float = 31500.0,
                 eta_a: float = 0.3,
                 level: tuple[float, float] | float = EXCITATION_LEVEL) -> Effect:
    """A first draw of one effect (scaled later by :func:`conceal`; the nonlinear ones are
    not: a magnet law's gap is drawn from the excitation level eta_a / i0 in ``level`` (a
    range or one value), a slew limit's S is calibrated later)."""
    u = rng.uniform
    if name in MAGNET_LAWS:
        lo, hi = (level, level) if np.isscalar(level) else level
        if not eta_a > 0:
            raise ValueError(f"{name}: the gap is drawn from eta / i0; eta is {eta_a} A")
        rig = load_rig()
        gap = eta_a / u(lo, hi) * rig.ki / rig.ks        # i0 = eta / level, g0 = i0 ki / ks
        p = {"gap_m": gap, "where": str(rng.choice(_WHERE))}
        if name == "iron_saturation":
            p.update(b_sat_ratio=u(1.3, 2.0), slopes="rig")
        return Effect(name, {k: (float(v) if isinstance(v, np.floating) else v)
                             for k, v in p.items()})
    if name == "actuator_lag":
        p = {"bandwidth_hz": u(300, 2000), "where": str(rng.choice(_WHERE))}
    elif name == "actuator_2nd":
        p = {"natural_hz": u(600, 2500), "zeta": u(0.4, 0.9), "where": str(rng.choice(_WHERE))}
    elif name == "eddy_current":
        p = {"corner_hz": u(300, 2000), "where": str(rng.choice(_WHERE))}
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
    elif name == "current_limit":       # i_max_a is set by calibrate_current_limit
        p = {"i_max_a": None, "recorded": str(rng.choice(["command", "coil"])),
             "clipped_share_target": u(0.01, 0.05)}
    elif name == "slew_limit":          # slew_a_per_s is set by calibrate_slew_limit
        p = {"slew_a_per_s": None, "recorded": "command",
             "limited_share_target": u(0.05, 0.25)}
    elif name == "amp_voltage_limit":   # slew_a_per_s = v_ratio x typical rate (calibrated)
        p = {"bandwidth_hz": u(1500.0, 4000.0), "v_ratio": u(*V_RATIO),
             "slew_a_per_s": None}
    elif name == "seal":
        # gas seal: cross-coupled k, direct K of either sign, C from a whirl-frequency
        # ratio k / (C Omega) of 0.3-0.8, a small cross-coupled damping
        where = str(rng.choice(SEAL_NODES))
        node = int(rng.integers(15, 27)) if where == "mid" else where
        k = u(2e4, 1e5)
        c = k / (u(0.3, 0.8) * speed_rpm * np.pi / 30.0)
        p = {"node": node, "k_direct_nm": k * u(-1.0, 2.0), "k_cross_nm": k,
             "c_direct_nsm": c, "c_cross_nsm": c * u(0.0, 0.2)}
    elif name == "coupling":
        p = {"end": str(rng.choice(["first", "last"])), "mass_kg": u(5.0, 40.0),
             "natural_hz": u(80.0, 400.0), "zeta": u(0.02, 0.1)}
    elif name == "probe_angle":
        p = {"bearing": str(rng.choice(["A", "B"])),
             "angle_deg": float(rng.choice([-1, 1]) * u(2.0, 8.0))}
    elif name == "ks_drift":
        # a total change of 2-6 % of ks over the record, either sign, centred mid-record
        p = {"where": str(rng.choice(_WHERE)),
             "rate_per_s": float(rng.choice([-1, 1]) * u(0.02, 0.06)) / duration_s,
             "t_ref_s": duration_s / 2, "segment_s": 0.025}
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
    elif e.name == "eddy_current":
        p["corner_hz"] /= f
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
    elif e.name in ("pedestal", "coupling"):
        p["mass_kg"] /= f
    elif e.name == "seal":
        for k in ("k_direct_nm", "k_cross_nm", "c_direct_nsm", "c_cross_nsm"):
            p[k] *= f
    elif e.name == "ks_drift":
        p["rate_per_s"] *= f
    elif e.name == "probe_angle":
        p["angle_deg"] *= f
    elif e.name in NONLINEAR:
        raise ValueError(f"{e.name} is not concealed: its strength is its own parameter")
    return Effect(e.name, p)


KS_DRIFT_CAP = 0.06
"""The largest total ks change over a record a ``ks_drift`` is strengthened to (-, of ks):
a few per cent, as coil heating gives; its concealment may then stay below 0.2."""


def _beyond_cap(e: Effect, duration_s: float) -> bool:
    """An effect stronger than physics allows (only ks_drift has a cap)."""
    return e.name == "ks_drift" and abs(e.params["rate_per_s"]) * duration_s > KS_DRIFT_CAP


def draw_case(kind: str, rng: np.random.Generator, *, controller_file: str | None = None,
              duration_s: float = 2.0, dt: float = 1e-4, noise_rms_m: float = 5e-8,
              habits: bool = True, eta_amplitude_a: float | None = None,
              excitation_level: tuple[float, float] | float = EXCITATION_LEVEL) -> CaseSpec:
    """Draw a case of a kind (KINDS, or 'pair:<a>+<b>'): bearings off nominal, habits drawn,
    effects drawn at a first guess (scaled to concealment in [0.2, 1) by :func:`conceal`;
    a current limit's i_max by :func:`calibrate_current_limit`, a slew limit's S by
    :func:`calibrate_slew_limit`, an amp_voltage_limit's by :func:`calibrate_amplifier`).
    'control_force' is a control with a process force at the discs (habits.draw_force,
    drawn last); 'control_one_channel' a control excited on one channel only (a test
    design, drawn last). 'force_law' (or 'magnet_force_law') is the magnets' force law at
    one or both bearings, 'slew_limit' the amplifiers' slew-rate limit; either may be
    named in a pair, e.g. 'pair:force_law+actuator_lag'. The coloured-disturbance kinds
    (disturbances.KINDS: 'coloured_r2', 'mains', 'pink_sensor', 'coloured_mix' and the
    held-out 'narrowband_r2', 'r1_band') are controls with a drawn ``disturbance``
    (disturbances.draw_disturbance, drawn after the habits).

    ``eta_amplitude_a``: the excitation amplitude (A) instead of the habits' 0.3 A (no
    extra draw). ``excitation_level``: the range (or value) of eta / i0 a magnet law's gap
    is drawn from (g0 = i0 ki / ks, i0 = eta / level)."""
    k_theta = {a: float(rng.uniform(-0.3, 0.3)) for a in AXES}
    c_nsm = {a: float(rng.uniform(0.0, 300.0)) for a in AXES}
    hab = draw_habits(rng, noise_rms_m) if habits else Habits(noise_rms_m=noise_rms_m)
    if eta_amplitude_a is not None:
        hab = replace(hab, eta_amplitude_a=float(eta_amplitude_a))
    truth, n_bending, effects = "reduced", 0, ()
    disturbance = None

    def one(name: str) -> Effect:
        return _draw_effect(KIND_EFFECT.get(name, name), rng, noise_rms_m, duration_s,
                            eta_a=hab.eta_amplitude_a, level=excitation_level)

    if kind == "control":
        pass
    elif kind == "control_force":
        hab = draw_force(hab, rng, load_rig().ki)
    elif kind == "control_one_channel":
        hab = replace(hab, eta_channels=(str(rng.choice(AXES)),))
    elif kind in DISTURBANCE_KINDS:
        hab, disturbance = draw_disturbance(kind, rng, hab, 31500.0)
    elif KIND_EFFECT.get(kind, kind) in (*IN_FAMILY, *HELD_OUT, *NONLINEAR_SEEN):
        effects = (one(kind),)
    elif kind == "pair" or kind.startswith("pair:"):
        names = (kind[5:].split("+") if ":" in kind
                 else list(rng.choice(IN_FAMILY, size=2, replace=False)))
        effects = tuple(_draw_effect(KIND_EFFECT.get(str(n), str(n)), rng, noise_rms_m,
                                     eta_a=hab.eta_amplitude_a, level=excitation_level)
                        for n in names)
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
                    controller_file=controller_file, disturbance=disturbance)


def conceal(spec: CaseSpec, ctrl: Controller, rng: np.random.Generator, rig: Rig,
            band: tuple[float, float] = (0.2, 1.0), max_tries: int = 40
            ) -> tuple[CaseSpec, dict[str, float]]:
    """Bring each effect's concealment into ``band`` (default [0.2, 1)): weaken it by steps
    of 0.7 while it is >= band[1]; if its first draw is below band[0], strengthen it by
    1/0.7 while the stronger version stays below band[1] (and, for a ks_drift, within
    KS_DRIFT_CAP). The nonlinear effects (NONLINEAR: a current or slew limit, a magnet law,
    a voltage-limited amplifier) are left alone (see write_case). Returns the
    case and the concealments per effect (index:name), of all effects together ('all') and of the
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
        if e.name in NONLINEAR:             # its strength is its own parameter instead
            continue
        c = conc(e)
        for _ in range(max_tries):
            if c < band[1]:
                break
            e = _weaker(e)
            c = conc(e)
        for _ in range(max_tries if c < band[0] else 0):
            stronger = _weaker(e, 1 / 0.7)
            if _beyond_cap(stronger, spec.duration_s):
                break
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


def calibrate_current_limit(spec: CaseSpec, ctrl: Controller, rng: np.random.Generator,
                            rig: Rig, max_tries: int = 5, rel_tol: float = 0.15
                            ) -> tuple[CaseSpec, dict[str, float]]:
    """Set a current limit's i_max so that the record clips on about its
    ``clipped_share_target`` of samples and channels: i_max starts at that quantile of |w|
    in the linear run and is moved to the quantile of the clipped run's commanded |w|
    (which clipping widens) until the share is within ``rel_tol`` of the target or after
    ``max_tries`` runs. Every trial runs on the draws the record will have (a copy of rng
    is used; rng itself is not advanced). Returns the case and {'i_max_a',
    'clipped_share' (measured), 'y_change_over_noise' (rms of y with minus y without the
    limit, same draws, over the noise rms)}."""
    i = next(k for k, e in enumerate(spec.effects) if e.name == "current_limit")
    target = spec.effects[i].params["clipped_share_target"]

    def trial(i_max: float | None) -> tuple[CaseSpec, Simulated]:
        effects = list(spec.effects)
        effects[i] = Effect("current_limit", {**effects[i].params, "i_max_a": i_max})
        sp = replace(spec, effects=tuple(effects))
        copy = np.random.Generator(type(rng.bit_generator)())
        copy.bit_generator.state = rng.bit_generator.state
        return sp, simulate(sp, ctrl, copy, rig)

    _, lin = trial(None)
    i_max = float(np.quantile(np.abs(lin.w), 1.0 - target))
    for _ in range(max_tries):
        sp, sim = trial(i_max)
        share = sim.draws["clipped_share"]
        if abs(share - target) <= rel_tol * target:
            break
        i_max = float(np.quantile(np.abs(sim.w), 1.0 - target))
    change = float(np.sqrt(np.mean((sim.y - lin.y) ** 2)) / spec.habits.noise_rms_m)
    return sp, {"i_max_a": sp.effects[i].params["i_max_a"], "clipped_share": share,
                "y_change_over_noise": change}


V_RATIO = (0.7, 1.4)
"""The range an amp_voltage_limit's v_ratio is drawn from: S = v_ratio x the rms rate of
the unlimited lag. With 0.3 A binary eta the rms rate is about 0.7 x the rate a full
0.6 A eta step starts with, so v_ratio < ~1.2 caps every eta step (README gives the shares
and the rate cap's own effect on y over this range)."""


def _copy(rng: np.random.Generator) -> np.random.Generator:
    """A generator in the same state (rng itself is not advanced)."""
    copy = np.random.Generator(type(rng.bit_generator)())
    copy.bit_generator.state = rng.bit_generator.state
    return copy


def _with(spec: CaseSpec, i: int, **params: Any) -> CaseSpec:
    """The case with effect i's params updated."""
    effects = list(spec.effects)
    effects[i] = Effect(effects[i].name, {**effects[i].params, **params})
    return replace(spec, effects=tuple(effects))


def _without(spec: CaseSpec, i: int) -> CaseSpec:
    return replace(spec, effects=spec.effects[:i] + spec.effects[i + 1:])


def _i_max(spec: CaseSpec) -> float:
    return min([e.params["i_max_a"] for e in spec.effects
                if e.name == "current_limit" and e.params["i_max_a"] is not None] or [np.inf])


def _y_change(a: Simulated, b: Simulated, spec: CaseSpec) -> float:
    return float(np.sqrt(np.mean((a.y - b.y) ** 2)) / spec.habits.noise_rms_m)


def record_change(spec: CaseSpec, ctrl: Controller, rng: np.random.Generator, rig: Rig,
                  i: int) -> float:
    """rms(y with - y without effect i) / noise rms on the record's own draws (habits on;
    rng not advanced): the record-level strength of a nonlinear effect."""
    return _y_change(simulate(spec, ctrl, _copy(rng), rig),
                     simulate(_without(spec, i), ctrl, _copy(rng), rig), spec)


def calibrate_slew_limit(spec: CaseSpec, ctrl: Controller, rng: np.random.Generator,
                         rig: Rig, max_tries: int = 5, rel_tol: float = 0.15
                         ) -> tuple[CaseSpec, dict[str, float]]:
    """Set a slew limit's S so that the current fails to reach the command within the
    sample on about its ``limited_share_target`` of samples and channels: S dt starts at
    that quantile of the command's steps |a[k] - a[k-1]| in the unlimited run (a the
    amplifier's target, clip(w) under a current limit) and moves to that quantile of
    |a[k] - i_end[k-1]| in the limited run until the share is within ``rel_tol`` of the
    target or after ``max_tries`` runs, all on the record's own draws (rng not advanced).
    Returns the case and {'slew_a_per_s', 'slew_limited_share' (measured),
    'y_change_over_noise' (rms of y with minus y without the limit, over the noise rms)}."""
    i = next(k for k, e in enumerate(spec.effects) if e.name == "slew_limit")
    target = spec.effects[i].params["limited_share_target"]
    i_max = _i_max(spec)

    def steps(sim: Simulated) -> NDArray:
        return np.abs(np.clip(sim.w[1:], -i_max, i_max) - sim.coil[:-1])

    def trial(S: float | None) -> tuple[CaseSpec, Simulated]:
        sp = _with(spec, i, slew_a_per_s=S)
        return sp, simulate(sp, ctrl, _copy(rng), rig)

    _, free = trial(None)
    S = float(np.quantile(steps(free), 1.0 - target)) / spec.dt
    for _ in range(max_tries):
        sp, sim = trial(S)
        share = sim.draws["slew_limited_share"]
        if abs(share - target) <= rel_tol * target:
            break
        S = float(np.quantile(steps(sim), 1.0 - target)) / spec.dt
    return sp, {"slew_a_per_s": sp.effects[i].params["slew_a_per_s"],
                "slew_limited_share": share, "y_change_over_noise": _y_change(sim, free, spec)}


def calibrate_amplifier(spec: CaseSpec, ctrl: Controller, rng: np.random.Generator,
                        rig: Rig) -> tuple[CaseSpec, dict[str, float]]:
    """Set an amp_voltage_limit's S = v_ratio x the typical rate: the rms over the recorded
    samples and channels of wb |a[k] - i(t_k)| (the rate the unlimited lag starts each
    sample with) on the record's own draws (rng not advanced). Returns the case and
    {'slew_a_per_s', 'typical_rate_a_per_s', 'slew_limited_share' (measured),
    'y_change_over_noise' (against an ideal amplifier), 'rate_cap_y_change_over_noise'
    (against the same lag without the cap)}."""
    i = next(k for k, e in enumerate(spec.effects) if e.name == "amp_voltage_limit")
    p = spec.effects[i].params
    i_max = _i_max(spec)
    free = simulate(_with(spec, i, slew_a_per_s=None), ctrl, _copy(rng), rig)
    rate = 2 * np.pi * p["bandwidth_hz"] * np.abs(np.clip(free.w[1:], -i_max, i_max)
                                                   - free.coil[:-1])
    typical = float(np.sqrt(np.mean(rate**2)))
    sp = _with(spec, i, slew_a_per_s=p["v_ratio"] * typical)
    sim = simulate(sp, ctrl, _copy(rng), rig)
    ideal = simulate(_without(sp, i), ctrl, _copy(rng), rig)
    return sp, {"slew_a_per_s": sp.effects[i].params["slew_a_per_s"],
                "typical_rate_a_per_s": typical,
                "slew_limited_share": sim.draws["slew_limited_share"],
                "y_change_over_noise": _y_change(sim, ideal, spec),
                "rate_cap_y_change_over_noise": _y_change(sim, free, spec)}


def truth_record(spec: CaseSpec, rig: Rig, concealments: dict[str, float],
                 draws: dict[str, Any]) -> dict[str, Any]:
    """The truth file's content (see README.md of this package for the keys)."""
    draws = dict(draws)
    dist = None
    if spec.disturbance is not None:    # its parameters and what was drawn, in one place
        dist = {**spec.disturbance.to_dict(), "draws": draws.pop("disturbance", {})}
    held = [e.name for e in spec.effects if e.name in HELD_OUT]
    held += list(dist["held_out"]) if dist else []
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
        "held_out": held,
        "habits": spec.habits.to_dict(),
        "draws": draws,
        "disturbance": dist,
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
    names = [e.name for e in spec.effects]
    calib: dict[str, Any] = {}
    # the nonlinear effects' strength: record-level, rms(y with - y without) / noise
    if "current_limit" in names:
        spec, limit = calibrate_current_limit(spec, ctrl, rng, rig)
        conc[f"{names.index('current_limit')}:current_limit"] = limit["y_change_over_noise"]
    if "slew_limit" in names:
        spec, limit = calibrate_slew_limit(spec, ctrl, rng, rig)
        conc[f"{names.index('slew_limit')}:slew_limit"] = limit["y_change_over_noise"]
    if "amp_voltage_limit" in names:
        spec, limit = calibrate_amplifier(spec, ctrl, rng, rig)
        conc[f"{names.index('amp_voltage_limit')}:amp_voltage_limit"] = \
            limit["y_change_over_noise"]
        calib.update({k: limit[k] for k in ("typical_rate_a_per_s",
                                            "rate_cap_y_change_over_noise")})
    for i, n in enumerate(names):
        if n in MAGNET_LAWS:
            conc[f"{i}:{n}"] = record_change(spec, ctrl, rng, rig, i)
    if len(names) == 1 and names[0] in NONLINEAR:
        conc["all"] = conc[f"0:{names[0]}"]
    sim = simulate(spec, ctrl, rng, rig)
    truth = truth_record(spec, rig, conc, {**sim.draws, **calib})
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
                          "concealment": truth["concealment"],
                          "disturbance": (truth["disturbance"] or {}).get("families")})
    (out / "index.json").write_text(json.dumps(index, indent=1))
    return index
