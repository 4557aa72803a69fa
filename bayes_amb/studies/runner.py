"""Run a study: all replicates, in parallel, resumable, on a process pool or Dask.

Results are appended to DIR/results.jsonl one line per finished replicate (O_APPEND, flushed
and fsync'd), so killing a study loses at most the replicates in flight; starting it again
skips every replicate already recorded. The final tables are rebuilt from that file.
SIGINT and SIGTERM stop a study cleanly (:mod:`bayes_amb.studies.stopping`): no new work,
finished replicates written, workers terminated, :class:`StudyInterrupted` raised.

With ``workers > 1`` the pool starts its processes with forkserver (and Dask with spawn), so
a script that calls :func:`run_study` must guard its top level with
``if __name__ == "__main__":``, as the multiprocessing documentation requires.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

from bayes_amb import __version__
from bayes_amb.errors import StudyInterrupted
from bayes_amb.io.atomic import write_text_atomic
from bayes_amb.io.nonfinite import plain, read_result_json, result_json_line, result_json_text
from bayes_amb.results.files import read_rows
from bayes_amb.studies.replicate import replicate_id, replicate_seeds, run_replicate
from bayes_amb.studies.spec import StudyError, StudySpec
from bayes_amb.studies.stopping import StopSignals, kill_processes, worker_init

_DASK_LOG_ENV = "DASK_LOGGING__DISTRIBUTED"
_POLL_S = 0.2          # how often the parent looks for finished replicates and signals


def drop_torn_tail(path: Path) -> None:
    """Cut a last line that lacks its newline (killed mid-write), so that the next append
    starts a line of its own instead of being glued to the fragment and lost with it."""
    if not path.is_file():
        return
    data = path.read_bytes()
    if data and not data.endswith(b"\n"):
        with path.open("r+b") as fh:
            fh.truncate(data.rfind(b"\n") + 1)


def append_row(path: Path, row: dict[str, Any]) -> None:
    """Append one JSON line atomically enough for a crash: single write, fsync. A
    non-finite number (a NaN bias of a failed replicate, an infinite interval) is written
    as null and listed under ``non_finite`` (bayes_amb.io.nonfinite); :func:`read_rows`
    puts it back."""
    data = (result_json_line(plain(row, _jsonable)) + "\n").encode("utf-8")
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        os.write(fd, data)
        os.fsync(fd)
    finally:
        os.close(fd)


def _jsonable(o: Any) -> Any:
    if hasattr(o, "item"):
        return o.item()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def pending(spec: StudySpec, done: set[str]) -> list[tuple[int, int]]:
    return [(c, r) for c in range(len(spec.cells)) for r in range(spec.replicates)
            if replicate_id(c, r) not in done]


def _pool_results(spec: StudySpec, todo: list[tuple[int, int]], workers: int,
                  stop: StopSignals) -> Iterator[dict[str, Any]]:
    if workers <= 1:
        for c, r in todo:
            if stop.stopped:
                return
            stop.interruptible = True               # a signal raises StudyInterrupted here
            try:
                row = run_replicate(spec, c, r)
            finally:
                stop.interruptible = False
            yield row
        return
    # forkserver, not fork: the parent may already run threads (tqdm's monitor, scipy's FFT
    # pool), and forking a threaded process can deadlock the child
    pool = ProcessPoolExecutor(max_workers=workers, initializer=worker_init,
                               initargs=(os.getpid(),),
                               mp_context=multiprocessing.get_context("forkserver"))

    def workers_of_pool() -> list[Any]:
        return list((getattr(pool, "_processes", None) or {}).values())

    stop.on_hard_stop(lambda: [p.kill() for p in workers_of_pool()])
    clean = False
    try:
        left = {pool.submit(run_replicate, spec, c, r) for c, r in todo}
        while left and not stop.stopped:
            done, left = wait(left, timeout=_POLL_S, return_when=FIRST_COMPLETED)
            yield from _finished_rows(done, stop)
        if stop.stopped:                            # flush what finished meanwhile
            yield from _finished_rows({f for f in left if f.done()}, stop)
        clean = not stop.stopped
    finally:
        if clean:
            pool.shutdown(wait=True)
        else:
            procs = workers_of_pool()
            pool.shutdown(wait=False, cancel_futures=True)
            kill_processes(procs)


def _finished_rows(done: Iterable[Future], stop: StopSignals) -> Iterator[dict[str, Any]]:
    """The rows of finished futures; a worker killed by the signal that stops the study
    (SIGTERM to the process group) ends the stream instead of raising."""
    for fut in done:
        if fut.cancelled():
            continue
        exc = fut.exception()
        if isinstance(exc, BrokenProcessPool):
            t_end = time.monotonic() + 2.0          # our own handler may run a moment later
            while not stop.stopped and time.monotonic() < t_end:
                time.sleep(0.05)
            if stop.stopped:
                continue
            raise StudyError("study: a worker process died unexpectedly (killed from "
                             "outside?); finished replicates are saved, run the same "
                             "command with --resume") from exc
        yield fut.result()


def _dask_results(spec: StudySpec, todo: list[tuple[int, int]], scheduler: str | None,
                  n_local: int | None, stop: StopSignals) -> Iterator[dict[str, Any]]:
    from dask.distributed import Client, LocalCluster

    cluster = None
    if scheduler is None:
        quiet = logging.getLogger().getEffectiveLevel() > logging.INFO
        if quiet:                                   # Dask logs at INFO by default
            logging.getLogger("distributed").setLevel(logging.ERROR)
        # the worker processes are spawned with SIGINT ignored (kept across exec), so a
        # Ctrl-C to the process group reaches only this process, which stops them itself
        old = (signal.signal(signal.SIGINT, signal.SIG_IGN)
               if threading.current_thread() is threading.main_thread() else None)
        # the spawned workers read their logging level from the environment at import
        env_before = os.environ.get(_DASK_LOG_ENV)
        if quiet:
            os.environ[_DASK_LOG_ENV] = "critical"
        try:
            cluster = LocalCluster(n_workers=n_local or 2, threads_per_worker=1,
                                   processes=True, dashboard_address=None)
        finally:
            if old is not None:
                signal.signal(signal.SIGINT, old)
            if env_before is None:
                os.environ.pop(_DASK_LOG_ENV, None)
            else:
                os.environ[_DASK_LOG_ENV] = env_before
        client = Client(cluster)
    else:
        client = Client(scheduler)
    left: list[Any] = []
    try:
        left = [client.submit(run_replicate, spec, c, r, pure=False) for c, r in todo]
        while left and not stop.stopped:
            flags = [f.done() for f in left]
            done = [f for f, d in zip(left, flags, strict=True) if d]
            left = [f for f, d in zip(left, flags, strict=True) if not d]
            if not done:
                time.sleep(_POLL_S)
            for fut in done:
                yield fut.result()
        if stop.stopped:
            for fut in [f for f in left if f.done() and f.status == "finished"]:
                yield fut.result()
    finally:
        if stop.stopped and left:
            client.cancel(left)
        client.close()
        if cluster is not None:
            cluster.close()


def study_manifest(spec: StudySpec) -> dict[str, Any]:
    return {"format": "bayes-amb-study/1", "package_version": __version__,
            "study": spec.to_dict(), "source": spec.source, "cells": spec.cells,
            "seeds": {replicate_id(c, r): replicate_seeds(spec, c, r)[0]
                      for c in range(len(spec.cells)) for r in range(spec.replicates)}}


def run_study(spec: StudySpec, out_dir: str | Path, *, workers: int = 2,
              dask_local: int | None = None, scheduler: str | None = None,
              progress: bool = False) -> list[dict[str, Any]]:
    """Run every replicate not yet in OUT/results.jsonl; returns all rows, sorted by id.

    Raises
    ------
    StudyInterrupted
        On SIGINT or SIGTERM (main thread only): no new replicate starts, the finished ones
        are written, the workers are terminated, and the exception says how many replicates
        are saved. Calling run_study again with the same folder resumes.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    manifest = out / "study.json"
    if manifest.is_file():
        old = read_result_json(manifest.read_text(encoding="utf-8"))
        if old.get("study") != plain(spec.to_dict(), _jsonable):
            raise StudyError(f"study folder {out}: field study.json: it holds results of a "
                             "different study definition; use another --out folder")
    write_text_atomic(manifest, result_json_text(plain(study_manifest(spec), _jsonable)))
    results = out / "results.jsonl"
    drop_torn_tail(results)
    done = {r["id"] for r in read_rows(results)}
    todo = pending(spec, done)
    bar = None
    if progress and todo:
        from tqdm import tqdm
        bar = tqdm(total=spec.n_replicates_total, initial=len(done), unit="replicate",
                   file=sys.stderr, desc=f"study {spec.name}")
    n_saved = len(done)
    try:
        with StopSignals() as stop:
            if dask_local or scheduler:
                stream: Iterable[dict[str, Any]] = _dask_results(spec, todo, scheduler,
                                                                 dask_local, stop)
            else:
                stream = _pool_results(spec, todo, workers, stop)
            for row in stream:
                append_row(results, row)
                n_saved += 1
                if bar is not None:
                    bar.update(1)
            if stop.signum is not None:
                raise StudyInterrupted(stop.signum)
    except StudyInterrupted as exc:
        raise StudyInterrupted(exc.signum, n_saved, spec.n_replicates_total,
                               str(results)) from None
    finally:
        if bar is not None:
            bar.close()
    return sorted(read_rows(results), key=lambda r: r["id"])
