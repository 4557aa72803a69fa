"""One linearisation for a whole node scan: every location's linear screen at once.

Unbalance at any node. A 1x force at node j enters the reduced model only through
T_L Bf_j (model.py, line responses), a vector in the model's own input directions. Over
all shaft nodes these span a space of small rank r, at most the model's number of modal
force directions (eight for the rigid-body model at speed; two of them, the static and
the couple unbalance, carry all but 3e-4 of it). So an unbalance at any node is exactly a
real combination of unbalance at r *virtual planes* (node weights from the SVD of the
stacked [T_L Bf_j[:, 0]; T_L Bf_j[:, 1]], j over every node), and its response, being
linear in T_L Bf, is the same combination of theirs.

Cross-coupling at any node. A kxy at node j changes the reduced A by kxy Delta_j with
Delta_j = T_L B_w,j C_z,j T_R (its reduced LFT, eqs. 51-52), exactly and linearly. Over
every node the Delta_j span r matrices (eleven on the reference rig; singular values 1,
0.26, 0.097, 2.4e-4, ..., 2.3e-11, then 1.1e-12 and down to 2e-18), so kxy at any node is
exactly a combination of r *virtual couplings*.

The projection. The linear screen (prescreen.py) of one member is the log posterior
linearised in its own parameters t. Its Jacobian is that of the basis times the member's
coefficients C (phi = C t), so the member's linear model is the basis' linear model on
the line phi = C t, with the member's prior in place of the basis' (wide, flat) ones. One
linearisation of the basis (2 r + 1 kernel rows for the planes, r + 1 for the couplings)
therefore gives every member's linear screen, each maximised over its own prior box at
the cost of a few evaluations of that small model, not of the likelihood. Measured against
each member's own linear screen: 4e-10 nats for lines (exact: the residual is affine in
their coefficients), 8e-5 nats for couplings (the two forward-difference Jacobians);
tests/test_prescreen.py. A line's projected screen is its screen. A coupling's decides
its route as its own would: below screen_min - margin it is pruned (reported with
``how = 'family'``), otherwise it is screened on its own as before.

It is used when a scan has more members than its basis has elements (select.py), so the
default five unbalance and four cross-coupling locations are screened one by one as
before; a scan over every node of the shaft costs one linearisation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bayes_amb.discrepancy.fitting import FittedModel, _embed, extend
from bayes_amb.discrepancy.gauss_newton import (
    LinearModel,
    linearise,
    log_prior_curvature,
    log_prior_gradient,
    maximise_in_box,
)
from bayes_amb.discrepancy.library.base import Candidate, EffectParam, ModelContext
from bayes_amb.discrepancy.library.cross_coupling import CrossCoupling
from bayes_amb.discrepancy.library.unbalance import Unbalance
from bayes_amb.discrepancy.prescreen import NESTED_TOL
from bayes_amb.inference.priors import Prior
from bayes_amb.reduction.pseudo_modal import ReducedModel
from bayes_amb.rotor import dof_index
from bayes_amb.uncertainty import lft_reduced

RANK_TOL = 1e-11
"""Singular values below this fraction of the largest are dropped from a family's basis.
On the reference rig (rigid-body model at 31500 rpm) the planes' fall 1, 0.17, 2.6e-4,
2.6e-7, ..., 7.4e-10, then 4.2e-13: eight planes, every node reproduced to ~1e-13; the
couplings' fall to 2.3e-11, then 1.1e-12: eleven virtual couplings."""

WIDE_SD = 1e6
"""Prior sd of a basis' coefficients, in their own units (~1 for the size of the largest
member's response): flat on the scale of any fit; the projection replaces it by the
member's own prior."""

N_MIN = 8
"""A scan with at most this many members is screened member by member without building its
basis (no basis on the reference rig is smaller: 8 planes, 11 couplings)."""


