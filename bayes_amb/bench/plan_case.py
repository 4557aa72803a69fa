"""``bayes-amb bench --only plan``: the plan's prediction against the study it replaces.

The plan of the eight bearing coefficients for the default design (random binary 0.5 A on
all channels, 2 s at 10 kHz, 50 nm sensor noise, the reference rig and controller), timed
as the user runs it (the rig's model built, the design simulated, the information formed),
median of 3; side by side, one identification of one record of that design (map-only, the
user's defaults otherwise), of which a study of the prediction's quality needs >= 50.
Target (issue 30): plan under 5 s.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from bayes_amb.bench.results import Result


@dataclass(frozen=True)
class PlanBench(Result):
    """plan_s: median wall time of plan() (s); identify_s: one map-only identification of
    one record of the design (s); study_s: 50 of them; speedup: study_s / plan_s;
    requirement_s: the target; max_sd_ratio: largest identify sd / predicted sd on it."""

    plan_s: float
    identify_s: float
    study_s: float
    speedup: float
    requirement_s: float
    max_sd_ratio: float


def bench_plan(quick: bool = False) -> PlanBench:
    from bayes_amb.control.export import export_controller, reference_controller
    from bayes_amb.inference.identify import IdentifyOptions, identify
    from bayes_amb.planning import Design, Noise, plan
    from bayes_amb.planning.plan import BEARING_COEFFICIENTS, design_recording
    from bayes_amb.rig import load_rig

    design, noise = Design(duration=0.5 if quick else 2.0), Noise(noise_rms=5e-8)
    walls = []
    for _ in range(1 if quick else 3):
        t0 = time.perf_counter()
        rig = load_rig()
        ctrl = export_controller(reference_controller(rig, design.dt), rig)
        p = plan(rig, ctrl, design, noise)
        walls.append(time.perf_counter() - t0)
    rec, _ = design_recording(rig, ctrl, design, noise, seed=5)
    t0 = time.perf_counter()
    res = identify(rec, BEARING_COEFFICIENTS, options=IdentifyOptions(map_only=True))
    ident = time.perf_counter() - t0
    ratio = max(res.parameters[n].sd / p.sd(n) for n in BEARING_COEFFICIENTS)
    plan_s = float(np.median(walls))
    return PlanBench(plan_s=plan_s, identify_s=ident, study_s=50 * ident,
                     speedup=50 * ident / plan_s, requirement_s=5.0, max_sd_ratio=float(ratio))
