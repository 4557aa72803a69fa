"""identify's adequacy test, run beside identify's own fit.

The adequacy test (discrepancy/adequacy.assess_fit) reads only the recording, the names,
the priors and the seed: nothing of identify's fit. It runs beside identify from the start,
while identify finds its MAP and samples. Whether identify samples at all depends on the
verdict (a model that is not adequate is not sampled), so the sampler is started on
speculation and stopped at its next check once the verdict says the model is doubted.
Both computations are the same as run one after the other, and so are their results: only
the wall time changes.

Where it can, the test runs in a forked process: much of both computations is numpy on
small arrays, which holds the interpreter's lock, so as a second thread the two took turns
more than they shared two cores (on the posterior benchmark the pair took 6.9 s of wall
where the longer alone takes 4.5 s). A process shares nothing but the pipe its verdict
comes back on (pickled, a few MB, milliseconds). Elsewhere it is a thread, as before:
where fork is not the platform's way (macOS, Windows), inside a worker process (a study's
pool or a Dask worker, whose cores its siblings already use), or with
BAYES_AMB_ADEQUACY=thread. The process ignores Ctrl-C, is ended by close() (identify calls
it on every way out) and by the kernel when its parent dies; one that ends without a
verdict (killed) is replaced by the test run in the caller.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import sys
import warnings
from concurrent.futures import Future, ThreadPoolExecutor
from multiprocessing.connection import Connection
from typing import Any

from bayes_amb.discrepancy.adequacy import assess_fit
from bayes_amb.discrepancy.model_error import model_error
from bayes_amb.inference.doubted import within_band
from bayes_amb.inference.priors import Prior
from bayes_amb.io.recording import Recording
from bayes_amb.threads import POOL_VAR

BACKEND_ENV = "BAYES_AMB_ADEQUACY"
"""Environment variable: "thread" keeps the adequacy test in a thread of the caller."""


class Doubted(Exception):
    """Raised inside the sampler's progress check when the adequacy test has doubted the
    model: the speculative sample is dropped."""


def _assessed(recording: Recording, names: tuple[str, ...],
              priors: dict[str, Prior] | None, seed: int) -> tuple[Any, Any]:
    return assess_fit(recording, names, priors, seed=seed, band_hz="validity")


def forks() -> bool:
    """Whether the adequacy test may run in a forked process here (module docstring)."""
    return (sys.platform.startswith("linux")
            and os.environ.get(BACKEND_ENV, "").strip().lower() != "thread"
            and "fork" in multiprocessing.get_all_start_methods()
            and multiprocessing.parent_process() is None)


def _die_with(parent: int) -> None:
    """Have the kernel end this process when the thread that forked it ends (Linux
    PR_SET_PDEATHSIG): a parent killed before it could end its test leaves nothing
    running."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)   # 1: PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:                  # the parent ended before the call
        os._exit(1)


