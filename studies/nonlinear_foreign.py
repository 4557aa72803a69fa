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


def with_bias(json_path: Path, i0: float) -> None:
    """Write the reference rig with its bias current into the record's sidecar."""
    side = json.loads(json_path.read_text())
    rig = load_rig("reference").to_dict()
    rig["bearings"]["bias_current"] = i0
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
    if nl is not None and nl.name == "magnet_force_law" and "magnet_force_law" in eff:
        g = eff["magnet_force_law"]["gap_m"]
        row["gap"] = {b: [g, nl.estimate[b], *nl.hdi90[b]] for b in nl.where}
        row["gap_inside"] = all(lo <= g <= hi for _, _, lo, hi in row["gap"].values())
    if nl is not None and nl.name == "slew_limit" and "slew_limit" in eff:
        s = eff["slew_limit"]["slew_a_per_s"]
        lo, hi = nl.hdi90["all"]
        row["slew"] = [s, nl.estimate["all"], lo, hi]
        row["slew_inside"] = bool(lo <= s <= hi)
    return row


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", required=True)
    ap.add_argument("--kinds", default="force_law=3,slew_limit=3,control=2,actuator_lag=2")
    ap.add_argument("--seed", type=int, default=7)
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    ctrl = _controller_file(out, 1e-4)
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
            if "force_law" in kind:
                i0 = truth["draws"]["magnets"][0]["i0_a"]
                with_bias(paths["json"], i0 * (1 + rng.uniform(-BIAS_ERROR, BIAS_ERROR)))
            t0 = time.perf_counter()
            d = diagnose(load_recording(paths["csv"]))
            row = {"name": name, "kind": kind, **score(d, truth),
                   "time_s": time.perf_counter() - t0}
            with rows_path.open("a") as f:
                f.write(json.dumps(row) + "\n")
            print(json.dumps({k2: row[k2] for k2 in ("name", "verdict", "modelled",
                                                      "n_inside", "time_s")}
                             | {k2: row[k2] for k2 in ("gap", "slew") if k2 in row}),
                  flush=True)


if __name__ == "__main__":
    main()
