"""Study tables, calibration statistics and plain-language conclusions."""

from __future__ import annotations

import csv
import io
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from bayes_amb.io.atomic import write_netcdf_atomic, write_text_atomic
from bayes_amb.io.nonfinite import plain, read_result_json, result_json_text
from bayes_amb.results.study import Study
from bayes_amb.studies.binomial import binomial_band, binomial_interval
from bayes_amb.studies.concealed import benchmark_conclusions, benchmark_table
from bayes_amb.studies.replicate import N_RANK_DRAWS
from bayes_amb.studies.spec import StudySpec, cell_estimate


def write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys and k != "traceback"]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=keys, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: r.get(k, "") for k in keys})
    write_text_atomic(path, buf.getvalue())


def cell_summary(spec: StudySpec, rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per cell and parameter: bias, RMSE, mean interval width, coverage with its 95 %
    Clopper-Pearson interval, fraction converged, failures."""
    out = []
    for ci, cell in enumerate(spec.cells):
        rs = [r for r in rows if r["cell"] == ci]
        ok = [r for r in rs if not r.get("error")]
        for n in cell_estimate(spec, cell):
            good = [r for r in ok if f"{n}_mean" in r]
            err = np.array([r[f"{n}_mean"] - r[f"true_{n}"] for r in good])
            width = np.array([r[f"{n}_hdi_hi"] - r[f"{n}_hdi_lo"] for r in good])
            cov = sum(bool(r[f"{n}_covered"]) for r in good)
            lo, hi = binomial_interval(cov, len(good))
            out.append({"cell": ci, **{f"f_{k}": v for k, v in cell.items()}, "param": n,
                        "n": len(rs), "n_ok": len(good),
                        "true_mean": float(np.mean([r[f"true_{n}"] for r in good]))
                        if good else float("nan"),
                        "bias": float(err.mean()) if good else float("nan"),
                        "rmse": float(np.sqrt(np.mean(err**2))) if good else float("nan"),
                        "mean_width90": float(width.mean()) if good else float("nan"),
                        "coverage90": cov / len(good) if good else float("nan"),
                        "coverage90_lo": lo, "coverage90_hi": hi,
                        "frac_converged": float(np.mean([bool(r["converged"]) for r in rs]))
                        if rs else float("nan"),
                        "failures": len(rs) - len(ok)})
    return out


def sbc_statistics(spec: StudySpec, rows: list[dict[str, Any]], n_bins: int = 10
                   ) -> dict[str, Any]:
    """Simulation-based calibration (Talts et al. 2018) per parameter: rank histogram with a
    chi-square uniformity p-value, and coverage of central 50 % / 90 % intervals against the
    99 % binomial band."""
    out: dict[str, Any] = {}
    ok = [r for r in rows if not r.get("error")]
    for n in spec.estimate:
        ranks = np.array([r[f"{n}_rank"] for r in ok if f"{n}_rank" in r])
        qs = np.array([r[f"{n}_q"] for r in ok if f"{n}_q" in r])
        m = ranks.size
        if m == 0:
            continue
        edges = np.linspace(0, N_RANK_DRAWS + 1, n_bins + 1)
        hist, _ = np.histogram(ranks, bins=edges)
        p_unif = float(stats.chisquare(hist).pvalue)
        res = {"n": int(m), "rank_hist": hist.tolist(), "uniformity_p": p_unif}
        for level in (0.5, 0.9):
            cov = float(np.mean(np.abs(qs - 0.5) <= level / 2))
            band = binomial_band(m, level)
            res[f"coverage{int(level * 100)}"] = cov
            res[f"band{int(level * 100)}"] = band
            res[f"coverage{int(level * 100)}_ok"] = band[0] <= cov <= band[1]
        res["calibrated"] = bool(res["coverage50_ok"] and res["coverage90_ok"] and p_unif > 0.01)
        out[n] = res
    return out


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.3g}"
    return str(v)


def _pinned(r: dict[str, Any]) -> bool:
    """RMSE within 5 % of the true value (0.1 floor) and 90 % coverage plausible."""
    return bool(np.isfinite(r["rmse"]) and r["rmse"] <= 0.05 * max(abs(r["true_mean"]), 0.1)
                and r["coverage90_hi"] >= 0.8)


def _sort_key(v: Any) -> tuple[int, Any]:
    return (0, float(v)) if isinstance(v, (int, float)) else (1, str(v))


def conclusions(spec: StudySpec, summary: list[dict[str, Any]],
                sbc: dict[str, Any] | None) -> list[str]:
    """One plain-language sentence per parameter and varied factor (plus SBC verdicts)."""
    lines = []
    if sbc:
        for n, s in sbc.items():
            verdict = "calibrated" if s["calibrated"] else "NOT calibrated"
            lines.append(f"{n}: {verdict} over {s['n']} datasets: 50 % intervals cover "
                         f"{s['coverage50']:.0%} (99 % band {s['band50'][0]:.0%}-"
                         f"{s['band50'][1]:.0%}), 90 % intervals cover {s['coverage90']:.0%} "
                         f"(band {s['band90'][0]:.0%}-{s['band90'][1]:.0%}), rank uniformity "
                         f"p = {s['uniformity_p']:.2f}.")
    for factor in spec.factors:
        for n in spec.estimate:
            rs = [r for r in summary if r["param"] == n]
            if not rs:
                continue
            levels = sorted({r[f"f_{factor}"] for r in rs}, key=_sort_key)
            share = {v: np.mean([_pinned(r) for r in rs if r[f"f_{factor}"] == v])
                     for v in levels}
            always = [v for v in levels if share[v] == 1.0]
            never = [v for v in levels if share[v] == 0.0]
            some = [v for v in levels if 0.0 < share[v] < 1.0]
            other = len(rs) // len(levels) > 1
            scope = " (in every combination of the other factors)" if other else ""
            if not always and not some:
                lines.append(f"{n} is not identified within 5 % (RMSE) at any {factor} tried "
                             f"({', '.join(_fmt(v) for v in levels)}).")
                continue
            parts = []
            if always:
                parts.append(f"at {factor} = {', '.join(_fmt(v) for v in always)}{scope}")
            if some:
                parts.append(f"in some cells at {factor} = {', '.join(_fmt(v) for v in some)}")
            text = f"{n} is identified within 5 % (RMSE) with calibrated intervals " + \
                "; ".join(parts)
            if never:
                text += f"; not at {', '.join(_fmt(v) for v in never)}"
            lines.append(text + ".")
    return lines


def finalise(spec: StudySpec, rows: list[dict[str, Any]], out_dir: str | Path,
             sbc: bool | None = None) -> Study:
    """Write results.csv, summary.csv, results.nc and conclusions into study.json; returns
    the finished study (results/study.py)."""
    out = Path(out_dir)
    write_csv(out / "results.csv", rows)
    if spec.inference == "diagnose":
        return _finalise_benchmark(rows, out)
    summ = cell_summary(spec, rows)
    write_csv(out / "summary.csv", summ)
    _write_netcdf(out / "results.nc", rows)
    sbc_stats = sbc_statistics(spec, rows) if (sbc if sbc is not None else
                                                spec.draw_from_prior) else None
    text = conclusions(spec, summ, sbc_stats)
    manifest = read_result_json((out / "study.json").read_text(encoding="utf-8"))
    manifest.update({"n_rows": len(rows), "failures": sum(bool(r.get("error")) for r in rows),
                     "conclusions": text, "sbc": sbc_stats,
                     "wall_s_total": float(sum(r.get("wall_s", 0.0) for r in rows))})
    write_text_atomic(out / "study.json", result_json_text(plain(manifest)))
    return replace(Study.from_dict(plain(manifest), str(out / "study.json")), rows=rows)


def _finalise_benchmark(rows: list[dict[str, Any]], out: Path) -> Study:
    """Concealed-effect benchmark: per-case table (summary.csv) and the four targets."""
    table = benchmark_table(rows)
    write_csv(out / "summary.csv", [{"case": c, **v} for c, v in table["per_case"].items()])
    _write_netcdf(out / "results.nc", rows)
    manifest = read_result_json((out / "study.json").read_text(encoding="utf-8"))
    manifest.update({"n_rows": len(rows), "failures": sum(bool(r.get("error")) for r in rows),
                     "conclusions": benchmark_conclusions(table), "benchmark": table,
                     "wall_s_total": float(sum(r.get("wall_s", 0.0) for r in rows))})
    write_text_atomic(out / "study.json", result_json_text(plain(manifest)))
    return replace(Study.from_dict(plain(manifest), str(out / "study.json")), rows=rows)


def _write_netcdf(path: Path, rows: list[dict[str, Any]]) -> None:
    import xarray as xr

    keys: list[str] = []
    for r in rows:                     # union of the rows' keys (diagnose rows differ)
        keys += [k for k in r if k not in keys and k != "traceback"]
    data = {}
    for k in keys:
        vals = [r.get(k) for r in rows]
        if all(isinstance(v, (int, float, bool)) and not isinstance(v, str) for v in vals
               if v is not None):
            data[k] = ("replicate", np.array([math.nan if v is None else float(v)
                                              for v in vals]))
        else:
            data[k] = ("replicate", np.array(["" if v is None else str(v) for v in vals]))
    write_netcdf_atomic(xr.Dataset(data), path)
