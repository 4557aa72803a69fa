"""Reading TOML input files (rig, prior and study files) with one-line errors."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from bayes_amb.errors import BayesAmbError


def read_toml(path: str | Path, what: str, error: type[BayesAmbError]) -> dict[str, Any]:
    """Parse a TOML file; a missing file or invalid TOML raises ``error`` naming the file.

    Examples
    --------
    >>> from bayes_amb.errors import RigError
    >>> read_toml("/no/such.toml", "rig file", RigError)
    Traceback (most recent call last):
    ...
    bayes_amb.errors.RigError: rig file /no/such.toml: field <file>: not found
    """
    p = Path(path)
    if not p.is_file():
        raise error(f"{what} {p}: field <file>: not found")
    try:
        return tomllib.loads(p.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise error(f"{what} {p}: field <toml>: not valid TOML ({exc})") from None
