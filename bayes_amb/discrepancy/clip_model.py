"""A clipping amplifier, modelled rather than absorbed into the coefficients.

The plant received the current plus a defect d that enters the loop where r2 does, so
eps - T_r2(theta) d is linear in the model again, and the nominal fit is redone on it
(twice, T_r2 at the previous fit). d is clip(u) - u at the limit the clipping regression
estimates (linearity.py) when the DAQ recorded the command; when it recorded the clipped
coil current (flat tops in u_*), d is the documented controller's output on the held
samples minus the recorded current there, and eps is formed from the controller's output.
The modelled clip is not known exactly: its uncertainty is the fit's extra_cov, added to
every interval drawn from it (fitstats.draws): from refits at the limit +- LIMIT_SD, or
CLIP_MODEL_SD of the coefficients' shift for a recorded coil current.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayes_amb.discrepancy.checks import DataChecks, recompute_u
from bayes_amb.discrepancy.fitting import FittedModel, fit_nominal
from bayes_amb.discrepancy.linearity import (
    Clipping,
    at_extremes,
    clip_defect,
    clipping,
    flat_top_channels,
    r2_response,
)
from bayes_amb.inference.offline import dual_youla_eps
from bayes_amb.inference.priors import Prior
from bayes_amb.io.recording import Recording


@dataclass(frozen=True)
class TakenIn:
    """The nominal fit with any clipping taken in: the fit, its eps, the clipping
    regression's result (None when the defect came from a recorded coil current or was
    not looked for), how it was modelled ('command', 'coil' or None) and how far the
    coefficients moved."""

    fitted: FittedModel
    eps: np.ndarray
    clip: Clipping | None
    modelled: str | None
    shift: np.ndarray | None


def take_in_clipping(recording: Recording, names: tuple[str, ...],
                     priors: dict[str, Prior] | None, seed: int, checks: DataChecks,
                     parts, eps: np.ndarray, nominal: FittedModel) -> TakenIn:
    """Look for clipping and, where found, refit the nominal model with it modelled."""
    d = coil_defect(recording, checks)
    clip = None
    if d is not None:
        eps = dual_youla_eps(parts, checks.y, checks.u - d)     # the commanded current
    else:
        clip = clipping(nominal.like, nominal.params, nominal.log10_sigma, checks.u)
        d = (clip_defect(checks.u, clip.limit_a, np.array(clip.centre_a)) if clip.found
             else None)
    if d is None:
        return TakenIn(nominal, eps, clip, None, None)
    raw = nominal.params.copy()
    corrected = eps
    for _ in range(2):                           # T_r2 at the previous fit
        corrected = eps - r2_response(nominal.like.forward, nominal.params, d)
        refit = fit_nominal(recording, names, corrected, priors, seed=seed,
                            start=checks.start)
        if not np.isfinite(refit.log_post):
            break
        nominal = refit
    shift = nominal.params - raw
    if clip is None:
        nominal.extra_cov = (CLIP_MODEL_SD**2) * np.outer(shift, shift)
    else:
        nominal.extra_cov = _limit_spread(recording, names, priors, seed, checks, eps,
                                          nominal, clip)
    return TakenIn(nominal, corrected, clip, "command" if clip is not None else "coil", shift)


def _limit_spread(recording: Recording, names: tuple[str, ...],
                  priors: dict[str, Prior] | None, seed: int, checks: DataChecks,
                  eps: np.ndarray, fitted: FittedModel, clip: Clipping) -> np.ndarray:
    """The coefficients' covariance from the estimated limit's own error: refits with the
    limit LIMIT_SD above and below it (the same centres, T_r2 at the fit), half their
    difference as one sd (rank one)."""
    ends = []
    for sign in (1.0, -1.0):
        d = clip_defect(checks.u, clip.limit_a * (1.0 + sign * LIMIT_SD),
                        np.array(clip.centre_a))
        fit = fit_nominal(recording, names,
                          eps - r2_response(fitted.like.forward, fitted.params, d), priors,
                          seed=seed, start=checks.start)
        ends.append(fit.params if np.isfinite(fit.log_post) else fitted.params)
    half = 0.5 * (ends[0] - ends[1])
    return np.outer(half, half)


CLIP_MODEL_SD = 0.1
"""Relative sd of the modelled clip's effect on the coefficients when the defect is read
from a recorded coil current (exact but for the amplifier offset and noise it leaves out):
the fit's extra_cov is (0.1 shift)(0.1 shift)^T, shift: how far the coefficients moved."""
LIMIT_SD = 0.01
"""Relative sd of an estimated amplifier limit (the regression's profile): 1 %, the
largest error seen on the command-recorded clips of the first benchmark run (0.2-1 %,
mean 0.6 %: the amplifier noise and offsets before the clip that d leaves out); with 2 %
the intervals of a 3-5 % clipped record span most of the prior."""


def coil_defect(recording: Recording, checks: DataChecks) -> np.ndarray | None:
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
        top, bottom = at_extremes(u_rec[:, c])
        at = top | bottom
        d[at, c] = (u_rec - command)[at, c]
    return d
