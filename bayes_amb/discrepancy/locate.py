"""Where does the nominal model fail? Residual tests after the nominal fit.

The residual r = eps - S(theta_hat) x is coloured by the loop (eq. 14), so every test works
on quantities whose null distribution does not depend on that colour:

coherence   per frequency band and channel, the residual DFT regressed on the excitation
            DFT (4 inputs); F-test of "the excitation explains part of the residual"
            (complex regression: F(8, 2(n_b - 4)) under the null). Only needs the noise to
            be locally white within a band, not the noise model to be right.
lines       per channel, each bin of the residual periodogram against a running median of
            its neighbours (exponential null); only lines at 1x the running speed count
            as a mismatch; other lines (mains, neighbouring machines) are measurement
            habits: reported under ``lines`` and kept out of the floor/whiteness tests.
floor       per band, the residual whitened by the fitted noise spectrum against its
            expected power (Gamma null): excess power the noise model does not explain.
whiteness   Ljung-Box on the whitened residual of each channel (Ljung, ch. 16).
crosscorr   cross-correlation of the residual with the excitation at lags 0..M,
            chi-square statistic (Ljung, ch. 16). The excitation is used, not u: under
            feedback u is correlated with the noise. Both series are first flattened by
            their own smoothed amplitude spectra (per channel), so that the lags are
            independent under the null whatever the colour of the noise: with a coloured
            residual the plain statistic has the right mean but a heavier tail (lags
            correlated), and sensor noise of a real rig is coloured.
windows     the flattened residual variance over 8 time windows (Bartlett's test; flattened
            for the same reason: Bartlett's null assumes independent samples).
ppc         posterior predictive p-values of the largest coherence F and of the whitened
            residual power, from replicated residuals under the fitted model.

Two families. The *mismatch* tests (coherence, lines at 1x, crosscorr, windows) look for
structure rotor physics can leave; they are Holm-corrected together at a family-wise 1 %,
and only they set ``detected``. The *noise* tests (floor, whiteness) ask whether the
residual spectrum is the loop noise model's; they fail on coloured sensor noise or a
band-limited disturbance, which are habits of a record, not physics, and which the
noise-marginalised likelihood already tolerates. They are reported (``noise_findings``),
Holm-corrected in their own family, and never count as a mismatch.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats
from scipy.ndimage import median_filter, uniform_filter1d
from scipy.optimize import minimize_scalar

from bayes_amb.control.discrete import ss_freqresp_modal
from bayes_amb.discrepancy.likelihood import RobustWhittle, alias_hz
from bayes_amb.inference.narrow_lines import SPEED_TOLERANCE
from bayes_amb.rig import CHANNELS

ALPHA = 0.01
"""Family-wise error rate of the whole battery of location tests."""


@dataclass(frozen=True)
class LocateOptions:
    """Band layout and test settings: n_bands (log-spaced, merged to >= min_bins each),
    ljung_box lags, cross-correlation lags, time windows, posterior predictive draws (0:
    none, and no posterior predictive p-values; identify's adequacy test, which reports
    only the verdict, takes none)."""

    n_bands: int = 24
    min_bins: int = 16
    lb_lags: int = 20
    xcorr_lags: int = 25
    n_windows: int = 8
    n_ppc: int = 200
    seed: int = 0


@dataclass
class Location:
    """Result of :func:`locate`: the verdict and the per-band numbers behind it."""

    detected: bool
    channels: list[str]
    bands_hz: list[list[float]]
    time_s: list[float] | None
    evidence: dict[str, Any]
    findings: list[dict[str, Any]]
    band_lo_hz: NDArray
    band_hi_hz: NDArray
    coherence: NDArray            # (n_bands, 4) multiple coherence residual vs excitation
    coherence_p: NDArray          # (n_bands, 4)
    floor_ratio: NDArray          # (n_bands, 4) residual power / fitted noise floor
    floor_p: NDArray              # (n_bands,)
    whiteness_p: NDArray          # (4,) Ljung-Box
    xcorr: NDArray                # (4, 4, lags + 1) residual channel x input channel
    xcorr_bound: float
    autocorr: NDArray             # (4, lb_lags + 1)
    lines: list[dict[str, Any]] = field(default_factory=list)
    noise_findings: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """The ``mismatch`` block of diagnosis.json."""
        return {"detected": self.detected, "channels": self.channels,
                "bands_hz": self.bands_hz, "time_s": self.time_s, "evidence": self.evidence,
                "findings": self.findings, "noise_findings": self.noise_findings,
                "lines": self.lines}


def holm(pvals: NDArray) -> NDArray:
    """Holm step-down adjusted p-values (same shape)."""
    p = np.asarray(pvals, dtype=float).ravel()
    order = np.argsort(p)
    m = p.size
    adj = np.empty(m)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[i]))
        adj[i] = running
    return adj.reshape(np.shape(pvals))


def locate_bands(k: NDArray, n: int, dt: float, n_bands: int, min_bins: int) -> list[NDArray]:
    """Index sets into the bins k: log-spaced bands merged until each has >= min_bins."""
    f = k / (n * dt)
    edges = np.geomspace(max(f[0], 1.0 / (n * dt)), f[-1] * (1 + 1e-9), n_bands + 1)
    bands: list[NDArray] = []
    cur: list[int] = []
    for lo, hi in itertools.pairwise(edges):
        cur += list(np.flatnonzero((f >= lo) & (f < hi)))
        if len(cur) >= min_bins:
            bands.append(np.array(cur))
            cur = []
    if cur:
        if bands:
            bands[-1] = np.concatenate([bands[-1], cur])
        else:
            bands.append(np.array(cur))
    return bands


def _coherence(R: NDArray, X: NDArray, bands: list[NDArray],
               bases: list[NDArray] | None = None) -> tuple[NDArray, NDArray]:
    """Multiple coherence and F-test p-value of R (nf, 4) on X (nf, m) per band, channel;
    R may carry a leading batch dimension (nd, nf, 4), then so do the results. The
    regression residual is R minus its projection on the band's orthonormal basis of X
    (shared by the batch).

    The basis spans only the directions X has: an excitation channel that is zero (one
    channel excited) adds no regressor. A QR of X with zero columns still returns m
    orthonormal columns, arbitrary directions of the band (unit bins, in practice), and a
    residual whose noise peaks in the band (a mode of the noise response) then looked
    "coherent with the excitation": 31 of 50 effect-free one-channel foreign records were
    called unexplained that way (the F-test's degrees of freedom counted the dead columns
    as well). ``bases``: the bands' bases, excitation_bases(X, bands), when they are at
    hand."""
    R3 = R[None] if R.ndim == 2 else R
    coh = np.zeros((R3.shape[0], len(bands), R3.shape[2]))
    p = np.ones_like(coh)
    bases = excitation_bases(X, bands) if bases is None else bases
    for b, (idx, Q) in enumerate(zip(bands, bases, strict=True)):
        m = Q.shape[1]
        if m == 0 or idx.size <= m + 1:
            continue
        Rb = R3[:, idx]
        ss1 = np.sum(np.abs(Rb - Q @ (np.conj(Q.T) @ Rb)) ** 2, axis=1)
        ss0 = np.sum(np.abs(Rb) ** 2, axis=1)
        coh[:, b] = 1.0 - ss1 / np.maximum(ss0, 1e-300)
        F = ((ss0 - ss1) / m) / np.maximum(ss1 / (idx.size - m), 1e-300)
        p[:, b] = stats.f.sf(F, 2 * m, 2 * (idx.size - m))
    return (coh[0], p[0]) if R.ndim == 2 else (coh, p)


def excitation_bases(X: NDArray, bands: list[NDArray]) -> list[NDArray]:
    """The orthonormal basis of X over each band (excitation_basis)."""
    return [excitation_basis(X[idx]) for idx in bands]


def excitation_basis(Xb: NDArray, rtol: float = 1e-9) -> NDArray:
    """Orthonormal basis (nk, r) of the columns of Xb (nk, m): r its numerical rank, the
    singular values above rtol times the largest (zero columns add none)."""
    U, s, _ = np.linalg.svd(Xb, full_matrices=False)
    if s.size == 0 or s[0] == 0.0:
        return U[:, :0]
    return U[:, :int(np.sum(s > rtol * s[0]))]


def noise_cholesky(like: RobustWhittle, log10_sigma: NDArray) -> NDArray:
    """Per-bin Cholesky factor L_k (nf, 4, 4) of the fitted residual DFT covariance
    N Phi(w_k) (loop noise filters at the likelihood's reference, prewhitening gain)."""
    A, B, C, D = like.forward.noise_system(like.theta_ref)
    H = ss_freqresp_modal(A, B, C, D, like.z) / like.scale                    # (nf, 4, 12)
    s = np.repeat(10.0 ** np.asarray(log10_sigma), 4)
    Hs = H * s[None, None, :]
    Phi = (Hs @ np.conj(np.swapaxes(Hs, 1, 2))) * like.w_gain2[:, None, None] * like.n
    Phi += 1e-12 * np.trace(Phi, axis1=1, axis2=2).real[:, None, None] * np.eye(4) / 4
    return np.linalg.cholesky(Phi)


def whiten(L: NDArray, R: NDArray) -> NDArray:
    """R_k -> L_k^-1 R_k: complex standard normal per bin and channel under the fit."""
    return np.linalg.solve(L, R[..., None])[..., 0]


def whitened_series(W: NDArray, k: NDArray, n: int) -> NDArray:
    """Real time series (n, 4) whose rfft is W on bins k (zero elsewhere), unit variance."""
    full = np.zeros((n // 2 + 1, W.shape[1]), dtype=complex)
    full[k] = W
    return _unit_variance(np.fft.irfft(full, n, axis=0))


def _unit_variance(e: NDArray) -> NDArray:
    """Each column of a series scaled to unit mean square."""
    return e / np.sqrt(np.maximum(np.mean(e**2, axis=0, keepdims=True), 1e-300))


def ljung_box(e: NDArray, lags: int) -> tuple[NDArray, NDArray]:
    n = e.shape[0]
    ac = np.array([[np.dot(e[:n - j, c], e[j:, c]) / n for j in range(lags + 1)]
                   for c in range(e.shape[1])])
    ac = ac / ac[:, :1]
    q = n * (n + 2) * np.sum(ac[:, 1:] ** 2 / (n - np.arange(1, lags + 1)), axis=1)
    return ac, stats.chi2.sf(q, lags)


FLATTEN_BINS = 63
"""Width (bins) of the running mean of |DFT|^2 that flattens a series' spectrum."""


def flatten(F: NDArray, width: int = FLATTEN_BINS) -> NDArray:
    """Divide each column of a DFT (nf, c) by the square root of its running mean power
    over ``width`` bins: a nonparametric prewhitening (zero bins stay zero)."""
    P = uniform_filter1d(np.abs(F) ** 2, size=width, axis=0, mode="reflect")
    return F / np.sqrt(np.maximum(P, 1e-300 + 1e-12 * P.max(initial=0.0)))


def flat_series(x: NDArray) -> NDArray:
    """A real series (n, c) with its spectrum flattened (:func:`flatten`), unit variance."""
    n = x.shape[0]
    X = np.fft.rfft(x - x.mean(axis=0), axis=0)
    X[0] = 0.0
    return _unit_variance(np.fft.irfft(flatten(X), n, axis=0))


def _xcorr(e: NDArray, x: NDArray, lags: int) -> tuple[NDArray, NDArray]:
    """r_{e_c x_i}(tau), tau = 0..lags (x leads), and the chi-square p per (c, i); e and x
    should be (near) white, as after :func:`flatten`."""
    n = e.shape[0]
    xs = (x - x.mean(axis=0)) / np.maximum(x.std(axis=0), 1e-300)
    out = np.zeros((e.shape[1], x.shape[1], lags + 1))
    for tau in range(lags + 1):
        out[:, :, tau] = e[tau:].T @ xs[:n - tau] / n
    q = n * np.sum(out**2, axis=2)
    return out, stats.chi2.sf(q, lags + 1)


def _lines(W: NDArray, like: RobustWhittle, f_rot: float
           ) -> tuple[list[dict[str, Any]], float, NDArray]:
    """Bins of the whitened residual W whose power stands out of a running median of 51
    bins (exponential null: the median of Exp(1) is ln 2); Bonferroni p-values.

    Returns the lines found (each marked synchronous or not), the smallest p-value among
    bins at 1x the running speed (within SPEED_TOLERANCE; the only lines physics can
    explain: unbalance, runout), and a mask (nf,) of the bins of the other lines:
    measurement lines (mains, a neighbouring machine) that are a habit of the record, not
    rotor physics. They are reported and kept out of the floor and whiteness tests.
    """
    P = np.abs(W) ** 2
    med = median_filter(P, size=(51, 1), mode="reflect") / np.log(2)
    ratio = P / np.maximum(med, 1e-300)
    n_tests = ratio.size
    p_bin = np.minimum(1.0, np.exp(-ratio) * n_tests)
    df = 1.0 / (like.n * like.forward.dt)
    freq = like.k * df
    alias = alias_hz(f_rot, 1.0 / like.forward.dt)
    sync_bin = np.abs(freq - alias) <= max(2.0 * df, SPEED_TOLERANCE * f_rot)
    found: list[dict[str, Any]] = []
    nuisance = np.zeros(freq.size, dtype=bool)
    sig = np.flatnonzero(np.min(p_bin, axis=1) < ALPHA)
    for i in sig:
        if not sync_bin[i]:
            nuisance[max(i - 1, 0):i + 2] = True
        if found and freq[i] - found[-1]["freq_hz"] <= 1.5 * df:
            continue                                           # one line per cluster
        chans = [CHANNELS[c] for c in range(4) if p_bin[i, c] < ALPHA]
        found.append({"freq_hz": float(freq[i]), "channels": chans,
                      "p_value": float(np.min(p_bin[i])),
                      "power_ratio": float(np.max(ratio[i])),
                      "synchronous": bool(sync_bin[i])})
    p_sync = float(np.min(p_bin[sync_bin])) if np.any(sync_bin) else 1.0
    return found, p_sync, nuisance


def synchronous_speed(residual: NDArray, dt: float, speed_rpm: float,
                      tolerance: float = SPEED_TOLERANCE, pad: int = 16) -> float:
    """The running speed (rpm) of the 1x line in a residual (n, 4): the frequency within
    ``tolerance`` of the recorded speed that maximises the summed periodogram of the
    channels (zero-padded DFT, then a bounded scalar search between the neighbouring
    padded bins). The speed written in a record is often a set point; a line 0.5 % off it
    lies several bins away in a 2 s record, where a model at the written speed cannot
    fit it."""
    r = residual - residual.mean(axis=0)
    n = r.shape[0]
    t = np.arange(n) * dt
    f0 = speed_rpm / 60.0
    F = np.fft.rfft(r, pad * n, axis=0)
    f = np.fft.rfftfreq(pad * n, dt)
    band = np.flatnonzero(np.abs(f - alias_hz(f0, 1.0 / dt)) <= tolerance * f0)
    if band.size == 0:
        return speed_rpm
    i = band[np.argmax(np.sum(np.abs(F[band]) ** 2, axis=1))]
    df = f[1] - f[0]

    def neg_power(fr: float) -> float:
        return -float(np.sum(np.abs(np.exp(-2j * np.pi * fr * t) @ r) ** 2))

    res = minimize_scalar(neg_power, bounds=(f[i] - df, f[i] + df), method="bounded",
                          options={"xatol": 1e-4 * df})
    alias = alias_hz(f0, 1.0 / dt)               # unfold an aliased line
    sign = 1.0 if (f0 % (1.0 / dt)) <= 0.5 / dt else -1.0
    return 60.0 * (f0 + sign * (float(res.x) - alias))


def _windows(e: NDArray, n_windows: int, dt: float, skip: int = 0
             ) -> tuple[NDArray, list[float] | None]:
    """Bartlett's test of the residual's variance over n_windows time windows after the
    first ``skip`` samples (the prewhitening FIR filling up: its output's variance grows
    over its length, which is no model error), and the worst window [t0, t1] (s)."""
    skip = min(int(skip), e.shape[0] // 2)
    e = e[skip:]
    n = e.shape[0] // n_windows * n_windows
    parts = e[:n].reshape(n_windows, -1, e.shape[1])
    p = np.array([stats.bartlett(*parts[:, :, c]).pvalue for c in range(e.shape[1])])
    v = np.var(parts, axis=1)                                   # (n_windows, 4)
    worst = int(np.argmax(np.max(np.abs(np.log(v / np.median(v, axis=0))), axis=1)))
    seg = n // n_windows
    return p, [(skip + worst * seg) * dt, (skip + (worst + 1) * seg) * dt]


def _ppc(like: RobustWhittle, P_hat: NDArray, cov: NDArray | None, L: NDArray,
         bands: list[NDArray], obs: tuple[float, float], opt: LocateOptions,
         chunk: int = 25) -> dict[str, float]:
    """Posterior predictive p-values of (max coherence F-p, whitened power) under the fit
    (draws taken ``chunk`` at a time through the coherence and whitening)."""
    rng = np.random.default_rng(opt.seed)
    p = P_hat.size
    draws = np.tile(P_hat, (opt.n_ppc, 1))
    if cov is not None:
        draws = rng.multivariate_normal(P_hat, cov[:p, :p], size=opt.n_ppc)
    Y, stable = like.prediction_dft(np.vstack([P_hat, draws]))
    ok = np.flatnonzero(stable[1:])
    nf = like.z.size
    L_inv = np.linalg.inv(L)
    bases = excitation_bases(like.X, bands)
    t_coh, t_pow = [], []
    for c in range(0, ok.size, chunk):
        j = ok[c:c + chunk]
        g = rng.normal(size=(j.size, 2, nf, 4))  # each draw's real, then imaginary part
        noise = (g[:, 0] + 1j * g[:, 1]) / np.sqrt(2)
        R = (Y[0][None] - Y[j + 1]) + (L[None] @ noise[..., None])[..., 0]
        _, pc = _coherence(R, like.X, bands, bases)
        t_coh += list(-np.log10(np.maximum(pc.min(axis=(1, 2)), 1e-300)))
        t_pow += list(np.sum(np.abs((L_inv[None] @ R[..., None])[..., 0]) ** 2,
                             axis=(1, 2)))
    t_coh, t_pow = np.array(t_coh), np.array(t_pow)
    return {"coherence": float(np.mean(t_coh >= obs[0])) if t_coh.size else 1.0,
            "power": float(np.mean(t_pow >= obs[1])) if t_pow.size else 1.0}


MISMATCH_TESTS = ("coherence", "crosscorr", "lines", "windows")
"""The tests whose findings count as a mismatch (structure physics can leave)."""


def locate(like: RobustWhittle, P_hat: NDArray, log10_sigma: NDArray,
           cov: NDArray | None = None, options: LocateOptions | None = None) -> Location:
    """Run the location tests on the residual of a fitted (nominal) model.

    like: the whole-band likelihood of the fitted model, with its noise reference at the
    fit; P_hat its parameter vector; log10_sigma the fitted noise intensities; cov the
    Laplace covariance (for the posterior predictive draws).
    """
    opt = options or LocateOptions()
    like.set_noise_reference(P_hat)
    R = like.residual_dft(P_hat[None])[0][0]                           # (nf, 4)
    bands = locate_bands(like.k, like.n, like.forward.dt, opt.n_bands, opt.min_bins)
    freq = like.k / (like.n * like.forward.dt)
    lo = np.array([freq[b[0]] for b in bands])
    hi = np.array([freq[b[-1]] for b in bands])
    coh, coh_p = _coherence(R, like.X, bands)
    L = noise_cholesky(like, log10_sigma)
    W = whiten(L, R)
    f_rot = like.forward.recording.speed_rpm / 60.0
    lines, line_p, nuisance = _lines(W, like, f_rot)
    keep = ~nuisance
    W_clean = np.where(keep[:, None], W, 0.0)          # measurement lines kept out
    pow_b = np.array([np.sum(np.abs(W_clean[b]) ** 2, axis=0) for b in bands])  # (nb, 4)
    counts = np.array([max(int(keep[b].sum()), 1) for b in bands])
    floor_ratio = pow_b / counts[:, None]
    floor_p = stats.gamma.sf(pow_b.sum(axis=1), 4 * counts)
    e = whitened_series(W_clean, like.k, like.n)
    ac, lb_p = ljung_box(e, opt.lb_lags)
    e_flat = whitened_series(flatten(W_clean), like.k, like.n)
    xc, xc_p = _xcorr(e_flat, flat_series(like.x_window), opt.xcorr_lags)
    win_p, window = _windows(e_flat, opt.n_windows, like.forward.dt, like.prefilter.size - 1)
    adj_f = _holm_families({"coherence": coh_p.ravel(), "crosscorr": xc_p.ravel(),
                            "lines": np.array([line_p]), "windows": win_p})
    adj_f.update(_holm_families({"floor": floor_p, "whiteness": lb_p}))
    obs = (-np.log10(max(coh_p.min(), 1e-300)), float(np.sum(np.abs(W) ** 2)))
    ppc = _ppc(like, P_hat, cov, L, bands, obs, opt) if opt.n_ppc > 0 else None
    sig_coh = adj_f["coherence"].reshape(coh_p.shape) < ALPHA
    findings: list[dict[str, Any]] = []
    for b in np.flatnonzero(sig_coh.any(axis=1)):
        findings.append({"test": "coherence", "band_hz": [float(lo[b]), float(hi[b])],
                         "channels": [CHANNELS[c] for c in np.flatnonzero(sig_coh[b])],
                         "coherence": float(coh[b].max()),
                         "p_adjusted": float(adj_f["coherence"].reshape(coh_p.shape)[b].min())})
    if adj_f["lines"][0] < ALPHA:
        for ln in (ln for ln in lines if ln["synchronous"]):
            findings.append({"test": "line", "band_hz": [ln["freq_hz"], ln["freq_hz"]],
                             "channels": ln["channels"], "synchronous": ln["synchronous"],
                             "p_adjusted": float(adj_f["lines"][0])})
    xc_adj = adj_f["crosscorr"].reshape(xc_p.shape)
    for c in np.flatnonzero((xc_adj < ALPHA).any(axis=1)):
        findings.append({"test": "crosscorr", "channels": [CHANNELS[c]],
                         "inputs": [CHANNELS[i] for i in np.flatnonzero(xc_adj[c] < ALPHA)],
                         "p_adjusted": float(xc_adj[c].min())})
    time_s = None
    if np.any(adj_f["windows"] < ALPHA):
        time_s = window
        findings.append({"test": "windows", "time_s": window,
                         "channels": [CHANNELS[c] for c in
                                      np.flatnonzero(adj_f["windows"] < ALPHA)],
                         "p_adjusted": float(adj_f["windows"].min())})
    noise_findings = _noise_findings(adj_f, floor_ratio, counts, lo, hi)
    detected = bool(findings)
    channels = sorted({c for f in findings for c in f.get("channels", [])},
                      key=CHANNELS.index)
    spans = [f["band_hz"] for f in findings if "band_hz" in f]
    p_min = float(min(adj_f[k].min() for k in MISMATCH_TESTS))
    evidence = {"p_adjusted_min": p_min,
                "strength": _strength(p_min, detected),
                "family_min_p_adjusted": {k: float(v.min()) for k, v in adj_f.items()},
                "n_tests": int(sum(adj_f[k].size for k in MISMATCH_TESTS)), "alpha": ALPHA,
                "posterior_predictive_p": ppc,
                "max_coherence": float(coh.max())}
    return Location(detected=detected, channels=channels, bands_hz=merge_spans(spans),
                    time_s=time_s, evidence=evidence, findings=findings, band_lo_hz=lo,
                    band_hi_hz=hi, coherence=coh, coherence_p=coh_p, floor_ratio=floor_ratio,
                    floor_p=floor_p, whiteness_p=lb_p, xcorr=xc,
                    xcorr_bound=float(2.576 / np.sqrt(like.n)), autocorr=ac, lines=lines,
                    noise_findings=noise_findings)


def _holm_families(families: dict[str, NDArray]) -> dict[str, NDArray]:
    """Holm-adjust the p-values of several tests together; returned per test."""
    adj = holm(np.concatenate(list(families.values())))
    out, pos = {}, 0
    for name, v in families.items():
        out[name] = adj[pos:pos + v.size]
        pos += v.size
    return out


def _noise_findings(adj_f: dict[str, NDArray], floor_ratio: NDArray, counts: NDArray,
                    lo: NDArray, hi: NDArray) -> list[dict[str, Any]]:
    """Floor and whiteness findings: the residual spectrum is not the loop noise model's."""
    out: list[dict[str, Any]] = []
    for b in np.flatnonzero(adj_f["floor"] < ALPHA):
        out.append({"test": "floor", "band_hz": [float(lo[b]), float(hi[b])],
                    "channels": [CHANNELS[c] for c in range(4)
                                 if floor_ratio[b, c] > 1 + 3 / np.sqrt(counts[b])],
                    "power_ratio": float(floor_ratio[b].mean()),
                    "p_adjusted": float(adj_f["floor"][b])})
    for c in np.flatnonzero(adj_f["whiteness"] < ALPHA):
        out.append({"test": "whiteness", "channels": [CHANNELS[c]],
                    "p_adjusted": float(adj_f["whiteness"][c])})
    return out


def _strength(p: float, detected: bool) -> str:
    if not detected:
        return "none"
    return "decisive" if p < 1e-6 else "strong" if p < 1e-4 else "moderate"


def merge_spans(spans: list[list[float]]) -> list[list[float]]:
    """Merge overlapping or touching [lo, hi] intervals (Hz)."""
    out: list[list[float]] = []
    for lo, hi in sorted(spans):
        if out and lo <= out[-1][1] * 1.05 + 1.0:
            out[-1][1] = max(out[-1][1], hi)
        else:
            out.append([lo, hi])
    return [[round(a, 2), round(b, 2)] for a, b in out]
