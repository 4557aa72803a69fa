"""Figures of a model-discrepancy diagnosis: where the nominal model fails, which physics
explains it, and the fit before and after.

Inputs are what a diagnosis leaves: a :class:`bayes_amb.results.Diagnosis` (diagnosis.json)
and residuals.nc (an xarray Dataset); nothing is recomputed. Displacements in micrometres,
frequencies in Hz.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.figure import Figure

from bayes_amb.plots.data import _grid
from bayes_amb.plots.style import styled
from bayes_amb.rig import CHANNELS

if TYPE_CHECKING:
    import xarray as xr

# A diagnosis is a bayes_amb.results.Diagnosis and a candidate row its CandidateScore;
# typed as Any here, since the results call into these plots (Diagnosis.plot).
Diagnosis = CandidateScore = Any

_BEFORE, _AFTER, _DATA = "#d9541e", "#1f4e9a", "#9a9a9a"


def round_number(c: CandidateScore) -> int:
    """The search round of a candidate row (a node refit's "2 node" is round 2)."""
    return int(str(c.round).split()[0])


def _shade(ax: Any, bands: list[list[float]], color: str = "#f2c14e") -> None:
    for lo, hi in bands:
        ax.axvspan(max(lo, 1e-3), max(hi, lo * 1.02 + 1.0), color=color, alpha=0.3, lw=0)


@styled
def plot_location(ds: xr.Dataset, d: Diagnosis) -> Figure:
    """Top: multiple coherence of the nominal residual with the excitation per band and
    channel (markers where significant after Holm correction). Bottom: residual power over
    the fitted noise floor per band. Shaded: the located bands."""
    fig, axes = _grid(2, 1, (8.0, 4.2), sharex=True)
    f = np.sqrt(ds["band_lo_hz"].values * ds["band_hi_hz"].values)
    mm = d.mismatch
    sig = {(x.band_hz[0], c) for x in mm.findings
           if x.test == "coherence" for c in x.channels or []}
    lo = ds["band_lo_hz"].values
    for j, ch in enumerate(CHANNELS):
        coh = ds["coherence"].values[:, j]
        line, = axes[0, 0].semilogx(f, coh, marker=".", lw=1.0, label=ch)
        hit = [i for i in range(f.size) if (float(lo[i]), ch) in sig]
        axes[0, 0].plot(f[hit], coh[hit], "o", ms=7, mfc="none", color=line.get_color())
        axes[1, 0].semilogx(f, ds["floor_ratio"].values[:, j], marker=".", lw=1.0, label=ch)
    for ax in axes[:, 0]:
        _shade(ax, mm.bands_hz)
    axes[0, 0].set_ylabel("coherence with\nexcitation")
    axes[0, 0].set_title("Nominal residual: part explained by the excitation "
                         "(circles: significant, family-wise 1 %)")
    axes[1, 0].axhline(1.0, color="k", lw=0.8, ls="--")
    axes[1, 0].set_ylabel("residual power /\nnoise floor")
    axes[1, 0].set_xlabel("frequency (Hz)")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=4, fontsize=8.5)
    return fig


@styled
def plot_residual_spectra(ds: xr.Dataset, bands: list[list[float]] | None = None) -> Figure:
    """Welch spectra per channel: eps (grey), residual of the nominal model (orange) and of
    the model with the named physics (blue)."""
    fig, axes = _grid(2, 2, (8.0, 4.2), sharex=True)
    f = ds["freq"].values
    keep = f > 0
    for j, ch in enumerate(CHANNELS):
        ax = axes[j // 2, j % 2]
        ax.loglog(f[keep], 1e12 * ds["psd_eps"].values[keep, j], color=_DATA, lw=0.8,
                  label="ε")
        ax.loglog(f[keep], 1e12 * ds["psd_before"].values[keep, j], color=_BEFORE, lw=1.0,
                  label="residual, nominal")
        ax.loglog(f[keep], 1e12 * ds["psd_after"].values[keep, j], color=_AFTER, lw=1.0,
                  ls="--", label="residual, with named physics")
        _shade(ax, bands or [])
        ax.set_title(ch)
        if j % 2 == 0:
            ax.set_ylabel("PSD (µm²/Hz)")
        if j >= 2:
            ax.set_xlabel("frequency (Hz)")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=3, fontsize=8.5)
    return fig


CANDIDATES_SHOWN = 8
"""Candidates drawn per round in :func:`plot_candidates`: every one fitted fully, then the
best by screening gain (the report's table lists them all)."""


def _candidate_label(row: CandidateScore) -> str:
    """'c_Ax' for a bearing coefficient (its location is the parameter), else
    'effect@location'."""
    if row.effect == "bearing_coefficient":
        return str(row.location)
    return row.key


