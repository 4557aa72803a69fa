"""A named actuator lag that may be the amplifier's capped current loop.

Under a random binary excitation most steps are the same size, so a rate cap that acts on
few of them is nearly linear in the command: the screen's linear-free test cannot see it
(current_loop.py), and the search names the loop's lag alone. Named so, the cap's part
bends the coefficients (on a foreign record whose cap the amplifier reached on the largest
steps only, 2 of 8 inside their intervals). So once the search has named actuator
dynamics, the cap is looked for on the named model's residual, where the lag no longer
hides it (the cap stage, without the linear-free test), and where it shows, the loop is
modelled (loop_model.py) and compared with the named model: the difference of their log
posteriors less the extra parameter's Occam factor, log(prior width / (sqrt(2 pi) sd)) with
the rate's prior uniform in log over the screen's range and sd its posterior's (Laplace),
gives the log Bayes factor L and, at equal prior odds, the loop's weight
w = 1 / (1 + exp(-L)). Above WEIGHT_NAMED the loop replaces the name (the diagnosis is
redone with it modelled: verdict nonlinear); between WEIGHT_MIN and that the record cannot
tell them apart, so the naming is tentative, the alternative is reported as a stand-in,
and the coefficients are the mixture of both models' posteriors in the weights.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bayes_amb.discrepancy.current_loop import RATE_RATIOS, cap_stage_at
from bayes_amb.discrepancy.fitting import FittedModel
from bayes_amb.discrepancy.linearity import Regression
from bayes_amb.discrepancy.loop_model import model_loop
from bayes_amb.discrepancy.nonlinear import LOOP, Nonlinearity
from bayes_amb.inference.priors import Prior
from bayes_amb.io.recording import Recording

PRIOR_WIDTH = float(np.log(max(RATE_RATIOS) / min(RATE_RATIOS)))
"""The cap's prior, uniform in log rate over the screen's range of rates (0.5 .. 2 times
the rms rate the uncapped loop asks): its width is the Occam factor's numerator."""
WEIGHT_MIN = 0.05
WEIGHT_NAMED = 0.95


@dataclass
class Alternative:
    """The capped loop beside a named lag: its fit, the modelled nonlinearity, its log
    Bayes factor against the named model (Laplace) and its weight."""

    fit: FittedModel
    nonlinearity: Nonlinearity
    log_bf: float
    weight: float

    def stand_in(self, named: str) -> dict[str, Any]:
        """The alternative as a stand-in entry of the diagnosis."""
        est, hdi = self.nonlinearity.estimate, self.nonlinearity.interval90
        return {"effect": named.split("@")[0], "location": named.split("@")[-1],
                "quantity": "slew_a_per_s", "hdi90": list(hdi["all"]), "plausible": [],
                "why": "a capped current loop is a lag on the small steps",
                "line": (f"{named} may be the amplifier's current loop "
                         f"({est['bandwidth_hz']:.4g} Hz) with its rate capped at "
                         f"{est['all']:.4g} A/s (90 % {hdi['all'][0]:.4g} .. "
                         f"{hdi['all'][1]:.4g}): it fits as well (log Bayes factor "
                         f"{self.log_bf:.1f}, weight {self.weight:.2f}), so the "
                         "coefficients are averaged over both in those weights")}


def named_bandwidths(final: FittedModel) -> list[float]:
    """The bandwidths (Hz) of the actuator dynamics a model names: a lag's corner, a
    second-order actuator's natural frequency, 1 / (2 pi delay) of a delay."""
    fwd = final.forward
    out = []
    for c, sl in zip(fwd.candidates, fwd.slices, strict=True):
        if c.entry.side != "actuator":
            continue
        phys = c.physical(final.params[None, sl], fwd.ctx)
        for key in ("bandwidth_hz", "natural_hz", "delay_s"):
            if key in phys:
                v = float(np.ravel(phys[key][0])[0])
                out.append(v if key != "delay_s" else 1.0 / (2.0 * np.pi * max(v, 1e-9)))
    return out


def loop_alternative(recording: Recording, names: tuple[str, ...],
                     priors: dict[str, Prior] | None, start: int, u: NDArray,
                     eps: NDArray, nominal: FittedModel, final: FittedModel
                     ) -> Alternative | None:
    """The capped loop as an alternative to the actuator dynamics ``final`` names (module
    docstring), or None where it names none, the cap does not show, or its weight is
    below WEIGHT_MIN."""
    bws = named_bandwidths(final)
    if not bws:
        return None
    reg = Regression(final.like, final.params, final.log10_sigma, u)
    found, rate, stats = cap_stage_at(reg, u, recording.dt, min(bws))
    if not found:
        return None
    start_nl = Nonlinearity(LOOP, True, where=("all",), parameter="slew_a_per_s",
                            estimate={"all": rate, "bandwidth_hz": min(bws)},
                            interval90={"all": (rate, rate),
                                        "bandwidth_hz": (min(bws), min(bws))}, **stats)
    _, fit, nl, sd = model_loop(recording, names, priors, start, u, eps, nominal, start_nl)
    if sd is None:                  # the rate has no maximum: the cap is not there
        return None
    occam = np.log(PRIOR_WIDTH / (np.sqrt(2.0 * np.pi) * sd))
    log_bf = float(fit.log_post - final.log_post - occam)
    weight = float(1.0 / (1.0 + np.exp(-np.clip(log_bf, -50, 50))))
    if weight < WEIGHT_MIN:
        return None
    return Alternative(fit, nl, log_bf, weight)


def mixed(named: NDArray, other: NDArray, weight: float, n_theta: int) -> NDArray:
    """Draws of the mixture of the named model's coefficient posterior (weight 1 - w) and
    another's (w), over the first n_theta columns (the named model's own parameters stay
    its draws)."""
    n = named.shape[0]
    k = round(weight * n)
    out = named.copy()
    rows = np.arange(k) % other.shape[0]
    out[:k, :n_theta] = other[rows, :n_theta]
    return out
