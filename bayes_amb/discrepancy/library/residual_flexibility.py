"""Residual flexibility: the static contribution of the FE modes the model leaves out."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from bayes_amb.discrepancy.library.base import (
    Candidate,
    EffectEntry,
    EffectParam,
    ModelContext,
    Quantity,
    Sampled,
)
from bayes_amb.inference.priors import Prior


@dataclass(frozen=True)
class ResidualFlexibility(Candidate):
    """The modes a reduced model truncates still bend the shaft: far below their own
    frequencies they respond quasi-statically, y_res = D u with D = G_FE(0) - G_model(0)
    (``ModelContext.static_residual``, m/A, nominal bearings; it follows the bending pairs
    the model keeps, so that a pair added later is not counted twice). Sampled: a scale g
    of the FE prediction (null 0: no residual flexibility; prior normal(1, 0.5)).

    Sampled form: a mode far above the sampling rate settles within one sample, so at t_k it
    shows the quasi-static response to the current held over the previous sample,
    y[k] += g D u[k-1]: four states z[k+1] = u[k] appended to the sampled plant (strictly
    proper, as the loop requires). Modes between the kept ones and the Nyquist frequency are
    dynamic, not static: those are flexible_mode's (one instance per bending pair).

    Where the nominal model already holds that compliance (a model that keeps bending
    pairs, ``ctx.static_in_nominal``: one lumped mode of the left-out modes, ForwardModel),
    g scales it instead (the model applies it; null 1: the FE value), so the candidate is
    a correction of the FE compliance, not a second copy."""

    scales_static = True

    def params(self, ctx: ModelContext) -> tuple[EffectParam, ...]:
        ps = super().params(ctx)
        return tuple(replace(p, null=1.0) for p in ps) if ctx.static_in_nominal else ps

    def structure(self, phi, ctx):
        if ctx.static_in_nominal:
            return np.zeros(phi.shape[0], dtype=int)
        return (np.nan_to_num(phi[:, 0]) != 0.0).astype(int)

    def discrete(self, Ad, Bd, Cd, phi, ctx):
        g = np.nan_to_num(phi[:, 0])
        if ctx.static_in_nominal or not np.any(g != 0.0):
            return Ad, Bd, Cd
        nb, n, _ = Ad.shape
        m = Bd.shape[-1]
        Cd = np.broadcast_to(Cd, (nb, *Cd.shape[-2:]))
        A2 = np.zeros((nb, n + m, n + m))
        A2[:, :n, :n] = Ad
        B2 = np.concatenate([Bd, np.broadcast_to(np.eye(m), (nb, m, m))], axis=1)
        C2 = np.concatenate([Cd, g[:, None, None] * ctx.static_residual[None]], axis=2)
        return A2, B2, C2

    def physical(self, draws, ctx):
        ki = np.array([m.ki for m in ctx.rig.channel_magnets])
        D = ctx.static_residual / ki[None, :]          # per A of each bearing's current
        g = draws[:, 0]
        return {"scale": (g, "-"),
                "compliance_A": (g * 0.5 * (D[0, 0] + D[1, 1]), "m/N"),
                "compliance_B": (g * 0.5 * (D[2, 2] + D[3, 3]), "m/N")}

    def describe(self, values):
        return (f"residual flexibility of the truncated modes, {values['scale']:.2g} x the FE "
                f"value (static compliance {values['compliance_A'] * 1e9:.3g} nm/N at "
                f"bearing A, {values['compliance_B'] * 1e9:.3g} nm/N at B)")


ENTRY = EffectEntry(
    name="residual_flexibility", title="residual flexibility",
    description=("the static (quasi-static) deflection of the FE modes the model leaves "
                 "out: a constant compliance from every actuator to every sensor, scaled "
                 "from the FE prediction"),
    fingerprint=("a residual growing with frequency like the rigid-body compliance falls "
                 "(~f^2 relative to it), on every channel, largest in the cross-bearing "
                 "terms"),
    side="plant", locations=("truncated modes",),
    sampled=(Sampled("residual_scale", Prior("normal", 1.0, 0.5), 0.0, "-",
                     "scale of the FE static residual (0: none, 1: FE value; null 1 where "
                     "the nominal model holds it)"),),
    physical=(Quantity("scale", "-", "scale of the FE static residual", plausible=(0.25, 4.0),
                       why="the truncated modes' static compliance follows from the FE "
                           "stiffness that also places the kept modes; a factor of 4 "
                           "either way contradicts them"),
              Quantity("compliance_A", "m/N", "static compliance at bearing A"),
              Quantity("compliance_B", "m/N", "static compliance at bearing B")),
    make=lambda loc: ResidualFlexibility("residual_flexibility", loc))
ResidualFlexibility.entry = ENTRY