@dataclass(frozen=True)
class VirtualPlane(Unbalance):
    """Unbalance distributed over the shaft nodes by ``weights`` (one per node, node 1
    first): a basis element of the scan's span, never reported as an effect."""

    weights: tuple[float, ...] = ()

    def line_force(self, ctx: ModelContext) -> NDArray:
        mats = ctx.assembled()
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
    mats = ctx.assembled()
    n_q, n = mats.n_q, ctx.rig.n_nodes
    T_v = T_L[:, n_q:]                                  # forces enter the velocity rows
    V = np.vstack([T_v @ mats.M_inv[:, [dof_index(j, ax) for j in range(1, n + 1)]]
                   for ax in ("x", "y")])               # (2 n_red, n): node j's [x; y]
    _, s, Wt = np.linalg.svd(V, full_matrices=False)
    r = int(np.sum(s > RANK_TOL * s[0]))
    return tuple(VirtualPlane("unbalance", f"plane{i + 1}", weights=tuple(Wt[i] / s[i]))
                 for i in range(r))


@dataclass(frozen=True)
class VirtualCoupling(CrossCoupling):
    """A stiffness change ``phi`` Delta of the reduced A in the model's own coordinates
    (``delta``: Delta, row-major): a basis element of the span of every node's kxy, never
    reported as an effect."""

    delta: tuple[float, ...] = ()

    def lft_names(self):
        return ()

    def continuous(self, A, B, C, phi, ctx):
        # the plant's states come first (candidates before may have appended theirs)
        n = math.isqrt(len(self.delta))
        A = A.copy()
        A[:, :n, :n] += phi[:, 0, None, None] * np.asarray(self.delta).reshape(n, n)
        return A, B, C

    def params(self, ctx: ModelContext) -> tuple[EffectParam, ...]:
        return (EffectParam(f"kxy_{self.location}", Prior("normal", 0.0, WIDE_SD), 0.0, "-"),)


def virtual_couplings(base: ReducedModel, ctx: ModelContext) -> tuple[VirtualCoupling, ...]:
    """The virtual couplings spanning every node's Delta_j (orthogonal, each scaled by the
    largest singular value: a unit of any of them moves A about as much as kxy = k_ref at
    the node that moves it most)."""
    n = ctx.rig.n_nodes
    up = lft_reduced(base, ctx.rig, tuple(f"kxy_n{j}" for j in range(1, n + 1)))
    D = np.stack([(up.B_w[:, 2 * j:2 * j + 2] @ up.C_z[2 * j:2 * j + 2]).ravel()
                  for j in range(n)], axis=1)               # (n_red^2, n): node j's Delta_j
    U, s, _ = np.linalg.svd(D, full_matrices=False)
    r = int(np.sum(s > RANK_TOL * s[0]))
    return tuple(VirtualCoupling("cross_coupling", f"coupling{i + 1}",
                                 delta=tuple(U[:, i] * s[0]))
                 for i in range(r))


def scan_families(parent: FittedModel, pool: list
                  ) -> list[tuple[list[Candidate], tuple[Candidate, ...]]]:
    """(members, basis) of each node scan in a pool with more members than its basis has
    elements (only then does one screen of the basis save anything): the unbalance lines
    starting with the record, as screened, and the cross-couplings."""
    fwd = parent.forward
    out = []
    for members, basis in (
            ([c for c in pool if type(c) is Unbalance and c.start == "rest"],
             lambda: virtual_planes(fwd.base.T_L, fwd.ctx)),
            ([c for c in pool if type(c) is CrossCoupling],
             lambda: virtual_couplings(fwd.base, fwd.ctx))):
        if len(members) > N_MIN:
            b = basis()
            if len(members) > len(b):
                out.append((members, b))
    return out




@dataclass(frozen=True)
class MemberScreen:
    """A scan member's linear screen, projected from its basis': gain over the current
    model (nats) and the member's parameters at the optimum."""

    gain: float
    phi: dict[str, float]


class _Restricted:
    """One member's linear model (its parameters t less their null, from the basis'
    moments on the line of its coefficients) with the member's priors in place of the
    basis' wide ones."""

    def __init__(self, lin: LinearModel, priors: list[Prior], null: NDArray):
        self.lin, self.priors, self.null = lin, priors, null
        self.cols = np.arange(null.size)

    def value_grad(self, t: NDArray, ls: NDArray) -> tuple[float, NDArray, NDArray]:
        f, g, gl = self.lin.value_grad(t, ls)
        x = self.null + t
        f += 0.5 * float(t @ t) / WIDE_SD ** 2 + sum(
            float(p.logpdf(np.array([v]))[0]) for p, v in zip(self.priors, x, strict=True))
        g = g + t / WIDE_SD ** 2 + log_prior_gradient(self.priors, x)
        return f, g, gl

    def hessian(self, ls: NDArray) -> NDArray:
        """-d2 / dt2 of value_grad's function at t = 0: the linear model's, its wide priors'
        curvature taken out and the member's priors' put in."""
        return (self.lin.hessian(ls) - np.eye(self.cols.size) / WIDE_SD ** 2
                + np.diag(log_prior_curvature(self.priors, self.null)))


