"""Is the residual as white as the noise model says? If not, the intervals the white model
would give are replaced by those of its sandwich.

identify's likelihood (whittle.py) models the noise as three white sources through the
closed loop: sensor noise, r1 and r2 at the bearing currents. A real rig's noise has colour
the three cannot follow: a process force at a disc enters the rotor where no bearing
current does, a band-limited force puts its power in one band, a sensor's noise rises
towards low frequency. The estimate stays consistent (the noise is independent of the
excitation), but its spread is no longer the white model's curvature F^-1: it is the
sandwich F^-1 B F^-1, B the variance of the score under the true spectrum.

The true spectrum is measured on the record itself, at the MAP. Per likelihood band b the
residual's periodogram sum P_b, whitened by the model's N Phi_b = L_b L_b^H,

    C_b = L_b^-1 P_b L_b^-H / n_b         (the identity where the noise is as modelled),

is averaged over segments of at least MIN_BINS bins (a 4 x 4 complex Wishart mean of
n_s bins has entries of relative sd 1/sqrt(n_s)), and the true spectrum is L C L^H. Then

    F = 2 Re sum_k J_k^H W_k J_k,   B = 2 Re sum_k J_k^H W_k Phi_true,k W_k J_k,

J_k = dR_k/dtheta, W = Phi^-1, and the reported covariance becomes

    C_new = C + C (B - F) C         (= C B C + C P C for the Laplace C = (F + P)^-1),

the sandwich with the prior's curvature P kept. It is applied only where the whiteness test
rejects: T = sum_s n_s ||C_s - I||_F^2 is chi-square with 16 x (segments) degrees of
freedom under the model (4 real diagonal and 6 complex off-diagonal entries per segment), and
the model is doubted at p < P_DOUBT. C_new may be narrower than C in some directions: where
the model puts noise the record does not have (a force at one disc makes the white model
give the far bearing the near one's noise).

Measured on foreign records (the benchmark's generator, eight coefficients, MAP only;
studies/noise_check_foreign.py): under a process force at the discs (160 records) the
sandwich sd was 0.4-2.1 x the white model's, and the 90 % intervals held the truth in
1207/1280 against 1195/1280 (k_Bx 151 against 138 of 160); where the sandwich widened by
more than 1.25 x, 97 % against 85 %; where it narrowed below 0.8 x, 89 % against 99 %.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from bayes_amb.inference.posterior import stretch_draws, summarise, walkers_datatree
from bayes_amb.inference.sampler import SamplerRun
from bayes_amb.inference.spectrum import kept_counts
from bayes_amb.inference.whittle import WhittleLikelihood
from bayes_amb.rig import Rig

MIN_BINS = 32
"""Fewest frequency bins a colour segment averages (relative sd of its entries 1/sqrt(32))."""

P_DOUBT = 1e-3
"""Whiteness test level below which the sandwich replaces the white model's covariance."""

ROUNDING = 1e-6
"""A residual below this share of eps (RMS) is rounding (a noise-free simulation fitted
exactly): it has no noise whose colour could be tested (as adequacy.ROUNDING)."""

STEP = 1e-4
"""Central-difference step of the residual Jacobian (theta units; S is smooth in theta)."""

CLUSTER_BINS = 32
"""Fewest bins of a cluster of neighbouring bins whose summed score robust_check takes as
one draw (leakage correlates neighbouring bins)."""

EIG_FLOOR = 0.05
"""Smallest eigenvalue of C^-1/2 C_new C^-1/2: a sandwich may narrow an interval, never to
nothing (the colour is an estimate)."""


def white_spectrum(like: WhittleLikelihood, log10_sigma: NDArray) -> NDArray:
    """N Phi_b (n_bands, 4, 4) of the white sources at log10_sigma (the likelihood's own
    noise model, prewhitening and scale included)."""
    sig2 = 10.0 ** (2 * np.asarray(log10_sigma, dtype=float))
    return np.einsum("s,sbcd->bcd", sig2, like.phi_sources) * like.n


def residual_jacobian(like: WhittleLikelihood, theta: NDArray) -> NDArray:
    """dR_k/dtheta (nf, 4, p) of the likelihood's residual DFT at theta, by central
    differences of step STEP."""
    p = theta.size
    rows = np.tile(theta, (2 * p, 1))
    for j in range(p):
        rows[2 * j, j] += STEP
        rows[2 * j + 1, j] -= STEP
    R, stable = like.residual_dft(rows)
    if not np.all(stable):
        raise ValueError("the controller does not stabilise the model next to theta")
    return np.stack([(R[2 * j] - R[2 * j + 1]) / (2 * STEP) for j in range(p)], axis=-1)


