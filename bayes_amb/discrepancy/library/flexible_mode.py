"""Flexible modes: bending-mode pairs of the FE model that the 8-state model leaves out."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayes_amb.discrepancy.library.base import Candidate, EffectEntry, Quantity, Sampled
from bayes_amb.inference.priors import Prior


@dataclass(frozen=True)
class FlexibleMode(Candidate):
    """The reduced model extended with the first ``n_pairs`` bending-mode pairs of the FE
    model (the reduction keeping 8 + 4k states). Sampled: the log of a common frequency
    scale of the added modes (prior sd 3 %) and the log of a damping multiplier (prior
    lognormal, sd a factor e). The FE prediction is the null (0, 0)."""

    n_pairs: int = 1

    def n_bending(self):
        return self.n_pairs

    def modal(self, A, phi, ctx, n_rigid):
        s = np.exp(np.clip(phi[:, 0], -0.5, 0.5))
        md = np.exp(np.clip(phi[:, 1], -6.0, 6.0))
        A = A.copy()
        for i in range(n_rigid, n_rigid + 4 * self.n_pairs, 2):
            sig, om = A[:, i, i], A[:, i + 1, i]
            mod = np.hypot(sig, om)
            zeta = np.clip(-sig / mod * md, -0.99, 0.99)
            mod2 = mod * s
            sig2 = -zeta * mod2
            om2 = np.sign(om) * mod2 * np.sqrt(1 - zeta**2)
            A[:, i, i] = A[:, i + 1, i + 1] = sig2
            A[:, i + 1, i] = om2
            A[:, i, i + 1] = -om2
        return A

    def physical(self, draws, ctx):
        return {"frequency_hz": (ctx.bending_hz[0] * np.exp(draws[:, 0]), "Hz"),
                "damping_ratio": (ctx.bending_zeta[0] * np.exp(draws[:, 1]), "-")}

    def describe(self, values):
        return (f"bending mode near {values['frequency_hz']:.0f} Hz (damping ratio "
                f"{values['damping_ratio']:.2g}) missing from the model")


ENTRY = EffectEntry(
    name="flexible_mode", title="flexible (bending) modes",
    description=("the first bending-mode pair of the FE rotor, which the 8-state rigid-body "
                 "model leaves out, with its frequency and damping scaled"),
    fingerprint=("a narrow band near a bending frequency of the FE model, on the channels "
                 "where the mode shape is seen"),
    side="plant", locations=("bending pair 1",),
    sampled=(Sampled("log_freq_scale", Prior("normal", 0.0, 0.03), 0.0, "-",
                     "log of the frequency scale of the added modes (FE: 0)"),
             Sampled("log_damping_scale", Prior("normal", 0.0, 1.0), 0.0, "-",
                     "log of the damping multiplier (FE: 0)")),
    physical=(Quantity("frequency_hz", "Hz", "first bending frequency"),
              Quantity("damping_ratio", "-", "its damping ratio")),
    make=lambda loc: FlexibleMode("flexible_mode", loc, 1))
FlexibleMode.entry = ENTRY
