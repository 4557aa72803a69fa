"""Figures. The only subpackage that imports matplotlib (Agg canvas, no pyplot)."""

from bayes_amb.plots.model import (
    fidelity_figure,
    plot_campbell,
    plot_rotor_sketch,
    plot_singular_values,
)
from bayes_amb.plots.style import FigureError, save_figure, style_context, styled

__all__ = ["FigureError", "fidelity_figure", "plot_campbell", "plot_rotor_sketch",
           "plot_singular_values", "save_figure", "style_context", "styled"]
