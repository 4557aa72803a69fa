"""Is the loop linear? A nonlinearity is a data check, before any physics is named.

Every model here is linear. A loop that is not (an amplifier at its current limit, a
sensor at the end of its range) bends the estimates of a linear model without a word, and
the greedy search would explain the bend with some linear physics (a gain, a stiffness).
So a nonlinearity is looked for first and reported as a failed ``linearity`` check: the
diagnosis then names no physics, and the coefficients are marked unreliable.

flat tops   A recorded current or displacement that sits at its extreme value on many
            samples (a clipped coil current, a probe at the end of its range): continuous
            signals with noise reach their maximum once.
clipping    An amplifier that clips a commanded current the DAQ records unclipped leaves
            no flat top. Its trace is in the residual of the fitted linear model: the
            plant received clip(u), so the residual follows d = clip(u, +-c) - u. For a
            threshold c at the 99th, 97th and 95th percentile of |u| per channel, the
            residual DFT and the DFT of d are both freed of their least-squares fit on the
            DFTs of u and the excitation within narrow bands (Frisch-Waugh), then the
            residual is regressed on d within wide bands; this partial F-test of d
            beyond the two linear regressors has no
            power under a linear loop with Gaussian signals (Bussgang: the part of d not
            linear in u is uncorrelated with every signal jointly Gaussian with u), and
            all of it where the loop clips. The excitation is a regressor because a
            linear model error leaves a residual linear in it, which a non-Gaussian
            (binary) excitation would otherwise carry into d. Per-band
            p-values are combined per channel (Fisher), Bonferroni over channels and
            thresholds. The narrow bands (BAND_BINS bins) let linear physics the model lacks
            (a smooth transfer function) be taken up by the linear regressors; the wide
            ones give d's own (smooth) path through the loop the bins to be seen in.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import stats
from scipy.signal import lfilter

from bayes_amb.discrepancy.checks import Check
from bayes_amb.discrepancy.locate import locate_bands
from bayes_amb.io.recording import Recording
from bayes_amb.rig import CHANNELS

FLAT_SHARE = 1e-3
"""A channel is clipped when at least this share of its samples (and 5) sit at one of its
two extremes."""

QUANTILES = (0.99, 0.97, 0.95)

BAND_BINS = 48
"""Bins per regression band: narrow, so that a linear model error (a smooth transfer
function) is nearly constant across a band and fully taken by the linear regressors."""
ALPHA = 1e-4
"""Family-wise level of the clipping test (over channels and thresholds)."""


def flat_tops(rec: Recording) -> list[str]:
    """Channels (y_*, u_*) whose extremes are held on many samples, with the share."""
    found = []
    for g, v in (("u", rec.u), ("y", rec.y)):
        v = np.asarray(v, dtype=float)
        n = v.shape[0]
        for c, ch in enumerate(CHANNELS):
            x = v[:, c]
            span = float(np.ptp(x))
            if span <= 0:
                continue
            tol = 1e-9 * span
            share = max(np.sum(x >= x.max() - tol), np.sum(x <= x.min() + tol)) / n
            if share >= FLAT_SHARE and share * n >= 5:
                found.append(f"{g}_{ch} held at its extreme on {100 * share:.2g} % of the "
                             "samples")
    return found


def _residualise(A: NDArray, Z: NDArray, bands: list[NDArray]) -> NDArray:
    """A with its least-squares fit on Z removed within each band (A, Z: (nf, .))."""
    out = A.copy()
    for idx in bands:
        Q, _ = np.linalg.qr(Z[idx])
        out[idx] = A[idx] - Q @ (Q.conj().T @ A[idx])
    return out


def _partial_p(R: NDArray, D: NDArray, wide: list[NDArray], keep: float) -> NDArray:
    """Per wide band and channel the F-test p-value of R on D (both residualised on the
    linear regressors; ``keep`` the share of degrees of freedom they left)."""
    m = D.shape[1]
    p = np.ones((len(wide), R.shape[1]))
    for i, idx in enumerate(wide):
        dof = keep * idx.size - m
        if dof < 4:
            continue
        X = D[idx]
        for c in range(R.shape[1]):
            r = R[idx, c]
            ss0 = float(np.sum(np.abs(r) ** 2))
            ss1 = float(np.sum(np.abs(r - X @ np.linalg.lstsq(X, r, rcond=None)[0]) ** 2))
            if ss1 <= 0:
                continue
            p[i, c] = stats.f.sf(((ss0 - ss1) / m) / (ss1 / dof), 2 * m, 2 * dof)
    return p


def clipping(like, params: NDArray, u: NDArray) -> tuple[bool, float, float, list[str]]:
    """The clipping test on a fitted model's residual (module docstring).

    like: the model's likelihood (its residual DFT, prefilter, window and bins); u (N, 4)
    the recorded currents as they entered eps. Returns (found, p_adjusted, threshold in A
    of the strongest, channels)."""
    R = like.residual_dft(np.atleast_2d(params))[0][0]                  # (nf, 4)
    start = getattr(like, "start", 0)

    def dft(sig: NDArray) -> NDArray:
        w = lfilter(like.prefilter, [1.0], sig, axis=0)[start:]
        return np.fft.rfft(w, axis=0)[like.k]

    u = np.asarray(u, dtype=float)
    U = np.hstack([dft(u - u.mean(axis=0)), like.X])        # linear in u and in the excitation
    nf = like.k.size
    narrow = np.array_split(np.arange(nf), max(1, nf // BAND_BINS))
    wide = locate_bands(like.k, like.n, like.forward.dt, 12, 4 * BAND_BINS)
    keep = 1.0 - U.shape[1] / BAND_BINS
    Rr = _residualise(R, U, narrow)
    best = (1.0, 0.0, [])
    tests = 0
    dev = u - np.median(u, axis=0)                          # about the record's centre
    for q in QUANTILES:
        thr = np.quantile(np.abs(dev), q, axis=0)
        d = np.clip(dev, -thr, thr) - dev
        D = _residualise(dft(d), U, narrow)
        p = _partial_p(Rr, D, wide, keep)
        fisher = -2 * np.sum(np.log(np.maximum(p, 1e-300)), axis=0)
        pc = stats.chi2.sf(fisher, 2 * p.shape[0])
        tests += pc.size
        j = int(np.argmin(pc))
        if pc[j] < best[0]:
            best = (float(pc[j]), float(thr[j]),
                    [ch for ch, v in zip(CHANNELS, pc, strict=True) if v < ALPHA / 12])
    p_adj = min(1.0, best[0] * tests)
    return p_adj < ALPHA, p_adj, best[1], best[2]


def linearity_check(rec: Recording, like=None, params: NDArray | None = None,
                    u: NDArray | None = None) -> Check:
    """The ``linearity`` data check: flat tops in the record fail it; the clipping test on a
    fitted linear model's residual (given ``like`` and ``params``) is reported beside it as
    a suspicion, not a failure: on the foreign benchmark's linear physics outside the
    library (a pedestal resonance, a seal) its regression still found a partial
    correlation (p 1e-11 .. 1e-15), so alone it cannot tell a clipping amplifier from a
    linear mismatch."""
    flats = flat_tops(rec)
    found_clip, p_adj, thr, chans = (False, 1.0, 0.0, [])
    if like is not None and params is not None:
        found_clip, p_adj, thr, chans = clipping(like, params,
                                                 rec.u if u is None else u)
    values = {"flat_tops": flats, "clipping_p": p_adj, "clipping_suspected": found_clip,
              "clipping_channels": chans,
              "clipping_threshold_a": thr if found_clip else None}
    suspicion = (f"; the residual follows the current clipped at about {thr:.3g} A from the "
                 f"record's centre on {','.join(chans) or 'some channel'} (p {p_adj:.1e}): "
                 "an amplifier current limit is possible (or linear physics the model "
                 "lacks)" if found_clip else "")
    if not flats:
        return Check("linearity", True, "linearity: no flat tops in u or y" + (
            suspicion or f", and the residual does not follow a clipped current (p "
                         f"{p_adj:.2g})"), values)
    return Check("linearity", False,
                 "linearity: FAILED - " + "; ".join(flats) + suspicion + ". The loop is "
                 "not linear here: a linear model bends its coefficients to it, so they are "
                 "unreliable and no physics is named (keep the currents below the amplifier "
                 "limit and the probes inside their range: a smaller excitation)", values)
