"""One plotting style for every figure of bayes_amb, and atomic saving.

Figures are built as :class:`matplotlib.figure.Figure` objects with the Agg canvas, never
through pyplot, so nothing here touches the global backend or opens windows. The style is
applied with :func:`styled` (an rc_context around each plot function), not by changing the
global rcParams at import time.
"""

from __future__ import annotations

import functools
import os
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import matplotlib as mpl
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from bayes_amb.errors import BayesAmbError

RC: dict[str, Any] = {
    "font.size": 10.0,
    "axes.titlesize": 11.0,
    "axes.labelsize": 10.0,
    "legend.fontsize": 8.5,
    "xtick.labelsize": 9.0,
    "ytick.labelsize": 9.0,
    "axes.grid": True,
    "grid.alpha": 0.35,
    "grid.linewidth": 0.6,
    "lines.linewidth": 1.4,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "legend.frameon": False,
    "figure.dpi": 110.0,
    "savefig.dpi": 150.0,
    "savefig.bbox": "tight",
    "svg.fonttype": "none",
    "pdf.fonttype": 42,
}
"""rcParams of the bayes_amb style (readable at a 6.4 x 4 inch figure size)."""

FIGSIZE: tuple[float, float] = (6.4, 4.0)
"""Default figure size, inches."""

FORMATS: tuple[str, ...] = ("png", "svg", "pdf")
"""File formats :func:`save_figure` writes, chosen by the file extension."""


class FigureError(BayesAmbError):
    """A figure cannot be saved (unsupported file extension)."""


@contextmanager
def style_context() -> Iterator[None]:
    """Apply the bayes_amb rcParams inside a with-block."""
    with mpl.rc_context(RC):
        yield


def styled[**P, R](func: Callable[P, R]) -> Callable[P, R]:
    """Decorator: run a plot function inside :func:`style_context`."""

    @functools.wraps(func)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        with style_context():
            return func(*args, **kwargs)

    return wrapper


def new_figure(figsize: tuple[float, float] = FIGSIZE) -> Figure:
    """A constrained-layout figure with its own Agg canvas (no pyplot state)."""
    fig = Figure(figsize=figsize, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def new_axes(ax: Axes | None = None, figsize: tuple[float, float] = FIGSIZE
             ) -> tuple[Figure, Axes]:
    """The given axes and its figure, or a new Agg figure with one axes.

    Call it inside :func:`style_context` so that the new axes picks up the style.
    """
    if ax is not None:
        fig = ax.get_figure()
        while not isinstance(fig, Figure):      # a SubFigure: walk up to the root figure
            fig = fig.figure
        return fig, ax
    fig = new_figure(figsize)
    return fig, fig.add_subplot()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def save_figure(fig: Figure, path: str | Path) -> Path:
    """Save a figure atomically to PNG, SVG or PDF (format from the extension).

    The figure is written to a temporary file in the target folder, then moved into place
    with :func:`os.replace`, so a reader never sees a half-written file.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> fig, ax = new_axes()
    >>> with tempfile.TemporaryDirectory() as d:
    ...     p = save_figure(fig, pathlib.Path(d) / "empty.png")
    ...     p.stat().st_size > 0
    True
    """
    path = Path(path)
    fmt = path.suffix.lower().lstrip(".")
    if fmt not in FORMATS:
        raise FigureError(f"figure file {path}: unsupported extension {path.suffix!r}; "
                          f"expected one of {', '.join('.' + f for f in FORMATS)}")
    folder = path.parent if str(path.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".{fmt}.tmp", dir=folder)
    try:
        with os.fdopen(fd, "wb") as fh, style_context():
            fig.savefig(fh, format=fmt)
        os.chmod(tmp, 0o666 & ~_umask())        # mkstemp creates 0600; use the usual mode
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path
