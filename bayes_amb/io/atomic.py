"""File primitives: atomic writes, and deterministic, strict JSON.

Every file bayes_amb writes goes through these helpers: the data are written to a temporary
file in the target's directory, flushed and fsync'd, then ``os.replace``'d onto the target
(atomic on POSIX and Windows within one file system). If the writer raises, the temporary
file is deleted and the target is left untouched (a file is the old one or the complete new
one, never partial). JSON is written deterministically (:func:`json_text`) and read strictly
(:func:`parse_json_text`, :func:`read_json`: no NaN or infinity).
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["atomic_path", "json_text", "parse_json_text", "read_json", "write_bytes_atomic",
           "write_json_atomic", "write_text_atomic"]

_DEFAULT_UMASK = 0o022
_MAX_INT_DIGITS = 300  # larger JSON integers would overflow a float


def _current_umask() -> int:
    """The process umask, read without changing it (Linux), else the usual 022."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    return _DEFAULT_UMASK


def _fsync_dir(directory: Path) -> None:
    """Make a rename durable by fsync'ing its directory (POSIX only; best effort)."""
    if os.name != "posix":
        return
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; move it onto ``path`` only on success.

    The caller writes the complete file to the yielded path. On normal exit the file is
    fsync'd and ``os.replace``'d onto ``path`` (keeping the mode of an existing target,
    else the default mode under the umask). If the block raises, the temporary file is
    removed and ``path`` is unchanged.

    Parameters
    ----------
    path : str or path-like
        Final location. Its directory must exist.

    Yields
    ------
    pathlib.Path
        Temporary path in the same directory (hidden name ``.NAME.XXXX.tmp``).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> with atomic_path(d / "a.txt") as tmp:
    ...     _ = tmp.write_text("hello")
    >>> (d / "a.txt").read_text(), sorted(p.name for p in d.iterdir())
    ('hello', ['a.txt'])
    """
    target = Path(path)
    directory = target.parent
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp",
                                        dir=directory if str(directory) else ".")
    except OSError as exc:
        raise _naming(exc, target) from None
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        try:
            mode = os.stat(target).st_mode & 0o7777
        except FileNotFoundError:
            mode = 0o666 & ~_current_umask()
        os.chmod(tmp, mode)
        with open(tmp, "r+b") as f:
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        if tmp_name in (exc.filename, exc.filename2):
            raise _naming(exc, target) from exc
        raise
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_dir(directory)


def _naming(exc: OSError, target: Path) -> OSError:
    """The same OSError, naming the user's ``target`` instead of the temporary file (a
    missing or unwritable directory, a full disk, a target that is a directory)."""
    return type(exc)(exc.errno, exc.strerror, str(target))


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_path`).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "b.bin"
    >>> write_bytes_atomic(p, b"\\x00\\x01")
    >>> p.read_bytes()
    b'\\x00\\x01'
    """
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())


def write_text_atomic(path: str | os.PathLike[str], text: str, encoding: str = "utf-8") -> None:
    """Write ``text`` to ``path`` atomically, byte-exact (no newline translation).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "c.txt"
    >>> write_text_atomic(p, "line\\n")
    >>> p.read_bytes()
    b'line\\n'
    """
    write_bytes_atomic(path, text.encode(encoding))


def write_json_atomic(path: str | os.PathLike[str], obj: Any) -> None:
    """Write ``obj`` as deterministic JSON (:func:`json_text`) to ``path`` atomically."""
    write_text_atomic(path, json_text(obj))


def _json_scalar(obj: Any) -> str:
    if isinstance(obj, np.generic):
        obj = obj.item()
    if obj is None or isinstance(obj, (bool, int, float, str)):
        return json.dumps(obj, allow_nan=False, ensure_ascii=False)
    raise TypeError(f"cannot write {type(obj).__name__} {obj!r} to JSON")


def _json_block(obj: Any, level: int) -> str:
    if isinstance(obj, np.ndarray):
        obj = obj.tolist()
    pad, inner = "  " * level, "  " * (level + 1)
    if isinstance(obj, dict):
        if not obj:
            return "{}"
        items = []
        for k, v in obj.items():
            if not isinstance(k, str):
                raise TypeError(f"JSON object keys must be strings, got {k!r}")
            key = json.dumps(k, ensure_ascii=False)
            items.append(f"{inner}{key}: {_json_block(v, level + 1)}")
        return "{\n" + ",\n".join(items) + "\n" + pad + "}"
    if isinstance(obj, (list, tuple)):
        if all(not isinstance(v, (dict, list, tuple, np.ndarray)) for v in obj):
            return "[" + ", ".join(_json_scalar(v) for v in obj) + "]"
        return ("[\n" + ",\n".join(inner + _json_block(v, level + 1) for v in obj)
                + "\n" + pad + "]")
    return _json_scalar(obj)


def json_text(obj: Any) -> str:
    """Deterministic, human-readable JSON: 2-space indent, numeric rows on one line.

    Floats are written with ``repr`` (shortest round-trip form), so equal data give equal
    bytes. NaN and infinity are refused (ValueError); numpy arrays and scalars are accepted.

    Examples
    --------
    >>> print(json_text({"A": [[0.5, 0.0], [0.1, 0.25]], "n": 2}), end="")
    {
      "A": [
        [0.5, 0.0],
        [0.1, 0.25]
      ],
      "n": 2
    }
    """
    return _json_block(obj, 0) + "\n"


def _reject_constant(name: str) -> Any:
    raise ValueError(f"non-finite number {name} is not allowed")


def _finite_float(s: str) -> float:
    v = float(s)
    if not math.isfinite(v):
        raise ValueError(f"number {s} overflows a float")
    return v


def _bounded_int(s: str) -> int:
    if len(s.lstrip("-")) > _MAX_INT_DIGITS:
        raise ValueError(f"integer with {len(s)} digits is too large")
    return int(s)


def parse_json_text(text: str) -> Any:
    """Parse JSON strictly: NaN, Infinity and numbers that overflow a float raise ValueError.

    Examples
    --------
    >>> parse_json_text('{"dt": 1e-4}')
    {'dt': 0.0001}
    """
    try:
        return json.loads(text, parse_constant=_reject_constant, parse_float=_finite_float,
                          parse_int=_bounded_int)
    except RecursionError:
        raise ValueError("JSON nested too deeply") from None


def read_json(path: str | os.PathLike[str], where: str,
              error: type[Exception]) -> dict[str, Any]:
    """Read a file holding one strict JSON object (:func:`parse_json_text`).

    Failures raise ``error("<where>: field <file|json|top>: ...")``.

    Examples
    --------
    >>> read_json("/nonexistent.json", "controller file x", ValueError)
    Traceback (most recent call last):
    ...
    ValueError: controller file x: field <file>: not found
    """
    p = Path(path)
    if not p.is_file():
        raise error(f"{where}: field <file>: not found")
    try:
        data = parse_json_text(p.read_text(encoding="utf-8"))
    except UnicodeDecodeError as exc:
        raise error(f"{where}: field <json>: not UTF-8 ({exc.reason} at byte "
                    f"{exc.start})") from None
    except ValueError as exc:
        raise error(f"{where}: field <json>: not valid JSON ({exc})") from None
    if not isinstance(data, dict):
        raise error(f"{where}: field <top>: expected a JSON object, got {type(data).__name__}")
    return data


def write_netcdf_atomic(obj: Any, path: str | os.PathLike[str]) -> None:
    """Write an xarray Dataset or DataTree to NetCDF (h5netcdf) atomically."""
    with atomic_path(path) as tmp:
        obj.to_netcdf(tmp, engine="h5netcdf")
