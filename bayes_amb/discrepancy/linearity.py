"""Is the loop linear? A nonlinearity is a data check, before any physics is named.

Every model here is linear. A loop that is not (an amplifier at its current limit, a
sensor at the end of its range) bends the estimates of a linear model without a word, and
the greedy search would explain the bend with some linear physics (a gain, a stiffness).
So a nonlinearity is looked for first and reported as a failed ``linearity`` check: the
diagnosis then names no physics, and the coefficients are marked as estimated with the
nonlinearity modelled (or unreliable where it cannot be).

flat tops   A recorded current or displacement that sits at its extreme value on many
            samples (a clipped coil current, a probe at the end of its range): continuous
            signals with noise reach their maximum once.
clipping    An amplifier that clips a commanded current the DAQ records unclipped leaves
            no flat top. The plant received clip(u) = u + d, d = clip(u, c +- L) - u, and
            d enters the loop where r2 does: the residual of the fitted linear model then
            contains T_r2(theta) d, with T_r2 the model's own r2 -> eps filter and a gain
            of exactly one. This is a known shape, one real coefficient beta per limit L:
            the whitened residual DFT is regressed on the whitened DFT of T_r2 d together
            with the Jacobian of the residual in the parameters (so the coefficients may
            move to take what they can), with band-wise residual variances (a linear
            misfit in some band inflates that band's variance instead of faking a clip).
            For L over a grid of quantiles of |u - median| (pooled over the channels, one
            amplifier type), clipping is found when beta's z exceeds the Bonferroni
            threshold over the grid, beta reaches 0.5 .. 2 somewhere on it, and the z of
            the same regression with the residual and T_r2 d both freed of their fit on
            the DFTs of u and the excitation in 48-bin bands (the part of d not linear in
            the loop's signals) exceeds it too: with r2 excitation a linear misfit (a
            hidden actuator lag) is linear in the very currents d is cut from. Linear
            physics outside the library (a pedestal, a gas seal, a lag) gives beta ~ 0
            +- 0.05; a clipping amplifier beta = 1 at the limit.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import optimize, stats
from scipy.signal import lfilter

from bayes_amb.control.discrete import ss_freqresp_modal, ss_response
from bayes_amb.discrepancy.amplitude import amplitude_test
from bayes_amb.discrepancy.checks import Check
from bayes_amb.discrepancy.detection_lines import detection_line_test
from bayes_amb.discrepancy.flat_tops import FLAT_SHARE, flat_top_channels
from bayes_amb.discrepancy.locate import locate_bands
from bayes_amb.io.recording import Recording
from bayes_amb.rig import CHANNELS

QUANTILES = (0.999, 0.997, 0.995, 0.99, 0.985, 0.98, 0.97, 0.96, 0.95, 0.93, 0.9)
"""Candidate limits: these quantiles of |u - median| (0.1 .. 10 % of the samples clip)."""
ALPHA = 1e-4
"""Family-wise level of the clipping test (over the candidate limits)."""
GAIN_RANGE = (0.5, 2.0)
"""beta must reach 1 within this range: the clip's path through the loop is known."""
LIMIT_SD = 0.01
"""Relative sd of an estimated amplifier limit (the regression's profile): 1 %, the
largest error seen on the command-recorded clips of the first benchmark run (0.2-1 %,
mean 0.6 %: the amplifier noise and offsets before the clip that d leaves out); with 2 %
the intervals of a 3-5 % clipped record span most of the prior."""
JAC_STEP = 1e-4
BAND_BINS = 48
"""Bins per narrow band of the linear partialling (a smooth linear misfit is nearly
constant across one)."""


@dataclass(frozen=True)
class Clipping:
    """The clipping regression's result: found, the largest z of beta over the grid, the
    limit L (A, about each channel's median) where beta = 1 with the clipped share there,
    and beta, its sd at the z-maximising limit."""

    found: bool
    z: float
    limit_a: float
    share: float
    beta: float
    beta_sd: float
    centre_a: tuple[float, ...] = ()
    z_linear_free: float = 0.0

    def to_dict(self) -> dict[str, float | bool]:
        return {"clipping_found": self.found, "clipping_z": self.z,
                "clipping_limit_a": self.limit_a if self.found else None,
                "clipped_share": self.share if self.found else None,
                "clipping_gain": self.beta, "clipping_gain_sd": self.beta_sd,
                "clipping_centre_a": list(self.centre_a) if self.found else None,
                "clipping_z_linear_free": self.z_linear_free}


