"""Figures of a posterior: trace and rank plots per walker, a pair (corner) plot, prior
against posterior, and the posterior predictive eps = S(theta) x against the data.

Draws come as a dict name -> array (n_walkers, n_draws); walkers are drawn as chains (they
are not independent: the autocorrelation time tau in the table says how many draws count).
Dense artists are rasterised so that SVG output stays small while text stays vector.
"""

from __future__ import annotations

import re
import textwrap
from collections.abc import Callable, Sequence

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray
from scipy import stats

from bayes_amb.plots.style import new_figure, styled
from bayes_amb.rig import CHANNELS

_TRUE = "#2a9d48"
_MAP = "#d9541e"
_POST = "#1f4e9a"


def _grid(rows: int, cols: int, size: tuple[float, float], **kw):
    fig = new_figure(size)
    return fig, np.atleast_2d(fig.subplots(rows, cols, squeeze=False, **kw))


def _marks(ax, name: str, truth: dict[str, float], point: dict[str, float],
           vertical: bool = True) -> None:
    line = ax.axvline if vertical else ax.axhline
    if name in point:
        line(point[name], color=_MAP, lw=1.2, ls="--")
    if name in truth:
        line(truth[name], color=_TRUE, lw=1.5)


def _legend_marks(fig: Figure, truth: dict[str, float], point_label: str) -> None:
    from matplotlib.lines import Line2D
    h = [Line2D([], [], color=_MAP, ls="--"), Line2D([], [], color=_TRUE)]
    lab = [point_label, "true value (simulated data)"]
    n = 2 if truth else 1
    fig.legend(h[:n], lab[:n], loc="outside lower center", ncols=n, fontsize=8.5)


@styled
def plot_trace(draws: dict[str, NDArray], labels: dict[str, str],
               truth: dict[str, float], point: dict[str, float]) -> Figure:
    """Trace (left: every walker against draw index) and marginal histogram (right)."""
    names = list(draws)
    fig, axes = _grid(len(names), 2, (8.0, 1.1 * len(names) + 0.9),
                      width_ratios=(2.6, 1.0))
    for i, n in enumerate(names):
        d = draws[n]
        a, h = axes[i]
        for w in range(d.shape[0]):
            a.plot(d[w], lw=0.5, alpha=0.5, color=f"C{w % 10}", rasterized=True)
        h.hist(d.ravel(), bins=40, orientation="horizontal", color=_POST, alpha=0.8)
        _marks(a, n, truth, point, vertical=False)
        _marks(h, n, truth, point, vertical=False)
        # rows are ~1.1 in tall: a long label (log10 sigma_noise (m) + 12) goes on two lines
        a.set_ylabel(_wrap(labels.get(n, n), 15), fontsize=9)
        h.set_yticklabels([])
        h.set_ylim(a.get_ylim())
    axes[-1, 0].set_xlabel(f"draw (after burn-in and thinning), {draws[names[0]].shape[0]} "
                           "walkers")
    axes[-1, 1].set_xlabel("count")
    _legend_marks(fig, truth, "MAP")
    return fig


