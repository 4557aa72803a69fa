"""The shortest record that reaches target precisions, within the rig's limits (issue 30).

The information of a design grows linearly with its length (twice the bins, the same
spectra), so one evaluation at a reference length gives, for each candidate design, the
length at which every target sd is reached: T = T_ref max_j (sd_ref,j / target_j)^2.
Candidates: the random binary (white, and held so that its power lies below 2000, 1000,
500 or 250 Hz: the same peak current, more of it where the rigid-body modes are), and
multisines to 250, 500 and 1000 Hz; each on all channels and on the channels of the
targets' bearings. A candidate whose reference record reaches a limit of the rig file
(amplifier current, slew rate, probe range: [limits]) is refused with the reason. The
choice is the shortest; the gain is against the default random binary on all channels.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from bayes_amb.errors import BayesAmbError
from bayes_amb.io.controller_file import ControllerFile
from bayes_amb.planning.plan import (
    Design,
    Noise,
    Plan,
    design_recording,
    information,
    plan,
    predicted_parameters,
)
from bayes_amb.rig import CHANNELS, Rig
from bayes_amb.uncertainty import get_spec

REF_S = 1.0
"""Reference length of each candidate's evaluation (s)."""

MIN_BINS = 64
"""The information check's smallest number of frequency bins (discrepancy/information.py)."""


@dataclass(frozen=True)
class Optimised:
    """The chosen design (its duration the shortest that reaches every target), its
    prediction, the default's length for the same targets, and every candidate tried."""

    design: Design
    plan: Plan
    targets: dict[str, float]
    default_s: float
    candidates: list[dict[str, Any]]

    @property
    def gain(self) -> float:
        """Default length / chosen length."""
        return self.default_s / self.design.duration

    def to_dict(self) -> dict[str, Any]:
        return {"format": "bayes-amb-plan-optimised/1", "targets": self.targets,
                "chosen": self.plan.to_dict(), "default_duration_s": self.default_s,
                "chosen_duration_s": self.design.duration, "gain": self.gain,
                "candidates": self.candidates}


def _channel_sets(targets: dict[str, float]) -> list[tuple[str, ...] | None]:
    bearings = {get_spec(n).location for n in targets}
    sets: list[tuple[str, ...] | None] = [None]
    if bearings <= {"A", "B"} and len(bearings) == 1:
        b = bearings.pop()
        sets.append(tuple(c for c in CHANNELS if c.startswith(b)))
    return sets


def candidate_designs(base: Design, targets: dict[str, float]) -> list[Design]:
    """The designs tried (module docstring), at the base design's amplitude, dt and port."""
    shapes: list[tuple[str, tuple[float, float] | None]] = [("random-binary", None)]
    shapes += [("random-binary", (1.0, hi)) for hi in (2000.0, 1000.0, 500.0, 250.0)
               if hi < 0.5 / base.dt]
    shapes += [("multisine", (5.0, hi)) for hi in (250.0, 500.0, 1000.0) if hi < 0.4 / base.dt]
    return [replace(base, excitation=k, band_hz=b, channels=ch, duration=REF_S)
            for k, b in shapes for ch in _channel_sets(targets)]


def _limits_reached(rig: Rig, rec: Any) -> str | None:
    lim = getattr(rig, "limits", None) or {}
    u, y = np.asarray(rec.u), np.asarray(rec.y)
    checks = (("current_a", float(np.max(np.abs(u))), "A", "peak current"),
              ("slew_a_per_s", float(np.max(np.abs(np.diff(u, axis=0)))) / rec.dt, "A/s",
               "peak slew rate"),
              ("sensor_range_m", float(np.max(np.abs(y))), "m", "peak displacement"))
    for key, v, unit, what in checks:
        if key in lim and v >= lim[key]:
            return f"{what} {v:.3g} {unit} reaches limits.{key} = {lim[key]:g} {unit}"
    return None


def optimise(rig: Rig, controller: ControllerFile, targets: dict[str, float],
             noise: Noise | None = None, base: Design | None = None,
             speed_rpm: float | None = None, seed: int = 0) -> Optimised:
    """The shortest candidate design (module docstring) reaching every target sd (theta
    units, e.g. {'k_By': 0.005}) within the rig's limits; BayesAmbError if none can."""
    if not targets:
        raise BayesAmbError("option --target: give at least one NAME=SD")
    for n, v in targets.items():
        get_spec(n)
        if not (np.isfinite(v) and v > 0):
            raise BayesAmbError(f"option --target: {n}: value {v:g} must be a positive sd")
    noise = noise or Noise()
    base = base or Design()
    names = tuple(targets)
    theta = np.zeros(len(names))
    rows, best, default_s = [], None, None
    for d in candidate_designs(base, targets):
        rec, _ = design_recording(rig, controller, d, noise, speed_rpm, None, seed)
        reason = _limits_reached(rig, rec)
        info = information(rig, controller, d, noise, names, theta, speed_rpm, seed, rec)
        pars = predicted_parameters(info, rig)
        need = max((pars[n]["sd"] / t) ** 2 for n, t in targets.items()) * REF_S
        need = max(need, MIN_BINS / info.f_max_hz, 0.1)
        row = {"excitation": d.excitation, "band_hz": d.band_hz,
               "channels": list(d.channels or CHANNELS), "duration_s": float(need),
               "peak_current_a": float(np.max(np.abs(np.asarray(rec.u)))),
               "peak_displacement_m": float(np.max(np.abs(np.asarray(rec.y)))),
               "refused": reason}
        rows.append(row)
        if d.excitation == "random-binary" and d.band_hz is None and d.channels is None:
            default_s = need
        if reason is None and (best is None or need < best[1]):
            best = (d, need)
    if best is None:
        raise BayesAmbError("plan: every candidate design reaches a limit of the rig file: "
                            + "; ".join(sorted({r["refused"] for r in rows if r["refused"]})))
    # the length scaling is first order (leakage, band edges): check at the chosen length
    # and lengthen until every target is met
    duration = best[1]
    for _ in range(4):
        chosen = replace(best[0], duration=float(np.ceil(duration * 100) / 100))
        result = plan(rig, controller, chosen, noise, names, None, speed_rpm, seed=seed)
        short = max((result.sd(n) / t) ** 2 for n, t in targets.items())
        if short <= 1.0:
            break
        duration = chosen.duration * short * 1.02
    return Optimised(design=chosen, plan=result, targets=dict(targets),
                     default_s=float(default_s), candidates=rows)
