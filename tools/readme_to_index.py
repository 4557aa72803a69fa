"""Write docs/index.md, the documentation site's home page, from README.md: the same text,
with links into docs/ made relative to docs/, and files of the repository outside docs/
(which the site does not hold) named in code (`make docs` runs it before mkdocs)."""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LINK = re.compile(r"\[([^\]]*)\]\(([^)\s]+)\)")


def index_text(readme: str) -> str:
    """The README with its relative links rewritten for a page inside docs/."""

    def fix(m: re.Match) -> str:
        text, target = m.group(1), m.group(2)
        if "://" in target:
            return m.group(0)
        if target.startswith("docs/"):
            return f"[{text}]({target[len('docs/'):]})"
        return text if text == target else f"{text} (`{target}`)"   # not in the site
    return LINK.sub(fix, readme)


def main() -> int:
    out = ROOT / "docs" / "index.md"
    out.write_text(index_text((ROOT / "README.md").read_text(encoding="utf-8")),
                   encoding="utf-8")
    sys.stdout.write(f"wrote {out.relative_to(ROOT)}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
