"""Coverage of identify's intervals on foreign recordings, with the noise check's sandwich
and without it (inference/noise_check.py; README, "Noise that is not white").

Identifies every STEP-th recording of KIND in RUN/recordings (written by the foreign
benchmark, with its .truth.json beside each), with identify's defaults or --map-only, into
RUN/OUT/NAME.json (resumable: a record already there is skipped), then scores the eight
bearing coefficients: inside the reported 90 % interval, inside the white model's
(``parameters_white_noise``), and both by how far the sandwich moved the sd.

    PYTHONPATH=. python studies/noise_check_foreign.py runs/cf50 --kind control_force \\
        --step 4 --out identify_sampled --shard 0/2      # and 1/2 beside it
    PYTHONPATH=. python studies/noise_check_foreign.py runs/cf50 --kind control_force \\
        --step 4 --out identify_sampled --score-only

The truth is read only to score, after identify has written its result.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.io.atomic import write_text_atomic
from bayes_amb.io.nonfinite import plain, result_json_text
from bayes_amb.io.recording import load_recording
from benchmarks.foreign.benchmark import COEFFICIENTS

BUCKETS = ((0.0, 0.8), (0.8, 0.9), (0.9, 1.1), (1.1, 1.25), (1.25, float("inf")))


def _records(run: Path, kind: str, step: int) -> list[Path]:
    csvs = sorted((run / "recordings").glob(f"{kind}_*.csv"),
                  key=lambda p: int(p.stem.rsplit("_", 1)[-1]))
    return csvs[::step]


def identify_all(run: Path, kind: str, step: int, out: str, map_only: bool, shard: int,
                 n_shards: int, initial_state: bool | None = None) -> None:
    for k, csv in enumerate(_records(run, kind, step)):
        dest = run / out / f"{csv.stem}.json"
        if k % n_shards != shard or dest.exists():
            continue
        t0 = time.perf_counter()
        res = identify(load_recording(csv), list(COEFFICIENTS),
                       options=IdentifyOptions(map_only=map_only,
                                               initial_state=initial_state))
        dest.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(dest, result_json_text(plain(res.to_dict(), float)))
        print(csv.stem, f"{time.perf_counter() - t0:.1f} s", "converged" if res.converged
              else "NOT converged", flush=True)


def _inside(row: dict, t: float) -> bool:
    return row["hdi90"][0] <= t <= row["hdi90"][1]


def score(run: Path, kind: str, step: int, out: str) -> dict:
    """Per coefficient and in all: inside the reported and the white intervals; per bucket
    of the sandwich's sd ratio, the same (coefficients on a prior bound left out there)."""
    total = {"reported": 0, "white": 0, "n": 0}
    per: dict[str, dict[str, int]] = {}
    buckets = {f"{lo:g}-{hi:g}": {"reported": 0, "white": 0, "n": 0} for lo, hi in BUCKETS}
    records = doubted = 0
    for csv in _records(run, kind, step):
        path = run / out / f"{csv.stem}.json"
        if not path.exists():
            continue
        s = json.loads(path.read_text())
        truth = json.loads(csv.with_suffix(".truth.json").read_text())["theta"]
        check = s.get("noise", {}).get("check") or {}
        ratio = check.get("sd_ratio") or {}
        records += 1
        doubted += bool(check.get("doubted"))
        white = s.get("parameters_white_noise") or s["parameters"]
        bound = set((s.get("identifiability") or {}).get("at_prior_bound", []))
        for n, row in s["parameters"].items():
            got = {"reported": _inside(row, truth[n]), "white": _inside(white[n], truth[n])}
            for d in (total, per.setdefault(n, {"reported": 0, "white": 0, "n": 0})):
                d["reported"] += got["reported"]
                d["white"] += got["white"]
                d["n"] += 1
            if n in bound:
                continue
            r = ratio.get(n, 1.0)
            for lo, hi in BUCKETS:
                if lo <= r < hi:
                    b = buckets[f"{lo:g}-{hi:g}"]
                    b["reported"] += got["reported"]
                    b["white"] += got["white"]
                    b["n"] += 1
    return {"records": records, "doubted": doubted, "all": total, "per_coefficient": per,
            "by_sd_ratio": buckets}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--kind", required=True)
    ap.add_argument("--step", type=int, default=1)
    ap.add_argument("--out", default="identify_noise_check")
    ap.add_argument("--map-only", action="store_true")
    ap.add_argument("--initial-state", action=argparse.BooleanOptionalAction,
                    default=None,
                    help="fit the start transient or not (default: as identify decides)")
    ap.add_argument("--shard", default="0/1")
    ap.add_argument("--score-only", action="store_true")
    a = ap.parse_args()
    if not a.score_only:
        i, n = (int(v) for v in a.shard.split("/"))
        identify_all(a.run, a.kind, a.step, a.out, a.map_only, i, n, a.initial_state)
    result = score(a.run, a.kind, a.step, a.out)
    print(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
