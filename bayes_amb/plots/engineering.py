"""Figures of the engineering answers: closed-loop modes against speed, per-axis
sensitivity with its posterior band, and frequency responses (model band, nominal model,
nonparametric estimate with coherence).

Each function takes a result object of :mod:`bayes_amb.engineering` and returns a Figure.
Legends sit outside the axes (below the figure), so that they never cover data.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter, LogLocator, MaxNLocator, NullFormatter

from bayes_amb.control.robustness import ISO_ZONES
from bayes_amb.plots.style import new_figure, styled
from bayes_amb.rig import CHANNELS

_BAND = "#1f4e9a"
_NOM = "0.35"
_MEAS = "#d9541e"
_MODE_COLOURS = ("#1f4e9a", "#2a9d48", "#8e44ad", "#b8860b", "#d9541e", "#c0392b")


def _log_x(ax: Any) -> None:
    """Log frequency axis labelled at decades only (no crowded minor labels)."""
    ax.set_xscale("log")
    ax.xaxis.set_major_locator(LogLocator(base=10.0))
    ax.xaxis.set_minor_formatter(NullFormatter())


def _log_y(ax: Any) -> None:
    """Log magnitude axis whose tick labels do not collide at the report's panel heights.

    Spanning under about a decade, matplotlib labels the minor ticks (or falls back to
    fine linear steps), and the labels run into each other; under two decades it shows
    one or two labels at most. Such an axis (under two decades) gets ticks at 1, 2 and 5
    per decade, or, under a factor 6.25 (fewer than two of those), three linear steps,
    labelled in plain numbers; minor ticks are never labelled."""
    ax.set_yscale("log")
    lo, hi = ax.get_ylim()
    ratio = hi / lo if lo > 0 else np.inf
    if ratio < 100.0:
        ax.yaxis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0))
                                   if ratio >= 6.25 else MaxNLocator(nbins=3))
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:.2g}"))
    ax.yaxis.set_minor_formatter(NullFormatter())


def _legend_below(fig: Figure, ax: Any, ncol: int = 4) -> None:
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=ncol, fontsize=8.5)


@styled
def plot_modes_vs_speed(res: Any) -> Figure:
    """Frequency and log decrement of each closed-loop mode against speed (median and 90 %
    interval over posterior draws, ``res.interval``: the tables' interval), the 1x
    running-speed line and the API 617 log-dec limit 0.1."""
    from bayes_amb.engineering.loop import API617_LOGDEC, MODE_LABELS, log_decrement

    fig = new_figure((7.2, 3.9))
    ax_f, ax_d = fig.subplots(1, 2)
    rpm = res.speeds_rpm
    for m, label in enumerate(MODE_LABELS):
        lam, lam_e = res.lam[:, :, m], res.lam_edge[:, :, m]
        f = lam.imag / (2 * np.pi)
        if not np.any(np.isfinite(f)):
            continue
        c = _MODE_COLOURS[m % len(_MODE_COLOURS)]
        for ax, v, ve in ((ax_f, f, lam_e.imag / (2 * np.pi)),
                          (ax_d, log_decrement(lam), log_decrement(lam_e))):
            with warnings.catch_warnings():            # a speed where the mode is missing
                warnings.simplefilter("ignore", RuntimeWarning)
                med = np.nanmedian(np.where(np.isfinite(v), v, np.nan), axis=0)
            lo, hi = res.interval(v, ve)
            ax.errorbar(rpm, med, yerr=[med - lo, hi - med], color=c, marker="o", ms=3.5,
                        lw=1.2, capsize=3, label=label)
    ax_f.plot(rpm, rpm / 60.0, color="k", lw=1.0, ls="--", label="1x running speed")
    ax_f.axvline(res.running_speed_rpm, color="0.5", lw=0.8, ls=":")
    ax_d.axvline(res.running_speed_rpm, color="0.5", lw=0.8, ls=":")
    ax_d.axhline(API617_LOGDEC, color="#c0392b", lw=1.0, ls="--",
                 label=f"log dec {API617_LOGDEC:g} (API 617)")
    ax_f.set_yscale("log")
    ax_d.set_yscale("log")
    ax_f.set_xlabel("speed (rpm)")
    ax_d.set_xlabel("speed (rpm)")
    ax_f.set_ylabel("frequency (Hz)")
    ax_d.set_ylabel("log decrement")
    ax_f.set_title("Closed-loop mode frequencies")
    ax_d.set_title("Log decrements")
    h1, l1 = ax_f.get_legend_handles_labels()
    h2, l2 = ax_d.get_legend_handles_labels()
    extra = [(h, lab) for h, lab in zip(h2, l2, strict=True) if "API 617" in lab]
    fig.legend(h1 + [h for h, _ in extra], l1 + [lab for _, lab in extra],
               loc="outside lower center", ncol=4, fontsize=8.5)
    return fig


@styled
def plot_sensitivity_band(res: Any) -> Figure:
    """|S| per axis at the running speed: posterior median and 90 % band (``res.interval``
    at every frequency), nominal plant, and the ISO 14839-3 zone limits."""
    fig = new_figure((7.2, 4.4))
    axes = fig.subplots(2, 2, sharex=True, sharey=True).ravel()
    f = res.sens_freq_hz
    db = 20 * np.log10(res.sens)
    med = np.nanmedian(db, axis=0)
    lo, hi = res.interval(db, 20 * np.log10(res.sens_edge))
    for c, (ax, ch) in enumerate(zip(axes, CHANNELS, strict=True)):
        ax.fill_between(f, lo[:, c], hi[:, c], color=_BAND, alpha=0.25, lw=0,
                        label="identified plant, 90 % band")
        ax.plot(f, med[:, c], color=_BAND, lw=1.3, label="identified plant, median")
        ax.plot(f, 20 * np.log10(res.sens_nominal[:, c]), color=_NOM, lw=1.0, ls="--",
                label="nominal plant")
        for zone, limit in ISO_ZONES:
            ax.axhline(20 * np.log10(limit), color="#c0392b", lw=0.7, ls=":",
                       label="ISO 14839-3 zone limits A/B/C" if zone == "A" else None)
        _log_x(ax)
        ax.set_title(f"axis {ch}")
        ax.set_ylim(-25, 16)
    for ax in axes[2:]:
        ax.set_xlabel("frequency (Hz)")
    for ax in axes[::2]:
        ax.set_ylabel("|S| (dB)")
    _legend_below(fig, axes[0])
    return fig


@styled
def plot_frf(res: Any, which: str = "plant") -> Figure:
    """Per-axis magnitude of the plant (m/A) or the closed-loop compliance (m/N): posterior
    band and median, nominal model, nonparametric estimate (excitation as instrument); the
    plant figure also shows the coherence of each output with the excitation."""
    band = res.plant_band if which == "plant" else res.compliance_band
    nom = res.plant_nominal if which == "plant" else res.compliance_nominal
    meas = res.plant_measured if which == "plant" else res.compliance_measured
    unit = "m/A" if which == "plant" else "m/N"
    f = res.freq_hz
    fig = new_figure((7.2, 4.9 if which == "plant" else 3.9))    # both on one A4 page
    if which == "plant":
        grid = fig.add_gridspec(4, 2, height_ratios=[3, 1, 3, 1])
        mags = [fig.add_subplot(grid[2 * (c // 2), c % 2]) for c in range(4)]
        cohs = [fig.add_subplot(grid[2 * (c // 2) + 1, c % 2], sharex=mags[c])
                for c in range(4)]
    else:
        mags = list(fig.subplots(2, 2, sharex=True).ravel())
        cohs = []
    for c, ch in enumerate(CHANNELS):
        ax = mags[c]
        ax.plot(f, meas[:, c], color=_MEAS, lw=0.9, label="measured (nonparametric)")
        ax.fill_between(f, band[0][:, c], band[2][:, c], color=_BAND, alpha=0.3, lw=0,
                        label="identified model, 90 % band")
        ax.plot(f, band[1][:, c], color=_BAND, lw=1.2, label="identified model, median")
        ax.plot(f, nom[:, c], color=_NOM, lw=1.0, ls="--", label="nominal model")
        _log_x(ax)
        ax.set_yscale("log")
        ax.set_title(f"{ch} → {ch}")
        ax.set_ylabel(f"|{'G' if which == 'plant' else 'compliance'}| ({unit})")
        if cohs:
            cohs[c].plot(f, res.coherence[:, c], color="k", lw=0.8)
            cohs[c].set_ylim(0, 1.05)
            _log_x(cohs[c])
            cohs[c].set_ylabel("coh.")
            cohs[c].set_xlabel("frequency (Hz)" if c >= 2 else "")
            ax.tick_params(labelbottom=False)
        elif c >= 2:
            ax.set_xlabel("frequency (Hz)")
    _legend_below(fig, mags[0])
    return fig


@styled
def plot_predictive_frf(freq_hz: Any, measured: Any, coherence: Any, draws: Any,
                        band_hz: float | None = None) -> Figure:
    """Posterior predictive in the frequency domain: the map from the excitation x to the
    innovation eps per channel (diagonal, |eps_j / x_j|), measured nonparametrically from
    the recording (x as instrument) against S(theta) for posterior draws. On a log scale
    both are visible even where S(theta) x is small against eps; the coherence says where
    the measured curve is data and where it is noise."""
    fig = new_figure((7.2, 4.5))            # ~115 mm on A4: shares its page with a figure
    grid = fig.add_gridspec(4, 2, height_ratios=[3, 1, 3, 1])
    for c, ch in enumerate(CHANNELS):
        ax = fig.add_subplot(grid[2 * (c // 2), c % 2])
        axc = fig.add_subplot(grid[2 * (c // 2) + 1, c % 2], sharex=ax)
        lo, med, hi = np.quantile(draws[:, :, c], [0.05, 0.5, 0.95], axis=0)
        ax.fill_between(freq_hz, 1e6 * lo, 1e6 * hi, color=_BAND, alpha=0.3, lw=0,
                        label="S(θ), posterior 90 % band")
        ax.plot(freq_hz, 1e6 * med, color=_BAND, lw=1.2, label="S(θ), posterior median")
        ax.plot(freq_hz, 1e6 * measured[:, c], color=_MEAS, lw=0.9,
                label="measured ε/x (excitation as instrument)")
        if band_hz:
            for a in (ax, axc):
                a.axvline(band_hz, color="0.4", lw=0.8, ls=":")
        _log_x(ax)
        _log_y(ax)
        ax.set_title(f"{ch} → {ch}")
        ax.set_ylabel("|ε/x| (µm/A)")
        ax.tick_params(labelbottom=False)
        axc.plot(freq_hz, coherence[:, c], color="k", lw=0.8)
        axc.set_ylim(0, 1.05)
        axc.set_ylabel("coh.")
        _log_x(axc)
        if c >= 2:
            axc.set_xlabel("frequency (Hz)")
        if c == 0:
            handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=3, fontsize=8.5)
    return fig


@styled
def plot_answers(answers: dict[str, Any], group: str) -> Figure:
    """Quantities of one group of the engineering answers, each relative to its median
    (the units differ within a group): the 90 % interval as a bar, the nominal value
    (theta = 0) as an open circle, in % of the median."""
    names = list(answers)
    fig = new_figure(figsize=(7.2, 1.1 + 0.32 * max(len(names), 1)))
    ax = fig.add_subplot()
    for i, n in enumerate(names):
        q = answers[n]
        ref = abs(q.value) if q.value else 1.0
        rel = [100.0 * (v - q.value) / ref for v in q.interval90]
        ax.plot(rel, [i, i], color="#1f4e9a", lw=2.5, label="90 % interval" if i == 0 else None)
        ax.plot(0.0, i, "o", color="#1f4e9a", label="median" if i == 0 else None)
        ax.plot(100.0 * (q.nominal - q.value) / ref, i, "o", mfc="none", color="#d9541e",
                label="nominal (θ = 0)" if i == 0 else None)
    ax.set_yticks(range(len(names)), [f"{n}: {answers[n].value:.4g} {answers[n].unit}"
                                      for n in names], fontsize=8)
    ax.invert_yaxis()
    ax.axvline(0.0, color="k", lw=0.6)
    ax.set_xlabel("% of the median")
    ax.set_title(group)
    _legend_below(fig, ax, ncol=3)
    return fig