@styled
def plot_rank(draws: dict[str, NDArray], labels: dict[str, str], n_bins: int | None = None
              ) -> Figure:
    """Rank plots: histogram of the pooled ranks of each walker's draws; for a mixed chain
    every walker is uniform (grey band: 99 % range of one uniform walker histogram).
    Default bins: about 10 draws per bin and walker, between 4 and 20."""
    names = list(draws)
    if n_bins is None:
        n_bins = int(np.clip(draws[names[0]].shape[1] // 10, 4, 20))
    cols = min(3, len(names))
    rows = -(-len(names) // cols)
    fig, axes = _grid(rows, cols, (2.3 * cols + 0.3, 1.1 * rows + 0.5))
    for ax, n in zip(axes.ravel(), names, strict=False):
        d = draws[n]
        ranks = stats.rankdata(d.ravel()).reshape(d.shape)
        edges = np.linspace(0.5, d.size + 0.5, n_bins + 1)
        n_w = d.shape[1]
        lo, hi = stats.binom.ppf([0.005, 0.995], n_w, 1.0 / n_bins)
        ax.axhspan(lo, hi, color="0.87", lw=0)
        ax.axhline(n_w / n_bins, color="0.3", lw=0.8)
        for w in range(d.shape[0]):
            c, _ = np.histogram(ranks[w], edges)
            ax.stairs(c, np.arange(n_bins + 1), color=f"C{w % 10}", lw=0.7, alpha=0.7)
        ax.set_title(labels.get(n, n), fontsize=9)
        ax.set_xticks([0, n_bins], ["lowest", "highest"])
        ax.set_xlabel("rank bin")
    for ax in axes.ravel()[len(names):]:
        ax.set_visible(False)
    for ax in axes[:, 0]:
        ax.set_ylabel("draws per walker")
    return fig


@styled
def plot_pair(draws: dict[str, NDArray], labels: dict[str, str], truth: dict[str, float],
              point: dict[str, float], max_points: int = 2000,
              rng: np.random.Generator | None = None) -> Figure:
    """Corner plot: marginal histograms on the diagonal, draws below it."""
    names = list(draws)
    k = len(names)
    # printed at 100 % (text width 7.17 in) and short enough to share an A4 page with the
    # prior-posterior figure that follows it in the report
    size = min(5.8, 1.9 * k + 1.2)
    fig, axes = _grid(k, k, (size, size + 0.3))
    flat = {n: draws[n].ravel() for n in names}
    m = flat[names[0]].size
    rng = rng or np.random.default_rng(0)
    idx = rng.choice(m, size=min(m, max_points), replace=False)
    for i, ni in enumerate(names):
        for j, nj in enumerate(names):
            ax = axes[i, j]
            if j > i:
                ax.set_visible(False)
                continue
            if i == j:
                ax.hist(flat[ni], bins=40, color=_POST, alpha=0.8)
                _marks(ax, ni, truth, point)
                ax.set_yticks([])
            else:
                ax.plot(flat[nj][idx], flat[ni][idx], ".", ms=1.5, alpha=0.35, color=_POST,
                        rasterized=True)
                _marks(ax, nj, truth, point)
                _marks(ax, ni, truth, point, vertical=False)
            if i == k - 1:
                ax.set_xlabel(_wrap(labels.get(nj, nj), 16), fontsize=8.5)
            else:
                ax.set_xticklabels([])
            if j == 0 and i > 0:
                ax.set_ylabel(labels.get(ni, ni), fontsize=8.5)
            elif j > 0:
                ax.set_yticklabels([])
            ax.tick_params(labelsize=8.0)
            for lab in ax.get_xticklabels():
                lab.set_rotation(35)
    _fold_x_multiplier(fig, axes[-1])
    _legend_marks(fig, truth, "MAP")
    return fig


def _wrap(label: str, width: int) -> str:
    """A label on lines of at most ``width`` characters, a shift ("+ 12", "− 0.5") kept
    with the word before it."""
    for sign in ("+", "−", "-"):
        label = label.replace(f" {sign} ", f"\u00a0{sign}\u00a0")
    return textwrap.fill(label, width).replace("\u00a0", " ")


def _fold_x_multiplier(fig: Figure, axes: NDArray) -> None:
    """Put an x axis' scale multiplier ("1e-7") into its label: drawn at the axis' right
    end it ran into the rotated tick labels and the label below them. An axis that also
    has an additive offset keeps matplotlib's own offset text (the report shifts such
    quantities itself: "k_By (θ) - 0.5")."""
    fig.canvas.draw()
    for ax in axes:
        off = ax.xaxis.get_offset_text()
        if ax.get_visible() and re.fullmatch(r"1e[−-]?\d+", off.get_text()):
            off.set_visible(False)
            ax.set_xlabel(f"{ax.get_xlabel()}\n(×{off.get_text()})")


@styled
def plot_prior_posterior(draws: dict[str, NDArray], priors: dict[str, tuple[NDArray,
                         Callable[[NDArray], NDArray]]], labels: dict[str, str],
                         truth: dict[str, float]) -> Figure:
    """Prior density against posterior histogram, each scaled to unit peak, over the prior
    range; an inset zooms on the posterior when it is much narrower than the prior.

    ``priors``: name -> (x grid over the prior support, pdf function).
    """
    names = list(draws)
    cols = min(2, len(names))
    rows = -(-len(names) // cols)
    # at most 7.1 in wide, so that the PDF prints the figure unscaled (fonts >= 7.5 pt)
    fig, axes = _grid(rows, cols, (3.4 * cols + 0.3, 2.3 * rows + 0.7))
    for ax, n in zip(axes.ravel(), names, strict=False):
        d = draws[n].ravel()
        grid, pdf = priors[n]
        p = pdf(grid)
        ax.fill_between(grid, p / np.max(p), color="0.9", ec="0.55", lw=1.0, label="prior")
        lo, hi = float(d.min()), float(d.max())
        width = max(hi - lo, 1e-300)
        c, e = np.histogram(d, bins=40, range=(lo - 0.05 * width, hi + 0.05 * width))
        span = grid[-1] - grid[0]
        ax.stairs(c / c.max(), e, color=_POST, lw=1.5, fill=False, label="posterior")
        if width < 0.03 * span:     # a spike on the prior scale: mark it, zoom in an inset
            ax.axvline(float(np.mean(d)), color=_POST, lw=1.5)
            ref = float(f"{np.mean(d):.3g}")
            ins = ax.inset_axes((0.56, 0.42, 0.42, 0.48))
            ins.stairs(c / c.max(), e - ref, color=_POST, lw=1.2, fill=True, alpha=0.35)
            if n in truth and e[0] <= truth[n] <= e[-1]:
                ins.axvline(truth[n] - ref, color=_TRUE, lw=1.3)
            ins.set_yticks([])
            ins.tick_params(labelsize=7.5)
            ins.set_title(f"zoom: θ − {ref:g}", fontsize=8.0,     # over the truth line
                          bbox={"facecolor": "white", "edgecolor": "none", "pad": 1.0})
            ins.xaxis.get_offset_text().set_fontsize(7.5)
        if n in truth:
            ax.axvline(truth[n], color=_TRUE, lw=1.5, label="true value")
        sd_ratio = float(np.std(d) / _grid_sd(grid, p))
        ax.set_title(f"{labels.get(n, n)}: posterior sd = {sd_ratio:.2g} x prior sd",
                     fontsize=9)
        ax.set_ylim(0, 1.1)
        ax.set_yticks([])
        ax.set_xlabel("θ (dimensionless)")
    for ax in axes.ravel()[len(names):]:
        ax.set_visible(False)
    h, lab = axes[0, 0].get_legend_handles_labels()      # below the axes, not over the prior
    fig.legend(h, lab, loc="outside lower center", ncols=len(lab), fontsize=8.5)
    return fig


def _grid_sd(grid: NDArray, p: NDArray) -> float:
    """Standard deviation of a density given on a uniform grid."""
    w = p / p.sum()
    mean = float(np.sum(w * grid))
    return float(np.sqrt(np.sum(w * (grid - mean) ** 2)))


@styled
def plot_predictive_time(t: NDArray, eps: NDArray, predictions: Sequence[NDArray],
                         window: tuple[float, float]) -> Figure:
    """Posterior predictive in time: data eps against S(theta_draw) x for a few posterior
    draws (thin lines), per channel, in micrometres."""
    m = (t >= window[0]) & (t <= window[1])
    fig, axes = _grid(4, 1, (8.0, 6.2), sharex=True)
    for j, ch in enumerate(CHANNELS):
        ax = axes[j, 0]
        for k, pred in enumerate(predictions):
            ax.plot(t[m], 1e6 * pred[m, j], color="#d9541e", lw=3.0, alpha=0.35,
                    label="S(θ) x, posterior draws" if k == 0 else None)
        ax.plot(t[m], 1e6 * eps[m, j], color="k", lw=0.9, marker=".", ms=2.5,
                label="data ε")
        ax.set_ylabel(f"ε {ch} (µm)")
    axes[0, 0].legend(loc="upper right", ncols=2, fontsize=8)
    axes[-1, 0].set_xlabel("time t (s)")
    fig.suptitle(f"Posterior predictive against the data ({len(predictions)} draws)",
                 fontsize=10.5)
    return fig