def band_colour(like: WhittleLikelihood, theta: NDArray, log10_sigma: NDArray
                ) -> tuple[NDArray, NDArray]:
    """Per band the residual's whitened periodogram mean C_b (n_bands, 4, 4) at (theta,
    log10_sigma), and the Cholesky factors L_b of the model's N Phi_b."""
    return _whitened(like, _residual(like, theta), log10_sigma)


def _residual(like: WhittleLikelihood, theta: NDArray) -> NDArray:
    """The residual DFT (1, nf, 4) at theta, which must be stabilised."""
    R, stable = like.residual_dft(np.atleast_2d(np.asarray(theta, dtype=float)))
    if not stable[0]:
        raise ValueError("the model is not stabilised at the fitted parameters")
    return R


def _whitened(like: WhittleLikelihood, R: NDArray, log10_sigma: NDArray,
              counts: NDArray | None = None) -> tuple[NDArray, NDArray]:
    """band_colour of the residual DFT R (1, nf, 4) (``counts``: each band's bins that R
    holds, where some were zeroed; at least one)."""
    counts = np.maximum(like.counts if counts is None else counts, 1)
    P = like._band_sums(R)[0] / counts[:, None, None]
    L = np.linalg.cholesky(white_spectrum(like, log10_sigma))
    Li = np.linalg.inv(L)
    C = Li @ P @ np.conj(np.swapaxes(Li, -1, -2))
    return 0.5 * (C + np.conj(np.swapaxes(C, -1, -2))), L


def segments(counts: NDArray, min_bins: int = MIN_BINS) -> list[NDArray]:
    """Consecutive bands grouped so that each group holds at least min_bins bins (the last
    group takes any remainder)."""
    out: list[list[int]] = []
    cur: list[int] = []
    n = 0
    for b, c in enumerate(counts):
        cur.append(b)
        n += int(c)
        if n >= min_bins:
            out.append(cur)
            cur, n = [], 0
    if cur:
        if out:
            out[-1].extend(cur)
        else:
            out.append(cur)
    return [np.array(g) for g in out]


def segment_colour(counts: NDArray, Cb: NDArray, min_bins: int = MIN_BINS
                   ) -> tuple[NDArray, list[NDArray]]:
    """Per band the bin-weighted mean of the colour C_b (n_bands, 4, 4) over its segment
    (:func:`segments`; a band of one bin alone has a rank-one colour of relative error 1),
    and the segments."""
    groups = segments(counts, min_bins)
    colour = np.empty_like(Cb)
    for g in groups:
        n_s = counts[g]
        colour[g] = np.tensordot(n_s, Cb[g], axes=(0, 0)) / n_s.sum()
    return colour, groups


