"""The first compile of the kernels says so (issue 28): after a plain ``pip install`` the
first command used to wait about 30 s in silence. numba raises ``numba:compile`` only on a
cache miss; the notice prints one line for the first bayes_amb function compiled."""

from __future__ import annotations

import io
import types

import pytest
from numba import njit
from numba.core import event

from bayes_amb import compile_notice


@pytest.fixture
def notice(monkeypatch):
    """A fresh notice writing to a buffer; the one an earlier CLI call in this process
    installed is set aside meanwhile."""
    old = compile_notice._state["listener"]
    if old is not None:
        event.unregister("numba:compile", old)
    monkeypatch.setattr(compile_notice, "_state", {"listener": None})
    buf = io.StringIO()
    assert compile_notice.install(buf)
    yield buf
    event.unregister("numba:compile", compile_notice._state["listener"])
    if old is not None:
        event.register("numba:compile", old)


def _fake_compile(module: str) -> None:
    """What numba's dispatcher does on a cache miss, without compiling anything."""
    disp = types.SimpleNamespace(py_func=types.SimpleNamespace(__module__=module))
    with event.trigger_event("numba:compile", data={"dispatcher": disp}):
        pass


def test_one_line_for_the_first_compile_of_ours(notice):
    _fake_compile("numpy.something")                 # another library's kernel: silent
    assert notice.getvalue() == ""
    _fake_compile("bayes_amb.inference.kernels")
    _fake_compile("bayes_amb.inference.eigen")       # still one line per process
    assert notice.getvalue() == compile_notice.MESSAGE + "\n"
    assert "compiling kernels once (about 30 s" in notice.getvalue()


def test_a_real_cache_miss_triggers_it(notice):
    """A tiny uncached njit function in a bayes_amb module: numba's own event fires."""
    code = compile("def f(x):\n    return x + 1\n", "<bayes_amb.fake>", "exec")
    ns = {"__name__": "bayes_amb.fake"}
    exec(code, ns)
    assert njit(ns["f"])(1) == 2
    assert notice.getvalue() == compile_notice.MESSAGE + "\n"


def test_install_is_idempotent(notice):
    listener = compile_notice._state["listener"]
    assert compile_notice.install() and compile_notice._state["listener"] is listener
