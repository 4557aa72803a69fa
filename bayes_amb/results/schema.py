"""The result files' schema, written out from the blocks themselves (docs/results.md).

    python -m bayes_amb.results.schema > docs/results.md

Each block is a table of its keys: the JSON key, its type (a block's name links to its
table) and whether it is always written. The test tests/test_results.py keeps the file in
step with the code.
"""

from __future__ import annotations

import dataclasses
import typing

from bayes_amb.results.blocks import Block, _schema
from bayes_amb.results.diagnosis import FORMAT as DIAGNOSIS_FORMAT
from bayes_amb.results.diagnosis import Diagnosis
from bayes_amb.results.engineering import FORMAT as ENGINEERING_FORMAT
from bayes_amb.results.engineering import EngineeringAnswers
from bayes_amb.results.identification import FORMAT as IDENTIFICATION_FORMAT
from bayes_amb.results.identification import Identification
from bayes_amb.results.records import FORMAT as RECORDS_FORMAT
from bayes_amb.results.records import RecordsDiagnosis
from bayes_amb.results.study import FORMAT as STUDY_FORMAT
from bayes_amb.results.study import Study

FILES = ((Diagnosis, "diagnosis.json", DIAGNOSIS_FORMAT),
         (Identification, "summary.json", IDENTIFICATION_FORMAT),
         (EngineeringAnswers, "answers.json", ENGINEERING_FORMAT),
         (RecordsDiagnosis, "records.json", RECORDS_FORMAT),
         (Study, "study.json", STUDY_FORMAT))


def _type_name(tp: object, found: list[type]) -> str:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, __import__("types").UnionType):
        names = [_type_name(a, found) for a in args if a is not type(None)]
        return " or ".join(names) + (" or null" if type(None) in args else "")
    if origin is list:
        return f"list of {_type_name(args[0], found)}"
    if origin is dict:
        return f"map of {_type_name(args[1], found)}"
    if isinstance(tp, type) and issubclass(tp, Block):
        if tp not in found:
            found.append(tp)
        return f"[{tp.__name__}](#{tp.__name__.lower()})"
    return getattr(tp, "__name__", str(tp)).replace("Any", "any")


def _presence(f: dataclasses.Field) -> str:
    if f.metadata.get("omit"):
        return "when it applies"
    if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
        return "always"
    return "always (older files: may lack it)"


def markdown() -> str:
    """docs/results.md: every block of every result file."""
    out = ["# Result files", "",
           "Written by `python -m bayes_amb.results.schema` from `bayes_amb/results/` "
           "(do not edit by hand). Each file is the JSON of a typed result object; "
           "`X.load(run_dir)` reads it back and `X.save(run_dir)` writes it. Keys a "
           "block does not name are kept (`extra`) and written back; a non-finite "
           "number is written as null and listed under `non_finite`.", ""]
    for cls, name, fmt in FILES:
        out += [f"- `{name}`: [{cls.__name__}](#{cls.__name__.lower()}), format `{fmt}`"]
    found: list[type] = [cls for cls, _, _ in FILES]
    i = 0
    while i < len(found):
        cls = found[i]
        rows = [(key, _type_name(tp, found), _presence(f)) for f, key, tp in _schema(cls)]
        doc = " ".join((cls.__doc__ or "").split())
        out += ["", f"## {cls.__name__}", "", doc, "", "| key | type | written |",
                "|---|---|---|"]
        out += [f"| `{k}` | {t} | {p} |" for k, t, p in rows]
        i += 1
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    print(markdown(), end="")