@dataclass(frozen=True)
class NoiseCheck:
    """The whiteness test and the sandwich of one record's fit (module docstring).

    doubted: the test rejects the white model (p < P_DOUBT); bands_hz: the segments of
    most and of least colour, [f_lo, f_hi, colour] (colour: the residual's power over the
    model's, the mean diagonal of C; 1 where white); F and B: the white model's information
    and its score's variance under the measured colour; sd_ratio: per parameter, the
    sandwich sd over the white model's, once a covariance has been widened
    (:meth:`sandwich`)."""

    doubted: bool
    p_value: float
    statistic: float
    dof: int
    names: tuple[str, ...]
    bands_hz: list[list[float]] = field(default_factory=list)
    F: NDArray | None = None
    B: NDArray | None = None
    sd_ratio: dict[str, float] | None = None
    floor: float = EIG_FLOOR

    @property
    def widens(self) -> bool:
        """Whether the intervals are this check's sandwich: the white model doubted, or a
        learned spectrum's intervals floored by the record's own scores (robust_check)."""
        return self.B is not None

    def sandwich(self, C: NDArray) -> tuple[NDArray, NoiseCheck]:
        """The covariance C (p, p; the white model's, zero rows for held parameters) as
        the sandwich C + C (B - F) C (sandwich_cov), and this check with its sd ratios."""
        C = np.asarray(C, dtype=float)
        new = sandwich_cov(C, self.F, self.B, self.floor)
        d_old, d_new = np.diag(C), np.diag(new)
        ratio = {n: float(np.sqrt(d_new[j] / d_old[j])) if d_old[j] > 0 else 1.0
                 for j, n in enumerate(self.names)}
        return new, replace(self, sd_ratio=ratio)

    @property
    def finding(self) -> str:
        """What the test found, without what was done about it."""
        if not self.doubted:
            return (f"The residual is as white as the noise model has it (whiteness test "
                    f"p = {self.p_value:.2g})")
        (a, b, hi), (c, d, lo) = self.bands_hz
        return (f"The residual's noise is not what the white noise model has (whiteness "
                f"test p = {self.p_value:.2g}; its power is x{hi:.2g} the model's at "
                f"{a:.0f}-{b:.0f} Hz, x{lo:.2g} at {c:.0f}-{d:.0f} Hz)")

    @property
    def line(self) -> str:
        """One line for the summary: what was found and what the intervals are."""
        found = self.finding
        if not self.doubted and self.sd_ratio:
            lo, hi = min(self.sd_ratio.values()), max(self.sd_ratio.values())
            return (found + f": the intervals of the learned spectrum, floored by the "
                    f"sandwich of the record's own scores ({lo:.2f}-{hi:.2f} x).")
        if not self.doubted:
            return found + ": intervals of the white model."
        if not self.sd_ratio:
            return found + ": the intervals are the white model's, which may be too narrow."
        lo, hi = min(self.sd_ratio.values()), max(self.sd_ratio.values())
        return (found + f": the intervals are the sandwich's, {lo:.2f}-{hi:.2f} x the white "
                "model's sds (the white model's in parameters_white_noise).")

    def to_dict(self) -> dict[str, Any]:
        return {"doubted": self.doubted, "p_value": self.p_value,
                "statistic": self.statistic, "dof": self.dof, "bands_hz": self.bands_hz,
                **({"sd_ratio": self.sd_ratio} if self.sd_ratio else {}), "line": self.line}


def sandwich_cov(C: NDArray, F: NDArray, B: NDArray, floor: float = EIG_FLOOR) -> NDArray:
    """C + C (B - F) C over the dimensions with positive variance in C, its relative
    eigenvalues against C floored at ``floor`` (1: never narrower than C); zero rows stay
    zero."""
    free = np.flatnonzero(np.diag(C) > 0)
    out = np.zeros_like(C)
    if free.size == 0:
        return out
    Cf = C[np.ix_(free, free)]
    D = (B - F)[np.ix_(free, free)]
    w, V = np.linalg.eigh(0.5 * (Cf + Cf.T))
    half = V @ np.diag(np.sqrt(np.maximum(w, 0.0))) @ V.T
    M = np.eye(free.size) + half @ D @ half
    mw, mV = np.linalg.eigh(0.5 * (M + M.T))
    M = mV @ np.diag(np.maximum(mw, floor)) @ mV.T
    out[np.ix_(free, free)] = half @ M @ half
    return out


@dataclass(frozen=True)
class _Measured:
    """The whiteness test's measurement at (theta, log10_sigma): the model's Cholesky
    factors L per band, the segment-averaged colour per band and its segments, each band's
    bins counted (``counts``: without the masked ones), the statistic and its p value."""

    L: NDArray
    colour: NDArray
    groups: list[NDArray]
    counts: NDArray
    stat: float
    p_value: float

    @property
    def dof(self) -> int:
        return 16 * len(self.groups)


def _measure(like: WhittleLikelihood, theta: NDArray, log10_sigma: NDArray, min_bins: int,
             mask: NDArray | None = None) -> _Measured | None:
    """The whiteness test (module docstring) of the residual at (theta, log10_sigma), the
    bins of ``mask`` left out; None for the naive 'iid' noise model, which is not meant to
    be right, and for a residual of rounding (no noise to test)."""
    if like.noise_model != "loop":
        return None
    R = _residual(like, np.asarray(theta, dtype=float))
    if np.sum(np.abs(R) ** 2) <= ROUNDING**2 * float(np.sum(np.abs(like.E) ** 2)):
        return None
    counts = kept_counts(like, mask)
    if mask is not None:                  # bins left out (synchronous lines: physics)
        R = np.where(mask[None, :, None], 0.0, R)
    Cb, L = _whitened(like, R, log10_sigma, counts)
    colour, groups = segment_colour(counts, Cb, min_bins)
    stat = sum(float(counts[g].sum() * np.sum(np.abs(colour[g[0]] - np.eye(4)) ** 2))
               for g in groups)
    return _Measured(L, colour, groups, counts, stat,
                     float(stats.chi2.sf(stat, 16 * len(groups))))


