"""CPU time of one default diagnosis against the size of the candidate library (issue 15).

    .venv/bin/python benchmarks/library_scaling.py

The recording is the one of ``bayes-amb bench --only diagnose`` (reduced truth, k_By = 0.3,
a hidden 2.5 kHz actuator lag at both bearings, 2 s at 10 kHz, seed 3). It is diagnosed
with default options and the library cut to its first 12 and 24 candidates, whole (34),
and grown by unbalance and cross-coupling at every further shaft node (half of them,
then all: registry.node_scan; family.py screens each scan with one linearisation). Prints
one line per library: its size, the CPU time (``time.process_time``), the effects named
and the verdict. The multiplicity bar rises with the library (prior odds
1/K), so the diagnosis itself may change with K; on this recording it does not.
"""

from __future__ import annotations

import time

from bayes_amb.bench.cases import make_recording
from bayes_amb.discrepancy import DiagnoseOptions, diagnose
from bayes_amb.discrepancy.library.registry import all_candidates, node_scan
from bayes_amb.rig import load_rig
from bayes_amb.simulate import parse_effect
from bayes_amb.threads import limited_threads


def libraries() -> dict[str, tuple]:
    """The libraries compared, by label."""
    base = all_candidates()
    scan = {e: node_scan([e], load_rig().n_nodes, base) for e in ("unbalance", "cross_coupling")}
    both = scan["unbalance"] + scan["cross_coupling"]
    return {"first 12": base[:12], "first 24": base[:24], "default": base,
            "+ unbalance at half the nodes": base + scan["unbalance"][::2],
            "+ unbalance at every node": base + scan["unbalance"],
            "+ cross-coupling at every node": base + scan["cross_coupling"],
            "+ both at every node": base + both}


@limited_threads
def main() -> None:
    rec = make_recording("reduced", {"k_By": 0.3}, 1e-4, 2.0, seed=3, noise_rms=2e-7,
                         r1_rms=1e-7, r2_rms=0.02,
                         effects=(parse_effect("actuator_lag:bandwidth_hz=2500"),))
    for label, lib in libraries().items():
        c0 = time.process_time()
        d = diagnose(rec, options=DiagnoseOptions(candidates=lib))
        cpu = time.process_time() - c0
        print(f"{label:32s} {len(lib):3d} candidates  CPU {cpu:6.1f} s  "
              f"named {', '.join(d.effects) or 'nothing'}  ({d.verdict})",
              flush=True)


if __name__ == "__main__":
    main()
