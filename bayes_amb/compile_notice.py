"""One line on stderr when the numba kernels compile, so that a first run is not a silent wait.

The kernels are ``@njit(cache=True)`` (bayes_amb.inference): compiled on first use and kept
in ``__pycache__``. ``make venv`` compiles them at install time (``python -m
bayes_amb.warmup``); after a plain ``pip install`` the first command that needs them
compiles them itself, about 30 s on a 2-core machine. :func:`install` registers a numba
listener for its ``numba:compile`` event, which numba raises only when a function is not
in the on-disk cache; the first such event for a bayes_amb function writes :data:`MESSAGE`
to stderr, once per process (study workers stay quiet). The CLI installs it at start-up;
from Python, call ``bayes_amb.compile_notice.install()`` yourself.
"""

from __future__ import annotations

import multiprocessing
import sys
from typing import Any, TextIO

__all__ = ["MESSAGE", "install"]

MESSAGE = "bayes-amb: compiling kernels once (about 30 s; cached for later runs) ..."

_state: dict[str, Any] = {"listener": None}


def _ours(event: Any) -> bool:
    data = getattr(event, "data", None) or {}
    func = getattr(data.get("dispatcher"), "py_func", None)
    return str(getattr(func, "__module__", "")).startswith("bayes_amb.")


def install(stream: TextIO | None = None) -> bool:
    """Register the listener (idempotent); ``stream`` default: sys.stderr at the time of the
    compile. Returns False if numba's event API is not available (nothing is printed then)."""
    if _state["listener"] is not None:
        return True
    try:
        from numba.core import event
    except ImportError:  # pragma: no cover - numba is a dependency; an API change is not
        return False

    class _Notice(event.Listener):
        def __init__(self) -> None:
            self.said = False

        def on_start(self, ev: Any) -> None:
            if self.said or not _ours(ev) or multiprocessing.parent_process() is not None:
                return
            self.said = True
            out = stream or sys.stderr
            out.write(MESSAGE + "\n")
            out.flush()

        def on_end(self, ev: Any) -> None:
            pass

    listener = _Notice()
    event.register("numba:compile", listener)
    _state["listener"] = listener
    return True
