"""Figures of the loop: pole-zero maps of G(theta) and S(theta) (the paper's Figs. 6, 7),
per-axis sensitivity with the ISO 14839-3 zone limits, and nominal against identified
plant singular values (Fig. 8).

Each function takes arrays or result objects computed elsewhere and returns a Figure.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from bayes_amb.control.robustness import ISO_ZONES, SensitivityData
from bayes_amb.plots.style import new_axes, new_figure, styled
from bayes_amb.rig import CHANNELS

_COLOURS = ("0.45", "#1f4e9a", "#d9541e", "#2a9d48")


class PoleZeroSet(Protocol):
    """Poles and zeros of one system (e.g. bayes_amb.report.derived.PoleZeroSet): complex
    arrays, continuous in rad/s or discrete in the z-plane; ``label`` its name."""

    label: str
    poles: NDArray
    zeros: NDArray


def _pz(ax, sets: Sequence[PoleZeroSet], zero_label: str) -> None:
    for k, s in enumerate(sets):
        c = _COLOURS[(k + (len(sets) == 1)) % len(_COLOURS)]
        ax.plot(s.poles.real, s.poles.imag, "x", color=c, ms=7, mew=1.6,
                label=f"{s.label}: poles ({s.poles.size})")
        if s.zeros.size:
            ax.plot(s.zeros.real, s.zeros.imag, "o", mfc="none", color=c, ms=7, mew=1.3,
                    label=f"{s.label}: {zero_label} ({s.zeros.size})")


@styled
def plot_pole_zero_continuous(sets: Sequence[PoleZeroSet], title: str,
                              zero_label: str = "zeros") -> Figure:
    """Pole-zero map in the s-plane (rad/s), right half-plane shaded (Fig. 6)."""
    fig, ax = new_axes(figsize=(6.4, 3.3))
    pts = np.concatenate([np.concatenate([s.poles, s.zeros]) for s in sets])
    pts = pts[np.isfinite(pts)]
    r = 1.15 * float(np.max(np.abs(pts))) if pts.size else 1.0
    ax.axvspan(0.0, r, color="#f6d5cc", alpha=0.6, lw=0, label="right half-plane (unstable)")
    ax.axvline(0.0, color="0.3", lw=0.8)
    ax.axhline(0.0, color="0.3", lw=0.8)
    _pz(ax, sets, zero_label)
    ax.set_xlim(-r, r)
    ax.set_ylim(-r, r)
    ax.set_aspect("equal")
    ax.set_xlabel("real part (rad/s)")
    ax.set_ylabel("imaginary part (rad/s)")
    ax.set_title(title)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0))
    return fig


@styled
def plot_pole_zero_discrete(sets: Sequence[PoleZeroSet], title: str, dt: float,
                            zero_label: str = "zeros") -> Figure:
    """Pole-zero map in the z-plane with the unit circle (Fig. 7); when most poles gather
    near z = 1 (fast sampling, dt in s) a second panel zooms there."""
    pts = np.concatenate([s.poles for s in sets])
    pts = pts[np.isfinite(pts)]
    near = pts[np.abs(pts - 1) < 0.2]
    zoom = near.size >= max(2, pts.size // 2)
    fig = new_figure((8.0, 3.5) if zoom else (6.4, 3.2))
    axes = fig.subplots(1, 2) if zoom else [fig.add_subplot()]
    phi = np.linspace(0.0, 2 * np.pi, 400)
    for a in axes:
        a.plot(np.cos(phi), np.sin(phi), color="0.3", lw=0.9, label="unit circle")
        a.axhline(0.0, color="0.6", lw=0.6)
        _pz(a, sets, zero_label)
        a.set_aspect("equal")
        a.set_xlabel("real part of z")
    ax = axes[0]
    zs = np.concatenate([s.zeros for s in sets])
    r = min(2.5, max(1.25, 1.08 * float(np.max(np.abs(zs), initial=0.0))))
    outside = int(np.sum(np.abs(zs) > r))
    if outside:
        ax.annotate(f"{outside} zero(s) beyond |z| = {r:.2g}", (0.02, 0.02),
                    xycoords="axes fraction", fontsize=8, color="0.35")
    ax.set_xlim(-r, r)
    ax.set_ylim(-r, r)
    ax.set_ylabel("imaginary part of z")
    if zoom:
        ax.set_title("whole plane")
        half = max(0.01, 1.15 * float(np.max(np.abs(near - 1))))
        axes[1].set_xlim(1 - half, 1 + 0.25 * half)
        axes[1].set_ylim(-0.625 * half, 0.625 * half)
        axes[1].set_title(f"zoom near z = 1 (dt = {dt:g} s)")
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=3, fontsize=8)
    fig.suptitle(title)
    return fig


@styled
def plot_sensitivity(curves: Sequence[tuple[str, SensitivityData]]) -> Figure:
    """Per-axis output sensitivity |S| in dB against frequency (Hz), one panel per axis,
    with the ISO 14839-3 zones shaded (A below 9.5 dB, B to 12 dB, C to 14 dB, D above)."""
    from matplotlib.patches import Patch

    fig = new_figure((8.0, 4.9))
    axes = fig.subplots(2, 2, sharex=True, sharey=True).ravel()
    limits = [20 * np.log10(lim) for _, lim in ISO_ZONES]
    bands = list(zip(limits, [*limits[1:], 40.0], strict=True))
    shades = ("#fbeec2", "#f8d0a8", "#f3b1a6")
    top = max(20.0, *(max(s.peak_db.values()) + 3 for _, s in curves))
    for j, (ax, ch) in enumerate(zip(axes, CHANNELS, strict=True)):
        for (lo, hi), shade in zip(bands, shades, strict=True):
            ax.axhspan(lo, hi, color=shade, lw=0, zorder=0)
        peaks = []
        for k, (_label, s) in enumerate(curves):
            ax.semilogx(s.freq_hz, 20 * np.log10(s.magnitude[:, j]),
                        color=_COLOURS[(k + 1) % len(_COLOURS)], ls="-" if k == 0 else "--")
            peaks.append(f"{s.peak_db[ch]:.1f}")
        ax.set_title(f"axis {ch}: peak {' / '.join(peaks)} dB", fontsize=9.5)
    for ax in axes[2:]:
        ax.set_xlabel("frequency (Hz)")
    for ax in axes[::2]:
        ax.set_ylabel("|S| (dB)")
    axes[0].set_ylim(-35, top)
    handles = [axes[0].lines[k] for k in range(len(curves))]
    handles += [Patch(color=c) for c in shades]
    labels = [label for label, _ in curves]
    labels += [f"ISO 14839-3 zone {z} (≥ {lo:.1f} dB)" for z, (lo, _hi)
               in zip(("B", "C", "D"), bands, strict=True)]
    fig.legend(handles, labels, loc="outside lower center", ncols=3, fontsize=8)
    fig.suptitle("Output sensitivity per axis, full FE plant with the recorded controller",
                 fontsize=10.5)
    return fig


@styled
def plot_plant_singular_values(omega: NDArray, curves: Sequence[tuple[str, NDArray]]
                               ) -> Figure:
    """Singular values (dB re 1 m/A) of the plant against frequency (rad/s), one colour per
    plant (nominal, identified, true...): thick the largest, thin the others (Fig. 8).

    ``curves``: (label, sv (n_w, 4) in m/A).
    """
    fig, ax = new_axes(figsize=(6.4, 4.2))
    for k, (label, sv) in enumerate(curves):
        c = _COLOURS[(k + 1) % len(_COLOURS)] if k else "0.35"
        db = 20 * np.log10(np.maximum(sv, np.finfo(float).tiny))
        ls = ("-", "--", ":")[k % 3]
        for i in range(1, db.shape[1]):
            ax.semilogx(omega, db[:, i], color=c, lw=0.7, alpha=0.7, ls=ls)
        ax.semilogx(omega, db[:, 0], color=c, lw=2.0, ls=ls, label=f"{label}, largest")
    ax.plot([], [], color="0.4", lw=0.7, label="other singular values (thin)")
    ax.set_xlim(omega[0], omega[-1])
    ax.set_xlabel("frequency ω (rad/s)")
    ax.set_ylabel("singular value (dB re 1 m/A)")
    ax.set_title("Nominal and identified plant G(θ), reduced model")
    ax.legend(loc="lower left")
    return fig
