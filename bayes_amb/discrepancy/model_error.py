"""Posteriors that include the model error: a band-wise discrepancy integrated out.

Without a model of its own error, a fitted model turns every misfit into a shift of its
parameters and reports them as precisely as if it were right (Kennedy & O'Hagan 2001;
Brynjarsdottir & O'Hagan 2014). Here the error of the model is written the way the
diagnosis already estimates what it cannot explain (unexplained.py): in each frequency band
d an unknown output-multiplicative error,

    R_k = E_k - (I + Delta_d) Y_k,      k in band d,   Y_k = S(theta) x_k (+ lines),

with Delta_d a full complex 4 x 4 matrix per band (any linear error of the loop in a band
looks like this: (S + dS) x = (I + dS S^-1) S x). Its entries get a hierarchical prior,
Delta_d[c, m] ~ CN(0, tau_g^2), with one scale tau_g per group of neighbouring bands,
estimated from the data (type-II maximum likelihood on the per-band least-squares
estimates of Delta_d, whose sampling covariance is known). Integrating Delta out of the
linearised likelihood at the MAP removes from the information about theta the part a
band's error could mimic (a Schur complement):

    H_marg = sum_d [ H_tt,d - H_tp,d (H_pp,d + 2 / tau_g^2 I)^-1 H_pt,d ],

with the Gauss-Newton curvatures H = 2 Re sum_k D_k^H W_k D_k of the likelihood's own band
weights W (WhittleLikelihood.curvature_weights). With tau = 0 (a model the data do not
fault) nothing changes; where the error is large against the noise, the bands it touches
inform theta only up to the model-error floor, however strong the signal. The widened
covariance is C_w = (C^-1 - (H_full - H_marg))^-1, C the Laplace covariance at the MAP
(so the prior's curvature is kept): it is never narrower than C.

Why this and not a tempered (SafeBayes) posterior or a sandwich covariance: both scale
the whole posterior by how much the bands' scores disagree, which misses a model error
that pulls every band the same way (the flexible modes a rigid-body model leaves out, a
delay): measured on six foreign recordings, the band sandwich left the coverage of a
full-order truth unchanged. Leaving the failing bands out (the third option) throws away
the bands that inform the damping most; the discrepancy keeps them with their weight
capped.

When the location tests doubt the fitted model (``robust=True``), the band sandwich is
added as a floor: C_s = C M C with M the sum of the outer products of the bands' scores
s_d = -2 Re sum_k J_k^H W_k R_k at the MAP, each corrected for its band's leverage
(band_sandwich: under the model E[C_s] = C).
A missing physics that makes the bands want different parameter values (a support
resonance in the rigid-body band: the bands below and above it pull the bearing
stiffness apart) shows there even when the discrepancy's Schur complement leaves the
informative bands untouched. The reported covariance is the Loewner maximum of C_w and
C_s (C_w^1/2 max(I, C_w^-1/2 C_s C_w^-1/2) C_w^1/2): never narrower than C_w, wider only
in the directions in which the bands disagree more than the model error allows. Only a
doubted model gets it: on an adequate one the sandwich's own scatter (few informative
bands) would widen intervals at random.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar

from bayes_amb.discrepancy.locate import locate_bands

N_DISC_BANDS = 24
"""Discrepancy bands (log-spaced, merged to >= MIN_BINS bins each), as locate.py's."""

MIN_BINS = 16

GROUP = 4
"""Neighbouring discrepancy bands that share one scale tau_g."""

_STEP = 1e-5


@dataclass(frozen=True)
class ModelError:
    """What the band-wise model error did to a posterior.

    tau: relative size of the model error per band group (|Delta| rms per entry), group_hz
    the groups' frequency spans; cov: the widened covariance (same layout as the one it
    widened); sd_ratio: widened / Laplace sd per free parameter (1 where untouched).
    """

    tau: NDArray
    group_hz: list[list[float]]
    cov: NDArray
    sd_ratio: dict[str, float]
    shift: NDArray
    sandwich_ratio: dict[str, float] | None = None

    @property
    def widened(self) -> bool:
        return bool(max(self.sd_ratio.values(), default=1.0) > 1.05)

    def to_dict(self) -> dict[str, Any]:
        return {"method": "band-wise output-multiplicative discrepancy (4 x 4 per band, "
                          "hierarchical scale per band group), integrated out at the MAP",
                "tau": [float(t) for t in self.tau], "group_hz": self.group_hz,
                "sd_ratio": self.sd_ratio, "widened": self.widened,
                **({"sandwich_ratio": self.sandwich_ratio,
                    "sandwich": "band scores' outer products, Loewner maximum with the "
                                "discrepancy's covariance (the model is doubted)"}
                   if self.sandwich_ratio is not None else {})}


