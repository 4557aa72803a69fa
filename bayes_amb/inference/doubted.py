"""What identify reports where its adequacy test (discrepancy/adequacy.py) doubts the model:
the intervals of the adequacy's fit with the model error integrated out, or moved by a
modelled nonlinearity; the verdict read for identify's own band; and, where nothing of the
record's information is left, the prior's interval said so.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from bayes_amb.discrepancy.adequacy import only_above
from bayes_amb.discrepancy.fitstats import draws, theta_summary
from bayes_amb.discrepancy.fitting import FittedModel
from bayes_amb.uncertainty import get_spec


def with_modelled_law(summary: dict[str, Any], nominal: FittedModel) -> None:
    """The model is adequate once the rig file's force law is modelled: this likelihood's
    own intervals (its noise model, its sampling) moved by how far modelling the law moved
    the adequacy fit's parameters, and widened by the law's own uncertainty (the bias's,
    nominal.extra_cov), as Gaussians add. The unmoved ones stay under
    ``parameters_model_only``."""
    own = summary["parameters"]
    rig = nominal.forward.recording.rig
    names = list(nominal.names)
    moved = {}
    for n, row in own.items():
        if n not in names:
            moved[n] = row
            continue
        i = names.index(n)
        dm = float(nominal.modelled_shift[i])
        extra = float(np.sqrt(max(nominal.extra_cov[i, i], 0.0)))
        sd = float(np.hypot(row["sd"], extra))
        half = [row["mean"] - row["hdi90"][0], row["hdi90"][1] - row["mean"]]
        grow = [float(np.hypot(h, 1.645 * extra)) for h in half]
        mean = row["mean"] + dm
        hdi = [mean - grow[0], mean + grow[1]]
        scale = get_spec(n).physical_scale(rig)
        moved[n] = {**row, "mean": mean, "sd": sd, "hdi90": hdi,
                    **({"map": row["map"] + dm} if "map" in row else {}),
                    "physical_mean": mean * scale, "physical_sd": sd * abs(scale),
                    "physical_hdi90": sorted([hdi[0] * scale, hdi[1] * scale])}
    summary["parameters_model_only"] = own
    summary["parameters"] = moved
    summary["parameters_from"] = ("the magnets' force law of the rig file's bias current is "
                                  "modelled: this likelihood's intervals moved by what "
                                  "modelling it moved the adequacy's fit, widened by the "
                                  "bias's uncertainty; the unmoved ones in "
                                  "parameters_model_only")
    summary.pop("laplace_cov", None)


def with_model_error(summary: dict[str, Any], nominal: FittedModel | None, seed: int
                      ) -> None:
    """When the model is not adequate (``nominal``: the adequacy's fit, carrying its model
    error), the reported intervals are those of the posterior with the band-wise model
    error integrated out (discrepancy/model_error.py), as diagnose reports them: an
    interval that covers what the model misses, not one around a biased value. The same
    fit's intervals stand in when this likelihood's own Laplace approximation failed (MAP
    only), so no interval is NaN. This likelihood's own stay under
    ``parameters_model_only``."""
    if nominal is None:
        return
    if (nominal.model_error is None and nominal.extra_cov is not None
            and nominal.modelled_shift is not None):
        with_modelled_law(summary, nominal)
        return
    own = summary["parameters"]
    why = ("the model is not adequate: intervals of the posterior with the band-wise model "
           "error integrated out (see adequacy)" if nominal.model_error is not None else
           "this likelihood's Laplace approximation failed at its MAP (no negative-definite "
           "curvature): intervals of the adequacy's fit (robust Whittle, Laplace)")
    rig = nominal.forward.recording.rig
    widened = theta_summary(nominal, draws(nominal, seed=seed))
    summary["parameters_model_only"] = own
    summary["parameters"] = {
        n: {**own[n], "mean": w["mean"], "sd": w["sd"], "hdi90": w["hdi90"],
            "physical_mean": w["physical_mean"],
            "physical_sd": w["sd"] * abs(get_spec(n).physical_scale(rig)),
            "physical_hdi90": w["physical_hdi90"]}
        for n, w in widened.items() if n in own}
    summary["parameters_from"] = why + "; this likelihood's own in parameters_model_only"
    summary.pop("laplace_cov", None)     # the correlations of the model-only posterior
    say_prior_wide(summary, nominal)


PRIOR_WIDE = 0.9
"""Share of the prior's sd above which a model-error interval is said to be the prior's."""


def say_prior_wide(summary: dict[str, Any], nominal: FittedModel) -> None:
    """Where the model error left a coefficient nothing of the record's information (its
    sd at least PRIOR_WIDE of the prior's), the identifiability notes say so: the prior's
    interval as a last resort, stated, never a silent default."""
    priors = dict(zip(nominal.post.priors.names, nominal.post.priors.priors, strict=True))
    said = {t.split(" ")[0] for t in summary.get("identifiability", {}).get("notes", [])}
    wide = [n for n, row in summary["parameters"].items()
            if n in priors and n not in said and np.isfinite(priors[n].sd)
            and row["sd"] >= PRIOR_WIDE * priors[n].sd]
    if not wide:
        return
    ident = summary.setdefault("identifiability", {"identifiable": True, "notes": []})
    ident["identifiable"] = False
    ident["prior_wide"] = wide
    ident["notes"] = [*ident.get("notes", []),
                      *(f"{n} is not identified here: the model is not adequate where the "
                        "record informs it, and the model error integrated out leaves "
                        "nothing of that information, so its interval is the prior's (a "
                        "last resort; this likelihood's own, which assumes the model right, "
                        "is under parameters_model_only). Run diagnose to name and model "
                        "what is missing" for n in wide)]


def within_band(verdict: Any, nominal: FittedModel, f_max_hz: float) -> Any:
    """The adequacy for identify's likelihood, which uses the bins up to f_max_hz only (the
    reduced model's validity band): where the whole-band test found structure only above
    it (flexible modes the reduced model leaves out by design) and no data check failed,
    the model is adequate for identify, and its own intervals stand (the model error of
    the whole-band fit would widen them for bands this likelihood does not use)."""
    if not only_above(verdict, f_max_hz):
        return verdict
    nominal.model_error = None
    spans = ", ".join(f"{lo:.0f}-{hi:.0f} Hz" for lo, hi in verdict.bands_hz[:3])
    return replace(verdict, adequate=True, line=(
        f"model adequate in identify's band (up to {f_max_hz:.0f} Hz, the reduced model's "
        f"validity band): the residual keeps structure only above it, at {spans} on "
        f"{','.join(verdict.channels)}, where the reduced model is not meant to hold "
        "(`bayes-amb diagnose` looks there)"))
