"""Figures of the recorded signals: excitation and innovation time series, their spectra,
and the residual tests (whiteness and cross-correlation with 99 % bounds, Ljung ch. 16).

Signals come in SI units (m, A) with shape (N, 4), channels Ax, Ay, Bx, By; displacements
are drawn in micrometres.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from bayes_amb.plots.style import new_figure, styled
from bayes_amb.rig import CHANNELS

UM = 1e6
_GROUP_LABEL = {"eta": ("η", "A"), "r2": ("r2", "A"), "r1": ("r1", "m")}


def _grid(rows: int, cols: int, size: tuple[float, float], **kw):
    fig = new_figure(size)
    return fig, np.atleast_2d(fig.subplots(rows, cols, squeeze=False, **kw))


def excitation_label(port: str) -> tuple[str, str, float]:
    """(symbol, unit shown, scale to that unit) of an excitation group."""
    sym, unit = _GROUP_LABEL.get(port, (port, "A"))
    return (sym, "µm", UM) if unit == "m" else (sym, unit, 1.0)


@styled
def plot_time_window(t: NDArray, x: NDArray, eps: NDArray, port: str,
                     window: tuple[float, float]) -> Figure:
    """Excitation x and innovation eps over a time window (s), one row per channel."""
    sym, xunit, xs = excitation_label(port)
    m = (t >= window[0]) & (t <= window[1])
    fig, axes = _grid(4, 2, (8.0, 5.6), sharex=True)
    for j, ch in enumerate(CHANNELS):
        axes[j, 0].step(t[m], xs * x[m, j], where="post", color="#1f4e9a", lw=0.9)
        axes[j, 1].plot(t[m], UM * eps[m, j], color="#d9541e", lw=0.9)
        axes[j, 0].set_ylabel(f"{sym} {ch} ({xunit})")
        axes[j, 1].set_ylabel(f"ε {ch} (µm)")
    axes[0, 0].set_title(f"excitation {sym} (injected)")
    axes[0, 1].set_title("innovation ε = M̃ y − Ñ u")
    for a in axes[-1]:
        a.set_xlabel("time t (s)")
    return fig


@styled
def plot_spectra(freq_hz: NDArray, curves: Sequence[tuple[str, NDArray]], ylabel: str,
                 title: str, band_hz: float | None = None,
                 styles: dict[str, dict] | None = None) -> Figure:
    """Power spectral densities per channel (2 x 2 panels), log-log.

    ``curves``: (label, psd (n_f, 4)) in the unit of ``ylabel``; curves with the same
    label share colour and legend entry; ``styles`` overrides line properties per label.
    ``band_hz`` marks the upper end of the band the likelihood uses.
    """
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    fig, axes = _grid(2, 2, (8.0, 4.8), sharex=True, sharey=True)
    f = freq_hz[1:]
    colours = ("#1f4e9a", "#d9541e", "0.45", "#2a9d48")
    order = list(dict.fromkeys(label for label, _ in curves))   # same label, same colour
    for j, (ax, ch) in enumerate(zip(axes.ravel(), CHANNELS, strict=True)):
        for label, psd in curves:
            kw = {"color": colours[order.index(label) % 4], "lw": 1.3,
                  **(styles or {}).get(label, {})}
            ax.loglog(f, np.maximum(psd[1:, j], 1e-300), label=label, **kw)
        if band_hz is not None:
            ax.axvline(band_hz, color="0.3", ls=":", lw=1.0)
        ax.set_title(f"channel {ch}", fontsize=10)
        ax.xaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:g}"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.yaxis.set_minor_formatter(NullFormatter())
    for ax in axes[-1]:
        ax.set_xlabel("frequency (Hz)")
    for ax in axes[:, 0]:
        ax.set_ylabel(ylabel)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    unique = dict(zip(labels, handles, strict=True))
    labels, handles = list(unique), list(unique.values())
    if band_hz is not None:
        from matplotlib.lines import Line2D
        handles.append(Line2D([], [], color="0.3", ls=":"))
        labels.append(f"likelihood band edge {band_hz:.0f} Hz")
    fig.legend(handles, labels, loc="outside lower center", ncols=min(4, len(labels)),
               fontsize=8.5)
    fig.suptitle(title, fontsize=10.5)
    return fig


@styled
def plot_correlations(lags_auto: NDArray, acf: NDArray, bound: float, lags_cross: NDArray,
                      ccf: NDArray, bound_cross: NDArray, port: str, dt: float) -> Figure:
    """Residual autocorrelation (left, 99 % bounds +-2.58/sqrt(N) of white data) and
    residual-excitation cross-correlation (right, 99 % bounds under independence), per
    channel.

    acf (n_lags, 4) for lags 0..; ccf (n_lags_cross, 4) of residual channel j against
    excitation channel j, bound_cross (4,); lags in samples, dt in s for the axis label.
    """
    sym = excitation_label(port)[0]
    fig, axes = _grid(4, 2, (8.0, 5.4), sharex="col")
    for j, ch in enumerate(CHANNELS):
        for a, lags, r, b in ((axes[j, 0], lags_auto[1:], acf[1:, j], bound),
                              (axes[j, 1], lags_cross, ccf[:, j], bound_cross[j])):
            out = np.abs(r) > b
            a.axhspan(-b, b, color="0.88", lw=0)
            a.vlines(lags, 0, r, color="#1f4e9a", lw=1.0)
            a.plot(lags[out], r[out], "o", color="#c0392b", ms=3)
            a.axhline(0, color="0.3", lw=0.6)
        axes[j, 0].set_ylabel(f"{ch}")
    axes[0, 0].set_title("autocorrelation of residual ε − S(θ̂)x")
    axes[0, 1].set_title(f"cross-correlation residual vs {sym}")
    axes[-1, 0].set_xlabel(f"lag (samples of {dt:g} s)")
    axes[-1, 1].set_xlabel(f"lag (samples of {dt:g} s; > 0: {sym} leads)")
    fig.suptitle("Grey band: 99 % bounds of uncorrelated data; red dots outside", fontsize=10)
    return fig
