"""The end-to-end demonstration behind ``bayes-amb demo`` (and ``make demo``).

1. Build the reference rig's FE model, reduce it, design and export the observer-based
   controllers (dt = 1e-3 s for the paper's case, 1e-4 s for the realistic one).
2. The paper's case: reduced truth with k_By = 0.5, dt = 1e-3 s, 0.5 s, no noise;
   identify k_By and compare with 0.5 and with the paper's 0.502.
3. A realistic recording: full 320-state truth at 10 kHz, sensor noise 2e-7 m, r1 1e-7 m,
   r2 0.02 A, a concealed actuator lag (2500 Hz bandwidth: its contribution to y is below
   the noise), 0.5 s; identify k_By and c_By, then diagnose the model discrepancy (the
   report shows it).
4. Write OUT/report.html and OUT/report.pdf for the realistic run, and the paper case's
   report in OUT/paper_run/.

    result = run_demo("reports/demo")
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.discrepancy import DiagnoseOptions, diagnose
from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.io.recording import load_recording, save_recording
from bayes_amb.reduction import reduce_pseudo_modal
from bayes_amb.reduction.fidelity import singular_value_data
from bayes_amb.report import ReportOptions, collect_run, write_report
from bayes_amb.results.identification import Identification
from bayes_amb.rig import load_rig
from bayes_amb.rotor import full_model, unstable_poles
from bayes_amb.simulate import SimulationConfig, parse_effect, simulate_recording

log = logging.getLogger(__name__)

PAPER_THETA = 0.502
"""The paper's estimate of k_By for a true 0.5 (Lauridsen et al., Section IV)."""


@dataclass(frozen=True)
class DemoConfig:
    """What the demo runs. ``quick`` shrinks everything to a smoke test (short records, a
    fixed small number of sampler steps, no paper-case report) for the test suite."""

    seed: int = 0
    quick: bool = False
    paper_theta: float = 0.5
    realistic_theta: dict[str, float] = field(default_factory=lambda: {"k_By": 0.3})
    realistic_params: str = "k_By,c_By"
    effect: str = "actuator_lag:bandwidth_hz=2500"

    def durations(self) -> tuple[float, float]:
        return (0.3, 0.1) if self.quick else (0.5, 0.5)

    def identify_options(self) -> IdentifyOptions:
        if self.quick:
            return IdentifyOptions(steps=300, walkers=12, seed=self.seed)
        return IdentifyOptions(seed=self.seed)


@dataclass
class DemoResult:
    """Where everything went, the estimates, and the wall time of each stage (s)."""

    out: Path
    paper: dict[str, Any]
    realistic: dict[str, Any]
    report_html: Path
    report_pdf: Path | None
    pdf_backend: str | None
    paper_report: Path | None
    diagnosis: str
    timings: dict[str, float]


def _estimates(res: Identification, truth: dict[str, float]) -> dict[str, Any]:
    return {n: {"map": res.map[n], "mean": p.mean, "hdi90": p.hdi90,
                "true": truth.get(n, 0.0), "physical_mean": p.physical_mean,
                "unit": p.unit}
            for n, p in res.parameters.items()} | {"converged": res.converged}


def _diagnose(run_dir: Path, csv: Path, params: str, seed: int) -> tuple[str, list[str]]:
    """Diagnose the recording into the run folder (diagnosis.json, residuals.nc, models/)
    so that the report shows it; returns the one-line summary and the named effects."""
    d = diagnose(load_recording(csv), params, options=DiagnoseOptions(seed=seed))
    d.save(run_dir)
    named = [f"{e.description} (log BF {e.score:.0f})" for e in d.explanations]
    after = ", ".join(f"{n} {v.mean:+.4f} [{v.hdi90[0]:+.4f}, {v.hdi90[1]:+.4f}]"
                      for n, v in d.parameters_after.items())
    text = "; ".join(named) if named else "no effect named"
    return (text + (f"; with it in the model: {after}" if named else "")), d.effects