def _real_design(Y: NDArray) -> NDArray:
    """D_k for the 32 real parameters (Re, Im of Delta[c, m]) of one band: (nk, 4, 32),
    delta_k[c] = sum_m Delta[c, m] Y_k[m]."""
    nk = Y.shape[0]
    D = np.zeros((nk, 4, 16), dtype=complex)
    for c in range(4):
        D[:, c, 4 * c:4 * c + 4] = Y
    return np.concatenate([D, 1j * D], axis=2)


def _fit_tau(z2: list[NDArray], h: list[NDArray]) -> float:
    """Type-II ML of tau for independent estimates with sampling precisions h and squared
    projections z2 (each real coordinate ~ N(0, tau^2 / 2 + 1 / h))."""
    z2a, ha = np.concatenate(z2), np.concatenate(h)
    keep = ha > 1e-12 * max(float(ha.max(initial=0.0)), 1e-300)
    z2a, ha = z2a[keep], ha[keep]
    if z2a.size == 0:
        return 0.0

    def neg(log_t: float) -> float:
        v = 0.5 * np.exp(2 * log_t) + 1.0 / ha
        return float(0.5 * np.sum(np.log(v) + z2a / v))

    res = minimize_scalar(neg, bounds=(np.log(1e-7), np.log(3.0)), method="bounded")
    t = float(np.exp(res.x))
    return 0.0 if neg(np.log(1e-7)) <= res.fun + 1e-9 else t


def _loewner_max(A: NDArray, B: NDArray) -> NDArray:
    """The smallest covariance (in the ordering the eigenvalues of A^-1/2 B A^-1/2 define)
    that is at least A and at least B: A^1/2 max(I, A^-1/2 B A^-1/2) A^1/2."""
    K = np.linalg.cholesky(A)
    Ki = np.linalg.inv(K)
    lam, V = np.linalg.eigh(Ki @ (0.5 * (B + B.T)) @ Ki.T)
    out = K @ (V * np.maximum(lam, 1.0)) @ V.T @ K.T
    return 0.5 * (out + out.T)


LEVERAGE_CAP = 0.95
"""Largest share of the information in any direction that one band's leverage correction
credits to it (caps the correction of a parameter a single band informs at sd x 4.5)."""


def band_sandwich(C: NDArray, band_scores: list[tuple[NDArray, NDArray]]) -> NDArray:
    """Cluster-robust covariance of the MAP, bands as clusters, from the bands' scores s_d
    and curvatures H_d at the MAP. The plain sandwich C (sum s_d s_d^T) C averages
    (1 - q / G_eff) C on a right model (the scores sum to zero at the MAP: G_eff
    informative bands, q parameters); each score is therefore first scaled by its band's
    leverage, s~_d = (I - L_d)^-1/2 s_d in the coordinates C^1/2 whitens, L_d = C^1/2 H_d
    C^1/2 (the CR2 correction, Bell & McCaffrey 2002), which makes it average C on a linear
    model with the noise model right."""
    K = np.linalg.cholesky(C)
    meat = np.zeros_like(C)
    for s_d, H_d in band_scores:
        lev, V = np.linalg.eigh(K.T @ (0.5 * (H_d + H_d.T)) @ K)
        u = V @ ((V.T @ (K.T @ s_d)) / np.sqrt(1.0 - np.clip(lev, 0.0, LEVERAGE_CAP)))
        meat += np.outer(u, u)
    return K @ meat @ K.T


