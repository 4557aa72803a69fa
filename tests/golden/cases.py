"""The golden cases of issue 31: ten foreign recordings diagnosed and five identified with
default options, their ``diagnosis.json`` and ``summary.json`` as the product writes them.

``tests/test_golden.py`` re-runs the cases and compares them with the files in this folder,
each number on its own scale (``tests/golden/compare.py``), so that the files hold on
another CPU and still catch a result that really changed. Regenerate only for a change meant
to alter results, and say so in the commit (name cases to write only theirs):

    PYTHONPATH=. .venv/bin/python -m tests.golden.cases [actuator_gain_00 ...]
"""

from __future__ import annotations

import gzip
import json
import sys
from pathlib import Path
from typing import Any

HERE = Path(__file__).parent
SEED = 11
DURATION_S = 1.0

# (kind, index): the verdicts explained, partly explained, no mismatch and nonlinear
# (current_limit_02: a recorded coil current at the amplifier's limit, 'data check failed'
# until the controller check learnt to tell it from a wrong controller), in-library
# effects at both ends of the loop,
# a stand-in-prone family, a held-out one and the full-order truth
DIAGNOSED = (("current_limit", 2), ("control", 6), ("control_force", 7), ("seal", 7),
             ("eddy_current", 6), ("actuator_gain", 0), ("sensor_gain", 1),
             ("sensor_delay", 0), ("runout", 2), ("full_truth", 4))
# (kind, index, sampled): MAP with Laplace, and one short emcee run
# the sampled run is on a record whose every coefficient is inside its prior: a short chain
# leaning on a bound (control_force_07's k_Ay) is not reproducible to its Monte Carlo
# error, and its "not identified" notes flip with rounding
IDENTIFIED = (("control", 6, True), ("seal", 7, False), ("actuator_gain", 0, False),
              ("probe_angle", 1, False), ("control_force", 7, False))
SAMPLED_STEPS = 300

def record(work: Path, kind: str, index: int) -> Path:
    """The foreign recording ``kind_index`` (seeded as the foreign benchmark seeds it)."""
    import numpy as np

    from benchmarks.foreign import draw_case, write_case
    from benchmarks.foreign.benchmark import _controller_file, kind_number

    rng = np.random.default_rng([SEED, index, kind_number(kind)])
    ctrl = _controller_file(work, 1e-4)
    spec = draw_case(kind, rng, controller_file=str(ctrl), duration_s=DURATION_S)
    return Path(write_case(spec, work / "recordings", f"{kind}_{index:02d}", rng)["csv"])


def diagnosis_json(work: Path, kind: str, index: int) -> dict[str, Any]:
    """diagnosis.json of the default diagnosis, as ``Diagnosis.save`` writes it."""
    from bayes_amb import diagnose, load_recording

    d = diagnose(load_recording(record(work, kind, index)))
    run = d.save(work / "runs" / f"{kind}_{index:02d}")
    return json.loads((run / "diagnosis.json").read_text())


def summary_json(work: Path, kind: str, index: int, sampled: bool) -> dict[str, Any]:
    """summary.json of identify on the eight bearing coefficients, as its ``save`` writes
    it: MAP with Laplace, or a short emcee run (fixed steps, seed 0)."""
    from bayes_amb import IdentifyOptions, identify, load_recording
    from bayes_amb.discrepancy.library import BEARING_COEFFICIENTS

    opts = (IdentifyOptions(steps=SAMPLED_STEPS) if sampled
            else IdentifyOptions(map_only=True))
    res = identify(load_recording(record(work, kind, index)), list(BEARING_COEFFICIENTS),
                   options=opts)
    run = res.save(work / "ident" / f"{kind}_{index:02d}")
    return json.loads((run / "summary.json").read_text())


def golden_path(kind: str, index: int, what: str) -> Path:
    return HERE / f"{kind}_{index:02d}.{what}.json.gz"


def read_golden(path: Path) -> dict[str, Any]:
    return json.loads(gzip.decompress(path.read_bytes()).decode())


def main(argv: list[str] | None = None) -> int:
    """Write every golden file, or only those of the cases named (e.g. actuator_gain_00)."""
    import tempfile

    from bayes_amb.threads import configure_process

    configure_process()       # one BLAS thread, as the tests run (before numpy is imported)

    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        only = set(sys.argv[1:] if argv is None else argv)

        def wanted(kind: str, index: int) -> bool:
            return not only or f"{kind}_{index:02d}" in only

        for kind, index in DIAGNOSED:
            if not wanted(kind, index):
                continue
            out = diagnosis_json(work, kind, index)
            golden_path(kind, index, "diagnosis").write_bytes(
                gzip.compress(json.dumps(out, indent=1).encode(), mtime=0))
            sys.stderr.write(f"{kind}_{index:02d}: {out['verdict']}\n")
        for kind, index, sampled in IDENTIFIED:
            if not wanted(kind, index):
                continue
            out = summary_json(work, kind, index, sampled)
            golden_path(kind, index, "summary").write_bytes(
                gzip.compress(json.dumps(out, indent=1).encode(), mtime=0))
            sys.stderr.write(f"{kind}_{index:02d}: identified\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