def run_demo(out_dir: str | Path = "reports/demo", config: DemoConfig | None = None,
             progress: Callable[[str], None] | None = None) -> DemoResult:
    """Run the four stages (module docstring); ``progress`` receives one line per step."""
    cfg = config or DemoConfig()
    say = progress or (lambda _m: None)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()

    # 1. model, reduction, controllers
    say("1/4 reference rig: FE model, reduction, controllers")
    rig = load_rig()
    fm = full_model(rig)
    red = reduce_pseudo_modal(fm)
    gap = singular_value_data(red, np.logspace(0, np.log10(5e4), 120)).max_gap_db()
    say(f"    {fm.n_states}-state FE model, {len(unstable_poles(fm))} unstable poles; "
        f"{red.n_states}-state reduction within {gap:.3f} dB below half the first bending "
        "mode")
    ctrls = {}
    for dt, name in ((1e-3, "controller_dt1e-3.json"), (1e-4, "controller_dt1e-4.json")):
        ctrls[dt] = export_controller(reference_controller(rig, dt), rig)
        ctrls[dt].save(out / name)
    say(f"    controllers exported to {out / 'controller_dt1e-3.json'} and "
        f"{out / 'controller_dt1e-4.json'}")
    timings["model_and_controllers"] = time.perf_counter() - t0

    # 2. the paper's case
    t = time.perf_counter()
    d_paper, d_real = cfg.durations()
    say(f"2/4 paper's case: reduced truth, k_By = {cfg.paper_theta}, dt = 1e-3 s, "
        f"{d_paper} s, no noise")
    truth_p = {"k_By": cfg.paper_theta}
    rec, truth = simulate_recording(rig, ctrls[1e-3], SimulationConfig(
        truth="reduced", params=truth_p, dt=1e-3, duration=d_paper, seed=cfg.seed))
    csv_p = save_recording(out / "paper_case.csv", rec, truth=truth)[0]
    res_p = identify(load_recording(csv_p), "k_By", options=cfg.identify_options())
    run_p = res_p.save(out / "paper_run")
    paper = _estimates(res_p, truth_p)
    k = paper["k_By"]
    say(f"    k_By: MAP {k['map']:.5f}, posterior mean {k['mean']:.5f} (true "
        f"{cfg.paper_theta}, paper {PAPER_THETA})")
    timings["paper_case"] = time.perf_counter() - t

    # 3. a realistic recording
    t = time.perf_counter()
    say(f"3/4 realistic recording: full truth, 10 kHz, {d_real} s, noise 2e-7 m, r1 1e-7 m, "
        f"r2 0.02 A, concealed {cfg.effect}")
    rec, truth = simulate_recording(rig, ctrls[1e-4], SimulationConfig(
        truth="full", params=dict(cfg.realistic_theta), effects=(parse_effect(cfg.effect),),
        dt=1e-4, duration=d_real, noise_rms=2e-7, r1_rms=1e-7, r2_rms=0.02, seed=cfg.seed))
    csv_r = save_recording(out / "realistic.csv", rec, truth=truth)[0]
    say(f"    identifying {cfg.realistic_params} (sampler runs to 50 autocorrelation times)"
        if not cfg.quick else f"    identifying {cfg.realistic_params}")
    res_r = identify(load_recording(csv_r), cfg.realistic_params,
                     options=cfg.identify_options())
    run_r = res_r.save(out / "realistic_run")
    realistic = _estimates(res_r, cfg.realistic_theta)
    for n in res_r.names:
        e = realistic[n]
        say(f"    {n}: mean {e['mean']:.4f}, 90 % HDI [{e['hdi90'][0]:.4f}, "
            f"{e['hdi90'][1]:.4f}] (true {e['true']})")
    say(f"    diagnosing the model discrepancy ({cfg.realistic_params} kept in every "
        "candidate model)")
    diagnosis, _ = _diagnose(run_r, csv_r, cfg.realistic_params, cfg.seed)
    say(f"    named: {diagnosis}")
    timings["realistic_case"] = time.perf_counter() - t

    # 4. reports
    t = time.perf_counter()
    say("4/4 reports")
    opts = ReportOptions(sensitivity_points=60, campbell_speeds=4, engineering_draws=10) \
        if cfg.quick \
        else ReportOptions()
    argv = ["bayes-amb", "demo", "--out", str(out)]

    def sub(msg: str) -> None:
        say(f"    {msg}")

    rep = write_report(collect_run(run_r), out, argv=argv, options=opts, progress=sub)
    paper_report = None
    if not cfg.quick:
        paper_report = write_report(collect_run(run_p), run_p, argv=argv, options=opts,
                                    progress=sub).html
    timings["reports"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t0
    return DemoResult(out, paper, realistic, rep.html, rep.pdf, rep.pdf_backend,
                      paper_report, diagnosis, timings)
