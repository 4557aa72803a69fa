"""Stopping a study (issue 19): SIGINT to the process group (Ctrl-C) and SIGTERM to the
parent (``kill PID``) stop it cleanly, on the process pool and on Dask.

Each backend runs the tiny study of tests/test_studies.py (3 noise levels x 2 replicates,
about 1 s per replicate) as ``bayes-amb study`` in a session of its own: SIGINT to the
process group once the first replicate lands, then ``--resume`` stopped by SIGTERM to the
parent once one more lands, then ``--resume`` to the end. Each stop must give exit status
128 + signal, one stderr line naming ``--resume`` (no traceback), no process of the session
left, and an intact results.jsonl (every line parses, no torn tail); the final resume must
complete the study with every replicate exactly once and the saved lines untouched.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

from bayes_amb.studies.replicate import replicate_id
from tests.test_studies import CONSOLE, ENV, _wait_for_lines, jsonl_lines, tiny, to_toml

ALL_IDS = sorted(replicate_id(c, r) for c in range(3) for r in range(2))
GRACE_S = 15.0     # the stop must end every process within this (measured: < 1 s on the
                   # pool, about 3-5 s on Dask, whose nannies wait for their workers)


def session_processes(sid: int) -> list[str]:
    """'pid command' of every live (non-zombie) process whose session id is ``sid``."""
    found = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()       # after "pid (comm) "
        state, session = fields[0], int(fields[3])
        if session == sid and state != "Z":
            found.append(f"{d.name} {stat[stat.index('(') + 1:stat.rindex(')')]}")
    return found


def _run_and_stop(cmd: list[str], results: Path, n_lines: int, sig: int,
                  to_group: bool) -> str:
    """Start ``cmd`` in a new session, send ``sig`` once results.jsonl has ``n_lines`` lines,
    check the stop (status, one stderr line, no process left, an intact file) and return
    the saved lines."""
    proc = subprocess.Popen(cmd, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    try:
        _wait_for_lines(results, n_lines, proc, timeout=300)
        if to_group:                                    # Ctrl-C in a terminal
            os.killpg(proc.pid, sig)
        else:                                           # kill PID
            proc.send_signal(sig)
        t0 = time.monotonic()
        _, err = proc.communicate(timeout=GRACE_S)
        left = session_processes(proc.pid)
        while left and time.monotonic() - t0 < GRACE_S:
            time.sleep(0.1)
            left = session_processes(proc.pid)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert not left, f"processes left {GRACE_S} s after the signal: {left}"
    assert proc.returncode == 128 + sig, err
    assert "Traceback" not in err, err
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert "--resume" in err and str(results.parent) in err
    assert results.read_bytes().endswith(b"\n")           # no torn last line
    lines = jsonl_lines(results)
    ids = [json.loads(x)["id"] for x in lines]             # every line parses
    assert n_lines <= len(ids) < len(ALL_IDS) and len(set(ids)) == len(ids)
    assert f"{len(ids)} of {len(ALL_IDS)} replicates" in err
    return lines


def _stop_twice_then_resume(tmp_path: Path, backend: list[str]) -> None:
    toml = tmp_path / "sig.toml"
    toml.write_text(to_toml(tiny(name="sig", replicates=2)), encoding="utf-8")
    out = tmp_path / "out"
    results = out / "results.jsonl"
    cmd = [str(CONSOLE), "study", str(toml), "--out", str(out), "--no-figures",
           "--no-progress", *backend]
    first = _run_and_stop(cmd, results, 1, signal.SIGINT, to_group=True)
    second = _run_and_stop([*cmd, "--resume"], results, len(first) + 1, signal.SIGTERM,
                           to_group=False)
    assert second[:len(first)] == first
    done = subprocess.run([*cmd, "--resume", "--json"], env=ENV, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    after = jsonl_lines(results)
    assert after[:len(second)] == second                # saved lines untouched
    assert sorted(json.loads(x)["id"] for x in after) == ALL_IDS   # none lost or repeated
    assert json.loads(done.stdout)["rows"] == len(ALL_IDS)


def test_pool_study_stops_cleanly_and_resumes(tmp_path):
    """SIGINT to the group, then SIGTERM to the parent, then a resume to the end."""
    _stop_twice_then_resume(tmp_path, ["--workers", "2"])


def test_dask_study_stops_cleanly_and_resumes(tmp_path):
    """The same on a local Dask cluster."""
    _stop_twice_then_resume(tmp_path, ["--dask-local", "2"])
