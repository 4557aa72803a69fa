"""Figures of the rotor model: singular values (Fig. 5), Campbell diagram, rotor sketch.

Each function takes a result object from the compute stages, draws on ``ax`` (or a new
figure) and returns the Figure. Nothing is computed here beyond unit conversion.
"""

from __future__ import annotations

import math

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import Polygon, Rectangle

from bayes_amb.plots.style import new_axes, styled
from bayes_amb.reduction.fidelity import SingularValueData
from bayes_amb.rig import Rig
from bayes_amb.rotor.campbell import CampbellData

_FULL = "#1f4e9a"
_REDUCED = "#d9541e"


def _db(x: np.ndarray) -> np.ndarray:
    return 20.0 * np.log10(np.maximum(x, np.finfo(float).tiny))


@styled
def plot_singular_values(sv_data: SingularValueData, ax: Axes | None = None) -> Figure:
    """Singular values of full and reduced model, dB of m/A against rad/s (the paper's Fig. 5).

    Thin lines are all singular values, thick lines the largest; a dotted vertical line
    marks half the first left-out (bending) frequency, the limit of
    :meth:`~bayes_amb.reduction.fidelity.SingularValueData.max_gap_db`.
    """
    fig, ax = new_axes(ax)
    w = sv_data.omega
    full, red = _db(sv_data.sv_full), _db(sv_data.sv_reduced)
    for k in range(full.shape[1]):
        ax.semilogx(w, full[:, k], color=_FULL, lw=0.7, alpha=0.6)
        ax.semilogx(w, red[:, k], color=_REDUCED, lw=0.7, alpha=0.6, ls="--")
    ax.semilogx(w, full[:, 0], color=_FULL, lw=2.0, label="full FE model, largest")
    ax.semilogx(w, red[:, 0], color=_REDUCED, lw=2.0, ls="--", label="reduced model, largest")
    ax.plot([], [], color="0.4", lw=0.7, label="all singular values (thin)")
    w_half = 0.5 * sv_data.first_bending_rad_s
    ax.axvline(w_half, color="0.3", ls=":", lw=1.2)
    ax.annotate(f"half first bending\n{w_half:.0f} rad/s", xy=(w_half, 0.97),
                xycoords=("data", "axes fraction"), xytext=(-4, 0),
                textcoords="offset points", ha="right", va="top", fontsize=8.5, color="0.3")
    gap = sv_data.max_gap_db()
    ax.set_xlim(w[0], w[-1])
    ax.set_xlabel("frequency ω (rad/s)")
    ax.set_ylabel("singular value (dB re 1 m/A)")
    ax.set_title(f"Full and reduced model at {sv_data.speed_rpm:.0f} rpm "
                 f"(largest gap below marker {gap:.2f} dB)")
    ax.legend(loc="lower left")
    return fig


@styled
def plot_campbell(campbell_data: CampbellData, ax: Axes | None = None) -> Figure:
    """Campbell diagram: flexible-mode frequencies (Hz) against speed (rpm).

    Frequencies are sorted at each speed; a line that rises with speed is drawn solid
    (forward whirl), one that falls dashed (backward whirl). The 1x synchronous line
    f = rpm/60 and the nominal running speed are marked.
    """
    fig, ax = new_axes(ax, figsize=(8.0, 4.0))
    rpm = campbell_data.speeds_rpm
    f = campbell_data.freqs_hz
    colours = [f"C{k // 2}" for k in range(f.shape[1])]
    seen: set[str] = set()
    for k in range(f.shape[1]):
        rising = f[-1, k] >= f[0, k]
        label = "forward whirl (rises)" if rising else "backward whirl (falls)"
        ax.plot(rpm, f[:, k], color=colours[k], ls="-" if rising else "--", marker=".",
                ms=4, label=None if label in seen else label)
        seen.add(label)
    f_top = 1.08 * float(np.nanmax(f)) if f.size else 1.0
    ax.plot(rpm, rpm / 60.0, color="k", lw=1.0, label="1x synchronous (rpm/60)")
    nominal = campbell_data.nominal_speed_rpm
    ax.axvline(nominal, color="0.3", ls=":", lw=1.2, label=f"running speed {nominal:.0f} rpm")
    ax.set_xlim(rpm[0], rpm[-1])
    ax.set_ylim(0.0, f_top)
    ax.set_xlabel("rotor speed (rpm)")
    ax.set_ylabel("natural frequency (Hz)")
    ax.set_title("Campbell diagram, open loop with bearing ks")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return fig


def _disc_size(mass: float, ip: float, id_: float, d_shaft: float) -> tuple[float, float]:
    """(diameter, width) in m of the uniform cylinder with the disc's mass and inertias.

    Ip = m r^2 / 2 and Id = m r^2 / 4 + m h^2 / 12; the sketch only, not the model.
    """
    r = math.sqrt(2.0 * ip / mass) if ip > 0 else d_shaft
    h2 = 12.0 * (id_ - mass * r**2 / 4.0) / mass
    h = math.sqrt(h2) if h2 > 0 else 0.2 * d_shaft
    return max(2.0 * r, 1.2 * d_shaft), max(h, 0.1 * d_shaft)


