"""Non-finite numbers in result files: written as null, listed, and restored on reading.

JSON has no NaN or infinity, and the strict writer (:func:`bayes_amb.io.atomic.json_text`)
refuses them. Input files (controller files, recording sidecars) must be finite and are
refused otherwise. A *result* (summary.json, diagnosis.json, answers, a command's --json
output) may legitimately hold one: a log Bayes factor of -inf when a model has zero
likelihood, an undefined sd when the Laplace covariance does not exist, a whiteness p-value
that underflows. Such a value is a condition to report, never a crash. The serialisation:

- each non-finite number is written as ``null``;
- the top-level object gets ``"non_finite": {"<JSON pointer>": "nan" | "inf" | "-inf"}``
  (RFC 6901 pointers, e.g. ``"/explanations/0/log_bf"``) and
  ``"non_finite_note"`` saying so in words;
- :func:`restore_non_finite` puts the floats back when the file is read.

Examples
--------
>>> text = result_json_text({"log_bf": float("-inf"), "sd": [1.0, float("nan")]})
>>> print(text, end="")
{
  "log_bf": null,
  "sd": [1.0, null],
  "non_finite": {
    "/log_bf": "-inf",
    "/sd/1": "nan"
  },
  "non_finite_note": "2 numbers were not finite (nan or +-inf): null here, see 'non_finite'"
}
>>> back = restore_non_finite(parse_json_text(text))
>>> back["log_bf"], back["sd"][1] != back["sd"][1], "non_finite" in back
(-inf, True, False)
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from bayes_amb.io.atomic import json_text, parse_json_text  # noqa: F401  (doctest)

__all__ = ["NON_FINITE_KEY", "plain", "read_result_json", "restore_non_finite",
           "result_json_line", "result_json_text", "split_non_finite"]

NON_FINITE_KEY = "non_finite"
NOTE_KEY = "non_finite_note"


def _escape(key: str) -> str:
    return key.replace("~", "~0").replace("/", "~1")


def _unescape(part: str) -> str:
    return part.replace("~1", "/").replace("~0", "~")


def _word(v: float) -> str:
    return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")


def split_non_finite(obj: Any, path: str = "") -> tuple[Any, dict[str, str]]:
    """A copy of ``obj`` (dicts, lists, tuples, numpy arrays and scalars, complex numbers
    as [re, im]) with every non-finite float replaced by None, and the JSON pointers of
    those values with "nan", "inf" or "-inf"."""
    found: dict[str, str] = {}

    def walk(o: Any, p: str) -> Any:
        if isinstance(o, np.ndarray):
            o = o.tolist()
        elif isinstance(o, np.generic):
            o = o.item()
        if isinstance(o, complex):
            o = [o.real, o.imag]
        if isinstance(o, dict):
            return {k: walk(v, f"{p}/{_escape(str(k))}") for k, v in o.items()}
        if isinstance(o, (list, tuple)):
            return [walk(v, f"{p}/{i}") for i, v in enumerate(o)]
        if isinstance(o, float) and not math.isfinite(o):
            found[p] = _word(o)
            return None
        return o

    return walk(obj, path), found


def _marked(obj: dict[str, Any]) -> dict[str, Any]:
    clean, found = split_non_finite({k: v for k, v in obj.items()
                                     if k not in (NON_FINITE_KEY, NOTE_KEY)})
    if found:
        clean[NON_FINITE_KEY] = found
        clean[NOTE_KEY] = (f"{len(found)} number{'s were' if len(found) > 1 else ' was'} "
                           f"not finite (nan or +-inf): null here, see '{NON_FINITE_KEY}'")
    return clean


def result_json_text(obj: dict[str, Any]) -> str:
    """Deterministic JSON of a result object (:func:`json_text`), non-finite numbers
    written as null and listed under ``non_finite`` (see the module docstring)."""
    return json_text(_marked(obj))


def result_json_line(obj: dict[str, Any]) -> str:
    """One line of JSON (keys sorted; a row of a .jsonl file), non-finite numbers written
    as null and listed under ``non_finite`` as in :func:`result_json_text`; no newline.

    >>> line = result_json_line({"b": float("nan"), "a": 1})
    >>> line[:47]
    '{"a": 1, "b": null, "non_finite": {"/b": "nan"}'
    >>> read_result_json(line)
    {'a': 1, 'b': nan}
    """
    return json.dumps(_marked(obj), sort_keys=True, allow_nan=False, ensure_ascii=False)


def plain(obj: Any, default: Any = None) -> Any:
    """``obj`` as JSON would give it back (keys as strings, tuples as lists, numpy scalars
    and anything ``default`` converts as plain values), non-finite floats kept: the form
    :func:`result_json_text` takes for objects json.dumps accepts but the strict writer
    does not (integer keys)."""
    def conv(o: Any) -> Any:
        if hasattr(o, "tolist"):
            return o.tolist()
        if default is not None:
            return default(o)
        raise TypeError(f"not JSON serialisable: {type(o).__name__}")

    return json.loads(json.dumps(obj, default=conv))


def read_result_json(text: str) -> Any:
    """Parse a result file written by :func:`result_json_text` or :func:`result_json_line`
    and put its non-finite numbers back (:func:`restore_non_finite`); older files with
    NaN/Infinity tokens parse too."""
    obj = json.loads(text)
    return restore_non_finite(obj) if isinstance(obj, dict) else obj


def restore_non_finite(obj: dict[str, Any]) -> dict[str, Any]:
    """Put back the non-finite floats a :func:`result_json_text` file lists (in place; the
    ``non_finite`` keys are removed). A listed pointer that does not resolve is ignored."""
    found = obj.pop(NON_FINITE_KEY, None)
    obj.pop(NOTE_KEY, None)
    if not isinstance(found, dict):
        return obj
    for pointer, word in found.items():
        if not (isinstance(pointer, str) and pointer.startswith("/")
                and word in ("nan", "inf", "-inf")):
            continue
        parts = [_unescape(p) for p in pointer[1:].split("/")]
        node: Any = obj
        try:
            for part in parts[:-1]:
                node = node[int(part)] if isinstance(node, list) else node[part]
            last = parts[-1]
            if isinstance(node, list):
                if node[int(last)] is None:
                    node[int(last)] = float(word)
            elif isinstance(node, dict) and node.get(last, 0) is None:
                node[last] = float(word)
        except (KeyError, IndexError, ValueError, TypeError):
            continue
    return obj
