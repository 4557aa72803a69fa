"""Demo step ``bayes-amb demo --import-formats``: bring rig data in, in every format.

A simulated recording (reference rig, reduced truth k_By = 0.3, c_By = 0.2, 1 s at 1 kHz,
0.2 um sensor noise) is written as a rig's DAQ would write it (.mat v5, .mat v7.3, TDMS,
HDF5, CSV; positions in V through 8 V/mm probes with offsets, the Ay probe inverted,
currents as amplifier set-points in V at 0.5 A/V, excitation in mA), each with its channel
map, imported back and identified (MAP + Laplace); the posterior is compared with the one
from the canonical CSV. The decentralised PID, documented MATLAB-style as a continuous
state space with negative feedback, is imported as the controller as shipped.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.control.pid import PIDSettings, continuous_pid, pid_gains
from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.io.atomic import write_text_atomic
from bayes_amb.io.channel_map import map_to_toml
from bayes_amb.io.controller_import import import_controller
from bayes_amb.io.daq_export import export_daq, realistic_channel_map, write_mat
from bayes_amb.io.daq_import import import_recording
from bayes_amb.io.nonfinite import result_json_text
from bayes_amb.io.recording import save_recording
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, simulate_recording

__all__ = ["FORMAT_SUFFIX", "ImportDemoResult", "run_import_demo"]

FORMAT_SUFFIX = {"mat": ".mat", "mat73": ".mat", "tdms": ".tdms", "hdf5": ".h5", "csv": ".csv"}
TRUTH = {"k_By": 0.3, "c_By": 0.2}


@dataclass(frozen=True)
class ImportDemoResult:
    """``formats``: per format the files, the posterior (mean, sd per parameter) and the
    largest |mean - canonical mean| / canonical sd; ``canonical``: the CSV's posterior;
    ``controller``: the imported PID's check; ``summary_path``: OUT/import_demo.json."""

    formats: dict[str, dict[str, Any]]
    canonical: dict[str, dict[str, float]]
    controller: dict[str, Any]
    summary_path: Path
    wall_s: float


def _posterior(rec) -> dict[str, dict[str, float]]:
    fit = identify(rec, ",".join(TRUTH), options=IdentifyOptions(map_only=True))
    return {n: {"mean": v.mean, "sd": v.sd} for n, v in fit.parameters.items()}


def run_import_demo(out_dir: str | Path, seed: int = 0) -> ImportDemoResult:
    """Export, import and identify in every DAQ format; import a MATLAB controller.

    Writes into ``out_dir``: canonical.csv/.json, rec_FORMAT.* with FORMAT.toml (the maps),
    imported_FORMAT.csv/.json, ctrl.json, pid_matlab.mat, pid_imported.json and
    import_demo.json (the numbers of the returned result).
    """
    t0 = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, 1e-3), rig)
    ctrl.save(out / "ctrl.json")
    rec, truth = simulate_recording(rig, ctrl, SimulationConfig(
        truth="reduced", params=TRUTH, dt=1e-3, duration=1.0, noise_rms=2e-7, seed=seed))
    save_recording(out / "canonical.csv", rec, truth=truth)
    canonical = _posterior(rec)
    formats: dict[str, dict[str, Any]] = {}
    for fmt, suffix in FORMAT_SUFFIX.items():
        m = realistic_channel_map(fmt, list(rec.excitation), controller="ctrl.json",
                                  speed_rpm=rec.speed_rpm)
        (out / f"{fmt}.toml").write_text(map_to_toml(m), encoding="utf-8")
        src = export_daq(rec, out / f"rec_{fmt}{suffix}", m)
        back = import_recording(src, out / f"{fmt}.toml")
        save_recording(out / f"imported_{fmt}.csv", back)
        post = _posterior(back)
        formats[fmt] = {"source": str(src), "map": str(out / f"{fmt}.toml"),
                        "posterior": post,
                        "max_shift_in_sd": max(abs(post[n]["mean"] - canonical[n]["mean"])
                                               / canonical[n]["sd"] for n in TRUTH)}
    A, B, C, D = continuous_pid(pid_gains(rig, PIDSettings()))
    write_mat(out / "pid_matlab.mat", {"A": A, "B": B, "C": -C, "D": -D, "Ts": 0.0})
    imp = import_controller(out / "pid_matlab.mat", rig, dt=1e-4, method="tustin")
    imp.controller.save(out / "pid_imported.json")
    controller = {"source": str(out / "pid_matlab.mat"), "discretisation": imp.discretisation,
                  "spectral_radius_full": imp.spectral_radius,
                  "sensitivity_peak_db": imp.sensitivity_peak_db, "iso14839_zone": imp.zone}
    wall = time.perf_counter() - t0
    summary = {"truth": TRUTH, "canonical": canonical, "formats": formats,
               "controller": controller, "wall_s": wall}
    write_text_atomic(out / "import_demo.json", result_json_text(summary))
    return ImportDemoResult(formats=formats, canonical=canonical, controller=controller,
                            summary_path=out / "import_demo.json", wall_s=wall)
