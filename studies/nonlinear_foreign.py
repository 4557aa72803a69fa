"""The magnets' force law and the amplifier's slew limit on the foreign generator: what
default ``diagnose`` says, and whether its intervals cover.

Cases are drawn and written by benchmarks.foreign (force_law, slew_limit, mixtures and
the linear controls); each is diagnosed with default options, as a user runs it. For the
force law the record's rig is the reference rig with the magnets' bias current written in
its rig file (``bearings.bias_current``), as an engineer knows it: the truth's i0 times
(1 + e), e uniform in +-BIAS_ERROR (the design value is not the machine's). Scored here,
the only place the truth is read: verdict, linearity check, what was modelled, the
nonlinear parameter against the truth (inside its 90 % interval), and the eight bearing
coefficients inside their 90 % intervals (parameters_after).

    PYTHONPATH=. python studies/nonlinear_foreign.py --out runs/nonlinear \
        --kinds force_law=3,slew_limit=3,control=2,actuator_lag=2

With ``--levels 0.15,0.3`` each case is recorded at both excitation levels (one machine,
habits per record), the rig file has no bias, and the records are diagnosed together
(diagnose_records: the force law across the levels, discrepancy/levels.py):

    PYTHONPATH=. python studies/nonlinear_foreign.py --out runs/nonlinear_levels \
        --levels 0.15,0.3 --kinds force_law=4,control=3
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from bayes_amb.api import diagnose
from bayes_amb.io.recording import load_recording
from bayes_amb.rig import load_rig
from benchmarks.foreign import draw_case, write_case
from benchmarks.foreign.benchmark import _controller_file

BIAS_ERROR = 0.05
SATURATION_ERROR = 0.05


def _saturation_given(truth: dict[str, Any], bearings: list[str],
                      rng: np.random.Generator) -> dict[str, float]:
    """An iron saturation's ratio as the engineer's rig file gives it: the truth's times
    (1 + e), e uniform in +-SATURATION_ERROR (none for an unsaturated law)."""
    eff = {e["name"]: e["params"] for e in truth["effects"]}
    if "iron_saturation" not in eff:
        return {}
    r = eff["iron_saturation"]["b_sat_ratio"]
    return {b: r * (1 + rng.uniform(-SATURATION_ERROR, SATURATION_ERROR)) for b in bearings}


def with_bias(json_path: Path, bias: dict[str, float],
              saturation: dict[str, float] | None = None) -> None:
    """Write the reference rig with the bias current of the bearings whose magnets follow
    the force law into the record's sidecar (a bearing without one is linear), and their
    iron's saturation ratio where ``saturation`` gives one."""
    side = json.loads(json_path.read_text())
    rig = load_rig("reference").to_dict()
    bt = rig["bearings"]
    ki, ks = bt.pop("ki"), bt.pop("ks")
    for b in "AB":
        bt[b] = {**bt[b], "ki": ki, "ks": ks, **({"bias_current": bias[b]} if b in bias
                                                 else {}),
                 **({"saturation_ratio": saturation[b]} if saturation and b in saturation
                    else {})}
    side["rig"] = rig
    json_path.write_text(json.dumps(side, indent=1))


def score(d: Any, truth: dict[str, Any]) -> dict[str, Any]:
    theta = truth["theta"]
    inside = {n: bool(c.hdi90[0] <= theta[n] <= c.hdi90[1])
              for n, c in d.parameters_after.items() if n in theta}
    lin = next(c for c in d.checks if c.check == "linearity")
    nl = d.nonlinearity
    row = {"verdict": d.verdict, "linearity_ok": lin.ok, "named": d.effects,
           "confident": [e.effect for e in d.explanations if e.confidence == "confident"],
           "modelled": nl.name if nl else None, "inside": inside,
           "n_inside": sum(inside.values()), "wall_s": d.wall_s}
    eff = {e["name"]: e["params"] for e in truth["effects"]}
    law = next((k for k in ("magnet_force_law", "iron_saturation") if k in eff), None)
    if nl is not None and nl.name == "magnet_force_law" and law is not None:
        g = eff[law]["gap_m"]
        row["gap"] = {b: [g, nl.estimate[b], *nl.hdi90[b]] for b in nl.where}
        row["gap_inside"] = all(lo <= g <= hi for _, _, lo, hi in row["gap"].values())
    if nl is not None and nl.name == "slew_limit" and "slew_limit" in eff:
        s = eff["slew_limit"]["slew_a_per_s"]
        lo, hi = nl.hdi90["all"]
        row["slew"] = [s, nl.estimate["all"], lo, hi]
        row["slew_inside"] = bool(lo <= s <= hi)
    if nl is not None and nl.name == "current_limit" and "current_limit" in eff \
            and nl.hdi90.get("all"):
        s = eff["current_limit"]["i_max_a"]
        lo, hi = nl.hdi90["all"]
        row["limit"] = [s, nl.estimate["all"], lo, hi]
        row["limit_inside"] = bool(lo <= s <= hi)
    if nl is not None and nl.name == "amp_current_loop" and "amp_voltage_limit" in eff:
        t = eff["amp_voltage_limit"]
        row["loop"] = {k: [t[k], nl.estimate[key], *nl.hdi90[key]] for k, key in
                       (("slew_a_per_s", "all"), ("bandwidth_hz", "bandwidth_hz"))}
        row["loop_inside"] = all(lo <= v <= hi for v, _, lo, hi in row["loop"].values())
    return row


