"""What the coefficients are reported from: the named model, with the direct terms of a
node force beside it, averaged with the nominal model when the naming is tentative.

Direct terms. A cross-coupled stiffness away from the bearings is a seal's or impeller's
force, and such a force has direct stiffness K and damping C as well (Childs 1993:
labyrinth, hole-pattern and impeller-eye seals all have them, K of either sign). The
selection names the cross-coupling because that is what the residual shows; the direct
terms leave almost nothing there, since between the bearings a node stiffness looks like a
change of both bearings' k (only its x-coupling of the two bearing planes differs). Left
out, they are taken by the bearing coefficients, which then come out precise and wrong
(seals on the foreign benchmark: 27/64 inside their 90 % intervals). So the coefficients of
a model with a cross-coupling at a disc or shaft node are reported from that model with K
and C fitted at the same node (flat priors over +-10 k_ref and +-10 c_ref): where the data
cannot tell K from the bearings' k, the intervals widen along that direction, as they
should. The named effect and its evidence stay those of the selection.

Averaging. An explanation is tentative when part of the mismatch is still unexplained
(unexplained.py): neither the nominal nor the named model is then right, and the Bayes
factor between them, computed as if one of them were, does not say which one's
coefficients to believe (an M-open comparison; Yao, Vehtari, Simpson & Gelman 2018). The
coefficients are then reported from the equal mixture of the two posteriors, each with its
model error integrated out: its interval spans both when they disagree.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from bayes_amb.discrepancy.fitting import (
    FittedModel,
    _embed,
    extend,
    free_covariance,
    local_fit,
)
from bayes_amb.discrepancy.library.cross_coupling import DirectTerms
from bayes_amb.inference.priors import Prior


def direct_companions(fm: FittedModel) -> tuple[DirectTerms, ...]:
    """Direct terms at every location of the model's cross-couplings away from the
    bearings (at a bearing they are its own k and c)."""
    bearings = fm.forward.recording.rig.bearing_nodes
    locs = [c.location for c in fm.candidates
            if c.effect == "cross_coupling" and c.location not in bearings]
    return tuple(DirectTerms("direct_terms", loc) for loc in dict.fromkeys(locs))


def with_direct_terms(fm: FittedModel, priors: dict[str, Prior] | None = None
                      ) -> FittedModel:
    """The model with the direct terms of its node forces fitted beside them (the model
    itself when it has none): MAP from the model's own, noise filters held at its own."""
    extra = direct_companions(fm)
    if not extra:
        return fm
    fwd, like, post = extend(fm, extra, priors)
    x, log_post = local_fit(post, _embed(fm, fwd))
    cov = free_covariance(post, x, last=2 * len(extra))
    return FittedModel((*fm.candidates, *extra), fwd, like, post, x, log_post, cov=cov,
                       log_bf=fm.log_bf, log_odds=fm.log_odds)


def averaged(named: NDArray, nominal: NDArray, n_theta: int) -> NDArray:
    """Draws of the equal mixture of the named and the nominal model's coefficient
    posteriors (the first n_theta columns; the named model's own parameters stay its
    draws)."""
    other = named.copy()
    rows = np.arange(named.shape[0]) % nominal.shape[0]    # emcee runs differ in length
    other[:, :n_theta] = nominal[rows, :n_theta]
    return np.concatenate([named, other])
