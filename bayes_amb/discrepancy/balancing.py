"""The named unbalance as a balancing answer: its equivalent in two correction planes.

The diagnosis names unbalance at one or more shaft locations (the discs, a few nodes, or
every node with ``--scan unbalance``). Which locations carry it is barely told by the data:
below the first bending mode the rotor responds to a 1x force at axial position z like a
rigid body, through the force and its moment about any point, so every unbalance set with
the same resultant U = sum u_j and moment M = sum u_j z_j gives the same response (the
virtual planes of family.py: two directions carry all but 3e-4 of any node's response on
the reference rig). What the data determine is therefore (U, M), and the engineer's form of
it is the classical two-plane equivalent (static and couple unbalance, ISO 21940):
the unbalance u_1, u_2 in two chosen planes z_1, z_2 with the same resultant and moment,

    u_1 + u_2 = U,     u_1 z_1 + u_2 z_2 = M,

each a complex number u e^{j phase} (kg m; phase at t = 0 of the record, the convention of
the unbalance candidate: f_x = u Omega^2 cos(Omega t + phase), f_y = u Omega^2
sin(Omega t + phase)). A correction mass m at radius r in plane i removes it when
m r = u_i and it sits at phase_i + 180 deg.

At speed the rotor is not quite rigid (31 500 rpm is half the reference rig's first bending
frequency), so the statics is the start, not the answer. The answer is the final model
refitted with its unbalance replaced by unbalance in the two planes: the pair whose 1x
response at the sensors is the named unbalance's, as the influence-coefficient method of
field balancing finds it. On the foreign generator two discs reproduce the line of
unbalance at any node to 3e-4, and the statics is within 2 % of that fit
(tests/test_balancing.py). The refit has its own Laplace posterior, so each plane carries
its own uncertainty, also a plane the greedy search did not name (a plane not named is not
known to be zero). The default planes are the rig's two discs furthest apart (else the two
bearings).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bayes_amb.discrepancy.fitstats import draws, hdi
from bayes_amb.discrepancy.fitting import FittedModel, free_covariance, local_fit
from bayes_amb.discrepancy.library.unbalance import Unbalance, node_of
from bayes_amb.discrepancy.model import ExtendedForwardModel
from bayes_amb.inference.estimate import LogPosterior
from bayes_amb.inference.priors import Prior
from bayes_amb.rig import Rig
from bayes_amb.rig.rig import RigError


def default_planes(rig: Rig) -> tuple[str, str]:
    """The two discs furthest apart, or the two bearings when the rig has fewer discs."""
    if len(rig.discs) >= 2:
        z = rig.shaft.node_z
        pair = min(((a, b) for a in rig.discs for b in rig.discs if a.node < b.node),
                   key=lambda ab: -(z[ab[1].node - 1] - z[ab[0].node - 1]))
        return pair[0].name, pair[1].name
    a, b = sorted(rig.bearing_nodes, key=rig.bearing_nodes.get)
    return a, b


def plane_z(rig: Rig, plane: str) -> float:
    """Axial position (m) of a correction plane: a disc, a bearing or a node 'n<j>'."""
    if plane in rig.bearing_nodes:
        node = rig.bearing_nodes[plane]
    else:
        try:
            node = node_of(rig, plane)
        except RigError:
            raise RigError(f"rig {rig.source}: no plane {plane!r}; a plane is a disc "
                           f"{[d.name for d in rig.discs]}, a bearing "
                           f"{sorted(rig.bearing_nodes)} or a node n1 .. n{rig.n_nodes}"
                           ) from None
    return float(rig.shaft.node_z[node - 1])


def check_planes(rig: Rig, planes: tuple[str, ...]) -> tuple[str, str]:
    """Two correction planes at different axial positions (RigError naming the plane
    otherwise): discs, bearings or nodes 'n<j>'."""
    if len(planes) != 2:
        raise RigError(f"rig {rig.source}: balancing needs two correction planes, got "
                       f"{len(planes)} ({', '.join(planes) or 'none'})")
    z = [plane_z(rig, p) for p in planes]
    if z[0] == z[1]:
        raise RigError(f"rig {rig.source}: correction planes {planes[0]!r} and "
                       f"{planes[1]!r} are at the same axial position ({z[0]:g} m)")
    return planes[0], planes[1]


def two_plane(u: NDArray, z: NDArray, z1: float, z2: float) -> tuple[NDArray, NDArray]:
    """The two-plane equivalent of unbalance u (complex, kg m; shape (..., n)) at axial
    positions z (n,): u_1 at z1 and u_2 at z2 with the same resultant and moment.

    Examples
    --------
    >>> u1, u2 = two_plane(np.array([2.0 + 0j]), np.array([0.25]), 0.0, 1.0)
    >>> float(abs(u1 - 1.5)), float(abs(u2 - 0.5))
    (0.0, 0.0)
    """
    if z1 == z2:
        raise ValueError("two_plane: the two planes are at the same axial position")
    U = np.sum(u, axis=-1)
    M = np.sum(u * z, axis=-1)
    return (M - U * z2) / (z1 - z2), (U * z1 - M) / (z1 - z2)


def balancing_model(final: FittedModel, planes: tuple[str, str] | None = None,
                    priors: dict[str, Prior] | None = None) -> FittedModel | None:
    """The final model with its unbalance replaced by unbalance in two planes (default
    :func:`default_planes`), refitted: MAP from the two-plane equivalent of the named
    unbalance (statics, :func:`two_plane`), then the Laplace covariance. None when the model
    names no unbalance. Its planes carry their own uncertainty, also a plane the selection
    left out (a plane the search did not name is not known to be zero)."""
    named = [c for c in final.candidates if isinstance(c, Unbalance)]
    if not named:
        return None
    fwd = final.forward
    rig = fwd.ctx.rig
    planes = check_planes(rig, planes) if planes else default_planes(rig)
    zp = [plane_z(rig, p) for p in planes]
    new = tuple(replace(named[0], location=p) for p in planes)
    cands = (*(c for c in final.candidates if not isinstance(c, Unbalance)), *new)
    u = _coefficients(final, final.params[None])
    eq = two_plane(u, np.array([plane_z(rig, c.location) for c in named]), *zp)
    start = {}
    for p, e in zip(planes, eq, strict=True):
        v = complex(e[0]) / named[0].UNIT
        start |= {f"unb_a_{p}": v.real, f"unb_b_{p}": v.imag}
    fwd2 = ExtendedForwardModel(fwd.recording, fwd.theta_names, cands, priors, template=fwd)
    x0 = np.concatenate([fwd2.null, final.log10_sigma])
    for j, n in enumerate(fwd2.params):
        x0[j] = start[n] if n in start else final.value(n) if n in final.names else x0[j]
    like = final.like.for_model(fwd2, x0[:len(fwd2.params)])
    post = LogPosterior(like, fwd2.priors)
    x, log_post = local_fit(post, x0)
    return FittedModel(cands, fwd2, like, post, x, log_post, cov=free_covariance(post, x))


def in_credible_ellipse(v: NDArray, mean: NDArray, cov: NDArray, prob: float = 0.9) -> bool:
    """Whether the point v (a, b) lies inside the ``prob`` credible ellipse of a Gaussian
    (mean, cov): Mahalanobis distance squared <= the chi-square (2 dof) quantile
    -2 ln(1 - prob). A singular covariance holds only its mean.

    Examples
    --------
    >>> cov, mean = np.eye(2), np.zeros(2)
    >>> [in_credible_ellipse(np.array([r, 0.0]), mean, cov) for r in (2.0, 2.2)]
    [True, False]
    """
    d = np.asarray(v, dtype=float) - np.asarray(mean, dtype=float)
    try:
        return bool(d @ np.linalg.solve(np.asarray(cov, dtype=float), d)
                    <= -2.0 * np.log(1.0 - prob))
    except np.linalg.LinAlgError:
        return not bool(np.any(d != 0))


def _log_likelihood(fm: FittedModel) -> float:
    """Log likelihood at the MAP: the log posterior less the log prior."""
    return float(fm.log_post - fm.post.priors.log_prior(fm.params[None],
                                                        fm.log10_sigma[None])[0])


def _coefficients(fitted: FittedModel, x: NDArray) -> NDArray:
    """u = (a + j b) UNIT (kg m) of every unbalance of the model, per row of x: (n, k)."""
    fwd = fitted.forward
    return np.stack([(x[:, sl][:, 0] + 1j * x[:, sl][:, 1]) * c.UNIT
                     for c, sl in zip(fwd.candidates, fwd.slices, strict=True)
                     if isinstance(c, Unbalance)], axis=-1)


def balancing(final: FittedModel, planes: tuple[str, str] | None = None,
              priors: dict[str, Prior] | None = None, seed: int = 0
              ) -> dict[str, Any] | None:
    """The balancing answer (module docstring) for the final model of a diagnosis: per
    correction plane u (kg m) and phase (deg) with means, MAP values and 90 % intervals,
    and the mean and 2 x 2 covariance of (a, b) = u (cos phase, sin phase); None when the
    model names no unbalance. From :func:`balancing_model` and its Laplace draws."""
    fm = balancing_model(final, planes, priors)
    if fm is None:
        return None
    named = [c.key for c in final.candidates if isinstance(c, Unbalance)]
    if fm.cov is None or not np.isfinite(fm.log_post):
        return {"planes": [], "from": named,
                "note": "the two-plane refit found no usable posterior: no balancing answer"}
    rig = fm.forward.ctx.rig
    planes = tuple(c.location for c in fm.candidates if isinstance(c, Unbalance))
    d_all = _coefficients(fm, draws(fm, seed=seed))
    m_all = _coefficients(fm, fm.params[None])[0]
    out = []
    for k, name in enumerate(planes):
        d, m = d_all[:, k], complex(m_all[k])
        ph0 = float(np.rad2deg(np.angle(m)))
        rel = np.rad2deg(np.angle(d * np.exp(-1j * np.angle(m))))
        ab = np.stack([d.real, d.imag])
        mean, cov = ab.mean(axis=1), np.cov(ab)
        out.append({
            "plane": name, "z_m": plane_z(rig, name),
            "u_kgm": {"mean": float(np.mean(np.abs(d))), "map": abs(m),
                      "hdi90": hdi(np.abs(d)), "unit": "kg m"},
            "phase_deg": {"mean": ph0 + float(np.mean(rel)), "map": ph0,
                          "hdi90": [ph0 + v for v in hdi(rel)], "unit": "deg"},
            "ab_kgm": {"mean": [float(v) for v in mean], "cov": cov.tolist(),
                       "unit": "kg m"},
            "nonzero": not in_credible_ellipse(np.zeros(2), mean, cov),
        })
    return {"planes": out,
            "from": named,
            "log_likelihood_change": _log_likelihood(fm) - _log_likelihood(final),
            "inference": "MAP with Laplace approximation",
            "meaning": ("the unbalance named, refitted as unbalance in two correction planes "
                        "(the pair with the same 1x response at the sensors, as the "
                        "influence-coefficient method finds it); a correction mass m at "
                        "radius r in a plane removes it when m r = u_kgm and it sits at "
                        "phase_deg + 180 (phase at t = 0 of the record; its interval may "
                        "pass +-180). nonzero: 0 lies outside the plane's 90 % credible "
                        "ellipse of (a, b); the interval of u_kgm never holds 0 (a "
                        "magnitude), so read this instead. log_likelihood_change: the "
                        "two-plane model's log likelihood at its MAP against the named "
                        "one's (about 0: the same response)")}
