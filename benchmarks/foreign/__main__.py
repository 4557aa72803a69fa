"""Write a foreign benchmark suite from the command line.

    bayes-amb controller --dt 1e-4 --export ctrl.json
    python -m benchmarks.foreign OUT_DIR --controller ctrl.json [--seed 1] [--scale 1]
        [--duration 2] [--kinds force_law=3,slew_limit=3,...] [--eta 0.3]

The default suite has 90 recordings: 10 controls, 4 of each of the 10 in-family single
effects, 10 pairs, 6 held-out (pedestal), 4 full-truth, then (issue 27) 5 controls with a
process force (control_force) and 5 of each held-out family current_limit, seal and
ks_drift; ``--scale`` multiplies every count. The first 70 are drawn as before (each
recording's seed is spawned by its position). OUT_DIR/index.json lists them with their
effects and concealments. ``--kinds`` writes those kinds and counts instead of the default
suite (e.g. the nonlinear ones: force_law, slew_limit, iron_saturation, amp_voltage_limit,
pair:force_law+actuator_lag; the coloured disturbances of issue 46: coloured_r2, mains,
pink_sensor, coloured_mix and the held-out narrowband_r2, r1_band; ``--kinds coloured``
is COLOURED_SUITE, 4 of each seen and 3 of each held-out family); ``--eta`` sets every
case's excitation amplitude (A; default the habits' 0.3 A; a magnet law's gap is drawn
from eta / i0, so it follows).
"""

from __future__ import annotations

import argparse

from benchmarks.foreign.cases import IN_FAMILY, write_suite
from benchmarks.foreign.disturbances import HELD_OUT as DISTURBANCE_HELD_OUT
from benchmarks.foreign.disturbances import SEEN as DISTURBANCE_SEEN

DEFAULT_SUITE = {"control": 10, **dict.fromkeys(IN_FAMILY, 4), "pair": 10, "held_out": 6,
                 "full_truth": 4, "control_force": 5, "current_limit": 5, "seal": 5,
                 "ks_drift": 5}
COLOURED_SUITE = {**dict.fromkeys(DISTURBANCE_SEEN, 4), **dict.fromkeys(DISTURBANCE_HELD_OUT, 3)}
"""``--kinds coloured``: the coloured-disturbance families of issue 46."""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.foreign", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out_dir")
    ap.add_argument("--controller", required=True, help="controller file (JSON)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--scale", type=float, default=1.0)
    ap.add_argument("--duration", type=float, default=2.0, help="record length, s")
    ap.add_argument("--kinds", default="",
                    help="kind=count,... instead of the default suite (--scale multiplies); "
                         "'coloured' for COLOURED_SUITE (coloured_r2, mains, pink_sensor, "
                         "coloured_mix, held out: narrowband_r2, r1_band)")
    ap.add_argument("--eta", type=float, default=None,
                    help="excitation amplitude, A (default: the habits' 0.3 A)")
    a = ap.parse_args(argv)
    suite = dict(DEFAULT_SUITE) if not a.kinds else {}
    for item in (c for c in a.kinds.split(",") if c):
        if item == "coloured":
            suite.update(COLOURED_SUITE)
        else:
            k, v = item.split("=")
            suite[k] = int(v)
    kinds = {k: max(1, round(n * a.scale)) for k, n in suite.items()}
    extra = {} if a.eta is None else {"eta_amplitude_a": a.eta}
    index = write_suite(a.out_dir, kinds, a.seed, a.controller, duration_s=a.duration,
                        **extra)
    print(f"{len(index)} recordings in {a.out_dir} (index.json)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
