"""Readers of the files data-acquisition systems write: .mat (v5 and v7.3), TDMS, HDF5, CSV.

Each reader returns the requested channels as 1-D float arrays, by the names the rig
engineer gave them. How a channel is named in each format:

- ``mat`` (MATLAB v4/v5/v7, read with :func:`scipy.io.loadmat`): a variable name, or a
  dotted path into a struct (``data.AMB1_X_pos``); the variable must be a vector
  (n x 1 or 1 x n).
- ``mat73`` (MATLAB v7.3, HDF5 inside, read with h5py): the same names; ``.`` and ``/``
  both separate struct levels. MATLAB stores arrays transposed (an n x 1 vector is an
  HDF5 dataset of shape (1, n)); a vector is read the same either way.
- ``tdms`` (National Instruments, read with npTDMS): ``group/channel``. A channel's
  ``wf_increment`` property, when present, gives its sample interval.
- ``hdf5``: a dataset path (``/daq/AMB1_X_pos``); the dataset must be a vector.
- ``csv``: a column name of the header row (any names; cells any form ``float`` reads).

``format = "auto"`` picks by suffix: ``.mat`` (v7.3 when the file is HDF5), ``.tdms``,
``.h5``/``.hdf5``/``.he5``, ``.csv``/``.txt``.
"""

from __future__ import annotations

import csv
import hashlib
import logging
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bayes_amb.errors import DataImportError
from bayes_amb.io.controller_file import short_repr

__all__ = ["SOURCE_FORMATS", "SourceData", "detect_format", "file_sha256", "read_channels"]

SOURCE_FORMATS = ("mat", "mat73", "tdms", "hdf5", "csv")
_SUFFIX = {".mat": "mat", ".tdms": "tdms", ".h5": "hdf5", ".hdf5": "hdf5", ".he5": "hdf5",
           ".csv": "csv", ".txt": "csv"}


@dataclass(frozen=True, eq=False)
class SourceData:
    """Channels read from one DAQ file.

    Attributes
    ----------
    path : Path
        The file read.
    format : str
        One of ``SOURCE_FORMATS``.
    channels : dict of str to ndarray
        Requested channel name -> samples, shape (n,), float64 (raw, in the file's units).
    increments : dict of str to float
        Sample interval in s stored with a channel (TDMS ``wf_increment``), where present.
    sha256 : str
        Checksum of the file's bytes.
    """

    path: Path
    format: str
    channels: dict[str, NDArray[np.float64]]
    increments: dict[str, float] = field(default_factory=dict)
    sha256: str = ""


def file_sha256(path: str | os.PathLike[str]) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def detect_format(path: str | os.PathLike[str], fmt: str = "auto") -> str:
    """The source format of ``path``: ``fmt`` itself, or chosen by suffix for ``"auto"``."""
    p = Path(path)
    if fmt != "auto":
        if fmt not in SOURCE_FORMATS:
            raise DataImportError(f"source {p}: field format: expected one of "
                                  f"{['auto', *SOURCE_FORMATS]}, got {short_repr(fmt)}")
        return fmt
    got = _SUFFIX.get(p.suffix.lower())
    if got is None:
        raise DataImportError(f"source {p}: field format: cannot tell the format from the "
                              f"suffix {p.suffix!r} (give format = one of {list(SOURCE_FORMATS)})")
    if got == "mat":
        import h5py

        if h5py.is_hdf5(p):
            return "mat73"
    return got


def _vector(value: Any, where: str) -> NDArray[np.float64]:
    """A numeric vector as a 1-D float64 array (DataImportError otherwise)."""
    arr = np.asarray(value)
    if arr.dtype.kind not in "biuf":
        what = "complex" if arr.dtype.kind == "c" else f"dtype {arr.dtype}"
        raise DataImportError(f"{where}: expected real numbers, got {what}")
    if sum(d > 1 for d in arr.shape) > 1:
        raise DataImportError(f"{where}: expected a vector (one sample per row), got shape "
                              f"{arr.shape}")
    return np.asarray(arr, dtype=float).reshape(-1)


def _missing(where: str, name: str, available: list[str]) -> DataImportError:
    shown = ", ".join(available[:12]) + (", ..." if len(available) > 12 else "")
    return DataImportError(f"{where}: channel {name!r}: not found in the file "
                           f"(it has: {shown or 'nothing'})")


def _read_mat5(p: Path, names: list[str]) -> tuple[dict, dict]:
    import scipy.io

    where = f"source {p}"
    data = scipy.io.loadmat(p, simplify_cells=True)
    top = sorted(k for k in data if not k.startswith("__"))
    out = {}
    for name in names:
        node: Any = data
        for part in name.replace("/", ".").split("."):
            if not isinstance(node, dict) or part not in node or part.startswith("__"):
                raise _missing(where, name, top)
            node = node[part]
        out[name] = _vector(node, f"{where}: channel {name!r}")
    return out, {}


def _read_h5(p: Path, names: list[str], fmt: str) -> tuple[dict, dict]:
    import h5py

    where = f"source {p}"
    out = {}
    with h5py.File(p, "r") as f:
        available: list[str] = []
        f.visititems(lambda k, v: available.append(k) if isinstance(v, h5py.Dataset) else None)
        for name in names:
            key = name.replace(".", "/") if fmt == "mat73" else name
            obj = f.get(key)
            if not isinstance(obj, h5py.Dataset):
                raise _missing(where, name, sorted(available))
            cls = obj.attrs.get("MATLAB_class", b"double")
            cls = cls.decode() if isinstance(cls, bytes) else str(cls)
            if fmt == "mat73" and cls not in ("double", "single", "int8", "uint8", "int16",
                                              "uint16", "int32", "uint32", "int64", "uint64"):
                raise DataImportError(f"{where}: channel {name!r}: MATLAB class {cls!r} is "
                                      "not a numeric array")
            out[name] = _vector(obj[()], f"{where}: channel {name!r}")
    return out, {}