def _child(conn: Connection, parent: int, args: tuple[Any, ...]) -> None:
    """The forked process: the verdict, or the error, sent back pickled. An interrupt is
    the parent's to handle (it ends this process, or the kernel does when it dies)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _die_with(parent)
    # the fit beside it takes the other core: this one's batches stay in one thread
    # (threads.over_rows; with two each, identify on ROSS's test rig took 12 % longer)
    os.environ[POOL_VAR] = "1"
    # the process's own streams: a notebook's sys.stderr is a socket the kernel's threads
    # flush, and those threads are not in a forked process (a warning goes to fd 2)
    sys.stdout = sys.__stdout__ or sys.stdout
    sys.stderr = sys.__stderr__ or sys.stderr
    try:
        out: tuple[str, Any] = ("ok", _assessed(*args))
    except Exception as exc:  # every failure goes back to the caller
        out = ("error", exc)
    try:
        conn.send(out)
    except Exception as exc:  # an error that does not pickle
        conn.send(("error", RuntimeError(f"{type(out[1]).__name__}: {out[1]} "
                                         f"(not picklable: {exc})")))
    conn.close()


class PendingAdequacy:
    """The adequacy verdict for identify's band (doubted.within_band, from set_band), being
    computed. It starts before identify has built its likelihood, whose band it does not
    need until the verdict is read. Call close() when done with it (identify does, also on
    an error): a process still running is ended."""

    def __init__(self, recording: Recording, names: tuple[str, ...],
                 priors: dict[str, Prior] | None, seed: int):
        self._args = (recording, names, priors, seed)
        self._f_max_hz: float | None = None
        self._read: tuple[Any, Any] | None = None
        self._out: tuple[str, Any] | None = None
        self._future: Future | None = None
        self._proc: Any = None
        if forks():
            ctx = multiprocessing.get_context("fork")
            self._conn, child = ctx.Pipe(duplex=False)
            self._proc = ctx.Process(target=_child, args=(child, os.getpid(), self._args),
                                     daemon=True, name="bayes-amb-adequacy")
            with warnings.catch_warnings():   # Python >= 3.12 warns of fork beside the
                warnings.simplefilter("ignore", DeprecationWarning)  # BLAS's idle threads
                self._proc.start()
            child.close()
        else:
            pool = ThreadPoolExecutor(1, thread_name_prefix="bayes-amb-adequacy")
            self._future = pool.submit(_assessed, *self._args)
            pool.shutdown(wait=False)

    def set_band(self, f_max_hz: float) -> None:
        """identify's band: the verdict is read for the bins up to f_max_hz."""
        self._f_max_hz = float(f_max_hz)

    def _in_band(self, raw: tuple[Any, Any]) -> tuple[Any, Any]:
        """The whole-band verdict read for identify's band, once."""
        if self._read is None:
            if self._f_max_hz is None:
                raise RuntimeError("PendingAdequacy: set_band was not called")
            verdict, nominal = raw
            verdict = within_band(verdict, nominal, self._f_max_hz)
            if not verdict.adequate and nominal.model_error is None and not verdict.failed:
                # the test read its verdict for the model's validity band and left the
                # model error out; identify's band differs from it here: formed now
                nominal.model_error = model_error(nominal.like, nominal.x, nominal.p,
                                                  nominal.cov, nominal.names, robust=True)
            self._read = (verdict, nominal)
        return self._read

    def _done(self, wait: bool) -> bool:
        """Whether the outcome is in, as ("ok", (verdict, fit)) or ("error", exception):
        taken from the thread, or received from the process if it has come."""
        if self._out is not None:
            return True
        if self._future is not None:
            if wait or self._future.done():
                exc = self._future.exception()
                self._out = ("error", exc) if exc is not None else ("ok",
                                                                      self._future.result())
        elif wait or self._conn.poll():
            try:
                self._out = self._conn.recv()
            except EOFError:                 # ended without a verdict: run it here
                try:
                    self._out = ("ok", _assessed(*self._args))
                except Exception as exc:  # raised by result()
                    self._out = ("error", exc)
            self.close()
        return self._out is not None

    def doubted(self) -> bool:
        """True once the verdict is in and doubts the model (it carries a model error), or
        the test failed (its error is raised by result()); False while it runs."""
        if not self._done(wait=False):
            return False
        kind, value = self._out  # type: ignore[misc]
        return kind != "ok" or self._in_band(value)[1].model_error is not None

    def result(self) -> tuple[Any, Any]:
        """(verdict, nominal fit), waiting for them."""
        self._done(wait=True)
        kind, value = self._out  # type: ignore[misc]
        if kind != "ok":
            raise value
        return self._in_band(value)

    def close(self) -> None:
        """End the process if it still runs (its verdict no longer wanted)."""
        if self._proc is None:
            return
        if self._proc.is_alive() and self._out is None:
            self._proc.terminate()
        self._proc.join(timeout=5)
        self._conn.close()
        self._proc = None
