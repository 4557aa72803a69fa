"""Is the model adequate for this recording? One line every estimate carries.

An interval is honest only when its model is: an identification that never asks leaves
an engineer with narrow intervals around a biased value. So ``identify`` runs the same
tests ``diagnose`` starts with, on the same model (the named parameters free): the data
checks (controller, start, offsets, excitation, linearity), the nominal fit over the whole
band and the location tests on its residual (locate.py). The model is adequate when no
data check fails and the mismatch tests find nothing; the line then says so, and
otherwise what was found, where, and what to do.

    a = assess(load_recording("run17.csv"), ("k_By", "c_By"))
    a.adequate, a.line
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from bayes_amb.discrepancy.checks import (Check, DataChecks, recompute_u, run_checks,
                                          settle_samples)
from bayes_amb.discrepancy.fitstats import fit_quality
from bayes_amb.discrepancy.fitting import FittedModel, fit_nominal
from bayes_amb.discrepancy.linearity import (clip_defect, clipping, flat_top_channels,
                                             linearity_check, r2_response)
from bayes_amb.discrepancy.locate import LocateOptions, Location, locate
from bayes_amb.discrepancy.model_error import model_error
from bayes_amb.inference.forward import ForwardModel
from bayes_amb.inference.offline import dual_youla_eps
from bayes_amb.inference.priors import Prior
from bayes_amb.io.recording import Recording


@dataclass(frozen=True)
class Adequacy:
    """Whether the model is adequate for the recording, in one line, and where not.

    channels and bands_hz: where the mismatch tests found structure the model leaves;
    failed: the data checks that failed; nonlinear: the linearity check failed (a clipped
    current or a held probe, linearity.py)."""

    adequate: bool
    line: str
    channels: list[str] = field(default_factory=list)
    bands_hz: list[list[float]] = field(default_factory=list)
    failed: list[str] = field(default_factory=list)
    nonlinear: bool = False

    def to_dict(self) -> dict[str, Any]:
        return {"adequate": self.adequate, "line": self.line, "channels": self.channels,
                "bands_hz": self.bands_hz, "failed_checks": self.failed,
                "nonlinear": self.nonlinear}


def loop_poles(fwd: ForwardModel) -> np.ndarray:
    """Discrete poles of the nominal x -> eps system (S at theta = 0)."""
    A, _, _ = fwd.excitation_system(np.zeros((1, len(fwd.params))))
    return np.linalg.eigvals(A[0])


def _spans(bands: list[list[float]], n: int = 3) -> str:
    return ", ".join(f"{a:.0f}-{b:.0f} Hz" for a, b in bands[:n]) + \
        (f" and {len(bands) - n} more" if len(bands) > n else "")


ROUNDING = 1e-6
"""A residual below this share of eps (NRMSE on every channel) is rounding: its structure
is the arithmetic's, not a mismatch (a noise-free simulation fitted exactly)."""


ADVICE = ("Run `bayes-amb diagnose` to locate and name it, or excite the bands it sits in "
          "differently.")
"""What an inadequate model's line tells the user to do (identify's; the diagnosis, which
has done it, points at its own findings instead)."""


def judge(checks: DataChecks, loc: Location, nrmse: float | None = None,
          advice: str = ADVICE) -> Adequacy:
    """The adequacy verdict from the data checks and the location of a fitted model;
    nrmse: the largest NRMSE of its residual over the channels, when known; advice: the
    last sentence of an inadequate model's line."""
    lin = next((c for c in checks.checks if c.name == "linearity"), None)
    exact = nrmse is not None and nrmse < ROUNDING
    nonlinear = lin is not None and not lin.ok
    if nonlinear:
        limit = lin.values.get("clipping_limit_a")
        how = {"command": f"the coefficients were estimated with an amplifier limit of "
                          f"about {limit or 0:.3g} A modelled, and stay marked unreliable",
               "coil": "the coefficients were estimated with the clipped coil current "
                       "modelled, and stay marked unreliable"}.get(
            lin.values.get("modelled"), "the coefficients are unreliable")
        return Adequacy(False, "model NOT adequate: the loop is not linear (see the "
                        f"linearity check); {how}. Record again with a smaller excitation, "
                        "keeping the currents below the amplifier limit and the probes "
                        "inside their range.", failed=checks.failed, nonlinear=True)
    if checks.failed:
        return Adequacy(False, "model NOT assessed: data check failed ("
                        + ", ".join(checks.failed) + "); no interval can be trusted until "
                        "the record is fixed (see the checks).", failed=checks.failed)
    if exact:
        return Adequacy(True, f"model adequate: it reproduces the record to rounding level "
                        f"(residual {nrmse:.1e} of eps on every channel).")
    if loc.detected:
        return Adequacy(False, f"model NOT adequate: the residual keeps structure on "
                        f"{','.join(loc.channels) or 'the record'} in "
                        f"{_spans(loc.bands_hz) or 'the band'} "
                        f"({loc.evidence.get('strength', 'detected')}); the intervals "
                        f"cannot cover what the model leaves out. {advice}",
                        channels=list(loc.channels), bands_hz=list(loc.bands_hz))
    return Adequacy(True, "model adequate: no data check failed and the location tests "
                    "find nothing the model leaves in the residual.")


