"""The transient of a record's start: whether identify fits it (the free response of the
loop's modes at the record's first sample, WhittleLikelihood.set_initial_state).

A rig's record starts mid-operation: the loop's states are not at rest at its first sample.
The data check of the diagnosis (discrepancy.checks.start_state) says whether the record
starts at rest; where it cannot tell (a measured current, an r2 disturbance in u), the
transient is fitted to be safe and kept only where it improves the fit at the MAP.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import stats

from bayes_amb.discrepancy.adequacy import loop_poles
from bayes_amb.discrepancy.checks import start_state
from bayes_amb.inference.estimate import LogPosterior, MapResult, find_map
from bayes_amb.inference.forward import ForwardModel
from bayes_amb.io.recording import Recording


def start_transient(recording: Recording, forward: ForwardModel,
                    choice: bool | None = None) -> dict[str, Any]:
    """Whether identify fits the record's start transient (IdentifyOptions.initial_state),
    and why: ``choice`` True or False as given; None (the default) by the data check of
    the diagnosis (discrepancy.checks.start_state): a record that starts mid-operation
    carries the free response of the loop's states at its first sample, which taken as
    noise leaves the intervals up to twice too wide (README, "A record that starts
    mid-operation"). Returns {"fitted", "reason"} and, when checked, "start_difference"
    (the controller's start-up difference, a share of u's RMS)."""
    if choice is not None:
        return {"fitted": bool(choice), "reason": "--initial-state" if choice
                else "--no-initial-state", "told": True}
    st = start_state(recording, loop_poles(forward))
    if not st.at_rest:
        where = (f"the record starts mid-operation (start-up difference {100 * st.rel_head:.2g}"
                 " % of u)")
    elif not st.told:
        where = (f"the recorded u differs from the documented controller's output by "
                 f"{100 * st.rel_tail:.2g} % throughout (a measured current, a DAQ's resolution, "
                 "an amplifier limit), so whether the record starts at rest cannot be told: "
                 "fitted to be safe")
    else:
        where = "the record starts at rest"
    return {"fitted": not (st.at_rest and st.told), "reason": f"data check: {where}",
            "start_difference": st.rel_head, "told": bool(st.told)}


TRANSIENT_P = 1e-3
"""Level of the likelihood-ratio test that keeps a start transient fitted only to be safe."""


def transient_kept(post: LogPosterior, m: MapResult, method: str,
                   start: dict[str, Any]) -> MapResult:
    """A start transient fitted only because the data check could not tell whether the
    record starts at rest (a measured current, an r2 disturbance in u) is kept where it
    improves the fit at the MAP by more than chance (likelihood ratio against chi-square
    with the transient's real weights as degrees of freedom, at TRANSIENT_P); else it is
    dropped and the MAP searched again without it. Its weights cost a second residual per
    likelihood evaluation: half again the sampler's time (bench, 8 parameters)."""
    told = start.pop("told", True)
    like = post.likelihood
    if told or not start["fitted"] or not like.initial_state:
        return m
    x = np.concatenate([m.theta, m.log10_sigma])[None]
    dof = like._transient_L.shape[-1]
    on = float(post(x)[0])
    like.set_initial_state(False)
    lr = 2.0 * (on - float(post(x)[0]))
    if stats.chi2.sf(lr, dof) < TRANSIENT_P:
        like.set_initial_state(True)
        start["reason"] += f"; it improves the fit (likelihood ratio {lr:.3g} on {dof})"
        return m
    start["fitted"] = False
    start["reason"] = (start["reason"].replace(": fitted to be safe", "")
                       + f"; not fitted: at the MAP it does not improve the fit (likelihood "
                       f"ratio {lr:.3g} on {dof} degrees of freedom)")
    return find_map(post, method, x0=x[0])
