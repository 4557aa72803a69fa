"""`bayes-amb import` (a DAQ file through a channel map) and `bayes-amb import-controller`."""

from __future__ import annotations

import argparse
import importlib

import numpy as np

from bayes_amb.cli.common import emit
from bayes_amb.io.daq_import import import_recording
from bayes_amb.io.recording import save_recording
from bayes_amb.rig import CHANNELS


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("import", help="import a DAQ recording (.mat, TDMS, HDF5, CSV)",
                       description="Read a .mat (v5 or v7.3), TDMS, HDF5 or CSV file through "
                       "a channel map (TOML: which channel is which signal, units, "
                       "sensitivities, gains, signs, offsets, time base, trimming, "
                       "decimation) and write the canonical recording NAME.csv + NAME.json "
                       "with provenance (sha256 of source and map, the map itself).")
    p.add_argument("source", help="the DAQ file")
    p.add_argument("--map", required=True, metavar="MAP.toml", help="the channel map")
    p.add_argument("--rig", default=None, help="rig file (default: recording.rig of the map)")
    p.add_argument("--controller", default=None,
                   help="controller file (default: recording.controller of the map)")
    p.add_argument("-o", "--output", required=True, metavar="NAME.csv",
                   help="the canonical recording to write (NAME.json beside it)")
    p.add_argument("--json", action="store_true", help="print JSON (default: text)")
    p.set_defaults(func=run)
    try:
        ctl = importlib.import_module("bayes_amb.cli.import_controller_cmd")
    except ModuleNotFoundError as exc:
        if exc.name != "bayes_amb.cli.import_controller_cmd":
            raise
    else:
        ctl.add_parser(sub)


def run(args: argparse.Namespace) -> int:
    rec = import_recording(args.source, args.map, rig=args.rig, controller=args.controller)
    csv_path, json_path = save_recording(args.output, rec)
    imp = rec.meta["provenance"]["import"]
    rms = {g: dict(zip(CHANNELS, np.sqrt(np.mean(np.asarray(a) ** 2, axis=0)).tolist(),
                       strict=True))
           for g, a in (("y", rec.y), ("u", rec.u), *rec.excitation.items())}
    d = {"csv": str(csv_path), "json": str(json_path), "samples": rec.n_samples,
         "dt": rec.dt, "duration_s": rec.n_samples * rec.dt, "speed_rpm": rec.speed_rpm,
         "excitation": list(rec.excitation), "rms_si": rms,
         "source_format": imp["source_format"], "source_sha256": imp["source_sha256"],
         "decimate": imp["decimate"], "offsets_removed_si": imp["offsets_removed_si"]}
    unit = {"y": ("um", 1e6), "r1": ("um", 1e6)}
    lines = [f"wrote {csv_path} and {json_path}: {rec.n_samples} samples at dt = {rec.dt:g} s "
             f"({d['duration_s']:g} s), {rec.speed_rpm:.0f} rpm, from {imp['source_format']} "
             f"{args.source} (sha256 {imp['source_sha256'][:12]}...), decimated by "
             f"{imp['decimate']}"]
    for g, vals in rms.items():
        u, f = unit.get(g, ("mA", 1e3))
        lines.append(f"  {g:>3} RMS: " + ", ".join(f"{c} {v * f:.3g} {u}"
                                                  for c, v in vals.items()))
    emit(d, "\n".join(lines), args.json)
    return 0