def nominal_assessment(recording: Recording, names: tuple[str, ...],
                       priors: dict[str, Prior] | None = None, seed: int = 0
                       ) -> tuple[DataChecks, FittedModel, np.ndarray]:
    """Data checks (with linearity), eps and the nominal fit: the start of a diagnosis.

    A clipping amplifier (linearity.py) is modelled, not absorbed: the plant received the
    current plus a defect d that enters the loop where r2 does, so eps - T_r2(theta) d is
    linear in the model again and the nominal fit is redone on it (twice, T_r2 at the
    previous fit). d is clip(u) - u at the estimated limit when the DAQ recorded the
    command, or, when it recorded the clipped coil current (flat tops in u_*), the
    documented controller's output on the held samples minus the recorded current there
    (eps is then formed from the controller's output)."""
    fwd = ForwardModel(recording, names)
    checks = run_checks(recording, loop_poles(fwd))
    eps = dual_youla_eps(fwd.parts, checks.y, checks.u)
    nominal = fit_nominal(recording, names, eps, priors, seed=seed, start=checks.start)
    if not np.isfinite(nominal.log_post):
        return checks, nominal, eps
    d = _coil_defect(recording, checks)
    clip = None
    if d is not None:
        eps = dual_youla_eps(fwd.parts, checks.y, checks.u - d)     # the commanded current
    else:
        clip = clipping(nominal.like, nominal.params, nominal.log10_sigma, checks.u)
        d = (clip_defect(checks.u, clip.limit_a, np.array(clip.centre_a)) if clip.found
             else None)
    shift = None
    if d is not None:
        raw = nominal.params.copy()
        corrected = eps
        for _ in range(2):                           # T_r2 at the previous fit
            corrected = eps - r2_response(nominal.like.forward, nominal.params, d)
            refit = fit_nominal(recording, names, corrected, priors, seed=seed,
                                start=checks.start)
            if not np.isfinite(refit.log_post):
                break
            nominal = refit
        eps = corrected
        shift = nominal.params - raw
        _widen_for_clip_model(nominal, shift, clip)
    modelled = None if d is None else ("command" if clip is not None else "coil")
    checks = replace(checks, checks=(*checks.checks,
                                     linearity_check(recording, clip, modelled, shift),
                                     information_check(recording, checks, nominal,
                                                       settle_samples(loop_poles(fwd), 10**12))))
    return checks, nominal, eps


CLIP_MODEL_SD = 0.1
"""Relative sd of the modelled clip's effect on the coefficients when the defect is read
from a recorded coil current (exact but for the amplifier offset and noise it leaves out);
with a command-recorded clip it is |1 - gain| + 2 sd(gain) of the clipping regression (the
free gain's distance from the one the model assumes)."""


def _widen_for_clip_model(fitted: FittedModel, shift: np.ndarray, clip) -> None:
    """The clip is modelled, not known: the coefficients moved by ``shift`` when it was
    taken in, and a share s of that move is uncertain (the limit, the centres and the
    amplifier's own noise before the clip). s^2 shift shift^T is added to the Laplace
    covariance of the coefficients, so every interval built on it (model error, draws,
    identify's fallback) carries it."""
    if fitted.cov is None:
        return
    s = CLIP_MODEL_SD if clip is None else abs(1.0 - clip.beta) + 2.0 * clip.beta_sd
    p = fitted.p
    cov = np.array(fitted.cov, dtype=float)
    cov[:p, :p] += s**2 * np.outer(shift, shift)
    fitted.cov = cov


