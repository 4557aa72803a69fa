"""Typed, range-checked numeric options for the `bayes-amb` parsers.

Each factory returns an argparse ``type=`` callable. A bad value becomes argparse's one-line
error naming the option as typed, e.g. ``argument --dt: value -0.001 out of range: must be
> 0 and <= 0.01 s``. Negative numbers and scientific notation (``-1e-3``) are values, not
options (see :class:`bayes_amb.cli.main._OneLineParser`). Non-finite values (nan, inf) are
refused everywhere.

Examples
--------
>>> dt = real(lo=0, lo_open=True, hi=0.01, unit="s")
>>> dt("1e-3")
0.001
>>> dt("-1e-3")
Traceback (most recent call last):
...
argparse.ArgumentTypeError: value -0.001 out of range: must be > 0 and <= 0.01 s
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

__all__ = ["SEED_MAX", "integer", "range_text", "real", "seed"]

SEED_MAX = 2**32 - 1


def _fmt(v: float) -> str:
    """A bound as a short number: 0.01, 63000, 1e-07; integers in full (4294967295)."""
    return str(v) if isinstance(v, int) else f"{v:g}"


def range_text(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
               hi_open: bool = False, unit: str = "") -> str:
    """The allowed range in words: ``>= 4``, ``> 0 and <= 0.01 s``, ``0..63000 rpm``."""
    u = f" {unit}" if unit else ""
    if lo is not None and hi is not None and not lo_open and not hi_open:
        return f"in {_fmt(lo)}..{_fmt(hi)}{u}"
    parts = []
    if lo is not None:
        parts.append(f"{'>' if lo_open else '>='} {_fmt(lo)}")
    if hi is not None:
        parts.append(f"{'<' if hi_open else '<='} {_fmt(hi)}")
    return " and ".join(parts) + u


def _check(v: float, lo: float | None, hi: float | None, lo_open: bool, hi_open: bool,
           unit: str) -> None:
    bad = ((lo is not None and (v <= lo if lo_open else v < lo))
           or (hi is not None and (v >= hi if hi_open else v > hi)))
    if bad:
        raise argparse.ArgumentTypeError(
            f"value {_fmt(v)} out of range: must be "
            f"{range_text(lo, hi, lo_open=lo_open, hi_open=hi_open, unit=unit)}")


def real(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
         hi_open: bool = False, unit: str = "") -> Callable[[str], float]:
    """A finite float in the given range (open or closed at each end)."""
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"value {text!r} is not a number") from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"value {text!r} is not a finite number")
        _check(v, lo, hi, lo_open, hi_open, unit)
        return v
    parse.__name__ = "number"
    return parse


def integer(lo: int | None = None, hi: int | None = None, *, unit: str = ""
            ) -> Callable[[str], int]:
    """An integer (decimal digits, optional sign) in lo..hi."""
    def parse(text: str) -> int:
        try:
            v = int(text.strip(), 10)
        except ValueError:
            raise argparse.ArgumentTypeError(f"value {text!r} is not an integer") from None
        _check(v, lo, hi, False, False, unit)
        return v
    parse.__name__ = "integer"
    return parse


seed = integer(0, SEED_MAX)
"""A random seed: an integer in 0..4294967295."""