def colour_correction(like: WhittleLikelihood, theta: NDArray, log10_sigma: NDArray,
                      min_bins: int = MIN_BINS, mask: NDArray | None = None
                      ) -> tuple[float, NDArray, NDArray] | None:
    """The whiteness test's p value at (theta, log10_sigma) and the colour it measured:
    per segment of at least min_bins bins its bin-weighted centre frequency (Hz) and mean
    whitened periodogram C (n_segments, 4, 4), the identity where the noise is as
    modelled (``mask``: bins left out). None as _measure."""
    m = _measure(like, theta, log10_sigma, min_bins, mask)
    if m is None:
        return None
    f = np.array([np.average(like.band_freq_hz[g], weights=like.counts[g]) for g in m.groups])
    return m.p_value, f, np.stack([m.colour[g[0]] for g in m.groups])


def _weighted_jacobian(like: WhittleLikelihood, theta: NDArray, log10_sigma: NDArray
                       ) -> tuple[NDArray, NDArray, NDArray]:
    """W_k J_k (nf, 4, p) (J = dR/dtheta, W = (N Phi_b)^-1 of the likelihood's spectrum at
    log10_sigma), each bin's band index, and the information F = 2 Re sum J^H W J."""
    J = residual_jacobian(like, theta)
    band = np.repeat(np.arange(like.counts.size), like.counts)
    WJ = np.einsum("kcd,kdj->kcj", np.linalg.inv(white_spectrum(like, log10_sigma))[band], J)
    F = 2 * np.einsum("kci,kcj->ij", J.conj(), WJ).real
    return WJ, band, 0.5 * (F + F.T)


def noise_check(like: WhittleLikelihood, theta: NDArray, log10_sigma: NDArray,
                names: tuple[str, ...] | list[str], min_bins: int = MIN_BINS
                ) -> NoiseCheck | None:
    """The whiteness test of the residual at (theta, log10_sigma), and where it rejects,
    the information F and score variance B its sandwich needs. None as _measure."""
    theta = np.asarray(theta, dtype=float)
    m = _measure(like, theta, log10_sigma, min_bins)
    if m is None:
        return None
    rows = []
    for g in m.groups:
        f = like.band_freq_hz[g]
        rows.append([float(f[0]), float(f[-1]), float(np.real(np.trace(m.colour[g[0]])) / 4)])
    far = [max(rows, key=lambda r: r[2]), min(rows, key=lambda r: r[2])]
    check = NoiseCheck(doubted=m.p_value < P_DOUBT, p_value=m.p_value, statistic=m.stat,
                       dof=m.dof, names=tuple(names), bands_hz=far)
    if not check.doubted:
        return check
    WJ, band, F = _weighted_jacobian(like, theta, log10_sigma)
    true = m.L @ m.colour @ np.conj(np.swapaxes(m.L, -1, -2))
    B = 2 * np.einsum("kci,kcd,kdj->ij", WJ.conj(), true[band], WJ).real
    return replace(check, F=F, B=0.5 * (B + B.T))


def robust_check(like: WhittleLikelihood, theta: NDArray, log10_sigma: NDArray,
                 check: NoiseCheck) -> NoiseCheck:
    """A learned spectrum's check (not doubted) with the information F of its likelihood
    and the empirical variance B of the record's own per-bin scores at the MAP,
    s_k = 2 Re J_k^H W_k R_k (W = (N Phi)^-1; under the model E[s s^T] sums to F), and a
    sandwich floor of 1: the intervals widen where the scores scatter more than the
    learned spectrum says (colour within a segment, leakage of a steep spectrum into the
    lowest bins, a line), never narrow. A learned spectrum is fitted to the same residual
    it weighs, so its own curvature alone is optimistic: on foreign pink-noise records
    the learned intervals' z-scores had RMS 1.22."""
    theta = np.asarray(theta, dtype=float)
    R = _residual(like, theta)[0]
    WJ, _, F = _weighted_jacobian(like, theta, log10_sigma)
    scores = 2 * np.einsum("kcj,kc->kj", WJ.conj(), R).real
    ends = np.append(like.starts, like.counts.sum())
    clustered = np.stack([scores[ends[g[0]]:ends[g[-1] + 1]].sum(axis=0)
                          for g in segments(like.counts, CLUSTER_BINS)])
    B = clustered.T @ clustered
    return replace(check, F=F, B=0.5 * (B + B.T), floor=1.0)