@styled
def plot_rotor_sketch(rig: Rig, ax: Axes | None = None) -> Figure:
    """Side view of the rotor: shaft, FE nodes, discs, bearings A/B and sensors (Fig. 4).

    Discs are drawn as the uniform cylinders with their mass and inertias; lengths in mm.
    """
    fig, ax = new_axes(ax, figsize=(7.2, 3.6))
    s = rig.shaft
    mm = 1e3
    z = np.asarray(s.node_z) * mm
    L, R = s.length * mm, 0.5 * s.max_diameter * mm
    if s.uniform:
        ax.add_patch(Rectangle((0.0, -R), L, 2 * R, facecolor="#c9ced6", edgecolor="k",
                               lw=1.0, zorder=2, label=f"shaft, Ø{s.diameter * mm:.0f} mm"))
    else:                       # each element as it is: stepped, tapered (outer contour)
        for j, e in enumerate(s.elements):
            z0, z1 = z[j], z[j + 1]
            r0, r1 = 0.5 * e.od[0] * mm, 0.5 * e.od[1] * mm
            ax.add_patch(Polygon([(z0, -r0), (z1, -r1), (z1, r1), (z0, r0)], closed=True,
                                 facecolor="#c9ced6", edgecolor="k", lw=0.6, zorder=2,
                                 label="shaft (elements)" if j == 0 else None))
    ax.plot(z, np.zeros_like(z), "o", color="k", ms=2.5, zorder=4,
            label=f"{s.n_nodes} FE nodes")
    for n in sorted({1, s.n_nodes, *range(5, s.n_nodes, 5)}):
        ax.annotate(str(n), (z[n - 1], 0.0), xytext=(0, 4), textcoords="offset points",
                    ha="center", va="bottom", fontsize=7.5, color="0.2", zorder=6)
    r_max = R
    for d in rig.discs:
        dia, width = (v * mm for v in _disc_size(d.mass, d.ip, d.id, s.max_diameter))
        zc = z[d.node - 1]
        ax.add_patch(Rectangle((zc - width / 2, -dia / 2), width, dia, facecolor="#7f95b5",
                               edgecolor="k", lw=1.0, zorder=3, alpha=0.9))
        ax.annotate(f"{d.name}\n{d.mass:g} kg", (zc, dia / 2), xytext=(0, 3),
                    textcoords="offset points", ha="center", va="bottom", fontsize=8.5)
        r_max = max(r_max, dia / 2)
    gap, h, w = 0.15 * R, 0.6 * R, 0.05 * L
    for name, node in rig.bearing_nodes.items():
        zb = z[node - 1]
        for sign in (1, -1):
            y0 = R + gap if sign > 0 else -R - gap - h
            ax.add_patch(Rectangle((zb - w / 2, y0), w, h, facecolor="#e3a33b",
                                   edgecolor="k", lw=0.8, zorder=3))
        ax.annotate(f"AMB {name}\nnode {node}", (zb, R + gap + h), xytext=(0, 3),
                    textcoords="offset points", ha="center", va="bottom", fontsize=8.5)
    y_sensor = -R - 2 * gap - 1.4 * h
    for name, node in rig.sensor_nodes.items():
        zs = z[node - 1]
        ax.plot([zs], [y_sensor], marker="^", color="#2a9d48", ms=8, zorder=4)
        ax.annotate(f"sensor {name}\nnode {node}", (zs, y_sensor), xytext=(0, -7),
                    textcoords="offset points", ha="center", va="top", fontsize=8.5,
                    color="#1d6e33")
    ax.plot([], [], "s", color="#e3a33b", label="radial AMB (x, y)")
    ax.plot([], [], "^", color="#2a9d48", label="displacement sensor (x, y)")
    ax.plot([], [], "s", color="#7f95b5", label="disc (equivalent cylinder)")
    ax.set_aspect("equal")
    y_lim = 1.7 * max(r_max, R + gap + h)
    ax.set_xlim(-0.12 * L, 1.12 * L)
    ax.set_ylim(-y_lim, y_lim)
    ax.set_xlabel("axial position z (mm)")
    ax.set_ylabel("radius (mm)")
    ax.set_title(f"Rotor '{rig.name}': {s.n_nodes - 1} elements, spin about +z")
    ax.grid(False)
    ax.legend(loc="lower center", bbox_to_anchor=(0.5, 1.08), ncols=3, fontsize=8)
    return fig


def fidelity_figure(rig: Rig, speed_rpm: float | None = None, n_bending: int = 0,
                    path: str | None = None) -> Figure:
    """The paper's Fig. 5 in one call: reduce the rig's FE model and plot full against
    reduced singular values from 1 to 5e4 rad/s; saved to ``path`` when given.

    Examples
    --------
    >>> from bayes_amb.rig import load_rig
    >>> fig = fidelity_figure(load_rig())
    >>> fig.axes[0].get_ylabel()
    'singular value (dB re 1 m/A)'
    """
    from bayes_amb.plots.style import save_figure
    from bayes_amb.reduction import reduce_pseudo_modal
    from bayes_amb.reduction.fidelity import singular_value_data

    fig = plot_singular_values(singular_value_data(
        reduce_pseudo_modal(rig, n_bending=n_bending, speed_rpm=speed_rpm)))
    if path is not None:
        save_figure(fig, path)
    return fig
