"""Issue 27: the amplitude-dependence test on every recording of a foreign benchmark run.

    PYTHONPATH=. python studies/amplitude_scan.py runs/f27 0/2     # and 1/2 beside it

Prints one JSON line per recording: the smallest one-sided p over the four channels and
whether the check fails (discrepancy/amplitude.py), on the nominal fit the diagnosis makes.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from bayes_amb.discrepancy.adequacy import nominal_assessment
from bayes_amb.discrepancy.amplitude import amplitude_test
from bayes_amb.discrepancy.library.bearing_coefficient import BEARING_COEFFICIENTS
from bayes_amb.io.recording import load_recording


def main() -> None:
    run, shard = Path(sys.argv[1]), sys.argv[2] if len(sys.argv) > 2 else "0/1"
    i, n = (int(v) for v in shard.split("/"))
    for j, f in enumerate(sorted((run / "recordings").glob("*.csv"))):
        if j % n != i:
            continue
        _, nom, _ = nominal_assessment(load_recording(f), BEARING_COEFFICIENTS)
        t = amplitude_test(nom)
        print(json.dumps({"name": f.stem, "p": None if t is None else min(t.p.values()),
                          "found": None if t is None else t.found}), flush=True)


if __name__ == "__main__":
    main()
