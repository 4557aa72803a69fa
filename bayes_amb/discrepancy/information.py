"""Does the record inform the parameters at all? The ``information`` data check.

A record of a few milliseconds, or one too weakly excited, leaves the parameters where
their priors put them. A frequency-domain likelihood also needs a record much longer than
the loop remembers. Such a record fails the check (no physics is named on it) and its
intervals are near the priors, never of zero width (fitstats.draws).
"""

from __future__ import annotations

import numpy as np

from bayes_amb.discrepancy.checks import Check, DataChecks
from bayes_amb.discrepancy.fitting import FittedModel
from bayes_amb.io.recording import Recording

UNINFORMED = 0.5
"""A parameter whose Laplace sd exceeds this share of its prior sd is not informed."""
MEMORIES = 4
"""A record must be at least this many loop memories long (information_check)."""


def information_check(recording: Recording, checks: DataChecks, fitted: FittedModel,
                      memory: int = 0) -> Check:
    """The ``information`` data check: does the record inform the parameters at all? It
    fails when the record is shorter than MEMORIES times the loop's memory (``memory``:
    samples for its slowest pole to decay, checks.settle_samples): the frequency-domain
    likelihood needs a record much longer than the loop remembers, and no physics is
    named on such a record. Parameters whose posterior sds exceed half their prior sds (a
    record too weakly excited for them) are listed, not failed: a band-limited process
    force widens every interval without being a fault of the record."""
    n = recording.y.shape[0]
    window = n - checks.start
    bounds = fitted.post.bounds()[:fitted.p]
    prior_sd = np.array([(hi - lo) / np.sqrt(12.0) if lo is not None and hi is not None
                         else np.inf for lo, hi in bounds])
    if fitted.cov is None:
        sd = np.full(fitted.p, np.inf)
    else:
        sd = np.sqrt(np.maximum(np.diag(fitted.cov)[:fitted.p], 0.0))
    weak = [name for name, a, b in zip(fitted.names, sd, prior_sd, strict=True)
            if a > UNINFORMED * b]
    values = {"samples": int(n), "compared_samples": int(window),
              "duration_s": float(n * recording.dt), "uninformed": weak}
    what = (f"the record ({n} samples, {1e3 * n * recording.dt:.3g} ms, {window} compared "
            "after the start-up)")
    if n < MEMORIES * memory:
        return Check("information", False,
                     f"information: FAILED - {what} is shorter than {MEMORIES} times the "
                     f"loop's memory ({memory} samples for its slowest pole to decay): it "
                     "cannot inform the parameters, and their intervals are near their priors'. "
                     "Record longer (seconds, not milliseconds)", {**values,
                                                                   "loop_memory": memory})
    tail = (f"; not informed: {', '.join(weak)} (intervals near their priors)" if weak
            else "")
    return Check("information", True, f"information: {what} informs "
                 f"{fitted.p - len(weak)} of {fitted.p} parameters" + tail, values)
