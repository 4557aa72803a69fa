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
