"""Does the compliance of the modes a reduced model leaves out belong in the model
identify fits on a flexible rotor?  On ROSS's real test rig the reduced model keeps the
rigid-body modes and bending pair 1 (12 states, valid to 193 Hz); the modes it leaves out
start at 386 Hz.

For each record of RUN (written by ``python -m benchmarks.foreign.ross_rig``, a generator
apart from the tool), the eight bearing coefficients are fitted in identify's band (the
reduced model's validity band) twice, with the diagnosis' likelihood and search
(discrepancy/fitting.py): the model without the left-out modes' compliance (the
library's ``residual_flexibility``, which scales it, held at 0 by a normal(0, 0.01)
prior), and the nominal model, which holds it at the FE value (ForwardModel.static).
Printed per record: the log posterior of each and each coefficient's
z = (MAP - truth) / Laplace sd. The truth is read only to score, after the fits.

    PYTHONPATH=. python studies/static_residual.py runs/rr57l/control_00*.csv

This study is why the nominal model of a rig that keeps bending pairs holds that
compliance (docs/validation.md, "ROSS's real test rig").
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

COEFFICIENTS = ("k_Ax", "k_Ay", "k_Bx", "k_By", "c_Ax", "c_Ay", "c_Bx", "c_By")


def in_band_fit(rec, eps, start, candidates, priors):
    """MAP, Laplace covariance and log posterior of the model with ``candidates`` over the
    bins up to the nominal model's validity band."""
    from bayes_amb.discrepancy.fitting import build, free_covariance, local_fit, nominal_map

    fwd, like, post = build(rec, COEFFICIENTS, eps, candidates, priors, start)
    like.limit_band(fwd.validity_band_hz())
    x = nominal_map(post)
    like.fixed_filters = like.phi_sources
    x, log_post = local_fit(post, x)
    return x, free_covariance(post, x), log_post


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("records", nargs="+", type=Path, help="NAME.csv of a ross_rig run")
    a = ap.parse_args(argv)
    from bayes_amb.discrepancy.adequacy import nominal_assessment
    from bayes_amb.discrepancy.library.registry import make_candidate
    from bayes_amb.inference.priors import Prior
    from bayes_amb.io.recording import load_recording

    models = (("without the left-out modes", (make_candidate("residual_flexibility"),),
               {"residual_scale": Prior("normal", 0.0, 0.01)}),
              ("nominal (with them)", (), None))
    for csv in a.records:
        rec = load_recording(csv)
        checks, _, eps = nominal_assessment(rec, COEFFICIENTS)
        fits = [(label, *in_band_fit(rec, eps, checks.start, cands, pri))
                for label, cands, pri in models]
        truth = json.loads(csv.with_suffix(".json").read_text())["truth"]["theta"]
        t = np.array([truth[n] for n in COEFFICIENTS])
        parts = []
        for label, x, cov, log_post in fits:
            sd = (np.sqrt(np.diag(cov)[:8]) if cov is not None else np.full(8, np.nan))
            z = (x[:8] - t) / sd
            parts.append(f"{label}: log post {log_post:.1f}, z "
                         + " ".join(f"{v:+.1f}" for v in z))
        print(csv.stem, " | ".join(parts), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
