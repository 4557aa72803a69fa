"""Issue 31: the typed results change no number. Ten foreign recordings are diagnosed and
five identified with default options, as main did before the typed results landed
(tests/golden/, written by ``python -m tests.golden.cases`` at c936d8d); every key and
value of ``diagnosis.json`` and ``summary.json`` must match (floats to a relative 1e-4,
timings and versions aside). The saved folders must load back to the same objects."""

from __future__ import annotations

import pytest

from bayes_amb.io.nonfinite import result_json_text
from bayes_amb.results import Diagnosis, Identification
from tests.golden.cases import (
    DIAGNOSED,
    IDENTIFIED,
    diagnosis_json,
    differences,
    golden_path,
    read_golden,
    summary_json,
)


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("golden")


@pytest.mark.parametrize(("kind", "index"), DIAGNOSED)
def test_diagnosis_json_is_what_main_wrote(work, kind, index):
    got = diagnosis_json(work, kind, index)
    diff = differences(got, read_golden(golden_path(kind, index, "diagnosis")))
    assert not diff, "\n".join(diff[:10])
    run = work / "runs" / f"{kind}_{index:02d}"
    loaded = Diagnosis.load(run)
    assert loaded.verdict == got["verdict"]
    assert [e.key for e in loaded.explanations] == [
        f"{e['effect']}@{e['location']}" for e in got["explanations"]]
    assert loaded.residuals is not None and "nominal" in (loaded.models or {})
    assert (result_json_text(loaded.to_dict())
            == (run / "diagnosis.json").read_text())          # the file, byte for byte


@pytest.mark.parametrize(("kind", "index", "sampled"), IDENTIFIED)
def test_summary_json_is_what_main_wrote(work, kind, index, sampled):
    got = summary_json(work, kind, index, sampled)
    diff = differences(got, read_golden(golden_path(kind, index, "summary")))
    assert not diff, "\n".join(diff[:10])
    loaded = Identification.load(work / "ident" / f"{kind}_{index:02d}")
    assert list(loaded.parameters) == got["parameters_estimated"]
    assert (loaded.posterior is not None) == sampled
    assert loaded.parameters["k_Ax"].mean == got["parameters"]["k_Ax"]["mean"]
    assert (result_json_text(loaded.to_dict())
            == (work / "ident" / f"{kind}_{index:02d}" / "summary.json").read_text())