def levels_group(kind: str, rng: np.random.Generator, ctrl: Path, out: Path, name: str,
                 levels: tuple[float, ...]) -> tuple[list[Path], dict[str, Any]]:
    """One machine (its coefficients, effects and gap drawn once, at the largest level)
    recorded at each excitation level (eta amplitude, A), habits drawn per record."""
    from dataclasses import replace

    from benchmarks.foreign.habits import draw_habits
    spec = draw_case(kind, rng, controller_file=str(ctrl), eta_amplitude_a=max(levels))
    paths, truth = [], None
    for i, a in enumerate(levels):
        h = replace(draw_habits(rng) if i else spec.habits, eta_amplitude_a=a)
        p = write_case(replace(spec, habits=h), out, f"{name}_l{i}", rng)
        truth = truth or json.loads(p["truth"].read_text())
        paths.append(p["csv"])
    return paths, truth


def score_levels(res: Any, truth: dict[str, Any]) -> dict[str, Any]:
    """The records' force-law block against the truth: named, gap inside, and the
    small-signal stiffnesses inside their intervals."""
    fl = res.force_law or {}
    eff = {e["name"]: e["params"] for e in truth["effects"]}
    row = {"named": bool(fl.get("named")), "z": fl.get("z"), "line": fl.get("line"),
           "truth_law": "magnet_force_law" in eff}
    law_at = set()
    if "magnet_force_law" in eff:
        w = eff["magnet_force_law"]["where"]
        law_at = {"A", "B"} if w == "all" else {w}
    row["law_at"] = sorted(law_at)
    row["named_at"] = fl.get("where", [])
    row["named_right"] = set(row["named_at"]) == law_at
    if fl.get("named") and law_at:
        g = eff["magnet_force_law"]["gap_m"]
        row["gap"] = {b: [g, fl["bearings"][b]["gap_m"], *fl["bearings"][b]["gap_hdi90"]]
                      for b in fl["where"]}
        row["gap_inside"] = all(lo <= g <= hi for _, _, lo, hi in row["gap"].values()
                                ) and set(fl["where"]) <= law_at
    if fl.get("named"):
        ins = {n: bool(v["hdi90"][0] <= truth["theta"][n] <= v["hdi90"][1])
               for n, v in fl["small_signal"].items()}
        row.update(small_signal_inside=ins, n_inside=sum(ins.values()))
    row["records_inside"] = [sum(c.hdi90[0] <= truth["theta"][n] <= c.hdi90[1]
                                 for n, c in d.parameters_after.items())
                             for d in res.diagnoses]
    return row


def main_levels(a: argparse.Namespace, out: Path, ctrl: Path) -> None:
    from bayes_amb.api import diagnose as diagnose_any
    rows_path = out / "levels.jsonl"
    levels = tuple(float(v) for v in a.levels.split(","))
    k = 0
    for item in a.kinds.split(","):
        kind, n = item.rsplit("=", 1)
        for i in range(int(n)):
            k += 1
            rng = np.random.default_rng(a.seed * 1000 + 500 + k)
            name = f"lv_{kind}_{i:02d}"
            paths, truth = levels_group(kind, rng, ctrl, out, name, levels)
            t0 = time.perf_counter()
            res = diagnose_any([load_recording(p) for p in paths])
            row = {"name": name, "kind": kind, **score_levels(res, truth),
                   "verdicts": res.verdicts, "time_s": time.perf_counter() - t0}
            with rows_path.open("a") as f:
                f.write(json.dumps(row) + "\n")
            print(json.dumps(row), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", required=True)
    ap.add_argument("--kinds", default="force_law=3,slew_limit=3,control=2,actuator_lag=2")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--magnet-data", action="store_true",
                    help="iron_saturation records get the bias current and the saturation "
                         "ratio in their rig file (each within 5 %%), as an engineer who "
                         "knows the magnet design writes them")
    ap.add_argument("--levels", default=None,
                    help="eta amplitudes (A), e.g. 0.15,0.3: each case recorded at every "
                         "level and diagnosed as several records (no bias in the rig file)")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    ctrl = _controller_file(out, 1e-4)
    if a.levels:
        main_levels(a, out, ctrl)
        return
    rows_path = out / "rows.jsonl"
    done = set()
    if rows_path.exists():
        done = {json.loads(x)["name"] for x in rows_path.read_text().splitlines() if x}
    k = 0
    for item in a.kinds.split(","):
        kind, n = item.rsplit("=", 1)
        for i in range(int(n)):
            k += 1
            name = f"{kind.replace(':', '_').replace('+', '_')}_{i:02d}"
            if name in done:
                continue
            rng = np.random.default_rng(a.seed * 1000 + k)
            spec = draw_case(kind, rng, controller_file=str(ctrl))
            paths = write_case(spec, out, name, rng)
            truth = json.loads(paths["truth"].read_text())
            if "force_law" in kind or (a.magnet_data and "iron_saturation" in kind):
                law = truth["draws"]["magnets"][0]
                bearings = sorted({ax[0] for ax in law["axes"]})
                with_bias(paths["json"], {b: law["i0_a"] * (1 + rng.uniform(-BIAS_ERROR,
                                                                            BIAS_ERROR))
                                          for b in bearings},
                          _saturation_given(truth, bearings, rng))
            t0 = time.perf_counter()
            d = diagnose(load_recording(paths["csv"]))
            row = {"name": name, "kind": kind, **score(d, truth),
                   "time_s": time.perf_counter() - t0}
            with rows_path.open("a") as f:
                f.write(json.dumps(row) + "\n")
            print(json.dumps({k2: row[k2] for k2 in ("name", "verdict", "modelled",
                                                      "n_inside", "time_s")}
                             | {k2: row[k2] for k2 in ("gap", "slew", "loop", "limit")
                                if k2 in row}),
                  flush=True)


if __name__ == "__main__":
    main()