def record_check(like: WhittleLikelihood, theta: NDArray, log10_sigma: NDArray,
                 names: tuple[str, ...] | list[str], learned: bool) -> NoiseCheck | None:
    """One record's noise check at (theta, log10_sigma): noise_check, and where the
    record's spectrum was ``learned`` and the check does not doubt it, floored by the
    record's own scores (robust_check). identify's single-record intervals and each
    record of a joint posterior take it alike: without the floor in the joint, the
    foreign generator's three-speed controls (studies/joint_foreign.py, twelve groups)
    covered 82/96 with k_Ax's z at an rms of 1.65, where each record's own covered
    257/288."""
    check = noise_check(like, theta, log10_sigma, names)
    if check is not None and not check.doubted and learned:
        check = robust_check(like, theta, log10_sigma, check)
    return check


def sandwich_draws(check: NoiseCheck, samples: NDArray, bounds: list[tuple[Any, Any]]
                   ) -> tuple[NDArray, NoiseCheck]:
    """Sampled draws (walkers, draws, dims; theta first) stretched about their mean so that
    the theta block's covariance goes from the draws' own to its sandwich (the open-faced
    adjustment of Shaby 2014, with the sandwich of :meth:`NoiseCheck.sandwich`), then
    clipped to the prior's ``bounds``; the walkers' structure is kept, so R-hat and ESS
    still apply. Also the check with its sd ratios."""
    p = len(check.names)
    flat = samples.reshape(-1, samples.shape[-1])[:, :p]
    mean = flat.mean(axis=0)
    base = np.atleast_2d(np.cov(flat.T))
    wide, check = check.sandwich(base)
    out = samples.copy()
    out[..., :p] = stretch_draws(samples[..., :p], mean, base, wide)
    for j, (lo, hi) in enumerate(bounds):
        out[..., j] = np.clip(out[..., j], -np.inf if lo is None else lo,
                              np.inf if hi is None else hi)
    return out, check


CHAIN_KEYS = ("ess_bulk", "ess_tail", "r_hat", "tau")
"""Summary keys that describe the sampler's chains, not the reported posterior: the
stretched draws keep the sampler's own (a linear map of the draws is no new chain)."""


def sandwich_rows(check: NoiseCheck, run: SamplerRun, bounds: list[tuple[Any, Any]],
                  rig: Rig, own: dict[str, dict[str, Any]]
                  ) -> tuple[dict[str, dict[str, Any]], NDArray, NoiseCheck]:
    """The summary rows of a sampled posterior's draws stretched to the sandwich
    (sandwich_draws), each keeping the sampler's diagnostics from ``own`` (its rows of the
    draws as sampled); also the stretched draws and the check with its sd ratios."""
    names = check.names
    samples, check = sandwich_draws(check, run.samples, bounds)
    tree = walkers_datatree({"posterior": {n: samples[:, :, j] for j, n in enumerate(names)}})
    wide = summarise(tree, names, run.tau, rig)
    rows = {n: {**wide[n], **{k: own[n][k] for k in CHAIN_KEYS}} for n in names}
    return rows, samples, check


def joint_check(checks: list[NoiseCheck | None], idx: list[NDArray],
                joint_names: list[str]) -> NoiseCheck | None:
    """The sandwich of a joint posterior: each widening record's B - F at the joint MAP
    (a doubted white model's, or a learned spectrum's floored by its own scores,
    robust_check), placed at its parameters' places in the joint vector (``idx``:
    record's parameter j is joint parameter idx[r][j]) and summed; records whose noise is
    as modelled add nothing. Never narrower than the joint Laplace covariance where any
    record is a learned spectrum's (its floor of 1), as identify's single records are.
    None where no record widens."""
    used = [(c, ix) for c, ix in zip(checks, idx, strict=True)
            if c is not None and c.widens]
    if not used:
        return None
    p = len(joint_names)
    D = np.zeros((p, p))
    for c, ix in used:
        D[np.ix_(ix, ix)] += c.B - c.F
    doubted = [c for c, _ in used if c.doubted]
    base = min(doubted, key=lambda c: c.p_value) if doubted else used[0][0]
    return replace(base, names=tuple(joint_names), F=np.zeros((p, p)), B=D,
                   statistic=sum(c.statistic for c, _ in used),
                   dof=sum(c.dof for c, _ in used),
                   floor=max(c.floor for c, _ in used))
