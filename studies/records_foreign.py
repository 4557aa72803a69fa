"""Issue 29: one diagnosis across three speeds, on the foreign generator.

The groups are those of studies/joint_foreign.py: one rotor, its effect drawn and concealed
once at the nominal speed, recorded at 0.65, 0.8 and 1.0 x 31 500 rpm with its own habits
per record. Each group is diagnosed as a user would: `diagnose_records` with default
options. Scored here, the only place the truth is read:

- the group's names: every physics effect named with confidence in at least one record,
  or named by the records together (records.joint_search), whose size, where it was
  fitted in two or more records, agrees across them (records.py), and which is not a place
  the records favour less than another for the same effect by more than 3 nats
  (records.prefer_locations);
  right when it names the truth's effect (benchmarks/foreign/benchmark.accepted_names);
- clean: an effect-free group whose records all end as "no mismatch" with no name;
- per record: whether that record alone named the truth (a group where one record alone
  misses it is one where the records together have to make up for it);
- time: the whole diagnose_records call over the sum of its records' own diagnosis times.

    PYTHONPATH=. python studies/records_foreign.py --out runs/records \
        --groups unbalance=4,runout=4,cross_coupling=4,control=6
    PYTHONPATH=. python studies/records_foreign.py --out runs/records_weak --band 0.1,0.3 \
        --groups unbalance=4,runout=4,cross_coupling=4
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from bayes_amb.discrepancy.records import diagnose_records
from bayes_amb.io.atomic import write_text_atomic
from bayes_amb.io.nonfinite import plain, result_json_text
from bayes_amb.io.recording import load_recording
from benchmarks.foreign.benchmark import _controller_file, accepted_names
from studies.joint_foreign import (
    append_row,
    done_groups,
    rows_by_kind,
    write_group,
    write_summary,
)


def _keys(key: str) -> set[str]:
    return {key, key.split("@")[0] + "@*"}


THRESHOLD = 3.0
"""A place the records favour less by more than this (summed log BF, nats; the search's
threshold) is not the group's name for the effect (records.prefer_locations)."""


def group_names(result: dict[str, Any], reports: list[dict[str, Any]]) -> list[str]:
    """The group's names (module doc) from records.json and the records' diagnoses."""
    confident = {f"{e['effect']}@{e['location']}" for r in reports for e in r["explanations"]
                 if e.get("kind", "physics") == "physics"
                 and e.get("confidence") == "confident"}
    return [row["effect"] for row in result["across"]
            if (row["effect"] in confident or row.get("named_jointly"))
            and (row.get("size") is None or row["size"]["agree"])
            and not (row.get("weaker_by") or 0.0) > THRESHOLD]


def score(truth: dict[str, Any], result: dict[str, Any], reports: list[dict[str, Any]]
          ) -> dict[str, Any]:
    targets = [accepted_names(e) for e in truth["effects"]]
    names = group_names(result, reports)
    right = [any(_keys(n) & t for n in names) for t in targets]
    wrong = [n for n in names if not any(_keys(n) & t for t in targets)]
    per_record = [all(any(_keys(f"{e['effect']}@{e['location']}") & t
                          for e in r["explanations"]) for t in targets) for r in reports]
    return {"effects": [e["name"] for e in truth["effects"]], "names": names,
            "right": bool(targets) and all(right), "wrong": wrong,
            "clean": not targets and not names
            and all(r["verdict"] == "no mismatch" for r in reports),
            "records_right": per_record,
            "sizes": {row["effect"]: row.get("size") and row["size"]["agree"]
                      for row in result["across"]}}


def run(out: Path, groups: dict[str, int], seed: int,
        band: tuple[float, float] = (0.2, 1.0)) -> None:
    (out / "records").mkdir(parents=True, exist_ok=True)
    ctrl = _controller_file(out, 1e-4)
    rows_path = out / "rows.jsonl"
    done = done_groups(rows_path)
    for kind, count in groups.items():
        for g in range(count):
            name = f"{kind}_{g:02d}"
            if name in done:
                continue
            paths = write_group(out, kind, g, seed, ctrl, band)
            recs = [load_recording(p) for p in paths]
            t0 = time.perf_counter()
            res = diagnose_records(recs)
            wall = time.perf_counter() - t0
            reports = [d.to_dict() for d in res.diagnoses]
            result = plain(res.to_dict(), float)
            write_text_atomic(out / "records" / f"{name}.json", result_json_text(result))
            truth = json.loads(paths[0].with_suffix(".truth.json").read_text())
            row = {"group": name, "kind": kind, "wall_s": wall,
                   "single_s": float(sum(r["wall_s"] for r in reports)),
                   "verdicts": [r["verdict"] for r in reports],
                   **score(truth, result, reports)}
            append_row(rows_path, row)
            print(f"{name}: names {row['names']} right={row['right']} wrong={row['wrong']} "
                  f"records right {row['records_right']} time x{wall / row['single_s']:.2f}",
                  flush=True)
    summarise(out)


def summarise(out: Path) -> dict[str, Any]:
    _, by_kind = rows_by_kind(out)
    lines = ["| kind: groups | named right | wrong names | clean | a record alone missed "
             "it | time / sum of single |", "|---|---|---|---|---|---|"]
    table = {}
    for kind, rs in by_kind.items():
        effect = kind != "control"
        ratio = [r["wall_s"] / r["single_s"] for r in rs]
        t = {"groups": len(rs), "right": sum(r["right"] for r in rs),
             "wrong": sum(bool(r["wrong"]) for r in rs), "clean": sum(r["clean"] for r in rs),
             "ambiguous": sum(not all(r["records_right"]) for r in rs),
             "time_ratio_max": float(max(ratio)), "time_ratio_median": float(np.median(ratio))}
        table[kind] = t
        lines.append(f"| {kind}: {len(rs)} | {t['right'] if effect else '–'} | {t['wrong']} | "
                     f"{'–' if effect else t['clean']} | "
                     f"{t['ambiguous'] if effect else '–'} | {t['time_ratio_median']:.2f} "
                     f"(max {t['time_ratio_max']:.2f}) |")
    write_summary(out, lines, table)
    return table


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--groups", default="unbalance=4,runout=4,cross_coupling=4,control=6")
    ap.add_argument("--seed", type=int, default=29)
    ap.add_argument("--band", default="0.2,1.0", metavar="LO,HI",
                    help="concealment band of the effects at the nominal speed (default "
                         "0.2,1.0, the generator's; 0.1,0.3 makes groups where a record "
                         "alone misses the effect)")
    ap.add_argument("--summary-only", action="store_true")
    a = ap.parse_args(argv)
    if a.summary_only:
        summarise(a.out)
        return 0
    lo, hi = (float(v) for v in a.band.split(","))
    run(a.out, {k: int(v) for k, v in (p.split("=") for p in a.groups.split(","))}, a.seed,
        (lo, hi))
    return 0


if __name__ == "__main__":
    sys.exit(main())