def flat_tops(rec: Recording) -> list[str]:
    """Channels (y_*, u_*) whose extremes are held on many samples, with the share."""
    return [f"{g}_{CHANNELS[c]} held at its extreme on {100 * s:.2g} % of the samples"
            for g, c, s in flat_top_channels(rec)]


LIMIT_REACHED = 0.995
"""A sample reaches a rig-file limit at this fraction of it (or beyond: a recorded command
may exceed what the amplifier delivered)."""


def limit_hits(rec: Recording) -> list[str]:
    """Channels that reach a limit of the rig file's [limits] on at least FLAT_SHARE of
    the samples (and 5 of them): the amplifier current |u|, its slew rate |du/dt|, the
    probes' range |y|."""
    lim = getattr(rec.rig, "limits", None) or {}
    u, y = np.asarray(rec.u, dtype=float), np.asarray(rec.y, dtype=float)
    series = {"current_a": ("u", np.abs(u), "A", "the amplifier current limit"),
              "slew_a_per_s": ("du/dt of u", np.abs(np.diff(u, axis=0)) / rec.dt, "A/s",
                               "the amplifier slew-rate limit"),
              "sensor_range_m": ("y", np.abs(y), "m", "the probe range")}
    found = []
    for key, (what, v, unit, name) in series.items():
        if key not in lim:
            continue
        hit = v >= LIMIT_REACHED * lim[key]
        for c in range(len(CHANNELS)):
            share = float(np.mean(hit[:, c]))
            if share >= FLAT_SHARE and np.sum(hit[:, c]) >= 5:
                label = f"u_{CHANNELS[c]}" if what == "u" else (
                    f"y_{CHANNELS[c]}" if what == "y" else f"du/dt of u_{CHANNELS[c]}")
                found.append(f"{label} reaches {name} of the rig file ({lim[key]:g} {unit}, "
                             f"limits.{key}) on {100 * share:.2g} % of the samples")
    return found


def _residualise(A: NDArray, bases: list[tuple[NDArray, NDArray]]) -> NDArray:
    """A (nf, .) with its least-squares fit on Z removed within each band, given as (the
    band's bins, an orthonormal basis Q of Z there: band_bases)."""
    out = A.copy()
    for idx, Q in bases:
        out[idx] = A[idx] - Q @ (Q.conj().T @ A[idx])
    return out


def band_bases(Z: NDArray, bands: list[NDArray]) -> list[tuple[NDArray, NDArray]]:
    """Each band's bins and the orthonormal basis of Z (nf, .) over them (QR)."""
    return [(idx, np.linalg.qr(Z[idx])[0]) for idx in bands]


def clip_defect(u: NDArray, limit: float, centre: NDArray | None = None) -> NDArray:
    """d = clip(u, centre +- limit) - u per channel, (N, 4); centre (4,) defaults to the
    median (an amplifier offset moves the true centre away from it)."""
    dev = u - (np.median(u, axis=0) if centre is None else np.asarray(centre))
    return np.clip(dev, -limit, limit) - dev


def r2_response(forward, theta: NDArray, d: NDArray) -> NDArray:
    """The model's eps response (N, 4) from rest to a current d (N, 4) added at the plant
    input, as r2 is (the noise system's r2 port at theta)."""
    A, B, C, D = forward.noise_system(np.asarray(theta, dtype=float))
    return ss_response(A, B[:, 8:12], C, np.asarray(D)[:, 8:12], d)


def r2_filter(like, theta: NDArray) -> NDArray:
    """T_r2 (nf, 4, 4): the model's own r2 -> eps filter at theta in the likelihood's bins,
    on the residual's scale (a current added at the plant input enters the residual
    through it with a gain of exactly one)."""
    return ss_freqresp_modal(*like.forward.noise_system(theta), like.z)[:, :, 8:12] / like.scale