@styled
def plot_candidates(d: Diagnosis, shown: int = CANDIDATES_SHOWN) -> Figure:
    """Evidence per candidate and round: screening gain and log Bayes factor (fitted ones),
    with the acceptance threshold; per round the candidates fitted fully and the best of
    the others by screening gain, ``shown`` in all, best first."""
    rows = [r for r in d.candidates if r.round != "revisit"]
    rounds = sorted({round_number(r) for r in rows})
    ncol = min(2, len(rounds))
    nrow = -(-len(rounds) // ncol)
    per_round = []
    for rnd in rounds:
        rs = [r for r in rows if round_number(r) == rnd]
        fitted = [r for r in rs if r.log_bayes_factor is not None]
        rest = sorted((r for r in rs if r.log_bayes_factor is None),
                      key=lambda r: -(r.screen_gain or -np.inf))
        pick = (fitted + rest)[:max(shown, len(fitted))]
        per_round.append((rnd, sorted(pick, key=lambda r: -(r.screen_gain or -np.inf)),
                          len(rs)))
    n_max = max(len(p) for _, p, _ in per_round)
    fig, axes = _grid(nrow, ncol, (7.2, nrow * (0.9 + 0.18 * n_max) + 0.4), sharey=False)
    for extra in range(len(rounds), nrow * ncol):
        axes[extra // ncol, extra % ncol].set_visible(False)
    thr = float(d.criterion.split()[-1]) if d.criterion else 3.0
    accepted = {e.key for e in d.explanations}
    for k, (rnd, rs, n_all) in enumerate(per_round):
        ax = axes[k // ncol, k % ncol]
        y = np.arange(len(rs))
        gain = [max(r.screen_gain or 0.0, 1e-2) for r in rs]
        ax.barh(y, gain, color="#cfd8e3", label="screening gain (nats)")
        for i, r in enumerate(rs):
            if r.log_bayes_factor is not None:
                acc = r.key in accepted
                ax.plot(max(r.log_bayes_factor, 1e-2), i, "D",
                        color=_AFTER if acc else _BEFORE, ms=6)
        ax.axvline(thr, color="k", ls="--", lw=0.8)
        ax.set_xscale("log")
        ax.set_yticks(y, [_candidate_label(r) for r in rs], fontsize=8)
        ax.set_ylim(len(rs) - 0.5, -0.5)
        ax.set_title(f"round {rnd}" + (f" (best {len(rs)} of {n_all})" if n_all > len(rs)
                                       else ""), fontsize=9.5)
        ax.set_xlabel("nats (log scale)")
    axes[0, 0].plot([], [], "D", color=_AFTER, label="log BF, accepted")
    axes[0, 0].plot([], [], "D", color=_BEFORE, label="log BF, rejected")
    handles, labs = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labs, loc="outside lower center", ncols=3, fontsize=8.5)
    return fig


@styled
def plot_improvement(d: Diagnosis) -> Figure:
    """Log-likelihood gain of the chosen model over the nominal one, per likelihood band."""
    imp = d.mismatch.improvement
    gb = np.array(imp.gain_by_band if imp is not None else [])
    fig, axes = _grid(1, 1, (8.0, 3.2))
    ax = axes[0, 0]
    if gb.size:
        f = np.sqrt(np.maximum(gb[:, 0], 1e-3) * np.maximum(gb[:, 1], 1e-3))
        ax.semilogx(f, gb[:, 2], drawstyle="steps-mid", color=_AFTER)
        ax.axhline(0, color="k", lw=0.6)
        _shade(ax, imp.bands_hz)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("log-likelihood gain per band")
    ax.set_title("Where the named physics improves the fit")
    return fig


@styled
def plot_parameters(d: Diagnosis, truth: dict[str, float] | None = None) -> Figure:
    """Stiffness/damping estimates (mean and 90 % HDI) before and after, true values when
    known."""
    pb, pa = d.parameters_before, d.parameters_after
    names = list(pb)
    fig, axes = _grid(1, 1, (6.0, 1.1 + 0.6 * len(names)))
    ax = axes[0, 0]
    for i, n in enumerate(names):
        for off, src, col, lab in ((-0.12, pb, _BEFORE, "nominal model"),
                                   (0.12, pa, _AFTER, "with named physics")):
            lo, hi = src[n].hdi90
            ax.plot([lo, hi], [i + off, i + off], color=col, lw=2.5,
                    label=lab if i == 0 else None)
            ax.plot(src[n].mean, i + off, "o", color=col)
        if truth and n in truth:
            ax.plot(truth[n], i, "k|", ms=18, mew=2, label="true" if i == 0 else None)
    ax.set_yticks(range(len(names)), names)
    ax.invert_yaxis()
    ax.set_xlabel("θ (dimensionless); bars: 90 % HDI")
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=3, fontsize=8.5)
    return fig


@styled
def plot_benchmark(table: dict[str, Any]) -> Figure:
    """Concealed-effect benchmark: per case, the share of recordings where the hidden
    effect(s) were named (controls: where nothing was named), with the targets."""
    cases = list(table["per_case"])
    vals, n = [], []
    for c in cases:
        v = table["per_case"][c]
        ok = v["n"] - v["false_names"] if c == "none" else v["right_named"]
        vals.append(ok / v["n"] if v["n"] else np.nan)
        n.append(v["n"])
    fig, axes = _grid(1, 1, (8.0, 3.8))
    ax = axes[0, 0]
    x = np.arange(len(cases))
    colors = ["#7a7a7a" if c == "none" else "#1f4e9a" if "+" not in c else "#6a3d9a"
              for c in cases]
    ax.bar(x, vals, color=colors)
    for i, (v, k) in enumerate(zip(vals, n, strict=True)):
        ax.text(i, min(v, 1.0) + 0.02, f"{v:.0%}\nn={k}", ha="center", fontsize=8)
    for goal, ls in ((0.9, "--"), (0.7, ":")):
        ax.axhline(goal, color="k", lw=0.8, ls=ls)
    ax.set_xticks(x, [c.replace("+", "+\n") for c in cases], fontsize=8, rotation=30,
                  ha="right")
    ax.set_ylim(0, 1.15)
    ax.set_ylabel("share correct")
    ax.set_title("Hidden effect named (controls: nothing named); targets 90 % (--), "
                 "pairs 70 % (:)")
    return fig
