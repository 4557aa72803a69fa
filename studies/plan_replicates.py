"""Issue 30: the plan against replicate recordings of one foreign case.

The Done-when asks for the predicted sd against the empirical sd of the posterior mean over
recordings of one design. Here those recordings come from the benchmark's foreign generator
(benchmarks/foreign, written apart from the library): one case (its bearings, the sizes and
colour of its noise, lines and disturbances, its excitation channels) is drawn as the
benchmark draws case CASE of KIND at SEED, and REPS recordings of it are simulated, each
with its own noise, excitation, line phases, r1/r2 and burn-in. Each is identified
(``identify --map-only`` without the adequacy test, as studies/plan_check.py does;
``--[no-]initial-state``: the record's start transient fitted or not, plan and identify) and
compared with the plan a user makes from the first replicate (plan_foreign.user_plan: its
rig, controller, excitation, its noise and colour as ``--noise-from`` measures them, at its
MAP):

- the predicted sd (what identify will report) against the mean reported sd;
- the predicted spread of the estimates and the predicted sd against the empirical sd of
  the estimates over the replicates (sampling sd of that ratio 1/sqrt(2 (REPS - 1)));
- the estimates' mean bias, in standard errors (the truth is read here only, to score).

Only coefficients the plan calls first-order informed are held to the 25 % tolerance
(elsewhere it says its prediction does not hold); the others are listed.

    PYTHONPATH=. python studies/plan_replicates.py --out runs/plan_rep \\
        --kinds control,control_force,control_one_channel --cases 0,1 --seed 11 --reps 50 \\
        --shard 0/2          # and 1/2 beside it; then --score-only for the table
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.io.atomic import write_text_atomic
from bayes_amb.io.recording import load_recording
from bayes_amb.planning.plan import BEARING_COEFFICIENTS
from benchmarks.foreign.benchmark import _controller_file, kind_number
from benchmarks.foreign.cases import draw_case, write_case

sys.path.insert(0, str(Path(__file__).parent))
from plan_foreign import user_plan

TOLERANCE = 0.25


def case_dir(out: Path, kind: str, case: int) -> Path:
    return out / f"{kind}_{case:02d}"


def simulate_and_identify(out: Path, kind: str, case: int, seed: int, reps: int,
                          shard: tuple[int, int], initial_state: bool | None = None) -> None:
    """Replicates of the case, each identified; a replicate already identified is kept."""
    where = case_dir(out, kind, case)
    where.mkdir(parents=True, exist_ok=True)
    ctrl = _controller_file(out, 1e-4)
    spec = draw_case(kind, np.random.default_rng([seed, case, kind_number(kind)]),
                     controller_file=str(ctrl))
    for r in range(reps):
        dest = where / f"rep{r:03d}.identify.json"
        if r % shard[1] != shard[0] or dest.exists():
            continue
        t0 = time.perf_counter()
        paths = write_case(spec, where, f"rep{r:03d}",
                           np.random.default_rng([seed, case, kind_number(kind), 1000 + r]))
        res = identify(load_recording(paths["csv"]), list(BEARING_COEFFICIENTS),
                       options=IdentifyOptions(map_only=True, adequacy=False,
                                               initial_state=initial_state))
        write_text_atomic(dest, json.dumps(res.to_dict(), default=float))
        print(f"{where.name} rep{r:03d} {time.perf_counter() - t0:.1f} s", flush=True)


def score_case(where: Path, initial_state: bool | None = None) -> dict:
    """The plan from the first replicate against all of them (module docstring)."""
    done = sorted(where.glob("rep*.identify.json"))
    if len(done) < 3:
        return {"replicates": len(done)}
    first = done[0].name.split(".")[0]
    p = user_plan(load_recording(where / f"{first}.csv"), json.loads(done[0].read_text()),
                  initial_state=initial_state)
    truth = json.loads((where / f"{first}.truth.json").read_text())["theta"]
    sums = [json.loads(f.read_text()) for f in done]
    out = {"replicates": len(sums), "parameters": {}}
    for k in BEARING_COEFFICIENTS:
        v = p.parameters[k]
        rows = [s["parameters"][k] for s in sums if s["parameters"][k]["sd"] is not None]
        est = np.array([r["mean"] for r in rows])
        sd = np.array([r["sd"] for r in rows])
        emp = float(np.std(est, ddof=1))
        out["parameters"][k] = {
            "first_order": bool(v["first_order"]), "informed": bool(v["informed"]),
            "n": len(rows), "predicted_sd": v["sd"], "predicted_spread": v["sd_of_estimates"],
            "mean_reported_sd": float(sd.mean()), "empirical_sd": emp,
            "reported_over_predicted": float(sd.mean() / v["sd"]),
            "empirical_over_predicted_sd": emp / v["sd"],
            "empirical_over_predicted_spread": emp / v["sd_of_estimates"],
            "bias_in_se": float((est.mean() - truth[k]) / (emp / np.sqrt(len(rows))))}
    return out


def score(out: Path, kinds: list[str], cases: list[int], initial_state: bool | None = None
          ) -> dict:
    table = {f"{kind}_{c:02d}": score_case(case_dir(out, kind, c), initial_state)
             for kind in kinds for c in cases}
    write_text_atomic(out / "summary.json", json.dumps(table, indent=1))
    lines = ["| case | coefficient | n | reported / predicted sd | empirical sd / predicted "
             "sd | empirical sd / predicted spread | bias (se) |", "|---|---|---|---|---|---|---|"]
    worst = 0.0
    for name, c in table.items():
        for k, v in c.get("parameters", {}).items():
            if not v["first_order"]:
                continue
            r = (v["reported_over_predicted"], v["empirical_over_predicted_sd"],
                 v["empirical_over_predicted_spread"])
            worst = max(worst, *(abs(x - 1.0) for x in r))
            lines.append(f"| {name} | {k} | {v['n']} | {r[0]:.2f} | {r[1]:.2f} | {r[2]:.2f} "
                         f"| {v['bias_in_se']:+.1f} |")
    lines.append(f"\nworst |ratio - 1| over first-order coefficients: {worst:.2f} "
                 f"(tolerance {TOLERANCE:g})")
    write_text_atomic(out / "summary.md", "\n".join(lines) + "\n")
    print("\n".join(lines))
    return table


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--kinds", default="control,control_force,control_one_channel")
    ap.add_argument("--cases", default="0,1")
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--reps", type=int, default=50)
    ap.add_argument("--shard", default="0/1")
    ap.add_argument("--score-only", action="store_true")
    ap.add_argument("--initial-state", action=argparse.BooleanOptionalAction,
                    default=None,
                    help="fit the start transient or not (default: as identify decides)")
    a = ap.parse_args()
    kinds = [k for k in a.kinds.split(",") if k]
    cases = [int(c) for c in a.cases.split(",")]
    if not a.score_only:
        i, n = (int(x) for x in a.shard.split("/"))
        for kind in kinds:
            for c in cases:
                simulate_and_identify(a.out, kind, c, a.seed, a.reps, (i, n),
                                      a.initial_state)
    if a.score_only or a.shard.split("/")[0] == "0":
        score(a.out, kinds, cases, a.initial_state)


if __name__ == "__main__":
    main()