def r2_bins(like, H: NDArray, d: NDArray) -> NDArray:
    """T_r2 d in the likelihood's bins (nf, 4) for a current d (N, 4) added at the plant
    input, prefiltered and windowed as the residual is (H: r2_filter)."""
    w = lfilter(like.prefilter, [1.0], np.asarray(d, dtype=float), axis=0)
    D = np.fft.rfft(w[getattr(like, "start", 0):], axis=0)[like.k]
    return np.einsum("kij,kj->ki", H, D)


class Regression:
    """The whitened residual DFT of a fitted model, its Jacobian, its r2 -> eps filter and
    the band grouping, shared by the clipping test and the limit's estimate."""

    def __init__(self, like, params: NDArray, log10_sigma: NDArray, u: NDArray):
        theta = np.asarray(params, dtype=float)
        self.like, self.start = like, getattr(like, "start", 0)
        p = theta.size
        rows = like.residual_dft(np.vstack([theta, theta + JAC_STEP * np.eye(p)]))[0]
        J = (rows[1:] - rows[0][None]) / JAC_STEP                     # (p, nf, 4)
        self.H = r2_filter(like, theta)
        chol = np.linalg.cholesky(like.curvature_weights(theta, log10_sigma))  # W = L L^H
        self.LH = np.conj(np.swapaxes(chol, 1, 2))[np.repeat(np.arange(like.starts.size),
                                                              like.counts)]
        self.y = self.rows(rows[0])
        self.J = self.rows(np.moveaxis(J, 0, -1))                      # (rows, p)
        band = np.empty(like.k.size, dtype=int)
        wide = locate_bands(like.k, like.n, like.forward.dt, 12, 192)
        for i, idx in enumerate(wide):
            band[idx] = i
        self.n_groups = len(wide)
        self.group = np.tile(np.repeat(band, 4), 2)
        self.u = np.asarray(u, dtype=float)
        self.pooled = np.abs(self.u - np.median(self.u, axis=0)).ravel()
        w = lfilter(like.prefilter, [1.0], self.u - self.u.mean(axis=0), axis=0)
        self.U = np.hstack([np.fft.rfft(w[self.start:], axis=0)[like.k], like.X])
        self.narrow = band_bases(self.U, np.array_split(np.arange(like.k.size),
                                                        max(1, like.k.size // BAND_BINS)))
        self.y_linear_free = self.rows(_residualise(rows[0], self.narrow))

    def rows(self, V: NDArray) -> NDArray:
        """Whitened bins, real and imaginary parts stacked as regression rows."""
        w = np.einsum("kij,kj...->ki...", self.LH, V)
        return np.concatenate([w.real.reshape(-1, *V.shape[2:]),
                               w.imag.reshape(-1, *V.shape[2:])])

    def defect_dft(self, d: NDArray) -> NDArray:
        """T_r2 d in the likelihood's bins (nf, 4) for a current d (N, 4) added at the
        plant input (r2_bins)."""
        return r2_bins(self.like, self.H, d)

    def clip_dft(self, limit: float, centre: NDArray | None = None) -> NDArray:
        """T_r2 d in the likelihood's bins (nf, 4), d the clip defect at this limit and
        centre."""
        return self.defect_dft(clip_defect(self.u, limit, centre))

    def linear_free(self, X: NDArray) -> NDArray:
        """Regression rows of bins X (nf, 4) freed of their fit on the DFTs of u and the
        excitation within narrow bands (the part not linear in the loop's own signals)."""
        return self.rows(_residualise(X, self.narrow))

    def z_rows(self, limit: float, centre: NDArray | None = None) -> NDArray:
        """Regression rows of T_r2 d for the clip defect at this limit and centre."""
        return self.rows(self.clip_dft(limit, centre))

    def partial_z(self, limit: float) -> float:
        """z of the clip regressor after both it and the residual are freed of their
        least-squares fit on the DFTs of u and the excitation within narrow bands
        (Frisch-Waugh): the part of d that is not linear in the loop's own signals. A
        linear misfit (a lag the model lacks, which with r2 excitation is linear in the
        very currents d is cut from) cannot fake it."""
        return self.linear_free_z(self.clip_dft(limit))

    def linear_free_z(self, X: NDArray) -> float:
        """z of a defect's bins X (nf, 4) regressed on the residual with both freed of the
        loop's own linear signals (linear_free), with band-wise weights."""
        x = self.linear_free(X)
        b, wt = self.band_weights(x[:, None], self.y_linear_free)
        return float(b[0] * np.sqrt(np.sum((x * wt) ** 2)))

    def band_weights(self, X: NDArray, y: NDArray) -> tuple[NDArray, NDArray]:
        """Least squares of y on X with band-wise residual variances (two passes):
        coefficients and row weights."""
        wt = np.ones_like(y)
        for _ in range(2):
            b = _weighted_lstsq(X, y, wt)
            s2 = np.bincount(self.group, (y - X @ b) ** 2, minlength=self.n_groups) / \
                np.maximum(np.bincount(self.group, minlength=self.n_groups), 1)
            wt = 1.0 / np.sqrt(np.maximum(s2[self.group], 1e-300))
        return b, wt

    def gain(self, limit: float, centre: NDArray | None = None
             ) -> tuple[float, float, NDArray]:
        """beta, its sd and the row weights at one limit (and centre: default the
        medians)."""
        X = np.column_stack([self.z_rows(limit, centre), self.J])
        b, wt = self.band_weights(X, self.y)
        Xw = X * wt[:, None]
        return float(b[0]), float(np.sqrt(np.linalg.pinv(Xw.T @ Xw)[0, 0])), wt

    def profile(self, lo: float, hi: float, wt: NDArray, centre: NDArray | None = None
                ) -> tuple[float, NDArray]:
        """The limit in [lo, hi] and the centre per channel that best explain the residual
        with the gain fixed at one: least residual sum of squares with the coefficients
        free (their Jacobian projected out) and fixed band weights. The limit first on a
        grid at the given centres (default: the medians), then both by Nelder-Mead."""
        Q, _ = np.linalg.qr(self.J * wt[:, None])

        def rss(limit: float, c: NDArray) -> float:
            r = (self.y - self.z_rows(limit, c)) * wt
            return float(np.sum((r - Q @ (Q.T @ r)) ** 2))

        c = np.median(self.u, axis=0) if centre is None else np.array(centre, dtype=float)
        limit = _argmin_1d(lambda v: rss(v, c), np.linspace(lo, hi, 41))
        # then limit and centres together (the centres move the clipped share of each
        # channel's two sides; coordinate steps stall in that valley)
        x0 = np.concatenate([[limit], c]) / lo
        res = optimize.minimize(lambda x: rss(x[0] * lo, x[1:] * lo), x0,
                                method="Nelder-Mead",
                                options={"xatol": 1e-3, "fatol": 1e-3 * rss(limit, c) / 1e4,
                                         "maxfev": 600, "initial_simplex": np.vstack(
                                             [x0, x0 + 0.05 * np.eye(x0.size)])})
        x = res.x * lo
        return float(np.clip(x[0], lo, hi)), x[1:]


def _weighted_lstsq(X: NDArray, y: NDArray, wt: NDArray) -> NDArray:
    """Least squares of y wt on X wt; one column in closed form (an SVD of one column cost
    2 ms a call, and the clipping screen makes about a hundred).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> X, y, w = rng.normal(size=(50, 1)), rng.normal(size=50), rng.uniform(1, 2, 50)
    >>> ref = np.linalg.lstsq(X * w[:, None], y * w, rcond=None)[0]
    >>> bool(np.allclose(_weighted_lstsq(X, y, w), ref, rtol=1e-12, atol=0))
    True
    """
    if X.shape[1] != 1:
        return np.linalg.lstsq(X * wt[:, None], y * wt, rcond=None)[0]
    xw = X[:, 0] * wt
    den = float(xw @ xw)
    return np.array([float(xw @ (y * wt)) / den if den > 0 else 0.0])


def _argmin_1d(f, grid: NDArray) -> float:
    """The minimiser of f over a uniform grid, refined by a parabola through the best."""
    vals = [f(v) for v in grid]
    j = int(np.argmin(vals))
    if 0 < j < grid.size - 1:
        a, b, c = vals[j - 1], vals[j], vals[j + 1]
        den = a - 2 * b + c
        if den > 0:
            return float(grid[j] + 0.5 * (a - c) / den * (grid[1] - grid[0]))
    return float(grid[j])


def clipping(like, params: NDArray, log10_sigma: NDArray, u: NDArray,
             reg: Regression | None = None) -> Clipping:
    """The clipping regression on a fitted model's residual (module docstring).

    like: the model's likelihood (residual DFT, prefilter, window, bins, noise spectrum);
    params, log10_sigma: its fit; u (N, 4) the recorded currents as they entered eps;
    reg: the regression of that fit, when already built (the nonlinearity screen shares
    it)."""
    reg = reg or Regression(like, params, log10_sigma, u)
    limits = np.quantile(reg.pooled, QUANTILES)
    fits = [reg.gain(limit) for limit in limits]
    beta = np.array([f[0] for f in fits])
    sd = np.array([f[1] for f in fits])
    z = beta / sd
    j = int(np.argmax(z))
    z_crit = stats.norm.isf(ALPHA / len(limits))
    zp = np.array([reg.partial_z(limit) for limit in limits])
    found = bool(z[j] > z_crit and zp.max() > z_crit and beta.max() >= GAIN_RANGE[0]
                 and np.any(beta <= GAIN_RANGE[1]))
    limit, centre = float(limits[j]), np.median(reg.u, axis=0)
    if found:
        limit, centre = reg.profile(float(limits[-1]), float(limits[0]), fits[j][2])
    share = float(np.mean(clip_defect(reg.u, limit, centre) != 0))
    return Clipping(found, float(z[j]), limit, share, float(beta[j]), float(sd[j]),
                    tuple(float(v) for v in centre), float(zp.max()))


def linearity_check(rec: Recording, clip: Clipping | None = None,
                    modelled: str | None = None, shift: NDArray | None = None,
                    fitted: Any = None, screened: tuple = ()) -> Check:
    """The ``linearity`` data check: it fails on flat tops in the record, or when the
    clipping regression (given as ``clip``) finds a clipped current in the residual, or
    the force-law or slew screens (``screened``, nonlinear.py) find theirs.
    modelled: how the fit took the nonlinearity in ('command': clip(u) at the estimated
    limit; 'coil': the documented controller's command on the held samples;
    'magnet_force_law', 'slew_limit': that law at its estimate), or None; shift: how far
    the coefficients moved when it was modelled."""
    flats = flat_tops(rec)
    hits = limit_hits(rec)
    lines = detection_line_test(rec)
    amp = None if fitted is None else amplitude_test(fitted)
    values: dict = {"flat_tops": flats, "rig_limits": hits,
                    "detection_lines": lines.to_dict(),
                    **({} if amp is None else amp.to_dict()),
                    **(clip.to_dict() if clip is not None else {}),
                    "screens": [n.to_dict() for n in screened],
                    "nonlinearity": next((n.to_dict() for n in screened
                                          if n.found or n.source == "rig file"), None),
                    "modelled": modelled,
                    "coefficient_shift": None if shift is None else [float(v) for v in shift]}
    problems = [*flats, *hits, *([lines.problem()] if lines.found else []),
                *([amp.problem()] if amp is not None and amp.found else [])]
    if clip is not None and clip.found:
        problems.append(
            f"the residual follows the recorded current clipped at {clip.limit_a:.3g} A "
            f"about its centre ({100 * clip.share:.2g} % of the samples beyond it): gain "
            f"{clip.beta:.2f} +- {clip.beta_sd:.2f} through the model's own loop, where a "
            f"clipping amplifier gives 1 (z {clip.z:.0f})")
    for n in screened:
        if n.found:
            problems.append(f"the residual follows the {n.text()} (z {n.z:.0f}, "
                            f"{n.z_linear_free:.0f} after the loop's linear signals are "
                            f"taken out; threshold {n.z_crit:.1f})")
    if not problems:
        tail = (f", and the residual does not follow a clipped current (z {clip.z:.1f})"
                if clip is not None else "")
        lims = (", no rig-file limit reached" if getattr(rec.rig, "limits", None) else "")
        odd = (", no odd distortion on the odd multisine's detection lines (largest "
               f"odd/even power ratio {lines.worst['ratio']:.2f})"
               if lines.design and lines.worst else "")
        grows = ("" if amp is None else ", the residual does not grow with the amplitude "
                 f"(p {min(amp.p.values()):.2g})")
        tested = [n for n in screened if n.source == "record"]
        laws = ("" if not tested else ", nor a magnet force law, a slew limit or a "
                 "capped current loop (z "
                + ", ".join(f"{n.z:.1f}" for n in tested) + ")")
        law = next((n for n in screened if n.source == "rig file"), None)
        if law is not None:
            laws += (f"; the {law.text()} is modelled (one record at one level cannot tell "
                     "it from a stiffness change; the coefficients are the small-signal "
                     "ones)")
        elif screened and fitted is not None and (caveat := unknown_bias_line(rec, fitted)):
            laws += "; " + caveat
        return Check("linearity", True,
                     "linearity: no flat tops in u or y" + lims + odd + grows + tail + laws,
                     values)
    what = {"magnet_force_law": "the magnets' force law beyond its linearisation: no "
                                "linear physics is named, and the coefficients are "
                                "estimated with the law modelled at the estimated gap "
                                "(a smaller excitation keeps the currents nearer the "
                                "linearisation)",
            "rig_force_law": "the magnets' force law the rig file gives (its bias "
                             "current, and its iron's saturation where stated): no linear "
                             "physics is named, and the coefficients are estimated with "
                             "that law modelled (a smaller excitation keeps the currents "
                             "nearer the linearisation)",
            "slew_limit": "the amplifier's slew-rate limit: no linear physics is named, "
                          "and the coefficients are estimated with the limit modelled "
                          "(a smaller excitation, or one with fewer fast steps, keeps "
                          "di/dt below the limit)",
            "amp_current_loop": "the amplifier's current loop with its rate capped: no "
                                "linear physics is named (its lag is part of the loop), "
                                "and the coefficients are estimated with the loop "
                                "modelled (a smaller excitation, or one with fewer fast "
                                "steps, keeps the loop a linear lag)"}.get(
        modelled, "an amplifier current limit or a probe at the end of its range: no "
                  "physics is named, and the coefficients are estimated with the limit "
                  "modelled where it can be (keep the currents below the amplifier limit "
                  "and the probes inside their range: a smaller excitation)")
    return Check("linearity", False,
                 "linearity: FAILED - " + "; ".join(problems) + ". The loop is not linear "
                 f"here ({what})", values)


READ_AT = "they are the small-signal ones"
"""The words of the linearity line that say a record's stiffnesses are read at its own
current (no force law in the rig file); the diagnosis' summary repeats the point."""


def unknown_bias_line(rec: Recording, fitted: Any) -> str:
    """What a record at one level cannot say about the magnets' force law when the rig
    file gives no bias current: the stiffness a linear fit reads is ks (1 + <(i/i0)^2>),
    equal to the small-signal ks within its interval only for a bias above a bound."""
    u = np.asarray(rec.u, dtype=float)
    rms = float(np.sqrt(np.mean((u - np.median(u, axis=0)) ** 2)))
    sd = [np.sqrt(fitted.cov[i, i]) for i, n in enumerate(fitted.names)
          if n.startswith("k_") and fitted.cov is not None and i < fitted.cov.shape[0]]
    half = 1.645 * float(np.median(sd)) if sd else 0.0
    if not half > 0 or rms <= 0:
        return ""
    return (f"the stiffnesses are read at this record's {rms:.3g} A rms current: {READ_AT} "
            f"within their intervals if the magnets' bias current "
            f"exceeds {rms / np.sqrt(half):.3g} A (the force law reads ks (1 + "
            "<(i/i0)^2>), and a saturating iron softens them; give bearings.bias_current "
            "(and saturation_ratio) in the rig file to model it, or diagnose records at "
            "two excitation levels)")
