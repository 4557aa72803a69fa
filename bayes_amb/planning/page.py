"""The plan as a page an engineer can hand on: the design, the predicted sd table, sd
against record length and amplitude, and (with targets) the designs tried."""

from __future__ import annotations

import html
import json
from pathlib import Path
from typing import Any

from bayes_amb.io.atomic import write_text_atomic
from bayes_amb.planning.plan import informed_word
from bayes_amb.plots.planning import sd_against
from bayes_amb.report.figures import render_figure


def _table(head: list[str], rows: list[list[str]], css: str = "") -> str:
    h = "".join(f"<th>{html.escape(c)}</th>" for c in head)
    b = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>"
                for r in rows)
    cls = f" class='{css}'" if css else ""
    return f"<table{cls}><thead><tr>{h}</tr></thead><tbody>{b}</tbody></table>"


UNITS = {"amplitude": "A", "duration": "s", "dt": "s", "band_hz": "Hz", "noise_rms": "m",
         "r1_rms": "m", "r2_rms": "A", "r1_band_hz": "Hz", "r2_band_hz": "Hz"}
"""The units of the design's and the noise's fields, as the page shows them."""


def _label(key: str) -> str:
    unit = UNITS.get(key)
    return f"{key} ({unit})" if unit else key


def _value(key: str, v: Any) -> str:
    """A design or noise field as an engineer reads it: 3 significant digits, channel
    names, '-' for a field that is not set ('all' channels)."""
    if v is None:
        return "all" if key == "channels" else "-"
    if isinstance(v, (list, tuple)):
        return ", ".join(_value(key, x) for x in v)
    if isinstance(v, float):
        return f"{v:.3g}"
    return str(v)


def write_plan_page(out: str | Path, plan: dict[str, Any],
                    optimised: dict[str, Any] | None = None) -> Path:
    """OUT/plan.json and OUT/plan.html (figures embedded); returns the HTML path."""
    d = Path(out)
    d.mkdir(parents=True, exist_ok=True)
    data = {"plan": plan, **({"optimised": optimised} if optimised else {})}
    write_text_atomic(d / "plan.json", json.dumps(data, indent=1, default=str) + "\n")
    targets = optimised["targets"] if optimised else None
    des, noise = plan["design"], plan["noise"]
    design_rows = [[_label(k), _value(k, v)] for k, v in des.items()]
    noise_rows = [[_label(k), _value(k, v)] for k, v in noise.items() if k != "colour"]
    if "colour" in noise:                   # measured on an earlier record (colour.py)
        c = noise["colour"]
        noise_rows.append(["colour", f"measured on {c['from']} ({c['n_bands']} bands, "
                           f"{c['f_hz'][0]:.3g}-{c['f_hz'][1]:.3g} Hz); mean diagonal in the "
                           "lowest third " + ", ".join(f"{v:.2f}" for v in c["low_third"])
                           + ", highest third "
                           + ", ".join(f"{v:.2f}" for v in c["high_third"])
                           + " (1: as white as identify's model)"])
    par_rows = [[n, f"{v['sd']:.3g}", f"{v['physical_sd']:.3g} {v['unit']}",
                 f"{v['sd_of_estimates']:.3g}", f"{v['prior_sd']:.3g}",
                 informed_word(v)] for n, v in plan["parameters"].items()]
    figs = [render_figure(sd_against(plan, k, targets), f"sd_{k}",
                          f"sd against {k}", "", vector=False) for k in ("duration",
                                                                         "amplitude")]
    parts = ["<h1>Test plan</h1>",
             "<p>Predicted posterior sd that <code>identify</code> will report on a record of "
             "this design (first order: the Fisher information of its Whittle likelihood; "
             f"{plan['n_bins']} frequency bins up to {plan['f_max_hz']:.0f} Hz, "
             f"{plan['speed_rpm']:.0f} rpm).</p>",
             "<h2>Design</h2>", _table(["field", "value"], design_rows),
             "<h2>Noise</h2>", _table(["source", "value"], noise_rows),
             "<h2>Prediction</h2>",
             _table(["parameter", "sd (theta)", "sd (physical)", "spread of estimates",
                     "prior sd", "informed"], par_rows, "nowrap")]
    parts += [f"<p class='note'>{html.escape(n)}</p>" for n in plan.get("notes", [])]
    for f in figs:
        parts.append(f"<figure><img src='{f.png_uri}' alt='{html.escape(f.title)}'>"
                     f"<figcaption>{html.escape(f.title)}: sd ~ 1/sqrt(length) and ~ "
                     "1/amplitude, exactly (the information is linear in the length and "
                     "quadratic in the amplitude)</figcaption></figure>")
    if optimised:
        parts.append("<h2>Designs tried for the targets</h2>")
        parts.append(f"<p>Targets: {html.escape(json.dumps(optimised['targets']))}. Chosen: "
                     f"{optimised['chosen_duration_s']:g} s; the default random binary "
                     f"needs {optimised['default_duration_s']:.2f} s "
                     f"({optimised['gain']:.1f}x longer).</p>")
        parts.append(_table(
            ["excitation", "band (Hz)", "channels", "length for the targets (s)",
             "peak current (A)", "peak displacement (um)", "refused"],
            [[c["excitation"], c["band_hz"] or "-", ",".join(c["channels"]),
              f"{c['duration_s']:.2f}", f"{c['peak_current_a']:.2f}",
              f"{c['peak_displacement_m'] * 1e6:.1f}", c["refused"] or ""]
             for c in optimised["candidates"]]))
    style = ("body{font-family:sans-serif;max-width:60em;margin:2em auto;color:#222}"
             "table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #ccc;"
             "padding:2px 8px;text-align:left}img{max-width:100%}.note{color:#a33}"
             ".nowrap td{white-space:nowrap}")
    page = (f"<!doctype html><html><head><meta charset='utf-8'><title>bayes-amb plan"
            f"</title><style>{style}</style></head><body>{''.join(parts)}</body></html>")
    path = d / "plan.html"
    write_text_atomic(path, page)
    return path
