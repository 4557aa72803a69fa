"""The package's import graph (issue 31): no import circles, counting the imports inside
functions too, and the product never imports the tests or the studies."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "bayes_amb"


def _graph() -> dict[str, set[str]]:
    """Module -> the bayes_amb modules it imports (a package's __init__ is the package).
    A package's __init__ importing its own submodules is an edge: importing the package
    runs them, so a circle through a re-export is a circle. A submodule importing one of
    its own parent packages is not (Python has that package half-built already)."""
    mods: dict[str, set[str]] = {}
    for p in PACKAGE.rglob("*.py"):
        parts = p.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        deps: set[str] = set()
        for n in ast.walk(ast.parse(p.read_text())):
            if isinstance(n, ast.ImportFrom) and n.module:
                deps.add(n.module)
                deps.update(f"{n.module}.{a.name}" for a in n.names)
            elif isinstance(n, ast.Import):
                deps.update(a.name for a in n.names)
        mods[name] = deps
    return {m: {d for d in ds if d in mods and d != m and not m.startswith(d + ".")}
            for m, ds in mods.items()}


def _cycle(edges: dict[str, set[str]]) -> list[str] | None:
    """One import circle, or None (depth-first search, three colours)."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> list[str] | None:
        state[m] = 1
        stack.append(m)
        for d in sorted(edges[m]):
            if state.get(d) == 1:
                return [*stack[stack.index(d):], d]
            if d not in state:
                found = visit(d)
                if found:
                    return found
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(edges):
        if m not in state:
            found = visit(m)
            if found:
                return found
    return None


def test_no_import_circles():
    assert _cycle(_graph()) is None, " -> ".join(_cycle(_graph()) or [])


def test_a_circle_through_a_packages_init_counts(tmp_path, monkeypatch):
    """pkg/__init__ re-exports pkg.a; pkg.a imports other; other imports pkg: a circle."""
    pkg = tmp_path / "bayes_amb"
    (pkg / "pkg").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "pkg" / "__init__.py").write_text("from bayes_amb.pkg.a import f\n")
    (pkg / "pkg" / "a.py").write_text("from bayes_amb.other import g\n")
    (pkg / "other.py").write_text("def g():\n    from bayes_amb.pkg import f\n")
    monkeypatch.setitem(globals(), "PACKAGE", pkg)
    assert _cycle(_graph()) is not None


def test_the_search_finds_a_circle():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None


def test_the_product_imports_neither_tests_nor_studies():
    for p in PACKAGE.rglob("*.py"):
        for n in ast.walk(ast.parse(p.read_text())):
            names = ([n.module or ""] if isinstance(n, ast.ImportFrom)
                     else [a.name for a in n.names] if isinstance(n, ast.Import) else [])
            assert not any(x.split(".")[0] in ("tests", "studies", "benchmarks")
                           for x in names), p
