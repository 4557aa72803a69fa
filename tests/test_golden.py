"""No change moves a result unnoticed. Ten foreign recordings are diagnosed and five
identified with default options (tests/golden/, written by ``python -m tests.golden.cases``);
every key and value of ``diagnosis.json`` and ``summary.json`` must match its golden copy,
each number on its own scale (tests/golden/compare.py: estimates within a hundredth of
their posterior sd, a twentieth under a learned noise spectrum, sampled ones within their
Monte Carlo error, p-values on the decision scale; words, names and verdicts exactly), so
the files hold on another CPU (tests/test_golden_kernels.py: under another CPU's BLAS
kernels). The saved folders must load back to the same objects."""

from __future__ import annotations

import json

import pytest

from bayes_amb.io.nonfinite import result_json_text
from bayes_amb.results import Diagnosis, Identification
from tests.golden.cases import (
    DIAGNOSED,
    IDENTIFIED,
    diagnosis_json,
    golden_path,
    read_golden,
    summary_json,
)
from tests.golden.compare import differences


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


def test_a_real_change_fails_the_golden_comparison(work):
    """The same record with its last tenth cut off: a real, small change of the data, which
    moves the estimates by a fraction of their sd. The comparison must see it."""
    from bayes_amb import IdentifyOptions, identify, load_recording
    from bayes_amb.discrepancy.library import BEARING_COEFFICIENTS
    from tests.golden.cases import record

    (work / "cut").mkdir(exist_ok=True)
    rec = load_recording(record(work / "cut", "control", 6))
    cut = rec.part(slice(0, int(0.9 * rec.t.size)))
    res = identify(cut, list(BEARING_COEFFICIENTS), options=IdentifyOptions(map_only=True))
    run = res.save(work / "cut" / "ident")
    got = json.loads((run / "summary.json").read_text())
    diff = differences(got, read_golden(golden_path("control", 6, "summary")))
    assert any(".parameters." in d for d in diff), diff[:5]
