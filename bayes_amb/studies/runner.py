"""Run a study: all replicates, in parallel, resumable, on a process pool or Dask.

Results are appended to DIR/results.jsonl one line per finished replicate (O_APPEND, flushed
and fsync'd), so killing a study loses at most the replicates in flight; starting it again
skips every replicate already recorded. The final tables are rebuilt from that file.

With ``workers > 1`` the pool starts its processes with forkserver (and Dask with spawn), so
a script that calls :func:`run_study` must guard its top level with
``if __name__ == "__main__":``, as the multiprocessing documentation requires.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import sys
from collections.abc import Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

from bayes_amb import __version__
from bayes_amb.io.atomic import write_text_atomic
from bayes_amb.studies.replicate import replicate_id, replicate_seeds, run_replicate
from bayes_amb.studies.spec import StudySpec


def read_rows(path: Path) -> list[dict[str, Any]]:
    """Rows of results.jsonl; a torn last line (killed mid-write) is ignored."""
    if not path.is_file():
        return []
    rows = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            rows.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return rows


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
    """Append one JSON line atomically enough for a crash: single write, fsync."""
    data = (json.dumps(row, sort_keys=True, default=_jsonable) + "\n").encode("utf-8")
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


def _pool_results(spec: StudySpec, todo: list[tuple[int, int]], workers: int
                  ) -> Iterator[dict[str, Any]]:
    if workers <= 1:
        for c, r in todo:
            yield run_replicate(spec, c, r)
        return
    # forkserver, not fork: the parent may already run threads (tqdm's monitor, scipy's FFT
    # pool), and forking a threaded process can deadlock the child
    with ProcessPoolExecutor(max_workers=workers,
                             mp_context=multiprocessing.get_context("forkserver")) as pool:
        futures = [pool.submit(run_replicate, spec, c, r) for c, r in todo]
        for fut in as_completed(futures):
            yield fut.result()


def _dask_results(spec: StudySpec, todo: list[tuple[int, int]], scheduler: str | None,
                  n_local: int | None) -> Iterator[dict[str, Any]]:
    from dask.distributed import Client, LocalCluster
    from dask.distributed import as_completed as dask_completed

    cluster = None
    if scheduler is None:
        cluster = LocalCluster(n_workers=n_local or 2, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
    else:
        client = Client(scheduler)
    try:
        futures = [client.submit(run_replicate, spec, c, r, pure=False) for c, r in todo]
        for fut in dask_completed(futures):
            yield fut.result()
    finally:
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
    """Run every replicate not yet in OUT/results.jsonl; returns all rows, sorted by id."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    manifest = out / "study.json"
    if manifest.is_file():
        old = json.loads(manifest.read_text(encoding="utf-8"))
        if old.get("study") != json.loads(json.dumps(spec.to_dict(), default=_jsonable)):
            from bayes_amb.studies.spec import StudyError
            raise StudyError(f"study folder {out}: field study.json: it holds results of a "
                             "different study definition; use another --out folder")
    write_text_atomic(manifest, json.dumps(study_manifest(spec), indent=2,
                                           default=_jsonable) + "\n")
    results = out / "results.jsonl"
    drop_torn_tail(results)
    done = {r["id"] for r in read_rows(results)}
    todo = pending(spec, done)
    if dask_local or scheduler:
        stream: Iterable[dict[str, Any]] = _dask_results(spec, todo, scheduler, dask_local)
    else:
        stream = _pool_results(spec, todo, workers)
    bar = None
    if progress and todo:
        from tqdm import tqdm
        bar = tqdm(total=spec.n_replicates_total, initial=len(done), unit="replicate",
                   file=sys.stderr, desc=f"study {spec.name}")
    try:
        for row in stream:
            append_row(results, row)
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    return sorted(read_rows(results), key=lambda r: r["id"])
