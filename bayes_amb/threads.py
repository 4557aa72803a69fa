"""BLAS/OpenMP thread control: small-matrix work runs single-threaded unless the user asks.

The fast paths of bayes_amb work on many small matrices (4 x 4 to 16 x 16, batches of
walkers). There, BLAS threads only add start-up and synchronisation cost, and on a loaded
machine they make the user's commands several times slower (issue 16: the paper's case took
66-80 s with OpenBLAS's default threads and 12.6 s with one). Parallelism comes from the
tool's own batching and worker pools instead.

Two levels of control:

* :func:`configure_process` runs once at CLI start, before numpy is imported where
  possible: it puts the thread count into ``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS``,
  ``MKL_NUM_THREADS`` (and friends) of ``os.environ`` unless the user set them, so the BLAS
  libraries start with it and worker processes inherit it.
* :func:`limited_threads` (a decorator) limits the BLAS pools around the library's hot
  entry points at run time (threadpoolctl), for users of the Python API.

The count is ``--threads N`` (CLI) or the environment variable ``BAYES_AMB_THREADS``,
default 1; ``0`` means "leave the BLAS libraries alone" (their own defaults or the user's
``OPENBLAS_NUM_THREADS``).
"""

from __future__ import annotations

import functools
import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from bayes_amb.errors import BayesAmbError

ENV_VAR = "BAYES_AMB_THREADS"
#: thread-count variables read by the BLAS/OpenMP runtimes numpy and scipy may load
BLAS_ENV_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
                 "BLIS_NUM_THREADS", "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")
DEFAULT_THREADS = 1


def parse_threads(value: str | int, source: str) -> int:
    """A thread count >= 0 from a string or int; BayesAmbError naming source otherwise.

    Examples
    --------
    >>> parse_threads("2", "BAYES_AMB_THREADS")
    2
    """
    try:
        n = int(value)
    except (TypeError, ValueError):
        n = -1
    if n < 0:
        raise BayesAmbError(f"{source}: expected a thread count >= 0 (0: the BLAS "
                            f"libraries' own default), got {value!r}")
    return n


def configured_threads() -> int:
    """The thread count in force: ``BAYES_AMB_THREADS`` if set, else 1 (0: no limit)."""
    value = os.environ.get(ENV_VAR, "").strip()
    return DEFAULT_THREADS if not value else parse_threads(value, ENV_VAR)


def configure_process(threads: int | None = None) -> int:
    """Set the process's BLAS/OpenMP thread variables; call before numpy is imported.

    Parameters
    ----------
    threads : int, optional
        Explicit count (the CLI's ``--threads``). It is written to ``BAYES_AMB_THREADS``
        and to every variable of BLAS_ENV_VARS, overriding them. Without it the count of
        :func:`configured_threads` fills only the variables the user left unset.

    Returns
    -------
    int
        The count in force (0: the libraries' defaults are kept).
    """
    explicit = threads is not None
    n = parse_threads(threads, "option --threads") if explicit else configured_threads()
    if explicit:
        os.environ[ENV_VAR] = str(n)
    if n == 0:
        return 0
    for var in BLAS_ENV_VARS:
        if explicit:
            os.environ[var] = str(n)
        else:
            os.environ.setdefault(var, str(n))
    _limit(n)                 # numpy may already be loaded: limit its pools at run time too
    return n


def _limit(n: int) -> Any:
    """Limit the BLAS/OpenMP pools loaded now to n threads; returns the limiter (its
    restore_original_limits() undoes it), None when numpy is not loaded yet.

    Costs about 0.3 ms (threadpoolctl inspects the loaded libraries each time): meant for
    entry points, not for inner loops.
    """
    import sys

    if "numpy" not in sys.modules:
        return None           # nothing loaded yet: the environment variables suffice
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=n)


def limited_threads[F: Callable[..., Any]](func: F) -> F:
    """Run func with the BLAS/OpenMP pools limited to :func:`configured_threads` threads.

    The previous limits are restored afterwards. With a count of 0 func runs untouched.
    """
    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        n = configured_threads()
        if n == 0:
            return func(*args, **kwargs)
        limiter = _limit(n)
        try:
            return func(*args, **kwargs)
        finally:
            if limiter is not None:
                limiter.restore_original_limits()

    return wrapper  # type: ignore[return-value]


POOL_VAR = "BAYES_AMB_POOL"
MAX_POOL = 8
"""At most this many threads in the tool's own pools (:func:`pool_threads`)."""


def pool_threads() -> int:
    """Threads for the tool's own pools of independent, GIL-releasing work (LAPACK on
    one posterior draw each: engineering/quantities.py and frf.py): the CPUs this process may run
    on, at most MAX_POOL; the count ``BAYES_AMB_POOL`` gives where it is set (0 or 1: no
    pool); 1 where the BLAS libraries may use threads of their own (a
    :func:`configured_threads` other than 1), which the pool would oversubscribe."""
    value = os.environ.get(POOL_VAR, "").strip()
    if value:
        return max(parse_threads(value, POOL_VAR), 1)
    if configured_threads() != 1:
        return 1
    try:
        cpus = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cpus = os.cpu_count() or 1
    return max(1, min(cpus, MAX_POOL))


ROW_THREAD_PREFIX = "bayes-amb-rows"
_ROW_POOL: tuple[int, int, ThreadPoolExecutor] | None = None     # (pid, threads, pool)


def row_pool() -> ThreadPoolExecutor | None:
    """The process's pool for splitting a batch of likelihood rows (:func:`over_rows`):
    :func:`pool_threads` threads, made on first use and again after a fork or a change of
    the count; None where the count is 1 or the caller is one of its own threads."""
    global _ROW_POOL
    n = pool_threads()
    if n <= 1 or threading.current_thread().name.startswith(ROW_THREAD_PREFIX):
        return None
    pid = os.getpid()
    if _ROW_POOL is None or _ROW_POOL[0] != pid or _ROW_POOL[1] != n:
        _ROW_POOL = (pid, n, ThreadPoolExecutor(n - 1, thread_name_prefix=ROW_THREAD_PREFIX))
    return _ROW_POOL[2]


def over_rows(fn: Callable[[int, int], Any], nb: int, min_rows: int = 2) -> None:
    """Call ``fn(lo, hi)`` on consecutive ranges of a batch of ``nb`` rows that together
    cover it: in parallel, one range per thread of :func:`row_pool` plus the calling
    thread, from ``min_rows`` rows on; as ``fn(0, nb)`` otherwise. For compiled kernels
    that release the GIL and compute each row alone, so that the result does not depend on
    the split (bit for bit). An exception of any range is raised here.

    Examples
    --------
    >>> seen = []
    >>> over_rows(lambda lo, hi: seen.append((lo, hi)), 5)
    >>> sorted(seen)[0][0], sorted(seen)[-1][1], sum(hi - lo for lo, hi in seen)
    (0, 5, 5)
    """
    pool = row_pool() if nb >= min_rows else None
    if pool is None:
        fn(0, nb)
        return
    k = min(_ROW_POOL[1] if _ROW_POOL else 1, nb)
    edges = [nb * i // k for i in range(k + 1)]
    futures = [pool.submit(fn, edges[i], edges[i + 1]) for i in range(1, k)]
    try:
        fn(edges[0], edges[1])
    finally:
        for f in futures:
            f.result()
