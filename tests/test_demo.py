"""``bayes-amb demo`` in its quick variant (short records, 300 sampler steps): every stage
runs, writes its files, and the paper's case is recovered.

Reference: the paper's case is noise-free (eps = S(0.5) x exactly), so the MAP of k_By is
0.5 to within the optimiser's tolerance; 1e-4 is far inside it and far outside the paper's
own error (0.502 - 0.5 = 2e-3).
"""

from __future__ import annotations

import contextlib
import io
import json

import pytest

from bayes_amb.cli.main import main

pytest.importorskip("jinja2")


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo") / "demo"
    buf, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(err):
        rc = main(["demo", "--quick", "--out", str(out), "--json"])
    return rc, json.loads(buf.getvalue()), err.getvalue(), out


def test_demo_runs_every_stage(demo):
    rc, res, progress, out = demo
    assert rc == 0
    for stage in ("1/4", "2/4", "3/4", "4/4"):
        assert stage in progress
    for name in ("controller_dt1e-3.json", "controller_dt1e-4.json", "paper_case.csv",
                 "paper_case.json", "paper_run/summary.json", "paper_run/posterior.nc",
                 "realistic.csv", "realistic_run/summary.json", "report.html", "report.pdf"):
        assert (out / name).is_file(), name
    assert res["report_pdf"] == str(out / "report.pdf") and res["pdf_backend"]
    assert set(res["timings"]) >= {"paper_case", "realistic_case", "reports", "total"}


def test_demo_paper_case_recovered(demo):
    k = demo[1]["paper"]["k_By"]
    assert k["true"] == 0.5
    assert k["map"] == pytest.approx(0.5, abs=1e-4)


def test_demo_report_is_the_realistic_run(demo):
    _, res, _, out = demo
    html = (out / "report.html").read_text(encoding="utf-8")
    assert "Identification report: realistic" in html
    assert "actuator_lag" in html                       # the simulated truth, shown as such
    assert set(res["realistic"]) == {"k_By", "c_By", "converged"}
    assert isinstance(res["diagnosis"], str) and res["diagnosis"]
    # the diagnosis lands in the run folder and the report shows it
    assert (out / "realistic_run" / "diagnosis.json").is_file()
    assert (out / "realistic_run" / "residuals.nc").is_file()
    assert 'id="discrepancy"' in html and "Every candidate tried" in html
