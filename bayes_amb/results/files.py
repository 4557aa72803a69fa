"""Reading and writing the result files: one-line errors naming the file, atomic writes."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from bayes_amb.errors import ResultError


def read_result(path: Path) -> dict[str, Any]:
    """A result file's JSON object, its non-finite numbers put back."""
    from bayes_amb.io.nonfinite import restore_non_finite

    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ResultError(f"{path}: not found") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ResultError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(data, dict):
        raise ResultError(f"{path}: expected a JSON object, got {type(data).__name__}")
    return restore_non_finite(data)


def require_format(path: Path, data: dict[str, Any], expected: str) -> None:
    """Refuse a file of another kind or a newer major version than this package reads."""
    got = data.get("format")
    if got != expected:
        raise ResultError(f"{path}: field format: expected {expected!r}, got {got!r}")


def read_block(cls: Any, path: Path, expected: str) -> Any:
    """The block ``cls`` a result file holds: read (:func:`read_result`), its format
    checked, older files brought up to date by ``cls.upgrade`` when it has one."""
    data = read_result(path)
    require_format(path, data, expected)
    return cls.from_dict(getattr(cls, "upgrade", lambda d: d)(data), str(path))


POSTERIOR_GROUPS = ("posterior", "observed_data", "constant_data")
"""The groups of one record's posterior.nc (identify); a joint one (several recordings)
has posterior and sample_stats."""


def read_posterior(path: Path, groups: tuple[str, ...] = POSTERIOR_GROUPS) -> Any:
    """An ArviZ NetCDF posterior (posterior.nc) with ``groups``, loaded."""
    import arviz as az

    try:
        dt = az.from_netcdf(path)
    except (OSError, ValueError) as exc:
        raise ResultError(f"{path}: cannot be read as ArviZ NetCDF ({exc})") from None
    for group in groups:
        if group not in dt.children:
            raise ResultError(f"{path}: group {group}: missing")
    return dt.load()


def read_rows(path: Path) -> list[dict[str, Any]]:
    """Rows of a .jsonl file (a study's results.jsonl); a torn last line (killed
    mid-write) is ignored; non-finite numbers put back."""
    from bayes_amb.io.nonfinite import read_result_json

    if not path.is_file():
        return []
    rows = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            rows.append(read_result_json(line))
        except json.JSONDecodeError:
            continue
    return rows


def write_result(path: Path, block: Any) -> None:
    """Write a result block's JSON atomically (non-finite numbers as null, listed)."""
    from bayes_amb.io.atomic import write_text_atomic
    from bayes_amb.io.nonfinite import result_json_text

    write_text_atomic(path, result_json_text(block.to_dict()))
