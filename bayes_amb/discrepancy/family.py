"""One screen for the whole unbalance scan: a bound on every node's gain.

A 1x force at node j enters the reduced model only through T_L Bf_j (model.py, line
responses), a vector in the model's own input directions. Over all shaft nodes these span
a space of small rank r, at most the model's number of modal force directions (eight for
the rigid-body model at speed; two of them, the static and the couple unbalance, carry all
but 3e-4 of it). So an unbalance at any node is exactly a real combination of unbalance at r
*virtual planes* (node weights from the SVD of the stacked [T_L Bf_j[:, 0]; T_L Bf_j[:, 1]],
j over every node), and its response, being linear in T_L Bf, is the same combination of
theirs. The best any node can do is bounded by what the r planes together can do.

The bound. The line screen of the planes (prescreen.linear_screen, exact for lines) with
priors so wide that they do not restrain the fit gives, less the planes' log prior, the
largest log-likelihood gain max dL any combination of the planes reaches. A node's screen
is dL at its optimum plus its own log prior there, so it is at most max dL + its prior's
largest log density. Where that is below screen_min - margin for every node of the scan,
none of them can be refined and none is screened: each is reported with the bound
(``how = 'family'``). Otherwise every node is screened as before. The cost is one screen of
2 r parameters, whatever the number of nodes: a scan over every node of the shaft costs
what the default five locations cost.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bayes_amb.discrepancy.fitting import FittedModel, _embed, extend
from bayes_amb.discrepancy.library.base import EffectParam, ModelContext
from bayes_amb.discrepancy.library.unbalance import Unbalance
from bayes_amb.discrepancy.prescreen import linear_screen
from bayes_amb.inference.priors import Prior
from bayes_amb.rotor import assemble, dof_index

RANK_TOL = 1e-11
"""Singular values below this fraction of the largest are dropped from the plane basis.
On the reference rig (rigid-body model at 31500 rpm) they fall 1, 0.17, 2.6e-4, 2.6e-7, ...,
7.4e-10, then 4.2e-13: eight planes, every node reproduced to ~1e-13."""

WIDE_SD = 1e6
"""Prior sd of the virtual planes' coefficients, in their own units (~1 for the size of
the largest node response): flat on the scale of any fit."""


@dataclass(frozen=True)
class VirtualPlane(Unbalance):
    """Unbalance distributed over the shaft nodes by ``weights`` (one per node, node 1
    first): a basis element of the scan's span, never reported as an effect."""

    weights: tuple[float, ...] = ()

    def line_force(self, ctx: ModelContext) -> NDArray:
        mats = assemble(ctx.rig)
        n_q = mats.n_q
        w = np.asarray(self.weights)
        Bf = np.zeros((2 * n_q, 2))
        for col, ax in enumerate(("x", "y")):
            dofs = [dof_index(j + 1, ax) for j in range(w.size)]
            Bf[n_q:, col] = mats.M_inv[:, dofs] @ w
        return Bf

    def params(self, ctx: ModelContext) -> tuple[EffectParam, ...]:
        return tuple(EffectParam(f"{ab}_{self.location}", Prior("normal", 0.0, WIDE_SD), 0.0,
                                 "-") for ab in ("plane_a", "plane_b"))


def virtual_planes(T_L: NDArray, ctx: ModelContext) -> tuple[VirtualPlane, ...]:
    """The planes spanning every node's T_L Bf (orthonormal there), for the model's T_L."""
    mats = assemble(ctx.rig)
    n_q, n = mats.n_q, ctx.rig.n_nodes
    T_v = T_L[:, n_q:]                                  # forces enter the velocity rows
    V = np.vstack([T_v @ mats.M_inv[:, [dof_index(j, ax) for j in range(1, n + 1)]]
                   for ax in ("x", "y")])               # (2 n_red, n): node j's [x; y]
    _, s, Wt = np.linalg.svd(V, full_matrices=False)
    r = int(np.sum(s > RANK_TOL * s[0]))
    return tuple(VirtualPlane("unbalance", f"plane{i + 1}", weights=tuple(Wt[i] / s[i]))
                 for i in range(r))


def scan_members(pool: list) -> list[Unbalance]:
    """The unbalance candidates of a pool the family bound covers (any disc or node; the
    line starting with the record, as screened)."""
    return [c for c in pool if type(c) is Unbalance and c.start == "rest"]


def largest_gain(parent: FittedModel, planes: tuple[VirtualPlane, ...],
                 priors: dict[str, Prior] | None = None) -> float:
    """max dL: an upper bound on the log-likelihood gain of unbalance anywhere on the shaft
    on top of ``parent`` (nats; inf where the linear screen fails: then screen every node),
    from the ``planes`` of the parent's model (:func:`virtual_planes`)."""
    fwd, _, post = extend(parent, planes, priors)
    x0 = _embed(parent, fwd)
    idx = np.arange(fwd.slices[-len(planes)].start, fwd.slices[-1].stop)
    lin = linear_screen(post, x0, idx, parent.log_post, exact=True)
    if not (np.isfinite(lin.gain) and lin.nested):
        return np.inf
    phi = lin.phi
    log_prior = float(sum(post.priors.priors[j].logpdf(np.array([v]))[0]
                          for j, v in zip(idx, phi, strict=True)))
    # the planes' priors pull the optimum in by ~|phi|^2 / sd^2 nats: counted twice
    return lin.gain - log_prior + float(np.sum((phi / WIDE_SD) ** 2)) + 1e-6


def member_bound(max_dl: float, member: Unbalance, ctx: ModelContext) -> float:
    """A node's largest possible screen gain: max dL plus its prior's largest log density
    (the priors of unbalance are normal: at their mean)."""
    return max_dl + float(sum(p.prior.logpdf(np.array([p.prior.a]))[0]
                              for p in member.params(ctx)))


__all__ = ["VirtualPlane", "largest_gain", "member_bound", "scan_members", "virtual_planes"]
