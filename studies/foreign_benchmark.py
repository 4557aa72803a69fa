"""The concealed-effect benchmark on the foreign generator (issue 14).

Recordings are made by tests/foreign, a simulator written apart from bayes_amb (its own
plant, effects as continuous-time state augmentations, real-record habits: offsets, drift,
a mid-operation start, coloured noise, mains lines; all eight bearing coefficients off
nominal), written to disk in the documented recording format, and diagnosed exactly as a
user would: ``diagnose(load_recording(csv))`` with default options. The truth file is read
only by the scoring below, after the diagnosis.

    PYTHONPATH=. .venv/bin/python studies/foreign_benchmark.py --out runs/foreign \
        [--per-kind 4] [--kinds control,actuator_lag,...] [--seed 1] [--duration 2]

Resumable: rows already in OUT/rows.jsonl are kept (each recording has its own seed).
Writes OUT/rows.jsonl (one row per recording, appended atomically line by line),
OUT/summary.md (the per-case table and the targets) and OUT/summary.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from tests.foreign import draw_case, write_case

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.discrepancy import diagnose
from bayes_amb.io.atomic import json_text, write_text_atomic
from bayes_amb.io.recording import load_recording
from bayes_amb.rig import load_rig

DEFAULT_KINDS = ("control", "actuator_lag", "actuator_delay", "sensor_delay", "sensor_gain",
                 "cross_coupling", "unbalance", "actuator_2nd", "sensor_lag",
                 "actuator_gain", "runout", "pair", "held_out", "full_truth")

IN_LIBRARY = {"actuator_lag", "actuator_delay", "sensor_delay", "sensor_gain",
              "cross_coupling", "unbalance"}
"""Foreign effects the diagnosis library can name (directly or by equivalence class)."""

def accepted_names(effect: dict[str, Any], rig) -> set[str]:
    """The diagnosis keys (effect@location) that name a foreign effect right, including
    its declared equivalence class."""
    name, p = effect["name"], effect["params"]
    if name == "actuator_lag":
        w = p.get("where", "all")
        return {"actuator_lag@both"} if w == "all" else {f"actuator_lag@{w}"}
    if name == "sensor_lag":
        # the same lag on all sensors is the actuator lag's equivalence class
        return {"actuator_lag@both"} if p.get("where", "all") == "all" else set()
    if name in ("actuator_delay", "sensor_delay"):
        return {"time_delay@controller"}
    if name == "sensor_gain":
        return {f"sensor_gain@{p['channel']}"}
    if name == "cross_coupling":
        return {f"cross_coupling@{p['where']}"}
    if name == "unbalance":
        out = set()
        for plane in p["planes"]:
            d = min(rig.discs, key=lambda dd: abs(dd.node - plane["node"]))
            out.add(f"unbalance@{d.name}")
        return out
    return set()


def score(truth: dict[str, Any], report: dict[str, Any], rig) -> dict[str, Any]:
    """One benchmark row from the truth file and diagnosis.json."""
    named = [f"{e['effect']}@{e['location']}" for e in report["explanations"]
             if e.get("kind", "physics") == "physics"]
    confident = [f"{e['effect']}@{e['location']}" for e in report["explanations"]
                 if e.get("kind", "physics") == "physics"
                 and e.get("confidence", "confident") == "confident"]
    effects = truth["effects"]
    kind = truth["kind"]
    flexible = truth["truth"] == "full" or truth.get("n_bending", 0) > 0
    right_sets = [accepted_names(e, rig) for e in effects]
    if flexible:
        right_sets.append({"flexible_mode@bending pair 1"})
    right = set().union(*right_sets) if right_sets else set()
    found = [bool(s & set(named)) for s in right_sets]
    wrong_conf = [n for n in confident if n not in right]
    in_lib = [e["name"] in IN_LIBRARY for e in effects]
    un = report.get("unexplained", {}).get("present", False)
    row = {
        "kind": kind, "effects": [e["name"] for e in effects], "named": named,
        "confident": confident, "all_named": bool(found) and all(found),
        "wrong_confident": wrong_conf, "unexplained": bool(un),
        "verdict": report.get("verdict"), "in_library": all(in_lib) if in_lib else True,
        "wall_s": report.get("wall_s"), "concealment": truth.get("concealment"),
    }
    # hidden physical parameters inside the 90 % HDI (bearing coefficients after diagnosis)
    th = truth["theta"]
    pa = report["parameters_after"]
    inside = [pa[n]["hdi90"][0] <= th[n] <= pa[n]["hdi90"][1] for n in pa if n in th]
    row["coeff_in_hdi"] = float(np.mean(inside)) if inside else None
    return row


def _controller_file(out: Path, dt: float) -> Path:
    path = out / "controller.json"
    if not path.is_file():
        rig = load_rig()
        write_text_atomic(path, json_text(export_controller(reference_controller(rig, dt),
                                                           rig).to_dict()) + "\n")
    return path


def run(out: Path, kinds: list[str], per_kind: int, seed: int, duration: float) -> None:
    out.mkdir(parents=True, exist_ok=True)
    rows_path = out / "rows.jsonl"
    done = set()
    if rows_path.is_file():
        done = {json.loads(line)["name"] for line in rows_path.read_text().splitlines()
                if line.strip()}
    ctrl = _controller_file(out, 1e-4)
    rig = load_rig()
    for i in range(per_kind):
        for j, kind in enumerate(kinds):
            name = f"{kind}_{i:02d}"
            if name in done:
                continue
            rng = np.random.default_rng([seed, i, j])
            spec = draw_case(kind, rng, controller_file=str(ctrl), duration_s=duration)
            paths = write_case(spec, out / "recordings", name, rng)
            t0 = time.perf_counter()
            try:
                d = diagnose(load_recording(paths["csv"]))
                report = d.report
                error = None
            except Exception as exc:  # a benchmark row, not a crash: record and go on
                report, error = None, f"{type(exc).__name__}: {exc}"
            truth = json.loads(Path(paths["truth"]).read_text())
            row = {"name": name, "error": error, "seconds": time.perf_counter() - t0}
            if report is not None:
                row.update(score(truth, report, rig))
                (out / "diagnoses").mkdir(exist_ok=True)
                write_text_atomic(out / "diagnoses" / f"{name}.json",
                                  json.dumps(report, default=float) + "\n")
            with rows_path.open("a") as fh:
                fh.write(json.dumps(row, default=float) + "\n")
            sys.stderr.write(f"{name}: {row.get('verdict')} named={row.get('named')} "
                             f"wrong={row.get('wrong_confident')} {row['seconds']:.0f} s\n")
    summarise(out)


def summarise(out: Path) -> dict[str, Any]:
    rows = [json.loads(line) for line in (out / "rows.jsonl").read_text().splitlines()
            if line.strip()]
    ok = [r for r in rows if r["error"] is None]
    singles = [r for r in ok if len(r["effects"]) == 1 and r["in_library"]]
    pairs = [r for r in ok if len(r["effects"]) == 2 and r["in_library"]]
    controls = [r for r in ok if r["kind"] == "control"]
    outside = [r for r in ok if not r["in_library"]]
    flex = [r for r in ok if r["kind"] == "full_truth"]

    def frac(rs, f):
        return (sum(1 for r in rs if f(r)), len(rs))

    s = {
        "recordings": len(rows), "failed": len(rows) - len(ok),
        "singles_named": frac(singles, lambda r: r["all_named"]),
        "pairs_named": frac(pairs, lambda r: r["all_named"]),
        "controls_clean": frac(controls, lambda r: not r["named"]),
        "confident_wrong": frac(ok, lambda r: bool(r["wrong_confident"])),
        "outside_library_flagged": frac(outside, lambda r: r["unexplained"]
                                        and not r["wrong_confident"]),
        "full_truth_flexible_only": frac(flex, lambda r: r["all_named"]
                                         and not r["wrong_confident"]),
        "coeff_in_hdi_mean": float(np.mean([r["coeff_in_hdi"] for r in ok
                                            if r["coeff_in_hdi"] is not None] or [np.nan])),
        "median_s": float(np.median([r["seconds"] for r in rows])) if rows else None,
        "max_s": float(np.max([r["seconds"] for r in rows])) if rows else None,
    }
    lines = ["| recording | effects | named (confident) | wrong | unexplained | verdict | s |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        if r["error"]:
            lines.append(f"| {r['name']} | | ERROR {r['error'][:60]} | | | | |")
            continue
        lines.append(f"| {r['name']} | {', '.join(r['effects']) or '-'} | "
                     f"{', '.join(r['named']) or '-'} ({len(r['confident'])}) | "
                     f"{', '.join(r['wrong_confident']) or '-'} | "
                     f"{'yes' if r['unexplained'] else '-'} | {r['verdict']} | "
                     f"{r['seconds']:.0f} |")
    lines.append("")
    for k, v in s.items():
        lines.append(f"- {k}: {v[0]}/{v[1]}" if isinstance(v, tuple) else f"- {k}: {v}")
    write_text_atomic(out / "summary.md", "\n".join(lines) + "\n")
    write_text_atomic(out / "summary.json", json.dumps(s, indent=1) + "\n")
    return s


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--kinds", default=",".join(DEFAULT_KINDS))
    ap.add_argument("--per-kind", type=int, default=4)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--duration", type=float, default=2.0)
    a = ap.parse_args(argv)
    run(a.out, [k for k in a.kinds.split(",") if k], a.per_kind, a.seed, a.duration)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
