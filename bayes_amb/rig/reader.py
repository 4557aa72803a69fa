"""Reading a rig file's tables: every error names the file and the field."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

from bayes_amb.errors import RigError


class FieldReader:
    """Reads fields from a parsed rig table and raises RigError naming file and field."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, field: str, msg: str) -> RigError:
        return RigError(f"rig file {self.source}: field {field}: {msg}")

    def table(self, data: dict, key: str, field: str, allowed: set[str] | None = None) -> dict:
        if key not in data:
            raise self.fail(field, "missing")
        t = data[key]
        if not isinstance(t, dict):
            raise self.fail(field, f"expected a table, got {t!r}")
        if allowed is not None:
            extra = sorted(set(t) - allowed)
            if extra:
                raise self.fail(f"{field}.{extra[0]}", f"unknown key (allowed: {sorted(allowed)})")
        return t

    def row(self, t: Any, field: str, allowed: set[str]) -> dict:
        """An entry of an array of tables (or of a table of tables): a table of the allowed
        keys."""
        if not isinstance(t, dict):
            raise self.fail(field, f"expected a table, got {t!r}")
        extra = sorted(set(t) - allowed)
        if extra:
            raise self.fail(f"{field}.{extra[0]}", f"unknown key (allowed: {sorted(allowed)})")
        return t

    def named_rows(self, raw: Any, key: str, allowed: set[str], prefix: str
                   ) -> Iterator[tuple[str, dict, str]]:
        """Each entry of an array of tables [[key]] as it is reached: its field name
        ('key[i]'), the table (of the allowed keys) and its name (``name``, else prefix1,
        prefix2, ...)."""
        if not isinstance(raw, list):
            raise self.fail(key, f"expected an array of tables, got {raw!r}")
        for i, t in enumerate(raw):
            f = f"{key}[{i}]"
            self.row(t, f, allowed)
            name = t.get("name", f"{prefix}{i + 1}")
            if not isinstance(name, str) or not name:
                raise self.fail(f"{f}.name", f"expected a non-empty string, got {name!r}")
            yield f, t, name

    def unique_names(self, names: list[str], key: str, noun: str) -> None:
        """Raise where two entries of [[key]] share a name."""
        if len(set(names)) != len(names):
            raise self.fail(key, f"{noun} names must be unique")

    def number(self, t: dict, key: str, field: str, *, positive: bool = True,
               nonneg: bool = False, upper: float | None = None) -> float:
        if key not in t:
            raise self.fail(field, "missing")
        v = t[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise self.fail(field, f"expected a finite number, got {v!r}")
        if positive and not nonneg and v <= 0:
            raise self.fail(field, f"expected a positive value, got {v!r}")
        if nonneg and v < 0:
            raise self.fail(field, f"expected a non-negative value, got {v!r}")
        if upper is not None and v >= upper:
            raise self.fail(field, f"expected a value below {upper}, got {v!r}")
        return float(v)

    def node(self, t: dict, key: str, field: str, n_nodes: int) -> int:
        if key not in t:
            raise self.fail(field, "missing")
        v = t[key]
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.fail(field, f"expected an integer node number, got {v!r}")
        if not 1 <= v <= n_nodes:
            raise self.fail(field, f"node {v} out of range 1..{n_nodes}")
        return v
