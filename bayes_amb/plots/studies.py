"""Study figures: bias and 90 % interval width against each factor with coverage, and SBC
rank histograms and interval coverage. Built from the study's summary and results files only."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from bayes_amb.plots.style import new_figure, save_figure, style_context, styled
from bayes_amb.studies.binomial import binomial_band
from bayes_amb.studies.replicate import N_RANK_DRAWS
from bayes_amb.studies.spec import StudySpec


def _read_csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _num(v: str) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")


def _mean_or_nan(values: list[float]) -> float:
    """Mean of the finite values (NaN when there are none, e.g. no Laplace interval)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(v.mean()) if v.size else float("nan")


@styled
def plot_factor(summary: list[dict[str, str]], factor: str, param: str) -> Figure:
    """Bias (+- RMSE) and mean 90 % interval width of one parameter against one factor,
    averaged over the other factors; below, coverage with its 95 % interval."""
    fig = new_figure((7.6, 4.4))
    ax, axc = fig.subplots(2, 1, sharex=True, height_ratios=(2, 1))
    rows = [r for r in summary if r["param"] == param]
    levels = sorted({_num(r[f"f_{factor}"]) for r in rows})
    agg = []
    for lv in levels:
        rs = [r for r in rows if _num(r[f"f_{factor}"]) == lv]
        agg.append([_mean_or_nan([_num(r[k]) for r in rs]) for k in
                    ("bias", "rmse", "mean_width90", "coverage90", "coverage90_lo",
                     "coverage90_hi")])
    a = np.array(agg)
    x = np.array(levels)
    positive = np.all(x > 0)
    xs = x if positive else np.arange(x.size)
    ax.errorbar(xs, a[:, 0], yerr=a[:, 1], fmt="o-", capsize=3, label="bias ± RMSE")
    ax.plot(xs, a[:, 2] / 2, "s--", label="half width of\n90 % interval")
    ax.axhline(0, color="0.4", lw=0.8)
    ax.set_ylabel(f"{param} (theta)")
    ax.set_title(f"{param} against {factor}")
    axc.fill_between(xs, a[:, 4], a[:, 5], alpha=0.25, label="its 95 % interval")
    axc.plot(xs, a[:, 3], "o-", label="coverage of\n90 % HDI")
    axc.axhline(0.9, color="C3", lw=0.8, ls=":", label="nominal 0.9")
    axc.set_ylim(-0.05, 1.05)
    axc.set_ylabel("coverage")
    for axis in (ax, axc):          # legends beside the axes: the band spans the whole width
        axis.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    if positive and x.max() / x.min() > 20:
        ax.set_xscale("log")
    if not positive:
        axc.set_xticks(xs, [f"{v:g}" for v in x])
    axc.set_xlabel(_factor_label(factor))
    return fig


def _factor_label(factor: str) -> str:
    units = {"noise_rms": "sensor noise RMS, m", "r1_rms": "r1 RMS, m", "r2_rms": "r2 RMS, A",
             "duration": "record length, s", "amplitude": "excitation amplitude, A",
             "dt": "sample time, s", "speed_rpm": "speed, rpm"}
    return units.get(factor, factor)


