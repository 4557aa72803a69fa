"""The report of a joint identification of several recordings: OUT/joint.html.

    from bayes_amb.report.joint import write_joint_report
    write_joint_report("runs/joint")       # after identify REC1 REC2 ... --out runs/joint
    write_joint_report("runs/joint", pdf_backend="auto")    # and runs/joint/joint.pdf

It reads what ``identify REC1 REC2 ... --out DIR`` wrote (DIR/summary.json, as
bayes_amb.results.Identification) and shows, without recomputing anything estimated:

- how the joint posterior was formed (sampled or MAP + Laplace, converged), the records'
  agreement on what they share and the adequacy line;
- the joint posterior of each parameter (shared, and per-record copies 'c_By@2');
- each record: file, speed, dt, noise intensities, adequacy;
- each record's own posterior beside the joint one, as a forest plot: the joint interval
  should lie inside the overlap of the records', about sqrt(n) narrower.
"""

from __future__ import annotations

from pathlib import Path

from bayes_amb.report.collect import ReportError
from bayes_amb.report.records import forest_figure, record_labels
from bayes_amb.report.render import write_page
from bayes_amb.report.sections import Section, Table, g
from bayes_amb.results.identification import Identification

__all__ = ["joint_sections", "write_joint_report"]


def _parameters_table(res: Identification) -> Table:
    sampled = res.sampler is not None
    rows = []
    for n, v in res.parameters.items():
        row = [n, g(v.mean, 3), g(v.sd, 2), f"[{g(v.hdi90[0], 3)}, {g(v.hdi90[1], 3)}]",
               f"{g(v.physical_mean, 3)} {v.unit}"]
        if sampled:
            row += ["–" if v.r_hat is None else f"{v.r_hat:.3f}",
                    "–" if v.ess_bulk is None else f"{v.ess_bulk:.0f}"]
        rows.append(row)
    header = ["parameter", "mean", "sd", "90 % HDI", "physical"]
    header += ["R-hat", "ESS"] * sampled
    note = ("theta: the fraction of the nominal value; 'c_By@2': a parameter estimated per "
            "record (record 2's).")
    if res.parameters_from:
        note += f" Intervals: {res.parameters_from}."
    return Table("The joint posterior", header, rows, note)


def _records_table(res: Identification) -> Table:
    rows = []
    for i, r in enumerate(res.records or [], 1):
        noise = ", ".join(f"{k.removeprefix('sigma_')} {v.value:.3g} {v.unit}"
                          for k, v in r.noise.items())
        ad = r.adequacy
        rows.append([str(i), Path(r.recording).name, g(r.speed_rpm, 5), g(r.dt, 3), noise,
                     "–" if ad is None else "adequate" if ad.adequate else "NOT adequate"])
    return Table("The records", ["#", "file", "rpm", "dt (s)", "noise (MAP)", "model"], rows,
                 "Each record keeps its own model (built at its speed), controller, dt and "
                 "noise intensities.", wrap=(1, 4))


def joint_sections(res: Identification) -> list[Section]:
    """The report's sections for a joint identification (``res``: identify_joint's result
    or Identification.load of its run folder)."""
    if not res.records:
        raise ReportError("joint report: the summary holds no records (not a joint "
                          "identification of several recordings)")
    n = len(res.records)
    lines = [f"{n} records, one posterior: {res.inference}; "
             f"{'converged' if res.converged else 'NOT converged'}."]
    if res.agreement is not None:
        line = res.agreement.line.rstrip(".")
        lines.append(line[:1].upper() + line[1:] + ".")
    bullets = [] if res.adequacy is None else [f"Adequacy: {res.adequacy.line}"]
    bullets += [f"Warning: {note}" for note in (res.identifiability or {}).get("notes", [])]
    bullets += [f"Noise of record {i}: {r.noise_check.line}"
                for i, r in enumerate(res.records, 1)
                if r.noise_check is not None and r.noise_check.doubted]
    if res.parameters_white_noise is not None:
        bullets.append("The joint intervals are the sandwich of the records' measured noise "
                       "(the white model's under parameters_white_noise in summary.json).")
    summary = Section("summary", "Summary", paragraphs=lines, bullets=bullets,
                      tables=[_parameters_table(res), _records_table(res)])
    names = [k for k in res.records[0].parameters
             if all(k in r.parameters for r in res.records)]
    per = {k: [r.parameters[k] for r in res.records] for k in names}
    fig = forest_figure(names, per, record_labels([r.speed_rpm for r in res.records]),
                        {k: res.parameters[k] for k in names if k in res.parameters},
                        "joint_coefficients", "Each record's posterior and the joint one",
                        "Mean and 90 % interval of each coefficient from each record alone "
                        "(colours) and from all records together (black), in units of the "
                        "joint sd about the joint mean: records that agree overlap at 0, "
                        "and n records of equal information are about sqrt(n) wider than "
                        "the joint. A parameter estimated per record has no joint "
                        "interval.", xlabel="(theta - joint mean) / joint sd")
    return [summary, Section("records", "Each record and the joint posterior",
                             figures=[fig])]


def is_joint_run(run_dir: str | Path) -> bool:
    """Whether RUN_DIR/summary.json is a joint identification (it lists ``recordings``)."""
    from bayes_amb.results.files import read_result

    path = Path(run_dir) / "summary.json"
    return path.is_file() and bool(read_result(path).get("recordings"))


def write_joint_report(run_dir: str | Path, out_dir: str | Path | None = None,
                       pdf_backend: str | None = None) -> Path:
    """Write OUT/joint.html (OUT defaults to the run folder) for a run folder of
    ``identify REC1 REC2 ... --out DIR``, and with ``pdf_backend`` (render.write_pdf)
    OUT/joint.pdf too; returns the HTML's path."""
    res = Identification.load(run_dir)
    return write_page(joint_sections(res), f"Joint identification of {len(res.records or [])} "
                      "records", run_dir, out_dir, "joint.html", pdf_backend)