class _Collect(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


def _read_tdms_strict(p: Path, where: str) -> Any:
    """TdmsFile.read, with npTDMS's warnings (truncated or damaged file) made errors."""
    from nptdms import TdmsFile
    from nptdms.log import log_manager

    loggers = [logging.getLogger(n) for n in ("nptdms", *log_manager.loggers)]
    saved = [(lg.propagate, lg.handlers[:]) for lg in loggers]
    sink = _Collect()
    for lg in loggers:
        lg.propagate, lg.handlers = False, [sink]
    try:
        f = TdmsFile.read(p)
    finally:
        for lg, (prop, handlers) in zip(loggers, saved, strict=True):
            lg.propagate, lg.handlers = prop, handlers
    if sink.messages:
        raise DataImportError(f"{where}: field <file>: damaged TDMS file "
                              f"({short_repr(sink.messages[0], 100)})")
    return f


def _read_tdms(p: Path, names: list[str]) -> tuple[dict, dict]:
    where = f"source {p}"
    f = _read_tdms_strict(p, where)
    available = sorted(f"{g.name}/{c.name}" for g in f.groups() for c in g.channels())
    out, inc = {}, {}
    for name in names:
        group, sep, chan = name.partition("/")
        if not sep or group not in [g.name for g in f.groups()] \
                or chan not in [c.name for c in f[group].channels()]:
            raise _missing(where, name, available)
        ch = f[group][chan]
        out[name] = _vector(ch[:], f"{where}: channel {name!r}")
        step = ch.properties.get("wf_increment")
        if step is not None:
            inc[name] = float(step)
    return out, inc


def _read_csv(p: Path, names: list[str]) -> tuple[dict, dict]:
    where = f"source {p}"
    with open(p, newline="", encoding="utf-8-sig") as f:
        reader = csv.reader(f)
        rows, lines = [], []
        for r in reader:
            if any(c.strip() for c in r):
                rows.append(r)
                lines.append(reader.line_num)
    if not rows:
        raise DataImportError(f"{where}: field <file>: empty (expected a header row)")
    header = [c.strip() for c in rows[0]]
    for i, row in enumerate(rows[1:]):
        if len(row) != len(header):
            raise DataImportError(f"{where}: row {i + 1} (line {lines[i + 1]}): expected "
                                  f"{len(header)} cells as in the header, got {len(row)}")
    out = {}
    for name in names:
        if name not in header:
            raise _missing(where, name, header)
        j = header.index(name)
        if header.count(name) > 1:
            raise DataImportError(f"{where}: channel {name!r}: column name appears "
                                  f"{header.count(name)} times")
        vals = np.empty(len(rows) - 1)
        for i, row in enumerate(rows[1:]):
            try:
                vals[i] = float(row[j])
            except ValueError:
                raise DataImportError(f"{where}: channel {name!r}: row {i + 1} (line "
                                      f"{lines[i + 1]}): not a number: {short_repr(row[j])}"
                                      ) from None
        out[name] = vals
    return out, {}


def read_channels(path: str | os.PathLike[str], names: list[str],
                  fmt: str = "auto") -> SourceData:
    """Read the named channels of a DAQ file (raw values, the file's units).

    Parameters
    ----------
    path : path
        The .mat, .tdms, .h5 or .csv file.
    names : list of str
        Channel names as the file spells them (module docstring).
    fmt : str
        ``"auto"`` (by suffix) or one of ``SOURCE_FORMATS``.

    Returns
    -------
    SourceData
        The channels (1-D float64 each), any stored sample intervals and the file's sha256.

    Raises
    ------
    DataImportError
        One line naming the file and the channel: a missing file or channel, an unreadable
        file, a channel that is not a real numeric vector.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "daq.csv"
    >>> _ = p.write_text("time,AMB1_X_pos\\n0,0.5\\n0.001,0.25\\n")
    >>> read_channels(p, ["AMB1_X_pos"]).channels["AMB1_X_pos"].tolist()
    [0.5, 0.25]
    """
    p = Path(path)
    if not p.is_file():
        raise DataImportError(f"source {p}: field <file>: not found")
    kind = detect_format(p, fmt)
    names = list(dict.fromkeys(names))
    readers = {"mat": lambda: _read_mat5(p, names), "tdms": lambda: _read_tdms(p, names),
               "mat73": lambda: _read_h5(p, names, "mat73"),
               "hdf5": lambda: _read_h5(p, names, "hdf5"), "csv": lambda: _read_csv(p, names)}
    try:
        channels, inc = readers[kind]()
    except DataImportError:
        raise
    except UnicodeDecodeError as exc:
        raise DataImportError(f"source {p}: field <file>: not UTF-8 text ({exc.reason})"
                              ) from None
    except Exception as exc:  # third-party parsers raise many types on corrupt files
        msg = " ".join(str(exc).split()) or type(exc).__name__
        raise DataImportError(f"source {p}: field <file>: not a readable {kind} file "
                              f"({type(exc).__name__}: {short_repr(msg, 120)})") from None
    return SourceData(path=p, format=kind, channels=channels, increments=inc,
                      sha256=file_sha256(p))
