"""identify and diagnose on ROSS's real AMB test rig, recorded by a generator written apart
from the tool (benchmarks/foreign/ross_rig.py: ROSS's own M, K, C, G, its two controllers
discretised by Tustin, r2 excitation, the DAQ habits), with the user's defaults.

Each record in RUN (written by ``python -m benchmarks.foreign.ross_rig --out RUN ...``) is
identified (``--map-only`` unless --sampled) and diagnosed; results go to RUN/OUT/NAME.json
(resumable: a record already there is skipped). Scored per family, reading the truth only
after the tool has answered: the eight bearing coefficients inside their 90 % intervals,
the median interval width over the prior's, and for the diagnosis the verdict and the
names (an actuator lag and the unbalance should be named; nothing with confidence on the
control records).

    PYTHONPATH=. python -m benchmarks.foreign.ross_rig --out runs/rr \\
        --kinds control=6,actuator_lag=6,unbalance=6,probe_angle=4 --duration 1 --seed 1
    PYTHONPATH=. python studies/ross_rig_foreign.py runs/rr --out res
    PYTHONPATH=. python studies/ross_rig_foreign.py runs/rr --out res --score-only
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

COEFFICIENTS = ("k_Ax", "k_Ay", "k_Bx", "k_By", "c_Ax", "c_Ay", "c_Bx", "c_By")
NAMED = {"actuator_lag": ("actuator_lag", "actuator_2nd"), "unbalance": ("unbalance",)}


def run_one(csv: Path, sampled: bool, diagnose_too: bool) -> dict:
    from bayes_amb import IdentifyOptions, diagnose, identify
    from bayes_amb.io.recording import load_recording

    rec = load_recording(csv)
    t0 = time.perf_counter()
    fit = identify(rec, ",".join(COEFFICIENTS), options=IdentifyOptions(map_only=not sampled))
    out = {"identify": {"wall_s": time.perf_counter() - t0,
                        "model": fit.model.line if fit.model else None,
                        "adequacy": fit.adequacy.line if fit.adequacy else None,
                        "parameters": {n: [p.mean, p.sd, *p.hdi90]
                                       for n, p in fit.parameters.items()}}}
    if diagnose_too:
        t0 = time.perf_counter()
        d = diagnose(rec)
        out["diagnose"] = {
            "wall_s": time.perf_counter() - t0, "verdict": d.verdict,
            "named": [[e.effect, e.location, e.confidence] for e in d.explanations],
            "parameters": {n: [c.mean, c.sd, *c.hdi90] for n, c in d.parameters_after.items()}}
    return out


def score(run: Path, res: Path) -> None:
    index = json.loads((run / "index.json").read_text())
    fams: dict[str, list] = {}
    for case in index:
        f = res / f"{case['name']}.json"
        if f.exists():
            fams.setdefault(case["kind"], []).append((case, json.loads(f.read_text())))
    print("| family | records | identify covered | identify width / prior | diagnose covered |"
          " diagnose width / prior | verdicts | named (confident) |")
    print("|---|---|---|---|---|---|---|---|")
    for kind, rows in fams.items():
        line = [kind, str(len(rows))]
        for stage in ("identify", "diagnose"):
            inside, widths = 0, []
            n = 0
            for case, r in rows:
                if stage not in r:
                    continue
                for c in COEFFICIENTS:
                    _, _, lo, hi = r[stage]["parameters"][c]
                    inside += lo <= case["theta"][c] <= hi
                    widths.append((hi - lo) / PRIOR_90)
                    n += 1
            line += [f"{inside}/{n}" if n else "-",
                     f"{np.median(widths):.3f}" if widths else "-"]
        verdicts = [r["diagnose"]["verdict"] for _, r in rows if "diagnose" in r]
        named = [";".join(f"{e}@{loc}" for e, loc, conf in r["diagnose"]["named"]
                          if conf == "confident") or "-" for _, r in rows if "diagnose" in r]
        line += [", ".join(f"{v} {verdicts.count(v)}" for v in dict.fromkeys(verdicts)),
                 " / ".join(named)]
        print("| " + " | ".join(line) + " |")
        want = NAMED.get(kind)
        if want:
            hit = sum(any(e in want for e, _, _ in r["diagnose"]["named"])
                      for _, r in rows if "diagnose" in r)
            print(f"|  | {kind} named | {hit}/{len(verdicts)} | | | | | |")


PRIOR_90 = 1.44
"""Width of the default bearing-coefficient prior's 90 % interval (uniform(-0.8, 0.8))."""


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("run")
    ap.add_argument("--out", default="res")
    ap.add_argument("--sampled", action="store_true")
    ap.add_argument("--identify-only", action="store_true")
    ap.add_argument("--score-only", action="store_true")
    a = ap.parse_args()
    run = Path(a.run)
    res = run / a.out
    res.mkdir(exist_ok=True)
    if not a.score_only:
        for case in json.loads((run / "index.json").read_text()):
            f = res / f"{case['name']}.json"
            if f.exists():
                continue
            out = run_one(run / case["csv"], a.sampled, not a.identify_only)
            tmp = f.with_suffix(".tmp")
            tmp.write_text(json.dumps(out))
            tmp.replace(f)
            print(case["name"], out["identify"]["wall_s"],
                  out.get("diagnose", {}).get("verdict"), flush=True)
    score(run, res)


if __name__ == "__main__":
    main()
