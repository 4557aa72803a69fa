"""The report of a diagnosis across several recordings: OUT/records.html.

    from bayes_amb.report.records import write_records_report
    write_records_report("runs/speeds")          # after diagnose REC1 REC2 ... --out runs/speeds

It reads what ``diagnose REC1 REC2 ... --out DIR`` wrote (DIR/records.json and each
DIR/record_<i>/diagnosis.json, as bayes_amb.results.records.RecordsDiagnosis) and shows,
without recomputing anything estimated:

- each record's verdict, fit (NRMSE before and after) and adequacy line;
- every effect across the records: where it was named, its log Bayes factor in each
  record, the joint search's sum, and whether its size agrees (discrepancy/records.py);
- what the records share: each bearing coefficient per record (the diagnosis'
  ``parameters_after``) with Cochran's Q of their agreement (inference/consistency.py), as
  a table and a forest plot. A coefficient that disagrees across speeds is either
  speed-dependent or absorbing something a record's model lacks.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from bayes_amb.inference.consistency import agreement
from bayes_amb.report import figures as fg
from bayes_amb.report.collect import ReportError
from bayes_amb.report.render import write_page
from bayes_amb.report.sections import Section, Table, g
from bayes_amb.results.diagnosis import Diagnosis

__all__ = ["collect_records", "records_sections", "write_records_report"]

def collect_records(run_dir: str | Path) -> Any:
    """The typed diagnosis across records of a run folder (records.json and each
    record_<i>/), as :class:`bayes_amb.results.records.RecordsDiagnosis`."""
    from bayes_amb.results.records import RecordsDiagnosis

    d = Path(run_dir)
    if not (d / "records.json").is_file():
        raise ReportError(f"records {d / 'records.json'}: not found (bayes-amb diagnose "
                          "REC1 REC2 ... --out DIR writes them)")
    return RecordsDiagnosis.load(d)


def _final_adequacy(r: Diagnosis) -> Any:
    return r.adequacy_after or r.adequacy


def _records_table(result: Any) -> Table:
    reports = result.diagnoses
    speeds = result.speeds_rpm or [None] * len(reports)
    rows = []
    for i, (r, rpm) in enumerate(zip(reports, speeds, strict=True), 1):
        before = max(r.fit.before.nrmse.values(), default=np.nan)
        after = max(r.fit.after.nrmse.values(), default=np.nan)
        named = ", ".join(e.key for e in r.explanations) or "–"
        ad = _final_adequacy(r)
        rows.append([str(i), Path(r.recording).name, "–" if rpm is None else g(rpm, 5),
                     r.verdict, named, f"{g(before, 3)} → {g(after, 3)}",
                     "adequate" if ad is not None and ad.adequate else "NOT adequate"])
    doubted = any(_final_adequacy(r) is not None and not _final_adequacy(r).adequate
                  for r in reports)
    return Table("Each record's diagnosis", ["#", "file", "rpm", "verdict",
                                             "named", "NRMSE before → after",
                                             "final model"], rows,
                 "NRMSE: the residual's RMS over eps's, the worst of the four channels."
                 + (" Why a final model is not adequate: listed above the table."
                    if doubted else ""), wrap=(1, 4))


def _bf(row: Any, k: str) -> str:
    v = row.log_bayes_factor[k]
    if v is not None:
        return g(v, 3)
    return "no gain" if row.present.get(k) is False else "not tested"


def _across_table(result: Any) -> Table | None:
    if not result.across:
        return None
    rows = []
    for row in result.across:
        bfs = "; ".join(f"{k}: {_bf(row, k)}" for k in row.log_bayes_factor)
        if row.named_in:
            where = "record " + ", ".join(map(str, row.named_in))
        elif row.named_jointly:
            where = "the records together"
        else:
            where = "nowhere (joint search)"
        joint = row.joint_log_posterior_odds
        if row.weaker_by is not None:
            where += (f"; the records prefer {row.preferred_location} "
                      f"(by {g(row.weaker_by, 3)} nats)")
        rows.append([row.effect, where, bfs, "–" if joint is None else g(joint, 3),
                     "yes" if row.in_every_record else "no",
                     row.size.reading if row.size else "–"])
    return Table("Effects across the records", ["effect", "named by", "log BF per record",
                                                "joint log posterior odds",
                                                "in every record", "size across records"],
                 rows, "An effect named in one record is tested alone in every other; the "
                       "joint search fits what the records' screens point to together and "
                       "adds its log Bayes factors (prior odds 1/K, threshold 3). An effect "
                       "named at several places: the records prefer the place with the "
                       "larger summed log Bayes factor.",
                 wrap=(2, 5))


def _coefficients(reports: list[Diagnosis]) -> tuple[list[str], dict[str, list[Any]]]:
    names = [n for n in reports[0].parameters_after
             if all(n in r.parameters_after for r in reports)]
    return names, {n: [r.parameters_after[n] for r in reports] for n in names}


def _shared_table(reports: list[Diagnosis]) -> tuple[Table | None, dict[str, Any]]:
    names, per = _coefficients(reports)
    if not names:
        return None, {}
    means = {n: [v.mean for v in per[n]] for n in names}
    sds = {n: [v.sd for v in per[n]] for n in names}
    test = agreement(means, sds)
    rows = []
    for n in names:
        t = test["parameters"].get(n)
        cells = [f"{g(v.mean, 3)} [{g(v.hdi90[0], 3)}, {g(v.hdi90[1], 3)}]" for v in per[n]]
        verdict = ("–" if t is None else
                   "DISAGREE" if n in test["disagree"] else "agree")
        rows.append([n, *cells, "–" if t is None else g(t["p_adjusted"], 2), verdict])
    header = ["coefficient", *(f"record {i}" for i in range(1, len(reports) + 1)),
              "Holm p", "across records"]
    return Table("Bearing coefficients per record (theta, 90 % HDI) and their agreement",
                 header, rows, "Holm p: Cochran's Q of the records' means against their "
                 "sds, Holm-adjusted over the coefficients. A coefficient that disagrees "
                 "is speed-dependent or absorbs what a record's model lacks.",
                 wrap=tuple(range(1, len(reports) + 1))), test


def _forest(reports: list[Diagnosis], speeds: list[float | None]
            ) -> fg.ReportFigure | None:
    names, per = _coefficients(reports)
    if not names:
        return None
    return forest_figure(names, per, record_labels(speeds), None, "records_coefficients",
                         "Bearing coefficients per record",
                         "Mean and 90 % HDI of each coefficient in each record's diagnosis "
                         "(parameters_after). Records that agree overlap; the table above "
                         "tests it.")


def record_labels(speeds: list[float | None]) -> list[str]:
    """'record 1 (20475 rpm)', ... for the legends."""
    return [f"record {i}" + ("" if v is None else f" ({v:.0f} rpm)")
            for i, v in enumerate(speeds, 1)]


def forest_figure(names: list[str], per: dict[str, list[Any]], labels: list[str],
                  joint: dict[str, Any] | None, key: str, title: str, caption: str,
                  xlabel: str = "theta (fraction of the nominal value)"
                  ) -> fg.ReportFigure:
    """Each coefficient's mean and 90 % HDI per record (``per[name]``: Posterior-like
    objects with mean and hdi90), and the joint one in black below them when given. With
    ``joint``, every value is shown as (value - joint mean) / joint sd, so that
    coefficients of very different size and precision share one axis."""
    import matplotlib.pyplot as plt
    n_rec = len(labels)
    rows = n_rec + (joint is not None)
    fig, ax = plt.subplots(figsize=(7.5, 0.45 * len(names) * max(rows, 2) / 2 + 1.2))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for j, n in enumerate(names):
        items = [(v, labels[i], colours[i % len(colours)]) for i, v in enumerate(per[n])]
        if joint is not None and n in joint:
            items.append((joint[n], "joint", "black"))
        c, w = 0.0, 1.0
        if joint is not None and n in joint and joint[n].sd > 0:
            c, w = joint[n].mean, joint[n].sd
        for i, (v, lab, col) in enumerate(items):
            y = j + (i - (rows - 1) / 2) * 0.8 / max(rows, 2)
            ax.plot([(h - c) / w for h in v.hdi90], [y, y], color=col, lw=2.2,
                    label=lab if j == 0 else None)
            ax.plot([(v.mean - c) / w], [y], "o", color=col, ms=4)
    ax.set_yticks(range(len(names)), names)
    ax.invert_yaxis()
    ax.axvline(0.0, color="0.6", lw=0.8)
    ax.set_xlabel(xlabel)
    ax.legend(loc="best", fontsize=8)
    ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    out = fg.render_figure(fig, key, title, caption)
    plt.close(fig)
    return out


def records_sections(result: Any) -> list[Section]:
    """The report's sections: the records, the effects across them, what they share
    (``result``: a RecordsDiagnosis with its records' diagnoses)."""
    reports = result.diagnoses
    shared, test = _shared_table(reports)
    n = len(reports)
    verdicts = ", ".join(f"{v} ({sum(r.verdict == v for r in reports)})"
                         for v in dict.fromkeys(r.verdict for r in reports))
    jointly = [row.effect for row in result.across if row.named_jointly]
    lines = [f"{n} records diagnosed, each with its own model, noise and speed: {verdicts}."]
    every = [row.effect for row in result.across if row.in_every_record]
    some = [row.effect for row in result.across if row.named_in and not row.in_every_record]
    if every:
        lines.append("Present in every record (a property of the machine): "
                     + ", ".join(every) + ".")
    if some:
        lines.append("Named in some records only (depends on what differs between them): "
                     + ", ".join(some) + ".")
    if jointly:
        lines.append("Named only by the records together (no record alone had the "
                     "evidence): " + ", ".join(jointly) + ".")
    if test:
        lines.append(test["line"][:1].upper() + test["line"][1:] + ".")
    if result.force_law:
        fl = result.force_law["line"]
        lines.append(fl[:1].upper() + fl[1:] + ".")
    doubted = [f"Record {i}: {_final_adequacy(r).line}" for i, r in enumerate(reports, 1)
               if _final_adequacy(r) is not None and not _final_adequacy(r).adequate]
    tables = [_records_table(result)]
    small = (result.force_law or {}).get("small_signal")
    if small:
        tables.append(Table(
            "Small-signal stiffnesses (the force law across the records' levels taken out)",
            ["coefficient", "mean", "90 % interval"],
            [[n, g(v["mean"], 4), f"[{g(v['hdi90'][0], 4)}, {g(v['hdi90'][1], 4)}]"]
             for n, v in small.items()],
            "theta units (relative reduction of ks); the records' stiffnesses read rise "
            "with their currents, these are the stiffnesses at zero current."))
    summary = Section("summary", "Summary", paragraphs=lines, bullets=doubted,
                      tables=tables)
    across = _across_table(result)
    sections = [summary]
    if across is not None:
        sections.append(Section("across", "Effects across the records", tables=[across]))
    if shared is not None:
        fig = _forest(reports, result.speeds_rpm or [None] * n)
        sections.append(Section("shared", "What the records share",
                                tables=[shared], figures=[fig] if fig else []))
    return sections


def write_records_report(run_dir: str | Path, out_dir: str | Path | None = None) -> Path:
    """Write OUT/records.html (OUT defaults to the run folder) for a run folder of
    ``diagnose REC1 REC2 ... --out DIR``; returns its path."""
    result = collect_records(run_dir)
    return write_page(records_sections(result), f"Diagnosis across {len(result.diagnoses)} "
                      "records", run_dir, out_dir, "records.html")
