"""Figures of a test plan: predicted posterior sd against record length and amplitude."""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.figure import Figure

from bayes_amb.plots.style import new_figure, styled


@styled
def sd_against(plan: dict[str, Any], kind: str, targets: dict[str, float] | None = None
               ) -> Figure:
    """Predicted sd of each parameter (theta units) against the record length ('duration')
    or the excitation amplitude ('amplitude'), from one plan: the information is linear in
    the length and quadratic in the amplitude (the noise does not depend on either), so
    sd ~ 1/sqrt(T) and ~ 1/A exactly. The planned design is marked; targets as lines."""
    fig = new_figure((6.4, 3.8))
    ax = fig.add_subplot(1, 1, 1)
    d = plan["design"]
    x0 = d["duration"] if kind == "duration" else d["amplitude"]
    x = x0 * np.geomspace(0.1, 10.0, 60)
    power = 0.5 if kind == "duration" else 1.0
    for name, v in plan["parameters"].items():
        sd = v["sd"] * (x0 / x) ** power
        line, = ax.loglog(x, sd, label=name)
        ax.plot([x0], [v["sd"]], "o", color=line.get_color(), ms=4)
        if targets and name in targets:
            ax.axhline(targets[name], color=line.get_color(), ls=":", lw=1.0)
    ax.axvline(x0, color="0.5", lw=0.8, ls="--")
    if kind == "duration":                 # the information check's 64 bins
        short = 64.0 / plan["f_max_hz"]
        if short > x[0]:
            ax.axvspan(x[0], short, color="0.88", lw=0, zorder=0)
            ax.text(x[0] * 1.1, ax.get_ylim()[0] * 1.2, "too short:\n< 64 bins", fontsize=7.5,
                    color="0.35")
    ax.set_xlabel("record length (s)" if kind == "duration" else "excitation amplitude (A)")
    ax.set_ylabel("predicted posterior sd (theta)")
    ax.set_title(f"Predicted sd against {'record length' if kind == 'duration' else 'amplitude'}"
                 " (dots: the planned design)")
    ax.legend(ncol=2, fontsize=7.5)
    return fig
