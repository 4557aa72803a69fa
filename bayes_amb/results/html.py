"""How a result shows itself in a notebook (``_repr_html_``): a title, its verdict or
status lines, the summary table and the key figure, never a wall of JSON.

The result classes build their parts from their own fields; this module only lays them
out. A figure that cannot be drawn (no draws, no residuals) is left out, not an error.
"""

from __future__ import annotations

import base64
import html
import io
from collections.abc import Callable, Sequence
from typing import Any

__all__ = ["figure_img", "result_html", "table_html"]

_STYLE = ("<style>.bamb{font-family:sans-serif;font-size:13px;max-width:920px}"
          ".bamb table{border-collapse:collapse;margin:6px 0}"
          ".bamb th,.bamb td{border-bottom:1px solid #ddd;padding:2px 8px;text-align:right}"
          ".bamb th:first-child,.bamb td:first-child{text-align:left}"
          ".bamb .verdict{font-weight:bold;font-size:15px}"
          ".bamb .lines{color:#333;margin:4px 0}</style>")


def table_html(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """An HTML table, every cell escaped."""
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in headers)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>"
                   for r in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def figure_img(make: Callable[[], Any], width_px: int = 720) -> str:
    """The figure ``make()`` returns as an inline PNG, or "" when it cannot be drawn."""
    from bayes_amb.errors import BayesAmbError

    try:
        fig = make()
    except (BayesAmbError, ValueError, KeyError, IndexError):
        return ""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    try:
        fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    finally:
        plt.close(fig)
    data = base64.b64encode(buf.getvalue()).decode("ascii")
    return (f'<img style="max-width:min(100%,{width_px}px)" '
            f'src="data:image/png;base64,{data}"/>')


def result_html(title: str, verdict: str = "", lines: Sequence[str] = (),
                tables: Sequence[tuple[Sequence[str], Sequence[Sequence[Any]]]] = (),
                figure: Callable[[], Any] | None = None) -> str:
    """The notebook view of a result: title, verdict, lines, tables, figure."""
    parts = [_STYLE, '<div class="bamb">', f"<h4>{html.escape(title)}</h4>"]
    if verdict:
        parts.append(f'<div class="verdict">{html.escape(verdict)}</div>')
    if lines:
        parts.append('<div class="lines">' + "<br/>".join(html.escape(s) for s in lines if s)
                     + "</div>")
    # a table wider than the page scrolls inside its own box (a docs page, a narrow cell)
    parts += [f'<div style="overflow-x:auto">{table_html(h, r)}</div>' for h, r in tables]
    if figure is not None:
        parts.append(figure_img(figure))
    parts.append("</div>")
    return "".join(parts)
