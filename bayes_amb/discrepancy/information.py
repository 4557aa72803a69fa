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
MIN_BINS = 64
"""A record must give the likelihood at least this many frequency bins."""


def information_check(recording: Recording, checks: DataChecks, fitted: FittedModel
                      ) -> Check:
    """The ``information`` data check: does the record inform the parameters at all? It
    fails when the compared window gives the likelihood fewer than MIN_BINS frequency bins
    in the model's validity band (a record of milliseconds): a frequency-domain likelihood
    needs many bins per band, and no physics is named on such a record. (A criterion on
    the loop's memory was tried and dropped: a PID's integrator pole makes that memory
    seconds long while a 1 s record identifies the bearings well.) Parameters whose
    posterior sds exceed half their prior sds (a record too weakly excited for them) are
    listed, not failed: a band-limited process force widens every interval without being
    a fault of the record."""
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
    bins = int(fitted.like.k.size)
    values["frequency_bins"] = bins
    if bins < MIN_BINS:
        return Check("information", False,
                     f"information: FAILED - {what} gives only {bins} frequency bins below "
                     f"{fitted.like.f_max_hz:.0f} Hz (at least {MIN_BINS} are needed): it "
                     "cannot inform the parameters, and their intervals are near their "
                     "priors'. Record longer (seconds, not milliseconds)", values)
    tail = (f"; not informed: {', '.join(weak)} (intervals near their priors)" if weak
            else "")
    return Check("information", True, f"information: {what} informs "
                 f"{fitted.p - len(weak)} of {fitted.p} parameters" + tail, values)
