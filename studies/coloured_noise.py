"""Coverage and width of identify's intervals on foreign records with coloured noise (issue 46).

Writes N records of each KIND with the foreign generator (benchmarks/foreign, written apart
from the tool) into RUN/recordings, identifies the eight bearing coefficients of each with
the user's defaults (``--map-only`` for MAP with Laplace) into RUN/OUT/NAME.json
(resumable: a record already there is skipped), then scores per kind: the share of the
coefficients inside their 90 % intervals, the median interval width, and, where the
generator's oracle is there (benchmarks/foreign/oracle.py, apart from the tool), the
median of width / the Cramer-Rao width of the true disturbance spectrum.

    PYTHONPATH=. python studies/coloured_noise.py runs/c46 --kinds coloured_r2=8,mains=8 \\
        --write-only
    PYTHONPATH=. python studies/coloured_noise.py runs/c46 --kinds coloured_r2=8,mains=8 \\
        --out map --map-only
    PYTHONPATH=. python studies/coloured_noise.py runs/c46 --kinds coloured_r2=8,mains=8 \\
        --out map --score-only

The tool before a change is run on the same records from a checkout of it:
``cd /tmp/base && PYTHONPATH=/tmp/base python /path/to/studies/coloured_noise.py RUN
--kinds ... --out map_base --map-only`` (only the identification imports the tool). The
truth is read only to score, after identify has written its result.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

COEFFICIENTS = ("k_Ax", "k_Ay", "k_Bx", "k_By", "c_Ax", "c_Ay", "c_Bx", "c_By")
SEED = 46


def _kinds(text: str) -> dict[str, int]:
    out = {}
    for part in text.split(","):
        k, _, n = part.partition("=")
        out[k.strip()] = int(n or 1)
    return out


def _names(kinds: dict[str, int]) -> list[str]:
    return [f"{k.replace(':', '_').replace('+', '_')}_{i:02d}" for k, n in kinds.items()
            for i in range(n)]


ORACLE_BAND_HZ = 514.0
"""The top of the band identify's likelihood uses on the reference rig (the 8-state model's
validity band at its nominal speed): the oracle is also taken up to it."""


def write_records(run: Path, kinds: dict[str, int], duration: float) -> None:
    """The records (csv, json, truth.json) and the oracle's Cramer-Rao half-widths of each
    (NAME.oracle.json: to Nyquist, ``half_width``, and to ORACLE_BAND_HZ,
    ``half_width_band``), for those not written yet."""
    from benchmarks.foreign import draw_case, write_case
    from benchmarks.foreign.benchmark import _controller_file
    from benchmarks.foreign.oracle import fisher_information, spec_from_truth

    run.mkdir(parents=True, exist_ok=True)
    ctrl = _controller_file(run, 1e-4)
    for j, (kind, n) in enumerate(kinds.items()):
        for i in range(n):
            name = f"{kind.replace(':', '_').replace('+', '_')}_{i:02d}"
            rec = run / "recordings" / f"{name}.csv"
            if not rec.exists():
                rng = np.random.default_rng([SEED, j, i])
                spec = draw_case(kind, rng, controller_file=str(ctrl), duration_s=duration)
                write_case(spec, run / "recordings", name, rng)
                print("wrote", name, flush=True)
            dest = run / "recordings" / f"{name}.oracle.json"
            if dest.exists():
                continue
            truth = json.loads((run / "recordings" / f"{name}.truth.json").read_text())
            fb = fisher_information(spec_from_truth(truth, str(ctrl)))
            full, band = fb.widths(), fb.widths(f_max_hz=ORACLE_BAND_HZ)
            dest.write_text(json.dumps({"half_width": full["half_width"],
                                        "half_width_band": band["half_width"]},
                                       default=float))


def identify_all(run: Path, kinds: dict[str, int], out: str, map_only: bool, shard: int,
                 n_shards: int, diagnose: bool = False) -> None:
    """identify (or with ``diagnose``, diagnose: its verdict, names and the coefficients
    after, as ``parameters``) of every record, into RUN/OUT/NAME.json."""
    from bayes_amb.inference.identify import IdentifyOptions, identify
    from bayes_amb.io.atomic import write_text_atomic
    from bayes_amb.io.nonfinite import plain, result_json_text
    from bayes_amb.io.recording import load_recording

    for k, name in enumerate(_names(kinds)):
        dest = run / out / f"{name}.json"
        if k % n_shards != shard or dest.exists():
            continue
        t0 = time.perf_counter()
        rec = load_recording(run / "recordings" / f"{name}.csv")
        if diagnose:
            from bayes_amb.discrepancy.diagnose import diagnose as run_diagnose
            dg = run_diagnose(rec).to_dict()
            d = {"verdict": dg["verdict"], "parameters": dg["parameters_after"],
                 "explanations": [f"{e['effect']}@{e['location']}"
                                  for e in dg["explanations"]]}
        else:
            d = identify(rec, list(COEFFICIENTS),
                         options=IdentifyOptions(map_only=map_only)).to_dict()
        d["study_wall_s"] = time.perf_counter() - t0
        dest.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(dest, result_json_text(plain(d, float)))
        print(name, f"{d['study_wall_s']:.1f} s", flush=True)


def _oracle_half(run: Path, name: str) -> dict[str, float] | None:
    p = run / "recordings" / f"{name}.oracle.json"
    if not p.exists():
        return None
    w = json.loads(p.read_text())
    return w.get("half_width_band") or w.get("half_width") or w


def score(run: Path, kinds: dict[str, int], out: str) -> dict[str, dict[str, float]]:
    """Per kind: coverage (inside / n), median width (theta units, k and c apart), median
    width over the oracle's, median wall time."""
    table = {}
    for kind in kinds:
        stem = kind.replace(":", "_").replace("+", "_")
        inside = n = 0
        wk, wc, ratio, wall = [], [], [], []
        verdicts: dict[str, int] = {}
        for name in [m for m in _names(kinds) if m.rsplit("_", 1)[0] == stem]:
            p = run / out / f"{name}.json"
            if not p.exists():
                continue
            s = json.loads(p.read_text())
            truth = json.loads((run / "recordings" / f"{name}.truth.json").read_text())["theta"]
            oracle = _oracle_half(run, name)
            wall.append(s.get("study_wall_s", s.get("wall_s", np.nan)))
            if "verdict" in s:
                verdicts[s["verdict"]] = verdicts.get(s["verdict"], 0) + 1
            for c in COEFFICIENTS:
                row = s["parameters"][c]
                lo, hi = row["hdi90"]
                n += 1
                inside += lo <= truth[c] <= hi
                (wk if c.startswith("k") else wc).append(hi - lo)
                if oracle is not None and c in oracle and oracle[c] and np.isfinite(oracle[c]):
                    ratio.append((hi - lo) / (2 * oracle[c]))
        if n:
            table[kind] = {"records": n // len(COEFFICIENTS), "coverage": inside / n,
                           "inside": inside, "n": n,
                           "median_width_k": float(np.median(wk)),
                           "median_width_c": float(np.median(wc)),
                           "median_width_over_oracle": float(np.median(ratio)) if ratio
                           else float("nan"),
                           "median_wall_s": float(np.median(wall)),
                           **({"verdicts": verdicts} if verdicts else {})}
    return table


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--kinds", required=True, help="kind=n,... (foreign generator kinds)")
    ap.add_argument("--duration", type=float, default=2.0)
    ap.add_argument("--out", default="map")
    ap.add_argument("--map-only", action="store_true")
    ap.add_argument("--diagnose", action="store_true",
                    help="diagnose instead of identify (verdicts scored too)")
    ap.add_argument("--shard", default="0/1")
    ap.add_argument("--write-only", action="store_true")
    ap.add_argument("--score-only", action="store_true")
    a = ap.parse_args(argv)
    kinds = _kinds(a.kinds)
    if a.write_only:
        write_records(a.run, kinds, a.duration)
        return 0
    if not a.score_only:
        shard, n_shards = (int(v) for v in a.shard.split("/"))
        identify_all(a.run, kinds, a.out, a.map_only, shard, n_shards, a.diagnose)
    table = score(a.run, kinds, a.out)
    print(f"{'kind':28s} {'records':>7s} {'coverage':>14s} {'width k':>9s} {'width c':>9s} "
          f"{'/oracle':>8s} {'wall s':>7s}")
    for k, r in table.items():
        print(f"{k:28s} {r['records']:7d} {r['inside']:4d}/{r['n']:<4d} {r['coverage']:5.2f} "
              f"{r['median_width_k']:9.4f} {r['median_width_c']:9.4f} "
              f"{r['median_width_over_oracle']:8.2f} {r['median_wall_s']:7.1f}"
              + (f"  {r['verdicts']}" if "verdicts" in r else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
