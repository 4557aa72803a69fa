"""`bayes-amb bench --only answers`: the engineering answers, one thread against the pool.

The engineering answers (``bayes-amb answers``, the report's engineering section;
engineering/quantities.py) put every posterior draw into the closed loop of the rig's full
FE model, at four speeds: on ROSS's test rig that is a ZOH and an eigendecomposition of 452
states per draw and speed. The draws run in a pool of threads (threads.pool_threads). Side
by side in one process on each rig (the records of ``--only rigs``, 0.3 s), the baseline
first: the same draws (NAMES about the case's truth, 40; quick: 6, one speed) with
``BAYES_AMB_POOL=1`` and with the default pool. The ratio is the speed-up; the answers must
be the same to the bit (``identical``).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from unittest.mock import patch

import numpy as np

from bayes_amb.bench.results import Result
from bayes_amb.bench.rig_case import NAMES, TRUTH, _case


@dataclass(frozen=True)
class AnswersRow(Result):
    """One rig: the wall time (s) with one thread (serial_s) and with the pool (pool_s) of
    pool_threads threads, their ratio (speedup), the draws and speeds evaluated (each draw
    and each edge point of the central region at every speed) and whether both gave the
    same answers."""

    rig: str
    serial_s: float
    pool_s: float
    speedup: float
    pool_threads: int
    draws: int
    speeds: int
    identical: bool


@dataclass(frozen=True)
class AnswersBench(Result):
    """Both rigs' rows."""

    reference: AnswersRow
    test_rig: AnswersRow


def _row(rig_name: str, quick: bool) -> AnswersRow:
    from bayes_amb.engineering.quantities import Draws, physical_quantities
    from bayes_amb.threads import pool_threads

    rec = _case(rig_name, 0.3)
    n = 6 if quick else 40
    centre = np.array([TRUTH.get(k, 0.0) for k in NAMES])
    draws = Draws(NAMES, centre + 0.02 * np.random.default_rng(1).standard_normal((n, 8)))
    speeds = [rec.speed_rpm] if quick else None

    def timed() -> tuple[float, dict]:
        t0 = time.perf_counter()
        res = physical_quantities(draws, rec, speeds, n_draws=n)
        return time.perf_counter() - t0, {k: (q.value, q.lo, q.hi)
                                          for k, q in res.quantities.items()}

    with patch.dict(os.environ, {"BAYES_AMB_POOL": "1"}):     # the baseline: one thread
        serial_s, serial = timed()
    pool_s, pooled = timed()                                   # the user's pool
    same = serial.keys() == pooled.keys() and all(
        np.array_equal(serial[k], pooled[k], equal_nan=True) for k in serial)
    return AnswersRow(rig=rig_name, serial_s=serial_s, pool_s=pool_s,
                      speedup=serial_s / pool_s, pool_threads=pool_threads(),
                      draws=n, speeds=1 if quick else 4, identical=bool(same))


def bench_answers(quick: bool = False) -> AnswersBench:
    """The case above on the reference rig and ROSS's test rig."""
    return AnswersBench(reference=_row("reference", quick), test_rig=_row("ross_test_rig",
                                                                         quick))
