"""Diagnosis across several recordings (issue 29, first path): each record diagnosed, and
every effect named in one record tested in all the others.

A record that names an effect gives a hypothesis chosen before the other records are
looked at, so in each other record it is tested alone: that record's nominal model
extended by that one candidate, its log Bayes factor with prior odds 1 (no multiplicity:
one pre-specified hypothesis), present when above the diagnosis' threshold (absent when
the candidate gives no likelihood gain at all, which the search does not refine). An effect
present in every record is a property of the machine; one present in some records only
depends on what differs between them (speed, amplitude, time), and the table says which.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from bayes_amb.discrepancy.diagnose import DiagnoseOptions, Diagnosis, diagnose
from bayes_amb.discrepancy.library import make_candidate
from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.priors import Prior
from bayes_amb.io.atomic import write_text_atomic
from bayes_amb.io.nonfinite import result_json_text
from bayes_amb.io.recording import Recording


@dataclass
class RecordsDiagnosis:
    """Each record's Diagnosis and ``across``: per effect named anywhere, where it was named
    and its log Bayes factor in every record."""

    diagnoses: list[Diagnosis]
    across: list[dict[str, Any]]
    sources: list[str]

    def to_dict(self) -> dict[str, Any]:
        return {"format": "bayes-amb-diagnosis-records/1", "recordings": self.sources,
                "verdicts": [d.report["verdict"] for d in self.diagnoses],
                "across": self.across}

    def save(self, out_dir: str | Path) -> Path:
        """OUT/record_<i>/ (each record's diagnosis files) and OUT/records.json."""
        d = Path(out_dir)
        for i, dg in enumerate(self.diagnoses, 1):
            dg.save(d / f"record_{i}")
        write_text_atomic(d / "records.json", result_json_text(self.to_dict()))
        return d


def _key(e: dict[str, Any]) -> str:
    return f"{e['effect']}@{e['location']}"


def diagnose_records(recordings: list[Recording], params: str | tuple[str, ...] | None = None,
                     priors: dict[str, Prior] | None = None,
                     options: DiagnoseOptions | None = None) -> RecordsDiagnosis:
    """Diagnose each recording, then test every effect named in one record in each of the
    others (module docstring)."""
    if len(recordings) < 2:
        raise BayesAmbError("diagnose: several recordings are needed to diagnose across "
                            f"records (got {len(recordings)})")
    opt = options or DiagnoseOptions()
    diags = [diagnose(r, params, priors, opt) for r in recordings]
    named: dict[str, list[int]] = {}
    for i, d in enumerate(diags):
        for e in d.report["explanations"]:
            if e.get("kind", "physics") == "physics":
                named.setdefault(_key(e), []).append(i)
    across = []
    for key, where in named.items():
        cand = make_candidate(key)
        row: dict[str, Any] = {"effect": key, "named_in": [i + 1 for i in where],
                               "log_bayes_factor": {}, "present": {}}
        for i, (rec, d) in enumerate(zip(recordings, diags, strict=True)):
            if i in where:
                lbf = next(e["score"] for e in d.report["explanations"] if _key(e) == key)
            elif d.report["checks"] and any(not c["ok"] for c in d.report["checks"]):
                lbf = None                              # a failed data check: not tested
            else:
                alone = diagnose(rec, params, priors, replace(
                    opt, candidates=(cand,), max_effects=1, sample=False, progress=None,
                    prescreen=False))
                c = next((c for c in alone.report["candidates"] if _key(c) == key), None)
                lbf = None if c is None else c["log_bayes_factor"]
                if lbf is None and c is not None and (c.get("screen_gain") or 0.0) <= 0.0:
                    # no likelihood gain at all: the fit is not refined, the effect absent
                    row["log_bayes_factor"][str(i + 1)] = None
                    row["present"][str(i + 1)] = False
                    continue
            row["log_bayes_factor"][str(i + 1)] = lbf
            row["present"][str(i + 1)] = (None if lbf is None
                                          else bool(lbf > opt.log_bf_threshold))
        tested = [v for v in row["present"].values() if v is not None]
        row["in_every_record"] = bool(tested) and all(tested)
        across.append(row)
    return RecordsDiagnosis(diags, across, [str(r.source) for r in recordings])