def _coefficients(basis: tuple[Candidate, ...], members: list[Candidate],
                  ctx: ModelContext, base: ReducedModel) -> list[NDArray]:
    """Per member, C (n_basis_params, n_member_params): its parameters in the basis'."""
    if isinstance(basis[0], VirtualPlane):
        def vec(c):
            Bf = base.T_L @ c.line_force(ctx)
            return np.concatenate([Bf[:, 0], Bf[:, 1]])
        P = np.stack([vec(b) for b in basis], axis=1)
        out = []
        for m in members:
            c = np.linalg.lstsq(P, vec(m), rcond=None)[0]
            C = np.zeros((2 * len(basis), 2))          # (a_i, b_i) = c_i (a, b)
            C[0::2, 0] = C[1::2, 1] = c
            out.append(C)
        return out
    P = np.stack([np.asarray(b.delta) for b in basis], axis=1)
    up = lft_reduced(base, ctx.rig, tuple(m.lft_names()[0] for m in members))
    return [np.linalg.lstsq(P, (up.B_w[:, 2 * k:2 * k + 2] @ up.C_z[2 * k:2 * k + 2]).ravel(),
                            rcond=None)[0][:, None] for k in range(len(members))]


def member_screens(parent: FittedModel, basis: tuple[Candidate, ...], members: list[Candidate],
                   priors: dict[str, Prior] | None = None) -> dict[str, MemberScreen] | None:
    """Every member's linear screen (prescreen.linear_screen) on top of ``parent``, from one
    linearisation of the scan's ``basis`` (:func:`scan_families`): the member's linear model
    is the basis' on the line of its coefficients. None where the linearisation fails or
    the basis does not nest the parent (then screen every member on its own)."""
    fwd, _, post = extend(parent, basis, priors)
    x0 = _embed(parent, fwd)
    idx = np.arange(fwd.slices[-len(basis)].start, fwd.slices[-1].stop)
    lin = linearise(post, x0, idx)
    if lin is None:
        return None
    ls = x0[post.p:]
    wide0 = idx.size * float(Prior("normal", 0.0, WIDE_SD).logpdf(np.array([0.0]))[0])
    f0 = lin.value_grad(np.zeros(idx.size), ls)[0] - wide0
    if not abs(f0 - parent.log_post) < NESTED_TOL:
        return None
    ctx = parent.forward.ctx
    out = {}
    for m, C in zip(members, _coefficients(basis, members, ctx, fwd.base), strict=True):
        eff = m.params(ctx)
        pri = [e.prior for e in eff]
        null = np.array([e.null for e in eff])
        lo = np.array([p.support[0] for p in pri]) - null
        hi = np.array([p.support[1] for p in pri]) - null
        # the member's own linear model: the basis' moments on the line phi = C t
        q = C.shape[1]
        T = np.zeros((q + 1, idx.size + 1))
        T[0, 0] = 1.0
        T[1:, 1:] = C.T
        MT = np.ascontiguousarray(np.einsum("xa,akc,yc->xky", T, lin.MT, T, optimize=True))
        restricted = _Restricted(LinearModel(post, x0, idx[:q], MT), pri, null)
        t, pred = maximise_in_box(restricted, ls, lo, hi)
        at_null = restricted.value_grad(np.zeros(len(eff)), ls)[0] - wide0
        out[m.key] = MemberScreen(float(at_null + pred - parent.log_post),
                                  {e.name: float(e.null + v) for e, v in zip(eff, t,
                                                                             strict=True)})
    return out


__all__ = ["MemberScreen", "VirtualCoupling", "VirtualPlane", "member_screens",
           "scan_families", "virtual_couplings", "virtual_planes"]
