"""Stopping a running study cleanly on SIGINT (Ctrl-C) and SIGTERM (``kill``).

While a study runs, :class:`StopSignals` replaces the handlers of both signals. The first
signal only sets a flag (or, while a replicate runs in this process, raises
:class:`~bayes_amb.errors.StudyInterrupted` at once): the runner then stops submitting work,
writes the replicates that have finished, terminates its worker processes and raises
:class:`~bayes_amb.errors.StudyInterrupted`, which the CLI turns into one line that says how
to resume. A second signal kills the workers and exits the process at once (status
128 + signal), without waiting for anything.

Worker processes (:func:`worker_init`) ignore SIGINT, so a Ctrl-C sent to the whole process
group reaches only the parent, which decides; and each worker exits by itself as soon as
the study's process has ended, so no worker outlives a study killed with SIGKILL.
"""

from __future__ import annotations

import os
import select
import signal
import threading
import time
from collections.abc import Callable
from types import FrameType
from typing import Any

from bayes_amb.errors import StudyInterrupted
from bayes_amb.threads import POOL_VAR

__all__ = ["StopSignals", "kill_processes", "worker_init"]

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopSignals:
    """Context manager catching SIGINT and SIGTERM while a study runs.

    Attributes
    ----------
    signum : int or None
        The first signal received, None while none has arrived.
    interruptible : bool
        Set by the runner while a replicate runs in this process: the first signal then
        raises StudyInterrupted at once instead of waiting for the replicate to end.

    Notes
    -----
    Outside the main thread signal handlers cannot be installed; the manager then does
    nothing and the default handlers stay.
    """

    def __init__(self) -> None:
        self.signum: int | None = None
        self.interruptible = False
        self._on_hard_stop: list[Callable[[], None]] = []
        self._old: dict[int, Any] = {}

    @property
    def stopped(self) -> bool:
        """True once a stop signal has arrived."""
        return self.signum is not None

    def on_hard_stop(self, fn: Callable[[], None]) -> None:
        """Call ``fn`` (e.g. kill the workers) before exiting on a second signal."""
        self._on_hard_stop.append(fn)

    def __enter__(self) -> StopSignals:
        if threading.current_thread() is threading.main_thread():
            for s in STOP_SIGNALS:
                self._old[s] = signal.signal(s, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        for s, h in self._old.items():
            signal.signal(s, h)
        self._old.clear()

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self.signum is not None:                 # second signal: stop at once
            for fn in self._on_hard_stop:
                try:
                    fn()
                except Exception:                   # exiting anyway
                    pass
            os.write(2, f"bayes-amb: {signal.Signals(signum).name} again: stopped at once; "
                     "finished replicates are saved (resume with --resume)\n".encode())
            os._exit(128 + signum)
        self.signum = signum
        if self.interruptible:
            self.interruptible = False
            raise StudyInterrupted(signum)


def kill_processes(procs: list[Any], grace_s: float = 3.0) -> None:
    """SIGTERM each multiprocessing Process, wait up to ``grace_s`` in all, then SIGKILL
    whatever is left, and reap them all."""
    for p in procs:
        if p.is_alive():
            p.terminate()
    t_end = time.monotonic() + grace_s
    for p in procs:
        p.join(max(0.0, t_end - time.monotonic()))
    for p in procs:
        if p.is_alive():
            p.kill()
            p.join(1.0)


def worker_init(study_pid: int | None = None) -> None:
    """Initializer of study worker processes: ignore SIGINT (the parent decides) and exit
    as soon as the process ``study_pid`` (the study's own process) has ended.

    The workers of a forkserver pool are children of the fork server, which itself stays
    alive while they run, so a parent-death signal would not fire when the study process is
    killed; a daemon thread watches the study process instead (a pidfd on Linux, else a
    poll every second).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # the workers are the parallelism: a batch's rows stay in its worker (threads.over_rows)
    os.environ.setdefault(POOL_VAR, "1")
    if study_pid is None:
        return
    try:
        fd = os.pidfd_open(study_pid)
    except (AttributeError, OSError):                # not Linux >= 5.3, or already gone
        fd = None
        if not _alive(study_pid):
            os._exit(1)

    def watch() -> None:
        if fd is not None:
            select.select([fd], [], [])              # readable once the process has exited
        else:
            while _alive(study_pid):
                time.sleep(1.0)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-study", daemon=True).start()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
