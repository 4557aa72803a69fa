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

from bayes_amb.discrepancy.checks import DataChecks, run_checks
from bayes_amb.discrepancy.clip_model import take_in_clipping
from bayes_amb.discrepancy.fitstats import fit_quality
from bayes_amb.discrepancy.fitting import FittedModel, fit_nominal, with_learned_noise
from bayes_amb.discrepancy.information import information_check
from bayes_amb.discrepancy.linearity import linearity_check
from bayes_amb.discrepancy.locate import LocateOptions, Location, locate
from bayes_amb.discrepancy.model_error import model_error
from bayes_amb.discrepancy.nonlinear import Nonlinearity
from bayes_amb.inference.forward import ForwardModel
from bayes_amb.inference.offline import dual_youla_eps
from bayes_amb.inference.priors import Prior
from bayes_amb.io.recording import Recording
from bayes_amb.threads import limited_threads


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
                       "modelled, and stay marked unreliable",
               "magnet_force_law": "the coefficients were estimated with the magnets' "
                                   "force law modelled (the gap and bias of the linearity "
                                   "check), with its uncertainty in their intervals",
               "slew_limit": "the coefficients were estimated with the amplifier's slew "
                             "limit modelled, with its uncertainty in their intervals",
               "amp_current_loop": "the coefficients were estimated with the amplifier's "
                                   "current loop and its rate cap modelled, with their "
                                   "uncertainty in their intervals"}.get(
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


def only_above(verdict: Any, f_max_hz: float) -> bool:
    """Whether a whole-band verdict that is not adequate found structure only above
    f_max_hz, with no data check failed and no nonlinearity (inference.doubted.within_band)."""
    return not (verdict.adequate or verdict.failed or verdict.nonlinear or not verdict.bands_hz
                or min(lo for lo, _ in verdict.bands_hz) <= f_max_hz)


def nominal_assessment(recording: Recording, names: tuple[str, ...],
                       priors: dict[str, Prior] | None = None, seed: int = 0,
                       learn: bool = False, forced: Nonlinearity | None = None
                       ) -> tuple[DataChecks, FittedModel, np.ndarray]:
    """Data checks (with linearity and information), eps and the nominal fit: the start
    of a diagnosis. A clipping amplifier is modelled, not absorbed (clip_model.py). With
    ``learn`` (identify's adequacy test) the record's narrowband lines leave the
    likelihood before the fit and the noise spectrum is learned from what is left
    (fitting.with_learned_noise), as identify's own likelihood has them. The diagnosis
    keeps the white sources with each band's spectrum integrated out: with the learned
    spectrum its models compared named a sensor gain and two runouts, confidently, on a
    foreign record whose only colour was a band-limited force, and gave tentative names to
    two more (of six; "unexplained" before). forced: a nonlinearity found after a first
    search, modelled from the start (take_in_clipping)."""
    fwd = ForwardModel(recording, names)
    checks = run_checks(recording, loop_poles(fwd))
    eps = dual_youla_eps(fwd.parts, checks.y, checks.u)
    nominal = fit_nominal(recording, names, eps, priors, seed=seed, start=checks.start,
                          leave_out_lines=learn)
    if not np.isfinite(nominal.log_post):
        return checks, nominal, eps
    taken = take_in_clipping(recording, names, priors, seed, checks, fwd.parts, eps, nominal,
                             forced)
    checks = replace(checks, checks=(
        *checks.checks,
        linearity_check(recording, taken.clip, taken.modelled, taken.shift, taken.fitted,
                        taken.screened),
        information_check(recording, checks, taken.fitted)))
    return checks, with_learned_noise(taken.fitted) if learn else taken.fitted, taken.eps


@limited_threads
def assess(recording: Recording, names: tuple[str, ...],
           priors: dict[str, Prior] | None = None, seed: int = 0) -> Adequacy:
    """Adequacy of the model with the named parameters free for one recording."""
    return assess_fit(recording, names, priors, seed)[0]


def assess_fit(recording: Recording, names: tuple[str, ...],
               priors: dict[str, Prior] | None = None, seed: int = 0,
               band_hz: float | str | None = None) -> tuple[Adequacy, FittedModel]:
    """Adequacy and the nominal fit it judged; when the model is not adequate, the fit
    carries its model error (model_error.py), so that its draws (fitstats.draws) are the
    posterior with the discrepancy integrated out. ``band_hz``: the band the verdict will
    be read for (identify's, inference.doubted.within_band; "validity": the nominal model's
    validity band, identify's by default); where the structure lies only above it, the
    model error is not formed (within_band drops it)."""
    checks, nominal, eps = nominal_assessment(recording, names, priors, seed, learn=True)
    if not np.isfinite(nominal.log_post):
        return Adequacy(False, "model NOT adequate: no parameter value in the prior gives a "
                        "finite likelihood", failed=["fit"]), nominal
    # the verdict reads the location's tests, not its posterior predictive p-values
    loc = locate(nominal.like, nominal.params, nominal.log10_sigma, nominal.cov,
                 LocateOptions(seed=seed, n_ppc=0))
    verdict = judge(checks, loc, worst_nrmse(nominal, eps))
    if band_hz == "validity":
        band_hz = nominal.forward.validity_band_hz()
    if not verdict.adequate and not (band_hz is not None and only_above(verdict, band_hz)):
        nominal.model_error = model_error(nominal.like, nominal.x, nominal.p, nominal.cov,
                                          nominal.names, robust=True)
    return verdict, nominal


def worst_nrmse(fm: FittedModel, eps: np.ndarray) -> float:
    """The largest NRMSE of a fitted model's residual over the channels."""
    return float(max(fit_quality(fm, eps)["nrmse"].values()))