UNINFORMED = 0.5
"""A parameter whose Laplace sd exceeds this share of its prior sd is not informed."""
MEMORIES = 4
"""A record must be at least this many loop memories long (information_check)."""


def information_check(recording: Recording, checks: DataChecks, fitted: FittedModel,
                      memory: int = 0) -> Check:
    """The ``information`` data check: does the record inform the parameters at all? It
    fails when more than half of them keep posterior sds above half their prior sds (a
    record too short or too weakly excited): their intervals are then their priors', and
    no physics is named on such a record. Fewer uninformed ones are listed, not failed.
    It also fails when the record is shorter than MEMORIES times the loop's memory
    (``memory``: samples for its slowest pole to decay, checks.settle_samples): the
    frequency-domain likelihood needs a record much longer than the loop remembers."""
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
                     "cannot inform the parameters, and their intervals are their priors'. "
                     "Record longer (seconds, not milliseconds)", {**values,
                                                                   "loop_memory": memory})
    if len(weak) * 2 > fitted.p:
        return Check("information", False,
                     f"information: FAILED - {what} does not inform {', '.join(weak)}: their "
                     "posterior sds exceed half their prior sds, so their intervals are "
                     "their priors'. Record longer or excite more (bayes-amb plan, when it "
                     "exists, says how much)", values)
    tail = (f"; not informed: {', '.join(weak)} (intervals near their priors)" if weak
            else "")
    return Check("information", True, f"information: {what} informs "
                 f"{fitted.p - len(weak)} of {fitted.p} parameters" + tail, values)


def _coil_defect(recording: Recording, checks: DataChecks) -> np.ndarray | None:
    """The clip defect of a recorded coil current held at its extremes (flat tops in u_*):
    recorded minus commanded current on the held samples, zero elsewhere; None when no u
    channel is held or the controller check failed (the command is then not known)."""
    held = [c for g, c, _ in flat_top_channels(recording) if g == "u"]
    if not held or "controller" in checks.failed:
        return None
    u_rec = np.asarray(recording.u, dtype=float)
    command = recompute_u(recording)
    d = np.zeros_like(u_rec)
    for c in held:
        x = u_rec[:, c]
        tol = 1e-9 * float(np.ptp(x))
        at = (x >= x.max() - tol) | (x <= x.min() + tol)
        d[at, c] = (u_rec - command)[at, c]
    return d


def assess(recording: Recording, names: tuple[str, ...],
           priors: dict[str, Prior] | None = None, seed: int = 0) -> Adequacy:
    """Adequacy of the model with the named parameters free for one recording."""
    return assess_fit(recording, names, priors, seed)[0]


def assess_fit(recording: Recording, names: tuple[str, ...],
               priors: dict[str, Prior] | None = None, seed: int = 0
               ) -> tuple[Adequacy, FittedModel]:
    """Adequacy and the nominal fit it judged; when the model is not adequate, the fit
    carries its model error (model_error.py), so that its draws (fitstats.draws) are the
    posterior with the discrepancy integrated out."""
    checks, nominal, eps = nominal_assessment(recording, names, priors, seed)
    if not np.isfinite(nominal.log_post):
        return Adequacy(False, "model NOT adequate: no parameter value in the prior gives a "
                        "finite likelihood", failed=["fit"]), nominal
    loc = locate(nominal.like, nominal.params, nominal.log10_sigma, nominal.cov,
                 LocateOptions(seed=seed))
    verdict = judge(checks, loc, worst_nrmse(nominal, eps))
    if not verdict.adequate:
        nominal.model_error = model_error(nominal.like, nominal.x, nominal.p, nominal.cov,
                                          nominal.names)
    return verdict, nominal


def worst_nrmse(fm: FittedModel, eps: np.ndarray) -> float:
    """The largest NRMSE of a fitted model's residual over the channels."""
    return float(max(fit_quality(fm, eps)["nrmse"].values()))
