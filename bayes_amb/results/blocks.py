"""Typed blocks of the result files: a frozen dataclass per JSON object.

A :class:`Block` is a frozen dataclass whose fields are the keys of one JSON object of a
result file (``diagnosis.json``, ``summary.json``, ...). ``from_dict`` builds it from the
parsed JSON, converting nested objects by the fields' type hints; ``to_dict`` writes it
back. The round trip is exact:

- a field without a default is a required key (a missing one is a one-line error naming
  the file and the key path);
- a field with ``omit=True`` in its metadata is left out of the JSON when it is None (keys
  written only in some cases, e.g. an explanation's ``node_range``), unless the file it
  was read from had it as null;
- a field with ``runtime=True`` in its metadata is not in the file (what a result just
  computed carries beside its numbers, e.g. the fitted models);
- a field may carry its JSON key in its metadata when the key is not a Python name
  (``"from"``) or is taken by a method (``"summary"``);
- keys a block does not name (written by a newer version, or not modelled) are kept in
  ``extra`` and written back after the named ones.

Data-keyed maps (per parameter, per channel) are ``dict[str, X]``; schema keys are fields.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import sys
import types
import typing
from dataclasses import dataclass, field
from typing import Any, ClassVar, Self

from bayes_amb.errors import BayesAmbError


def omitted(key: str | None = None) -> Any:
    """A field whose key is left out of the JSON when its value is None (default None)."""
    return field(default=None, metadata={"omit": True, **({"key": key} if key else {})})


def runtime(**kw: Any) -> Any:
    """A field that is not written to the file (default None, not compared, not shown)."""
    return field(default=None, repr=False, compare=False, metadata={"runtime": True}, **kw)


def keyed(key: str, **kw: Any) -> Any:
    """A field written under JSON key ``key``."""
    return field(metadata={"key": key}, **kw)


block = dataclass(frozen=True, kw_only=True)
"""The decorator of a block: frozen, keyword-only (fields in the file's key order, with
and without defaults mixed)."""


@block
class Block:
    """A JSON object of a result file as a frozen dataclass (see the module docstring)."""

    extra: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)
    nulls: frozenset[str] = field(default=frozenset(), repr=False, compare=False)

    where: ClassVar[str] = ""     # the block's place in its file, for errors

    @classmethod
    def from_dict(cls, data: Any, where: str | None = None) -> Self:
        """The block from its parsed JSON object; ``where`` names it in errors
        (``file: key.path``)."""
        here = where or cls.where or cls.__name__
        if not isinstance(data, dict):
            raise BayesAmbError(f"{here}: expected a JSON object, got "
                                f"{type(data).__name__}")
        kwargs: dict[str, Any] = {}
        named = set()
        for f, key, tp in _schema(cls):
            named.add(key)
            if key in data:
                kwargs[f.name] = _decode(tp, data[key], f"{here}.{key}")
            elif _required(f):
                raise BayesAmbError(f"{here}: required key {key!r} missing")
        kwargs["extra"] = {k: v for k, v in data.items() if k not in named}
        kwargs["nulls"] = frozenset(k for k, v in data.items() if v is None)
        return cls(**kwargs)

    def to_dict(self) -> dict[str, Any]:
        """The block as a JSON-ready dict (nested blocks written as dicts)."""
        out: dict[str, Any] = {}
        for f, key, _ in _schema(type(self)):
            v = getattr(self, f.name)
            if v is None and f.metadata.get("omit") and key not in self.nulls:
                continue
            out[key] = encode(v)
        out.update(self.extra)
        return out


def encode(v: Any) -> Any:
    """Blocks, lists, tuples and dicts of them as plain JSON values."""
    if isinstance(v, Block):
        return v.to_dict()
    if isinstance(v, (list, tuple)):
        return [encode(x) for x in v]
    if isinstance(v, dict):
        return {k: encode(x) for k, x in v.items()}
    return v


def _required(f: dataclasses.Field) -> bool:
    return f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING


@functools.cache
def _schema(cls: type) -> tuple[tuple[dataclasses.Field, str, Any], ...]:
    """(field, JSON key, type) of the fields in the file, types resolved in the module of
    the class that declares them (runtime fields are not resolved: their types may be
    imported for type checking only)."""
    out = []
    for f in dataclasses.fields(cls):
        if f.name in ("extra", "nulls") or f.metadata.get("runtime"):
            continue
        owner = next(c for c in cls.__mro__ if f.name in inspect.get_annotations(c))
        tp = f.type if not isinstance(f.type, str) else eval(  # the annotation, in its module
            f.type, vars(sys.modules[owner.__module__]))
        out.append((f, f.metadata.get("key", f.name), tp))
    return tuple(out)


def _decode(tp: Any, v: Any, where: str) -> Any:
    if v is None or isinstance(v, Block):
        return v
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        blocks = [a for a in args if isinstance(a, type) and issubclass(a, Block)]
        if blocks and isinstance(v, dict):
            return blocks[0].from_dict(v, where)
        return _decode(args[0], v, where) if len(args) == 1 else v
    if origin is list:
        (arg,) = typing.get_args(tp)
        if not isinstance(v, list):
            raise BayesAmbError(f"{where}: expected a JSON array, got {type(v).__name__}")
        return [_decode(arg, x, f"{where}[{i}]") for i, x in enumerate(v)]
    if origin is dict:
        _, arg = typing.get_args(tp)
        if not isinstance(v, dict):
            raise BayesAmbError(f"{where}: expected a JSON object, got {type(v).__name__}")
        return {k: _decode(arg, x, f"{where}.{k}") for k, x in v.items()}
    if isinstance(tp, type) and issubclass(tp, Block):
        return tp.from_dict(v, where)
    return v
