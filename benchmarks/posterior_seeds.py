"""The posterior benchmark (``bayes-amb bench --only posterior``) over several records,
side by side with a baseline checkout: one record's chain length is a draw.

The benchmark's one record (seed 2) stops its chain at 250-350 steps (R-hat checked every
50 steps past 200), and one more check moves its sampling time by 15-20 %: a ratio between
two commits on that record measures the stopping rule's draw as much as the code. So each
seed's record (the benchmark's case: 8 coefficients, 1 s of the full truth, noise + r1 +
r2) is identified by each tree in its own process, alternating, and the ratio is of the
medians and of the sums.

    .venv/bin/python benchmarks/posterior_seeds.py --base /tmp/base --seeds 2-8

``--base``: a checkout of the baseline commit (``git worktree add /tmp/base da937a1``),
run on this checkout's interpreter; its bench module may predate bench/recordings.py.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ONE = """
from bayes_amb.threads import configure_process
configure_process(None)
import json, sys
from bayes_amb.bench.cases import PARAMS_8, TRUE_8, _identify_side
try:
    from bayes_amb.bench.recordings import make_recording
except ImportError:
    from bayes_amb.bench.cases import make_recording
seed = int(sys.argv[1])
truth = {n: TRUE_8[n] for n in PARAMS_8}
rec = make_recording("full", truth, 1e-4, 1.0, seed=seed, noise_rms=2e-7, r1_rms=1e-7,
                     r2_rms=0.02)
side, s = _identify_side(rec, PARAMS_8, truth, "laplace", None)
print(json.dumps({"wall_s": s["wall_s"], "sampling_s": s["sampler"]["wall_s"],
                  "steps": s["sampler"]["steps"], "evals": s["sampler"]["likelihood_evals"],
                  "converged": s["converged"]}))
"""
CHECK = """
import bayes_amb
print("tree", bayes_amb.__file__)
"""


def run(tree: Path, seed: int) -> dict:
    out = subprocess.run([sys.executable, "-c", ONE + CHECK, str(seed)], capture_output=True,
                         text=True, env={**os.environ, "PYTHONPATH": str(tree)}, check=True,
                         cwd=tree)                # -c puts the working directory first
    lines = out.stdout.strip().splitlines()
    if not lines[-1].startswith(f"tree {tree}"):
        raise SystemExit(f"bayes_amb came from {lines[-1][5:]}, not {tree}")
    return json.loads(lines[-2])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", required=True, type=Path, help="the baseline checkout")
    ap.add_argument("--seeds", default="2-8", help="a range a-b of record seeds")
    a = ap.parse_args()
    lo, hi = (int(v) for v in a.seeds.split("-"))
    here = Path(__file__).resolve().parents[1]
    rows = {"base": [], "ours": []}
    for seed in range(lo, hi + 1):
        for side, tree in (("base", a.base.resolve()), ("ours", here)):
            r = run(tree, seed)
            rows[side].append(r)
            print(f"seed {seed} {side:4s}: wall {r['wall_s']:.2f} s, sampling "
                  f"{r['sampling_s']:.2f} s, {r['steps']} steps, {r['evals']} evaluations",
                  flush=True)
    for key in ("wall_s", "sampling_s"):
        b = [r[key] for r in rows["base"]]
        o = [r[key] for r in rows["ours"]]
        print(f"{key}: ours / base = {statistics.median(o) / statistics.median(b):.2f} "
              f"(medians {statistics.median(o):.2f} / {statistics.median(b):.2f} s), "
              f"{sum(o) / sum(b):.2f} (sums)")


if __name__ == "__main__":
    main()
