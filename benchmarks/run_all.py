"""Run the benchmarks and write benchmarks/results/latest.json (atomically).

    .venv/bin/python benchmarks/run_all.py [--quick] [--only NAME,...]

A thin wrapper around bayes_amb.bench: the same figures as ``bayes-amb bench --json``, plus
the git commit they were measured at, printed as the table and saved for comparison.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

from bayes_amb.bench import report, run_benchmarks
from bayes_amb.cli.bench_cmd import format_text, selected
from bayes_amb.io.atomic import json_text, write_text_atomic

RESULTS = Path(__file__).resolve().parent / "results" / "latest.json"


def git_state(repo: Path) -> dict[str, object]:
    """Commit and whether the working tree had uncommitted changes (None outside git)."""
    def git(*args: str) -> str | None:
        try:
            return subprocess.run(["git", *args], cwd=repo, capture_output=True, text=True,
                                  check=True).stdout.strip()
        except (OSError, subprocess.CalledProcessError):
            return None

    status = git("status", "--porcelain", "--untracked-files=no")
    return {"commit": git("rev-parse", "HEAD"), "dirty": None if status is None else bool(status)}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="smoke-test sizes")
    p.add_argument("--only", default=None, metavar="NAME,...")
    p.add_argument("-o", "--output", type=Path, default=RESULTS, help="JSON file to write")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    data = report(run_benchmarks(selected(args.only), quick=args.quick), args.quick)
    data["git"] = git_state(RESULTS.parents[2])
    data["measured_at"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    data["run_s"] = time.perf_counter() - t0
    args.output.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(args.output, json_text(data))
    sys.stdout.write(format_text(data) + f"\n\nwrote {args.output}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
