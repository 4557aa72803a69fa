"""The channel map: a TOML file saying which DAQ channel is which signal, in which unit.

Example (a dSPACE .mat file, positions in volts, currents as amplifier set-points)::

    [source]
    format = "auto"              # or mat, mat73, tdms, hdf5, csv

    [time]
    column = "time"              # a time column in s, or:
    # sample_rate_hz = 10000.0   # (both: they must agree to 1e-4)
    start_s = 0.0                # trim: keep start_s <= t - t[0] < stop_s
    stop_s = 2.0
    decimate = 1                 # integer factor (anti-alias filter, zero phase)

    [recording]
    rig = "reference"            # or a rig TOML file
    speed_rpm = 31500.0
    controller = "controller.json"   # the controller that ran (bayes-amb controller file),
                                     # or a MATLAB .mat (see below)
    notes = "run 17, rig hall B"

    [channels.y_Ax]
    source = "AMB1_X_pos"
    unit = "V"
    sensitivity = 8000.0         # V/m (8 V/mm probe)
    sign = -1                    # the probe looks the other way
    offset = 0.12                # V, subtracted before scaling (or remove_offset = true)

    [channels.u_Ax]
    source = "I_ref_1"
    unit = "V"
    gain = 0.5                   # A/V (amplifier transconductance)

Targets: ``y_*`` and ``u_*`` for all four channels (Ax, Ay, Bx, By), plus at least one
complete excitation group ``eta_*``, ``r2_*`` or ``r1_*``. ``u_*`` must be the current at
the plant input *including* an injected ``r2``: u = K(y + r1, eta) + r2 (the convention of
:mod:`bayes_amb.io.recording`). Map ``u_*`` to the signal after the excitation was added
(the amplifier reference); if your DAQ logged only the controller output, add the
excitation to it before the import. Conversion to SI::

    value = sign * factor(unit) * (raw - offset)

with ``factor``: displacements (``y``, ``r1``; SI m) ``m`` 1, ``mm`` 1e-3, ``um`` 1e-6,
``V`` 1/sensitivity, ``mV`` 1e-3/sensitivity; currents (``u``, ``eta``, ``r2``; SI A)
``A`` 1, ``mA`` 1e-3, ``V`` gain, ``mV`` 1e-3 gain. ``remove_offset = true`` subtracts
the mean of the trimmed record instead of a given ``offset``. Relative paths are relative
to the map file's folder.

A controller given as a MATLAB .mat (state space or per-axis transfer functions, see
:mod:`bayes_amb.io.controller_import`) is imported at the recording's sample time, with
``controller_method`` (``"tustin"``, default, or ``"zoh"``), ``controller_prewarp_hz``
and ``controller_feedback`` (``"negative"``, default, or ``"positive"``) in
``[recording]``, and checked on the rig at ``speed_rpm``.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bayes_amb.errors import DataImportError
from bayes_amb.io.controller_file import is_finite_number, short_repr
from bayes_amb.io.daq import SOURCE_FORMATS
from bayes_amb.io.recording import EXCITATION_GROUPS
from bayes_amb.rig import CHANNELS
from bayes_amb.tomlfile import read_toml

__all__ = ["SI_UNIT", "TARGETS", "ChannelMap", "ChannelSpec", "TimeBase",
           "channel_map_from_dict", "load_channel_map", "map_to_toml"]

SI_UNIT = {"y": "m", "r1": "m", "u": "A", "eta": "A", "r2": "A"}
TARGETS = tuple(f"{g}_{c}" for g in ("y", "u", *EXCITATION_GROUPS) for c in CHANNELS)
_LENGTH = {"m": 1.0, "mm": 1e-3, "um": 1e-6}
_CURRENT = {"A": 1.0, "mA": 1e-3}
_VOLT = {"V": 1.0, "mV": 1e-3}
_TOP = {"source", "time", "recording", "channels"}
_SOURCE_KEYS = {"format"}
_TIME_KEYS = {"column", "sample_rate_hz", "start_s", "stop_s", "decimate"}
_REC_KEYS = {"rig", "speed_rpm", "controller", "controller_method", "controller_prewarp_hz",
             "controller_feedback", "notes"}
_CHANNEL_KEYS = {"source", "unit", "sensitivity", "gain", "sign", "offset", "remove_offset"}
MAX_DECIMATE = 1000


@dataclass(frozen=True)
class ChannelSpec:
    """One mapped channel: ``target`` (e.g. ``y_Ax``) read from ``source`` in ``unit``.

    ``factor`` is the SI value of one source unit, sign included (m or A per unit);
    ``offset`` is in source units; ``remove_offset`` subtracts the record's mean instead.
    """

    target: str
    source: str
    unit: str
    factor: float
    offset: float = 0.0
    remove_offset: bool = False
    sensitivity: float | None = None
    gain: float | None = None
    sign: int = 1


@dataclass(frozen=True)
class TimeBase:
    """Time column name or sample rate (Hz), trimming (s from the first sample), decimation."""

    column: str | None = None
    sample_rate_hz: float | None = None
    start_s: float | None = None
    stop_s: float | None = None
    decimate: int = 1


@dataclass(frozen=True, eq=False)
class ChannelMap:
    """A validated channel map (see the module docstring for the file form).

    ``channels`` maps each target to its :class:`ChannelSpec`; ``groups`` are the excitation
    groups present; ``rig`` and ``controller`` are names or resolved paths; ``raw`` is the
    parsed TOML (stored in the recording's provenance); ``source`` the map's file name.
    """

    channels: dict[str, ChannelSpec]
    groups: tuple[str, ...]
    time: TimeBase
    format: str = "auto"
    rig: str = "reference"
    speed_rpm: float = 0.0
    controller: str | None = None
    controller_options: dict[str, Any] | None = None
    notes: str = ""
    raw: dict[str, Any] | None = None
    source: str = "<dict>"


class _Reader:
    def __init__(self, source: str):
        self.source = source

    def fail(self, fld: str, msg: str) -> DataImportError:
        return DataImportError(f"channel map {self.source}: {fld}: {msg}")

    def table(self, data: dict, key: str, allowed: set[str], required: bool = False) -> dict:
        t = data.get(key, None)
        if t is None:
            if required:
                raise self.fail(f"field [{key}]", "missing table")
            return {}
        if not isinstance(t, dict):
            raise self.fail(f"field {key}", f"expected a table, got {short_repr(t)}")
        for k in t:
            if k not in allowed:
                raise self.fail(f"field {key}.{k}", f"unknown key (allowed: {sorted(allowed)})")
        return t

    def number(self, t: dict, key: str, fld: str, *, positive: bool = False,
               nonneg: bool = False) -> float | None:
        if key not in t:
            return None
        v = t[key]
        if not is_finite_number(v) or (positive and v <= 0) or (nonneg and v < 0):
            need = "a positive number" if positive else ("a number >= 0" if nonneg
                                                         else "a finite number")
            raise self.fail(fld, f"expected {need}, got {short_repr(v)}")
        return float(v)

    def string(self, t: dict, key: str, fld: str) -> str | None:
        if key not in t:
            return None
        v = t[key]
        if not isinstance(v, str) or not v:
            raise self.fail(fld, f"expected a non-empty string, got {short_repr(v)}")
        return v


def _unit_factor(r: _Reader, target: str, c: dict) -> tuple[float, float | None, float | None]:
    """SI per source unit (without sign), and the sensitivity/gain used."""
    group = target.split("_")[0]
    si = SI_UNIT[group]
    fld = f"channel {target}"
    unit = c.get("unit", si)
    if not isinstance(unit, str):
        raise r.fail(fld, f"field unit: expected a string, got {short_repr(unit)}")
    sens = r.number(c, "sensitivity", f"{fld}: field sensitivity", positive=True)
    gain = r.number(c, "gain", f"{fld}: field gain", positive=True)
    direct = _LENGTH if si == "m" else _CURRENT
    allowed = f"{', '.join(direct)}, V, mV"
    if si == "m" and gain is not None:
        raise r.fail(fld, f"field gain: a displacement ({target}, m) is scaled by a "
                          "sensitivity in V/m, not an amplifier gain")
    if si == "A" and sens is not None:
        raise r.fail(fld, f"field sensitivity: a current ({target}, A) is scaled by an "
                          "amplifier gain in A/V, not a sensor sensitivity")
    if unit in direct:
        if sens is not None or gain is not None:
            raise r.fail(fld, f"unit {unit!r} is already {si}-based; sensitivity/gain apply "
                              "only to V or mV")
        return direct[unit], None, None
    if unit in _VOLT:
        if si == "m":
            if sens is None:
                raise r.fail(fld, f"unit {unit!r} cannot be converted to m without "
                                  "sensitivity (V/m)")
            return _VOLT[unit] / sens, sens, None
        if gain is None:
            raise r.fail(fld, f"unit {unit!r} cannot be converted to A without gain (A/V)")
        return _VOLT[unit] * gain, None, gain
    raise r.fail(fld, f"unit {short_repr(unit)} cannot be converted to {si} (allowed: "
                      f"{allowed})")


def channel_map_from_dict(data: Any, source: str = "<dict>",
                          base_dir: str | os.PathLike[str] | None = None) -> ChannelMap:
    """Validate a parsed channel map; relative rig/controller paths resolve against base_dir.

    Raises
    ------
    DataImportError
        ``channel map FILE: channel y_Ax: unit 'A' cannot be converted to m (...)``, etc.

    Examples
    --------
    >>> chans = {f"{g}_{c}": {"source": f"{g}{c}", "unit": "V", "sensitivity": 8000.0}
    ...          if g == "y" else {"source": f"{g}{c}", "unit": "mA"}
    ...          for g in ("y", "u", "r2") for c in ("Ax", "Ay", "Bx", "By")}
    >>> m = channel_map_from_dict({"time": {"sample_rate_hz": 1000.0},
    ...     "recording": {"controller": "k.json", "speed_rpm": 0.0}, "channels": chans})
    >>> m.groups, m.channels["y_Ax"].factor, m.channels["u_By"].factor
    (('r2',), 0.000125, 0.001)
    """
    r = _Reader(source)
    if not isinstance(data, dict):
        raise r.fail("field <top>", f"expected a table, got {short_repr(data)}")
    for k in data:
        if k not in _TOP:
            raise r.fail(f"field {k}", f"unknown table (allowed: {sorted(_TOP)})")
    fmt = r.string(r.table(data, "source", _SOURCE_KEYS), "format", "field source.format")
    fmt = fmt or "auto"
    if fmt not in ("auto", *SOURCE_FORMATS):
        raise r.fail("field source.format", f"expected one of {['auto', *SOURCE_FORMATS]}, "
                                            f"got {fmt!r}")
    tt = r.table(data, "time", _TIME_KEYS, required=True)
    column = r.string(tt, "column", "field time.column")
    rate = r.number(tt, "sample_rate_hz", "field time.sample_rate_hz", positive=True)
    if column is None and rate is None and fmt not in ("tdms", "auto"):
        raise r.fail("field time", "give column (a time channel in s) or sample_rate_hz")
    start = r.number(tt, "start_s", "field time.start_s", nonneg=True)
    stop = r.number(tt, "stop_s", "field time.stop_s", positive=True)
    if start is not None and stop is not None and stop <= start:
        raise r.fail("field time.stop_s", f"expected stop_s > start_s = {start!r}, got {stop!r}")
    q = tt.get("decimate", 1)
    if isinstance(q, bool) or not isinstance(q, int) or not 1 <= q <= MAX_DECIMATE:
        raise r.fail("field time.decimate", f"expected an integer 1..{MAX_DECIMATE}, got "
                                            f"{short_repr(q)}")
    rec = r.table(data, "recording", _REC_KEYS, required=True)
    base = Path(base_dir) if base_dir is not None else None

    def resolve(v: str | None) -> str | None:
        if v is None or v == "reference" or base is None or Path(v).is_absolute():
            return v
        return str(base / v)

    rig = resolve(r.string(rec, "rig", "field recording.rig")) or "reference"
    speed = r.number(rec, "speed_rpm", "field recording.speed_rpm", nonneg=True)
    if speed is None:
        raise r.fail("field recording.speed_rpm", "missing (the rotor speed during the "
                                                   "record, rpm)")
    ctrl = resolve(r.string(rec, "controller", "field recording.controller"))
    copts: dict[str, Any] = {}
    for key, allowed in (("controller_method", ("tustin", "zoh")),
                         ("controller_feedback", ("negative", "positive"))):
        if key in rec:
            if rec[key] not in allowed:
                raise r.fail(f"field recording.{key}", f"expected one of {list(allowed)}, got "
                                                      f"{short_repr(rec[key])}")
            copts[key.removeprefix("controller_")] = rec[key]
    pre = r.number(rec, "controller_prewarp_hz", "field recording.controller_prewarp_hz",
                   positive=True)
    if pre is not None:
        copts["prewarp_hz"] = pre
    if copts and (ctrl is None or not ctrl.lower().endswith(".mat")):
        raise r.fail(f"field recording.controller_{next(iter(copts))}", "applies only to a "
                     "controller given as a MATLAB .mat file")
    notes = rec.get("notes", "")
    if not isinstance(notes, str):
        raise r.fail("field recording.notes", f"expected a string, got {short_repr(notes)}")
    ch = data.get("channels")
    if not isinstance(ch, dict) or not ch:
        raise r.fail("field [channels]", f"expected a table of channels, got {short_repr(ch)}")
    specs: dict[str, ChannelSpec] = {}
    for target, c in ch.items():
        if target not in TARGETS:
            raise r.fail(f"channel {target}", f"unknown target (allowed: y_*, u_*, eta_*, "
                                              f"r2_*, r1_*; * in {'/'.join(CHANNELS)})")
        c = r.table(ch, target, _CHANNEL_KEYS)
        fld = f"channel {target}"
        src = r.string(c, "source", f"{fld}: field source")
        if src is None:
            raise r.fail(fld, "field source: missing (the channel's name in the file)")
        factor, sens, gain = _unit_factor(r, target, c)
        sign = c.get("sign", 1)
        if isinstance(sign, bool) or sign not in (1, -1):
            raise r.fail(fld, f"field sign: expected 1 or -1, got {short_repr(sign)}")
        offset = r.number(c, "offset", f"{fld}: field offset") or 0.0
        remove = c.get("remove_offset", False)
        if not isinstance(remove, bool):
            raise r.fail(fld, f"field remove_offset: expected true or false, got "
                              f"{short_repr(remove)}")
        if remove and "offset" in c:
            raise r.fail(fld, "give offset or remove_offset = true, not both")
        specs[target] = ChannelSpec(target=target, source=src, unit=str(c.get("unit", "")) or
                                    SI_UNIT[target.split("_")[0]], factor=int(sign) * factor,
                                    offset=offset, remove_offset=remove, sensitivity=sens,
                                    gain=gain, sign=int(sign))
    groups = []
    for g in ("y", "u", *EXCITATION_GROUPS):
        have = [c for c in CHANNELS if f"{g}_{c}" in specs]
        if (have and len(have) < len(CHANNELS)) or (not have and g in ("y", "u")):
            missing = next(f"{g}_{c}" for c in CHANNELS if f"{g}_{c}" not in specs)
            raise r.fail(f"channel {missing}", "missing (every group needs all of "
                                               f"{'/'.join(CHANNELS)})")
        if have and g in EXCITATION_GROUPS:
            groups.append(g)
    if not groups:
        raise r.fail("channel eta_Ax", "missing: map one excitation group (eta_*, r2_* or "
                                       "r1_*), the signal injected during the test")
    return ChannelMap(channels=specs, groups=tuple(groups), format=fmt,
                      time=TimeBase(column=column, sample_rate_hz=rate, start_s=start,
                                    stop_s=stop, decimate=q),
                      rig=rig, speed_rpm=speed, controller=ctrl, controller_options=copts,
                      notes=notes,
                      raw=data, source=source)


def load_channel_map(path: str | os.PathLike[str]) -> ChannelMap:
    """Read and validate a channel-map TOML file (DataImportError naming file and field)."""
    p = Path(path)
    return channel_map_from_dict(read_toml(p, "channel map", DataImportError), str(p),
                                 base_dir=p.parent)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("nan" if v != v else
                                                 ("inf" if v > 0 else "-inf"))
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} as a TOML value")


def map_to_toml(data: dict[str, Any]) -> str:
    """TOML text of a channel-map dict (tables of scalars, and ``channels`` of tables).

    Examples
    --------
    >>> print(map_to_toml({"time": {"sample_rate_hz": 1000.0},
    ...                    "channels": {"y_Ax": {"source": "X1", "sign": -1}}}))
    [time]
    sample_rate_hz = 1000.0
    <BLANKLINE>
    [channels.y_Ax]
    source = "X1"
    sign = -1
    <BLANKLINE>
    """
    out = []
    for key, table in data.items():
        if key == "channels" and isinstance(table, dict):
            for name, c in table.items():
                out.append(f"[channels.{name}]")
                out += [f"{k} = {_toml_value(v)}" for k, v in c.items()]
                out.append("")
        else:
            out.append(f"[{key}]")
            out += [f"{k} = {_toml_value(v)}" for k, v in table.items()]
            out.append("")
    return "\n".join(out)
