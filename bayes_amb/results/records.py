"""The result of a diagnosis across records: :class:`RecordsDiagnosis`, the typed content of
a ``diagnose REC1 REC2 ... --out DIR`` folder (records.json and record_<i>/).

    r = diagnose_records([rec1, rec2, rec3])     # or RecordsDiagnosis.load("runs/speeds")
    [(a.effect, a.named_in, a.in_every_record) for a in r.across]
    r.diagnoses[0].verdict                       # each record's own Diagnosis
    r.save("runs/speeds")                        # records.json and record_<i>/
    write_records_report("runs/speeds")          # records.html (report/records.py)

``records.json`` (format ``bayes-amb-diagnosis-records/1``) holds the records, their speeds
and verdicts and one row per effect across them (discrepancy/records.py); each record's
diagnosis is its own folder record_<i>/.
"""

from __future__ import annotations

from dataclasses import field, replace
from pathlib import Path
from typing import Any, Self

from bayes_amb.results.blocks import Block, block, omitted, runtime
from bayes_amb.results.diagnosis import Agreement, Diagnosis
from bayes_amb.results.files import read_block, write_result

FORMAT = "bayes-amb-diagnosis-records/1"
FILE = "records.json"


@block
class SizeAgreement(Block):
    """Whether an effect fitted in several records has the same size in each: the records,
    the agreement test of its size quantities, and the reading (discrepancy/records.py)."""

    records: list[int]
    test: Agreement
    agree: bool
    reading: str


@block
class AcrossRow(Block):
    """One effect across the records: where it was named, its log Bayes factor and
    presence in each record (keys: record numbers from 1; None: not tested), whether it is
    in every record, and its size's agreement; a row of the joint search also has the
    summed screens and the joint evidence. Where the records named the effect at several
    places, ``preferred_location`` is the one they favour together and ``weaker_by`` how
    far (summed log BF, nats) this place falls below it."""

    effect: str
    named_in: list[int]
    log_bayes_factor: dict[str, float | None]
    present: dict[str, bool | None]
    screen_gain_sum: float | None = omitted()
    joint_log_bayes_factor: float | None = omitted()
    joint_log_posterior_odds: float | None = omitted()
    named_jointly: bool | None = omitted()
    in_every_record: bool
    size: SizeAgreement | None = None
    preferred_location: str | None = omitted()
    weaker_by: float | None = omitted()


@block
class RecordsDiagnosis(Block):
    """Each record's diagnosis and the effects across them."""

    format: str = FORMAT
    recordings: list[str]
    speeds_rpm: list[float] = field(default_factory=list)
    verdicts: list[str]
    across: list[AcrossRow]
    force_law: dict[str, Any] | None = omitted()

    diagnoses: list[Diagnosis] | None = runtime()

    where = FILE

    def summary(self) -> str:
        """One line per record and per effect across them."""
        lines = [f"record {i}: {v} ({s})" for i, (v, s) in
                 enumerate(zip(self.verdicts, self.recordings, strict=True), 1)]
        lines += [f"{a.effect}: named in {a.named_in or 'no record alone'}"
                  + ("; named by the records together" if a.named_jointly else "")
                  + ("; in every record" if a.in_every_record else "")
                  for a in self.across]
        if self.force_law:
            lines.append(self.force_law["line"])
        return "\n".join(lines)

    def _repr_html_(self) -> str:
        """The notebook view: each record's verdict, and each effect across the records."""
        from bayes_amb.results.html import result_html

        recs = [[i, s, f"{r:g}" if r is not None else "-", v] for i, (s, r, v) in enumerate(
            zip(self.recordings, self.speeds_rpm or [None] * len(self.recordings),
                self.verdicts, strict=True), 1)]
        across = [[a.effect, ", ".join(map(str, a.named_in)) or "no record alone",
                   "yes" if a.named_jointly else "", "yes" if a.in_every_record else "",
                   a.size.reading if a.size is not None else ""] for a in self.across]
        line = (self.force_law or {}).get("line", "")
        return result_html(f"Diagnosis of {len(self.recordings)} records", "",
                           [line] if line else [],
                           [(["record", "recording", "speed (rpm)", "verdict"], recs),
                            (["effect", "named in records", "named together",
                              "in every record", "size across records"], across)])

    def save(self, out_dir: str | Path) -> Path:
        """OUT/record_<i>/ (each record's diagnosis files) and OUT/records.json, atomically
        (the page: report.records.write_records_report(OUT), as the CLI does)."""
        d = Path(out_dir)
        for i, dg in enumerate(self.diagnoses or [], 1):
            dg.save(d / f"record_{i}")
        write_result(d / FILE, self)
        return d

    @classmethod
    def load(cls, out_dir: str | Path) -> Self:
        """records.json and every record_<i>/ diagnosis of a folder."""
        d = Path(out_dir)
        out = read_block(cls, d / FILE, FORMAT)
        return replace(out, diagnoses=[Diagnosis.load(d / f"record_{i}")
                                       for i in range(1, len(out.recordings) + 1)])
