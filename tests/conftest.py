"""Fixtures shared by the test modules that run the foreign generator (benchmarks/foreign),
and the row threads of xdist workers."""

from __future__ import annotations

import os

import pytest

if os.environ.get("PYTEST_XDIST_WORKER"):
    # each xdist worker is one of the machine's CPUs: the likelihood's batches stay in it
    # (threads.over_rows); tests that split them set BAYES_AMB_POOL themselves
    os.environ.setdefault("BAYES_AMB_POOL", "1")


@pytest.fixture(scope="session")
def controller_file(tmp_path_factory) -> str:
    """The reference controller at dt = 1e-4 s, exported exactly as `bayes-amb controller
    --export` does: the file the foreign generator reads its controller from."""
    from bayes_amb.control.export import export_controller, reference_controller
    from bayes_amb.rig import load_rig
    rig = load_rig()
    path = tmp_path_factory.mktemp("ctrl") / "controller.json"
    export_controller(reference_controller(rig, 1e-4), rig).save(path)
    return str(path)


SHARED_FIXTURE_MODULES = {
    "tests.test_sbc_small": 184, "tests.test_report": 100, "tests.test_demo": 77,
    "tests.test_bench_cli": 30, "tests.test_identify": 20, "tests.test_direct_terms": 14,
    "tests.test_controller_cli": 8, "tests.test_studies": 8, "tests.test_nonfinite_results": 6,
    "tests.test_diagnose": 5}
"""Modules whose module-scoped fixtures cost seconds to build, with the seconds their
slowest one took (``pytest -n 2 --durations=0``, 2026-12-01, Intel Xeon, 2 cores)."""


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """The tests of a module in SHARED_FIXTURE_MODULES that use one of its module-scoped
    fixtures run on one xdist worker (``--dist loadgroup``, the Makefile's). Under plain
    ``load`` every worker that drew one of them built the fixture again: the SBC's 45
    identifications ran twice in one measured suite (115 s each, on both cores). The
    other tests, theirs included, are spread one by one."""
    for item in items:
        name = getattr(getattr(item, "module", None), "__name__", None)
        info = getattr(item, "_fixtureinfo", None)
        if name not in SHARED_FIXTURE_MODULES or info is None:
            continue
        if any(d.scope in ("module", "class") for fds in info.name2fixturedefs.values()
               for d in fds):
            item.add_marker(pytest.mark.xdist_group(name))