@styled
def plot_sbc_ranks(sbc: dict[str, Any], n_bins: int = 10) -> Figure:
    """Rank histograms of every parameter with the 99 % band of a uniform histogram."""
    names = list(sbc)
    cols = min(4, len(names))
    rows = -(-len(names) // cols)
    fig = new_figure((2.3 * cols + 0.6, 2.0 * rows + 0.8))
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False, sharey=True)).ravel()
    for ax, n in zip(axes, names, strict=False):      # spare axes hidden below
        s = sbc[n]
        hist = np.array(s["rank_hist"])
        m = s["n"]
        lo, hi = binomial_band(m, 1.0 / hist.size)
        ok = s.get("calibrated", True)
        ax.axhspan(lo * m, hi * m, color="0.88", zorder=0)
        ax.bar(np.arange(hist.size), hist, width=0.9, color="C0" if ok else "C3", zorder=1)
        for edge in (lo * m, hi * m):       # band edges stay visible above the bars
            ax.axhline(edge, color="0.45", lw=0.7, ls="--", zorder=2)
        ax.axhline(m / hist.size, color="0.2", lw=0.8, zorder=2)
        ax.set_title(f"{n}: p = {s['uniformity_p']:.2g}" + ("" if ok else ", NOT calibrated"),
                     fontsize=9, color="black" if ok else "C3")
        ax.set_xticks([-0.45, hist.size - 0.55], ["0", str(N_RANK_DRAWS)])
    for ax in axes[len(names):]:
        ax.set_visible(False)
    for ax in axes[::cols]:
        ax.set_ylabel("datasets")
    fig.supxlabel(f"rank of the true value among {N_RANK_DRAWS} posterior draws "
                  f"({hist.size} bins; line: uniform, dashed: its 99 % band)", fontsize=9)
    fig.suptitle(f"SBC rank histograms ({sbc[names[0]]['n']} datasets)")
    return fig


@styled
def plot_sbc_coverage(sbc: dict[str, Any]) -> Figure:
    """Coverage of the central 50 % and 90 % posterior intervals per parameter, against the
    99 % binomial band of a calibrated posterior (shaded)."""
    names = list(sbc)
    fig = new_figure((7.6, 3.0))
    axes = fig.subplots(1, 2, sharey=False)
    x = np.arange(len(names))
    for ax, level in zip(axes, (50, 90), strict=True):
        lo, hi = sbc[names[0]][f"band{level}"]
        ax.axhspan(lo, hi, color="0.88", zorder=0, label="99 % band")
        ax.axhline(level / 100, color="0.2", lw=0.8, zorder=1, label="nominal")
        cov = np.array([sbc[n][f"coverage{level}"] for n in names])
        ok = np.array([bool(sbc[n][f"coverage{level}_ok"]) for n in names])
        ax.plot(x[ok], cov[ok], "o", color="C0", zorder=2, label="inside the band")
        if not ok.all():
            ax.plot(x[~ok], cov[~ok], "X", color="C3", ms=8, zorder=2, label="outside")
        ax.set_xticks(x, names, rotation=45, ha="right", fontsize=8)
        pad = 0.06
        ax.set_ylim(min(lo, cov.min()) - pad, max(hi, cov.max()) + pad)
        ax.set_title(f"{level} % central intervals", fontsize=9)
        ax.set_ylabel("coverage")
    axes[1].legend(fontsize=7, loc="lower right")
    fig.suptitle(f"SBC coverage ({sbc[names[0]]['n']} datasets)")
    return fig


def study_figures(spec: StudySpec, out_dir: str | Path, study: Any) -> list[Path]:
    """Write DIR/figures/*.png for a finished study (``study``: its
    bayes_amb.results.Study, as finalise returns it); returns the paths."""
    out = Path(out_dir)
    figdir = out / "figures"
    figdir.mkdir(exist_ok=True)
    summary = _read_csv(out / "summary.csv")
    paths = []
    with style_context():
        for factor in spec.factors:
            if factor == "estimate" or not any(f"f_{factor}" in r for r in summary):
                continue
            for n in spec.estimate:
                fig = plot_factor(summary, factor, n)
                paths.append(save_figure(fig, figdir / f"{factor}_{n}.png"))
        if study.benchmark:
            from bayes_amb.plots.discrepancy import plot_benchmark
            paths.append(save_figure(plot_benchmark(study.benchmark), figdir / "benchmark.png"))
        if study.sbc:
            paths.append(save_figure(plot_sbc_ranks(study.sbc), figdir / "sbc_ranks.png"))
            paths.append(save_figure(plot_sbc_coverage(study.sbc), figdir / "sbc_coverage.png"))
    return paths
