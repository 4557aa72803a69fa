"""The documentation's sources hold together without building the site (`make docs`
builds it, with mkdocs --strict and the tutorials executed): every relative link of the
README and of docs/ resolves, every page of the site's navigation exists and every page is
in it, every object the API reference names imports, and the home page is the README."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
LINK = re.compile(r"\[([^\]]*)\]\(([^)\s]+)\)")


def _pages() -> list[Path]:
    return [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]


@pytest.mark.parametrize("page", _pages(), ids=lambda p: p.name)
def test_every_relative_link_resolves(page):
    broken = [m.group(2) for m in LINK.finditer(page.read_text(encoding="utf-8"))
              if "://" not in m.group(2) and m.group(2).split("#")[0]
              and not (page.parent / m.group(2).split("#")[0]).exists()]
    assert not broken, f"{page.name}: {broken}"


def _nav() -> list[str]:
    text = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    nav = text[text.index("nav:"):text.index("plugins:")]
    return re.findall(r":\s*([\w/]+\.(?:md|ipynb))\s*$", nav, flags=re.M)


def test_the_navigation_holds_every_page_and_no_missing_one():
    nav = _nav()
    assert len(nav) == len(set(nav))
    have = ({p.name for p in DOCS.glob("*.md")} | {"index.md"}
            | {f"tutorials/{p.name}" for p in DOCS.glob("tutorials/*.ipynb")})
    assert set(nav) - have == set(), set(nav) - have
    assert have - set(nav) == set(), have - set(nav)


def test_the_tutorials_are_notebooks_without_outputs():
    """They are executed when the site is built (mkdocs-jupyter), so none is stored run."""
    import json

    books = sorted(DOCS.glob("tutorials/*.ipynb"))
    assert len(books) >= 3
    for b in books:
        nb = json.loads(b.read_text(encoding="utf-8"))
        code = [c for c in nb["cells"] if c["cell_type"] == "code"]
        assert code and all(not c["outputs"] for c in code), b.name
        lines = "\n".join("".join(c["source"]) for c in code).splitlines()
        compile("\n".join(x for x in lines if not x.startswith("%")), str(b), "exec")


def test_every_object_of_the_api_reference_imports():
    names = re.findall(r"^::: ([\w.]+)\s*$", (DOCS / "api.md").read_text(), flags=re.M)
    assert len(names) >= 10
    for name in names:
        module, _, attr = name.rpartition(".")
        try:
            importlib.import_module(name)
        except ModuleNotFoundError:
            assert hasattr(importlib.import_module(module), attr), name


def test_the_home_page_is_the_readme_and_the_readme_is_short():
    import sys

    sys.path.insert(0, str(ROOT / "tools"))
    try:
        from readme_to_index import index_text
    finally:
        sys.path.pop(0)
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(readme.splitlines()) <= 300
    index = index_text(readme)
    assert "](docs/" not in index and "(docs/figures/diagnosis_location.png)" not in index
    for m in LINK.finditer(index):
        target = m.group(2).split("#")[0]
        assert "://" in target or (DOCS / target).exists(), target
    assert not re.search(r"\bissue \d+", readme, flags=re.I)      # no history in the README


@pytest.mark.parametrize("page", _pages(), ids=lambda p: p.name)
def test_no_inline_command_is_continued_by_a_backslash(page):
    """An inline `...` span that breaks its line with a backslash is not a command a
    reader can paste (nor tools/run_guide_commands.py run): the escaped line end became
    an escaped space, and runs/nl59's --kinds lost its third kind that way. Such a
    command belongs in a code block."""
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
    spans = text.split("`")[1::2]
    broken = [s[:80] for s in spans if "\\\n" in s]
    assert not broken, f"{page.name}: {broken}"