def model_error(like: Any, x: NDArray, p: int, cov: NDArray | None,
                names: tuple[str, ...], robust: bool = False) -> ModelError | None:
    """Widen the Laplace covariance ``cov`` of the fitted model at ``x`` (parameters first,
    p of them, then log10 sigma) by the band-wise model error (module docstring); with
    ``robust`` (the location tests doubt the model) the band sandwich is its floor.

    ``like`` is a WhittleLikelihood (identification) or RobustWhittle (diagnosis); only the
    free parameters (positive variance in ``cov``) are touched. None without a covariance.
    """
    if cov is None:
        return None
    theta, ls = x[:p], x[p:]
    free = np.flatnonzero(np.diag(cov)[:p] > 0)
    if free.size == 0:
        return None
    rows = np.tile(theta, (free.size + 1, 1))
    h = np.full(free.size, _STEP)
    rows[1 + np.arange(free.size), free] += h
    R, stable = like.residual_dft(rows)
    if not np.all(stable):
        return None
    R0 = R[0]
    J = np.moveaxis((R[1:] - R0) / h[:, None, None], 0, -1)           # (nf, 4, q)
    X = like.X                                                         # excitation DFT
    W_band = like.curvature_weights(theta, ls)                         # (n_bands, 4, 4)
    band_of_bin = np.repeat(np.arange(like.starts.size), like.counts)
    W = W_band[band_of_bin]
    bands = locate_bands(like.k, like.n, like.forward.dt, N_DISC_BANDS, MIN_BINS)
    freq = like.k / (like.n * like.forward.dt)
    q = free.size
    parts = []
    band_scores = []
    for idx in bands:
        Jd, Wd, Rd = J[idx], W[idx], R0[idx]
        Dd = _real_design(X[idx])
        WD = Wd @ Dd
        H_pp = 2 * np.einsum("kci,kcj->ij", Dd.conj(), WD).real
        H_tp = 2 * np.einsum("kci,kcj->ij", Jd.conj(), WD).real
        s = 2 * np.einsum("kci,kc->i", WD.conj(), Rd).real
        hv, U = np.linalg.eigh(0.5 * (H_pp + H_pp.T))
        hv = np.maximum(hv, 0.0)
        z = U.T @ s
        with np.errstate(divide="ignore", invalid="ignore"):
            zhat = np.where(hv > 0, z / np.where(hv > 0, hv, 1.0), 0.0)   # U^T phi_hat
        parts.append((H_tp, hv, U, zhat ** 2, z))
        band_scores.append((-2 * np.einsum("kci,kcd,kd->i", Jd.conj(), Wd, Rd).real,
                            2 * np.einsum("kci,kcd,kdj->ij", Jd.conj(), Wd, Jd).real))
    n_groups = int(np.ceil(len(bands) / GROUP))
    tau = np.zeros(n_groups)
    loss = np.zeros((q, q))
    pull = np.zeros(q)
    group_hz = []
    for g in range(n_groups):
        sel = range(g * GROUP, min((g + 1) * GROUP, len(bands)))
        tau[g] = _fit_tau([parts[d][3] for d in sel], [parts[d][1] for d in sel])
        group_hz.append([float(freq[bands[sel[0]][0]]), float(freq[bands[sel[-1]][-1]])])
        for d in sel:
            H_tp, hv, U, _, z = parts[d]
            if tau[g] > 0:
                B = H_tp @ U
                loss += (B / (hv + 2.0 / tau[g] ** 2)) @ B.T
                pull += B @ (z / (hv + 2.0 / tau[g] ** 2))
    try:
        K = np.linalg.cholesky(cov[np.ix_(free, free)])
    except np.linalg.LinAlgError:
        K = None
    new = cov.copy()
    shift = np.zeros(p)
    if K is not None and np.any(loss):
        lam, V = np.linalg.eigh(K.T @ (0.5 * (loss + loss.T)) @ K)
        lam = np.clip(lam, 0.0, 1.0 - 1e-6)
        Cw = K @ (V / (1.0 - lam)) @ V.T @ K.T
        new[np.ix_(free, free)] = 0.5 * (Cw + Cw.T)
        # the bands' pull that the discrepancy now explains is taken off theta
        # (one Newton step of the marginal posterior from the MAP)
        shift[free] = Cw @ pull
    sandwich_ratio = None
    if robust and K is not None:
        C = cov[np.ix_(free, free)]
        Cs = band_sandwich(C, band_scores)
        widened = new[np.ix_(free, free)]
        try:
            new[np.ix_(free, free)] = _loewner_max(widened, Cs)
        except np.linalg.LinAlgError:
            pass
        else:
            sandwich_ratio = {names[j]: float(np.sqrt(Cs[i, i] / C[i, i]))
                              for i, j in enumerate(free)}
    sd_ratio = {names[j]: float(np.sqrt(new[j, j] / cov[j, j])) for j in free}
    return ModelError(tau=tau, group_hz=group_hz, cov=new, sd_ratio=sd_ratio, shift=shift,
                      sandwich_ratio=sandwich_ratio)
