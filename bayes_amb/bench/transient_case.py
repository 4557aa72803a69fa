"""``bayes-amb bench --only transient``: what fitting a record's start transient costs.

A rig's record starts mid-operation, and identify then fits the free response of the loop's
states at its first sample by default (IdentifyOptions.initial_state; the data check
decides). The benchmark record is such a record: the reference rig with all eight bearing
coefficients set (reduced truth, TRUE_8), 50 nm sensor noise and r2 0.02 A, simulated for
1.3 s at 10 kHz and cut 0.3 s after its start. Side by side in the same process, the
baseline first: identify of the eight coefficients with the user's defaults (the transient
fitted; the adequacy test included, the same on both sides) and with
``initial_state=False`` (the transient taken as noise), each sampled to its own stopping
rule. The cost is the ratio of their wall times; what it buys
is the ratio of their sds (the transient as noise widens the intervals, and on the foreign
generator leaves them up to twice too wide: README, "A record that starts mid-operation").
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from bayes_amb.bench.recordings import PARAMS_8, TRUE_8, make_recording
from bayes_amb.bench.results import Result
from bayes_amb.io.recording import Recording


@dataclass(frozen=True)
class TransientBench(Result):
    """fitted_s, noise_s: identify wall time (s) with the transient fitted (the default on
    this record) and taken as noise; posterior_s_*: the sampler's part of each;
    evals_*: likelihood evaluations of each run (both 0 for a run identify did not sample:
    identify.not_sampled_note); cost: fitted_s / noise_s (the option's
    price, above 1: it costs more); sd_ratio: per parameter, the sd with the transient
    fitted over the sd without (below 1: narrower); fitted_by_default: the data check
    chose to fit it; converged: both runs met the stopping rule."""

    fitted_s: float
    noise_s: float
    posterior_s_fitted: float
    posterior_s_noise: float
    evals_fitted: int
    evals_noise: int
    cost: float
    sd_ratio: dict[str, float]
    fitted_by_default: bool
    converged: bool


def mid_operation_record(quick: bool = False) -> Recording:
    """The benchmark record: simulated from rest, its first 0.3 s cut away."""
    rec = make_recording("reduced", TRUE_8, 1e-4, 0.5 if quick else 1.3, seed=4,
                         noise_rms=5e-8, r2_rms=0.02)
    return rec.part(slice(round(0.3 / rec.dt), None))


def bench_transient(quick: bool = False) -> TransientBench:
    from bayes_amb.inference.identify import IdentifyOptions, identify

    names = ("k_By", "c_By") if quick else PARAMS_8
    rec = mid_operation_record(quick)
    steps = 100 if quick else None
    runs: dict[bool | None, tuple[float, object]] = {}
    for choice in (False, None):       # the baseline first, as the posterior benchmark does
        t0 = time.perf_counter()
        # the baseline takes the transient as white noise, as before the transient was
        # fitted (a learned spectrum would take it in as low-frequency noise instead)
        res = identify(rec, names, options=IdentifyOptions(
            steps=steps, initial_state=choice, learn_spectrum=choice is None))
        runs[choice] = (time.perf_counter() - t0, res)
    (t_on, on), (t_off, off) = runs[None], runs[False]
    return TransientBench(
        fitted_s=t_on, noise_s=t_off, posterior_s_fitted=_sampling(on)[0],
        posterior_s_noise=_sampling(off)[0], evals_fitted=_sampling(on)[1],
        evals_noise=_sampling(off)[1], cost=t_on / t_off,
        sd_ratio={n: float(on.parameters[n].sd / off.parameters[n].sd) for n in names},
        fitted_by_default=bool(on.start_transient.fitted),
        converged=bool(on.converged and off.converged))


def _sampling(res) -> tuple[float, int]:
    """The sampler's wall time and likelihood evaluations of an identification; 0 and 0
    where identify did not sample (with the transient taken as white noise the noise check
    can doubt the white model, and identify then reports the sandwich at the MAP)."""
    return (res.sampler.wall_s, res.sampler.likelihood_evals) if res.sampler else (0.0, 0)
