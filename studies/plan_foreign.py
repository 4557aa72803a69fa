"""Issue 30: the plan on the foreign generator's records.

For each effect-free foreign record of a benchmark run (benchmarks/foreign/benchmark.py with
--identify), the plan is made as a user with that rig would make it: the record's rig,
controller, speed and dt, its excitation (a random binary of the record's amplitude at its
port, on the channels it excites, its length), and its noise as `--noise-from` takes it
(planning.noise_from: the white intensities identify fits on it and the colour of its
residual; --white: the intensities alone, as before the colour). The predicted posterior
sd is compared with the sd identify reported on that record, and the estimates' errors
(truth read only here) with the predicted sd and the predicted spread of the estimates,
per coefficient over the records where the plan calls it informed (the first-order
prediction is claimed nowhere else; how many of the others identify put on a prior bound
is counted).

    PYTHONPATH=. python studies/plan_foreign.py runs/f27 --kinds control,control_force \
        [--at-map] [--white] [--[no-]initial-state] [--identify-dir identify] [--json OUT.json] \
        [--shard i/n]        # shards' JSONs scored together: --merge A.json B.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from bayes_amb.io.recording import Recording, load_recording
from bayes_amb.planning import Design, Noise, Plan, plan
from bayes_amb.planning.plan import BEARING_COEFFICIENTS, noise_from


def user_plan(rec: Recording, s: dict, white: bool = False, at_map: bool = True,
              initial_state: bool | None = None) -> Plan:
    """The plan a user with this record makes for a record like it: its rig, controller,
    speed and dt, its excitation (a random binary of its amplitude at its port, on the
    channels it excites, its length), its noise as --noise-from takes it (--white: the
    white intensities identify fitted, ``s`` being identify's summary), at identify's MAP
    (``at_map``) or the nominal."""
    x = next(iter(rec.excitation.values()))
    n = s["noise"]["map"]
    live = tuple(c for c, v in zip(("Ax", "Ay", "Bx", "By"), np.abs(x).max(axis=0),
                                   strict=True) if v > 0)
    design = Design(excitation="random-binary", amplitude=float(np.max(np.abs(x))),
                    duration=rec.t.size * rec.dt, dt=rec.dt, port=s["excitation_port"],
                    channels=None if len(live) == 4 else live)
    noise = (Noise(noise_rms=n["sigma_noise"]["value"], r1_rms=n["sigma_r1"]["value"],
                   r2_rms=n["sigma_r2"]["value"]) if white
             else noise_from(rec, initial_state))
    at = s["map"] if at_map else None     # the user's estimate from that record
    return plan(rec.rig, rec.controller, design, noise, speed_rpm=rec.speed_rpm, theta=at)


def check(run: Path, kinds: list[str], white: bool = False, at_map: bool = False,
          identify_dir: str = "identify", initial_state: bool | None = None,
          shard: tuple[int, int] = (0, 1)) -> dict:
    rows = []
    for j, ident in enumerate(sorted((run / identify_dir).glob("*.json"))):
        if j % shard[1] != shard[0]:
            continue
        name = ident.stem
        if name.rsplit("_", 1)[0] not in kinds:
            continue
        s = json.loads(ident.read_text())
        rec = load_recording(run / "recordings" / f"{name}.csv")
        p = user_plan(rec, s, white, at_map, initial_state)
        truth = json.loads((run / "recordings" / f"{name}.truth.json").read_text())["theta"]
        par = s.get("parameters_model_only", s["parameters"])
        if any(par[k]["sd"] is None for k in BEARING_COEFFICIENTS):
            continue                        # identify's Laplace failed on this record
        bound = set((s.get("identifiability") or {}).get("at_prior_bound", []))
        rows.append({"name": name, **{k: {
            "informed": p.parameters[k]["informed"], "at_prior_bound": k in bound,
            "predicted_sd": p.sd(k), "reported_sd": par[k]["sd"],
            "predicted_spread": p.parameters[k]["sd_of_estimates"],
            "z": (par[k]["mean"] - truth[k]) / p.parameters[k]["sd_of_estimates"],
            "z_sd": (par[k]["mean"] - truth[k]) / p.sd(k)}
            for k in BEARING_COEFFICIENTS}})
    return aggregate(rows)


def aggregate(rows: list[dict]) -> dict:
    """Per coefficient, over the records where the plan calls it informed: identify's sd
    over the predicted and the scaled errors (module docstring); ``rows`` as check makes
    them (several shards' rows may be joined)."""
    out = {"n": len(rows), "rows": rows, "parameters": {}}
    for k in BEARING_COEFFICIENTS:
        # the plan's first-order prediction is for what it calls informed; a record whose
        # identify put such a coefficient on its prior bound counts against it
        use = [r for r in rows if r[k]["informed"]]
        if len(use) < 2:
            out["parameters"][k] = {"informed_records": len(use)}
            continue
        ratio = np.array([r[k]["reported_sd"] / r[k]["predicted_sd"] for r in use])
        z = np.array([r[k]["z"] for r in use])
        z_sd = np.array([r[k]["z_sd"] for r in use])
        spread = np.array([r[k]["predicted_spread"] / r[k]["predicted_sd"] for r in use])
        out["parameters"][k] = {"informed_records": len(use),
                                "at_bound_though_informed": sum(r[k]["at_prior_bound"]
                                                                for r in use),
                                "uninformed_at_bound": sum(r[k]["at_prior_bound"]
                                                           for r in rows
                                                           if not r[k]["informed"]),
                                "median_ratio": float(np.median(ratio)),
                                "ratio_range": [float(ratio.min()), float(ratio.max())],
                                "sd_of_z": float(np.std(z, ddof=1)),
                                "sd_of_z_sd": float(np.std(z_sd, ddof=1)),
                                "median_spread_over_sd": float(np.median(spread))}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--kinds", default="control")
    ap.add_argument("--white", action="store_true",
                    help="plan with the fitted white intensities alone (no measured colour)")
    ap.add_argument("--at-map", action="store_true",
                    help="plan at identify's MAP on the record (default: at the nominal)")
    ap.add_argument("--identify-dir", default="identify",
                    help="the folder of RUN holding identify's summaries")
    ap.add_argument("--json", type=Path, help="also write the rows and figures here")
    ap.add_argument("--initial-state", action=argparse.BooleanOptionalAction,
                    default=None,
                    help="fit the start transient or not (default: as identify decides)")
    ap.add_argument("--shard", default="0/1",
                    help="i/n: every n-th record from the i-th (merge the JSONs with "
                    "--merge)")
    ap.add_argument("--merge", type=Path, nargs="*", default=None,
                    help="score the rows of these --json files together instead")
    a = ap.parse_args()
    i, n = (int(x) for x in a.shard.split("/"))
    if a.merge:
        r = aggregate([row for f in a.merge for row in json.loads(f.read_text())["rows"]])
    else:
        r = check(a.run, a.kinds.split(","), a.white, a.at_map, a.identify_dir,
                  a.initial_state, (i, n))
    if a.json:
        a.json.write_text(json.dumps(r, indent=1))
    print(f"{r['n']} records")
    for k, v in r["parameters"].items():
        if "median_ratio" not in v:
            print(f"{k}: informed in {v['informed_records']} records")
            continue
        print(f"{k}: informed in {v['informed_records']} records ("
              f"{v['at_bound_though_informed']} of them at a prior bound in identify; "
              f"uninformed and at a bound {v['uninformed_at_bound']}); "
              f"reported / predicted sd median {v['median_ratio']:.2f} "
              f"(range {v['ratio_range'][0]:.2f}-{v['ratio_range'][1]:.2f}), sd of "
              f"(estimate - truth) / predicted sd {v['sd_of_z_sd']:.2f}, sd of "
              f"(estimate - truth) / predicted spread {v['sd_of_z']:.2f} (predicted spread "
              f"/ predicted sd, median {v['median_spread_over_sd']:.2f})")


if __name__ == "__main__":
    main()
