"""Recordings: a CSV of sampled signals plus a JSON sidecar (``bayes-amb-recording/1``).

A recording ``NAME`` is two files side by side, both required. ``NAME.csv``: a header row,
then one row per sample; numbers in any form Python's ``float`` reads, written with full
precision (e.g. ``%.17g``). Columns, in any order:

- ``t`` (s): uniform and strictly increasing (every step equal to ``dt`` within 1e-6)
- ``y_Ax, y_Ay, y_Bx, y_By`` (m): measured displacements
- ``u_Ax, u_Ay, u_Bx, u_By`` (A): the coil currents at the plant input, *including* any
  injected ``r2`` excitation: u = K_u([y + r1; eta]) + r2, with K_u the u rows of the
  controller file (the one convention of the simulator, the data check
  :func:`bayes_amb.discrepancy.checks.recompute_u` and the identification model). Record
  the current the amplifier is commanded with after the excitation was added.
- the excitation that was applied, one or more groups of all four channels:
  ``eta_*`` (A, at the Youla port of an observer-based controller, inside it),
  ``r2_*`` (A, added to the controller's output current at the plant input, any controller;
  already part of ``u_*``), ``r1_*`` (m, added to the measured output the controller sees;
  not part of ``y_*``)

Unknown, missing or duplicated columns, empty or non-numeric cells, NaN, inf and fewer
than 2 rows are errors. ``NAME.json``: an object with exactly these keys (``notes``,
``provenance``, ``truth`` optional):

- ``format``: ``"bayes-amb-recording/1"``
- ``dt`` (s, > 0): sample time, equal to the step of ``t``
- ``speed_rpm`` (>= 0): rotor speed
- ``rig``: ``"reference"`` (a shipped rig) or an embedded rig object (rig-file form)
- ``controller``: the controller that ran, in ``bayes-amb-controller/1`` form (inputs y,
  eta; outputs u, eps), with the same ``dt``
- ``excitation``: ``{"columns": ["eta"], "injected_at": {"eta": "youla_port"}}``, the
  groups in the CSV and where each acts (``eta``: ``youla_port``, ``r2``: ``plant_input``,
  ``r1``: ``sensor``)
- ``units``: SI unit of each column group present, e.g. ``{"t": "s", "y": "m", "u": "A",
  "eta": "A"}`` (``r2``: ``"A"``, ``r1``: ``"m"``)
- ``notes``: free text; ``provenance``: free object (who, when, which software)
- ``truth`` (simulated data only): the true parameters; never part of the loaded
  :class:`Recording`, read only by :func:`load_truth`
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bayes_amb.errors import ControllerError, RecordingError, RigError
from bayes_amb.io.atomic import atomic_path, json_text, read_json
from bayes_amb.io.controller_file import (
    ControllerFile,
    check_fits_rig,
    controller_from_dict,
    frozen_array,
    is_finite_number,
    short_repr,
)
from bayes_amb.rig import CHANNELS, Rig, load_rig, rig_from_dict

__all__ = ["EXCITATION_GROUPS", "INJECTED_AT", "RECORDING_FORMAT", "UNITS", "Recording",
           "load_recording", "load_truth", "make_recording", "recording_paths",
           "save_recording"]

RECORDING_FORMAT = "bayes-amb-recording/1"
EXCITATION_GROUPS = ("eta", "r2", "r1")
INJECTED_AT = {"eta": "youla_port", "r2": "plant_input", "r1": "sensor"}
UNITS = {"t": "s", "y": "m", "u": "A", "eta": "A", "r2": "A", "r1": "m"}
SHIPPED_RIGS = ("reference",)
DT_RTOL = 1e-6  # relative tolerance on the steps of t and on dt agreement
_REQUIRED = ("format", "dt", "speed_rpm", "rig", "controller", "excitation", "units")
_ALLOWED = {*_REQUIRED, "notes", "provenance", "truth"}
_K = len(CHANNELS)
_COLUMNS = ("t", *(f"{g}_{c}" for g in ("y", "u", *EXCITATION_GROUPS) for c in CHANNELS))


def _row(i: int, line: int | None = None) -> str:
    """Data row i (0-based) as "row i+1 (line L)"; L defaults to i + 2."""
    return f"row {i + 1} (line {i + 2 if line is None else line})"


def _check_time(t: NDArray[np.float64], dt: float, where: str) -> None:
    """t strictly increasing, uniform to DT_RTOL, with step dt (RecordingError otherwise)."""
    if t.shape[0] < 2:
        raise RecordingError(f"{where}: field <rows>: expected >= 2 samples, got {t.shape[0]}")
    d = np.diff(t)
    step = float(np.median(d))
    for bad, what in ((~(d > 0), "not strictly increasing"),
                      (np.abs(d - step) > DT_RTOL * step,
                       f"non-uniform (usual step {step:.6g} s)")):
        if bad.any():
            i = int(np.argmax(bad)) + 1
            raise RecordingError(f"{where}: column t: {what} at {_row(i)}: t = "
                                 f"{float(t[i])!r} after {float(t[i - 1])!r}")
    mean_step = float(t[-1] - t[0]) / (t.shape[0] - 1)
    if abs(mean_step - dt) > DT_RTOL * dt:
        raise RecordingError(f"{where}: field dt: dt = {dt!r} s but column t has step "
                             f"{mean_step!r} s")


@dataclass(frozen=True, eq=False)
class Recording:
    """A validated recording; construction checks everything and raises RecordingError.

    ``t`` (N,) s, uniform, N >= 2; ``y`` (N, 4) m and ``u`` (N, 4) A, channels ``CHANNELS``;
    ``excitation``: dict with one or more of ``eta`` (A, Youla port), ``r2`` (A, plant
    input), ``r1`` (m, sensor), each (N, 4); ``dt`` s; ``speed_rpm`` rpm; ``rig`` a Rig;
    ``controller`` the ControllerFile that ran (4 in, 4 out, same dt); ``notes``; ``meta``
    the JSON sidecar without ``truth``; ``source`` the CSV path. Arrays are read-only copies.
    """

    t: NDArray[np.float64]
    y: NDArray[np.float64]
    u: NDArray[np.float64]
    excitation: dict[str, NDArray[np.float64]]
    dt: float
    speed_rpm: float
    rig: Rig
    controller: ControllerFile
    notes: str = ""
    meta: dict[str, Any] = field(default_factory=dict)
    source: str = "<memory>"

    def __post_init__(self) -> None:
        where = f"recording {self.source}"

        def fail(fld: str, msg: str) -> RecordingError:
            return RecordingError(f"{where}: field {fld}: {msg}")

        if not is_finite_number(self.dt) or self.dt <= 0:
            raise fail("dt", f"expected a positive sample time in s, got {short_repr(self.dt)}")
        if not is_finite_number(self.speed_rpm) or self.speed_rpm < 0:
            raise fail("speed_rpm", f"expected a number >= 0, got {short_repr(self.speed_rpm)}")
        for name, typ in (("rig", Rig), ("controller", ControllerFile), ("notes", str),
                          ("meta", dict), ("excitation", dict)):
            if not isinstance(getattr(self, name), typ):
                raise fail(name, f"expected {typ.__name__}, got {short_repr(getattr(self, name))}")
        exc, dt = self.excitation, float(self.dt)
        if not exc or not set(exc) <= set(EXCITATION_GROUPS):
            raise fail("excitation", f"expected one or more of {list(EXCITATION_GROUPS)}, got "
                                     f"{sorted(exc)}")
        t = frozen_array(self.t)
        if t.ndim != 1:
            raise fail("t", f"expected shape (N,), got {t.shape}")
        n, groups = t.shape[0], [g for g in EXCITATION_GROUPS if g in exc]
        sig = {"t": t.reshape(n, 1), "y": frozen_array(self.y), "u": frozen_array(self.u),
               **{g: frozen_array(exc[g]) for g in groups}}
        for g, arr in sig.items():
            if g != "t" and arr.shape != (n, _K):
                raise fail(g, f"expected shape ({n}, {_K}), got {arr.shape}")
            bad = np.argwhere(~np.isfinite(arr))
            if bad.size:
                i, j = (int(v) for v in bad[0])
                col = "t" if g == "t" else f"{g}_{CHANNELS[j]}"
                raise RecordingError(f"{where}: column {col}: {_row(i)}: not finite "
                                     f"({float(arr[i, j])!r})")
        _check_time(t, dt, where)
        for name, value in (("t", t), ("y", sig["y"]), ("u", sig["u"]), ("dt", dt),
                            ("excitation", {g: sig[g] for g in groups}),
                            ("speed_rpm", float(self.speed_rpm))):
            object.__setattr__(self, name, value)
        if "truth" in self.meta:
            raise fail("meta", "must not contain 'truth' (see load_truth)")
        try:
            check_fits_rig(self.controller, _K, _K)
        except ControllerError as err:
            raise fail("controller", str(err)) from None
        if abs(self.controller.dt - dt) > DT_RTOL * dt:
            raise fail("controller.dt", f"controller sample time {self.controller.dt!r} s "
                                        f"differs from the recording dt {dt!r} s")

    @property
    def n_samples(self) -> int:
        """Number of samples N."""
        return self.t.shape[0]

    def part(self, samples: slice) -> Recording:
        """The samples ``samples`` of this recording as a recording of their own, its time
        from zero: a record cut from a longer one (a record that starts mid-operation,
        when the cut is after the start)."""
        t = self.t[samples]
        return replace(self, t=t - t[0], y=self.y[samples], u=self.u[samples],
                       excitation={k: v[samples] for k, v in self.excitation.items()})


def require_excitation(recording: Recording) -> None:
    """Refuse a recording whose excitation is zero on every channel of every group.

    Identification and diagnosis call this first: without excitation S(theta) x is zero
    for every theta and the likelihood is flat, so an optimiser would return its start with
    "NOT converged" and no reason.

    Raises
    ------
    RecordingError
        ``recording NAME.csv: eta is zero on every channel: nothing to identify from``.
    """
    if any(np.any(np.asarray(v) != 0) for v in recording.excitation.values()):
        return
    groups = "/".join(recording.excitation)
    verb = "is" if len(recording.excitation) == 1 else "are"
    raise RecordingError(f"recording {recording.source}: {groups} {verb} zero on every "
                         "channel: nothing to identify from")


def recording_paths(path: str | os.PathLike[str]) -> tuple[Path, Path]:
    """The (NAME.csv, NAME.json) pair for a path to either file."""
    p = Path(path)
    if p.suffix.lower() not in (".csv", ".json"):
        raise RecordingError(f"recording {p}: field <file>: expected NAME.csv (with NAME.json),"
                             f" got suffix {p.suffix!r}")
    return p.with_suffix(".csv"), p.with_suffix(".json")


def _sidecar(dt: float, speed_rpm: float, rig: Rig, controller: ControllerFile,
             groups: list[str], notes: str, provenance: dict | None) -> dict[str, Any]:
    return {"format": RECORDING_FORMAT, "dt": dt, "speed_rpm": speed_rpm,
            "rig": rig.source if rig.source in SHIPPED_RIGS else rig.to_dict(),
            "controller": controller.to_dict(),
            "excitation": {"columns": groups, "injected_at": {g: INJECTED_AT[g] for g in groups}},
            "units": {g: UNITS[g] for g in ("t", "y", "u", *groups)}, "notes": notes,
            **({} if provenance is None else {"provenance": provenance})}


def make_recording(y: ArrayLike, u: ArrayLike, excitation: dict[str, ArrayLike], dt: float,
                   controller: ControllerFile, *, speed_rpm: float = 0.0,
                   rig: Rig | str | None = None, t: ArrayLike | None = None,
                   notes: str = "", provenance: dict[str, Any] | None = None,
                   source: str = "<memory>") -> Recording:
    """Build a validated Recording from arrays (SI units; see :class:`Recording`).

    ``rig`` defaults to the reference rig; ``t`` defaults to ``dt * arange(N)``.
    ``meta`` is set to the sidecar that :func:`save_recording` would write.
    """
    rig_obj = rig if isinstance(rig, Rig) else load_rig(rig)
    y_arr = np.asarray(y, dtype=float)
    t_arr = np.arange(y_arr.shape[0]) * float(dt) if t is None else t
    groups = [g for g in EXCITATION_GROUPS if g in excitation]
    meta = _sidecar(dt, speed_rpm, rig_obj, controller, groups, notes, provenance)
    return Recording(t=t_arr, y=y_arr, u=u, excitation=dict(excitation), dt=dt,
                     speed_rpm=speed_rpm, rig=rig_obj, controller=controller, notes=notes,
                     meta=meta, source=source)


def save_recording(path: str | os.PathLike[str], recording: Recording | None = None, *,
                   truth: dict[str, Any] | None = None, **arrays: Any) -> tuple[Path, Path]:
    """Write NAME.csv and NAME.json atomically; the same data always give the same bytes.

    ``path`` is NAME.csv (or NAME.json); ``recording`` is what to write, or else ``**arrays``
    go to :func:`make_recording`; ``truth`` (simulated data: the true parameters, a
    JSON-serialisable dict) goes into the sidecar only. Returns (csv_path, json_path).

    Examples
    --------
    >>> import numpy as np, tempfile, pathlib
    >>> from bayes_amb.io import ControllerFile, load_recording
    >>> k = ControllerFile(dt=1e-4, A=np.zeros((0, 0)), B=np.zeros((0, 8)),
    ...                    C=np.zeros((8, 0)), D=np.zeros((8, 8)), kind="generic")
    >>> z, p = np.zeros((3, 4)), pathlib.Path(tempfile.mkdtemp()) / "run.csv"
    >>> _ = save_recording(p, y=z, u=z, excitation={"r2": z + 0.1}, dt=1e-4, controller=k)
    >>> p.read_text().splitlines()[0]
    't,y_Ax,y_Ay,y_Bx,y_By,u_Ax,u_Ay,u_Bx,u_By,r2_Ax,r2_Ay,r2_Bx,r2_By'
    >>> float(load_recording(p).excitation["r2"][2, 3])
    0.1
    """
    if recording is None:
        recording = make_recording(**arrays)
    elif arrays:
        raise TypeError(f"save_recording: give a Recording or arrays, not both ({sorted(arrays)})")
    csv_path, json_path = recording_paths(path)
    r, groups = recording, list(recording.excitation)
    side = _sidecar(r.dt, r.speed_rpm, r.rig, r.controller, groups, r.notes,
                    r.meta.get("provenance"))
    side.update({} if truth is None else {"truth": truth})
    try:
        side_text = json_text(side)
    except (TypeError, ValueError) as exc:
        raise RecordingError(f"recording sidecar {json_path}: not writable as JSON ({exc})"
                             ) from None
    header = ["t", *(f"{g}_{c}" for g in ("y", "u", *groups) for c in CHANNELS)]
    data = np.column_stack([r.t, r.y, r.u, *(r.excitation[g] for g in groups)])
    lines = [",".join(header), *(",".join(map(repr, row)) for row in data.tolist()), ""]
    with atomic_path(csv_path) as tmp_csv, atomic_path(json_path) as tmp_json:
        tmp_csv.write_bytes("\n".join(lines).encode("ascii"))
        tmp_json.write_bytes(side_text.encode("utf-8"))
    return csv_path, json_path


def _parse_sidecar(side: dict[str, Any], json_path: Path) -> dict[str, Any]:
    """Validate the sidecar; returns the Recording arguments it gives, plus the groups."""
    where = f"recording sidecar {json_path}"

    def fail(fld: str, msg: str) -> RecordingError:
        return RecordingError(f"{where}: field {fld}: {msg}")

    if side.get("format") != RECORDING_FORMAT:
        got = f"got {short_repr(side['format'])}" if "format" in side else "missing"
        raise fail("format", f"expected {RECORDING_FORMAT!r}, {got}")
    for key in sorted(set(side) - _ALLOWED):
        raise fail(key, f"unknown key (allowed: {sorted(_ALLOWED)})")
    for key in (k for k in _REQUIRED if k not in side):
        raise fail(key, "missing")
    dt, speed, exc = side["dt"], side["speed_rpm"], side["excitation"]
    if not is_finite_number(dt) or dt <= 0:
        raise fail("dt", f"expected a positive sample time in s, got {short_repr(dt)}")
    if not is_finite_number(speed) or speed < 0:
        raise fail("speed_rpm", f"expected a number >= 0, got {short_repr(speed)}")
    if not isinstance(exc, dict) or set(exc) != {"columns", "injected_at"}:
        raise fail("excitation", f"expected keys 'columns', 'injected_at'; got {short_repr(exc)}")
    groups = exc["columns"]
    if (not isinstance(groups, list) or not groups or len(set(map(str, groups))) != len(groups)
            or not all(isinstance(g, str) and g in EXCITATION_GROUPS for g in groups)):
        raise fail("excitation.columns", f"expected distinct groups from "
                                         f"{list(EXCITATION_GROUPS)}, got {short_repr(groups)}")
    injected, units = ({g: INJECTED_AT[g] for g in groups},
                       {g: UNITS[g] for g in ("t", "y", "u", *groups)})
    for key, got, expected, note in (("excitation.injected_at", exc["injected_at"], injected, ""),
                                     ("units", side["units"], units, " (SI only)")):
        if got != expected:
            raise fail(key, f"expected {expected}{note}, got {short_repr(got, 120)}")
    for key, typ in (("notes", str), ("provenance", dict), ("truth", dict)):
        if key in side and not isinstance(side[key], typ):
            raise fail(key, f"expected {'a string' if typ is str else 'an object'}, got "
                            f"{short_repr(side[key])}")
    rig = side["rig"]
    if not isinstance(rig, dict) and not (isinstance(rig, str) and rig in SHIPPED_RIGS):
        raise fail("rig", f"unknown rig {short_repr(rig)} (shipped: {list(SHIPPED_RIGS)}; embed"
                          f" any other rig as an object)")
    try:  # dimensions are fixed by the controller format; Recording checks the fit again
        rig_obj = load_rig(rig) if isinstance(rig, str) else rig_from_dict(
            rig, source=f"{json_path}#rig")
        ctrl = controller_from_dict(side["controller"], f"{json_path}#controller",
                                    where=where, field_prefix="controller.")
    except RigError as err:
        raise fail("rig", str(err)) from None
    except ControllerError as err:
        raise RecordingError(str(err)) from None
    return {"dt": float(dt), "speed_rpm": float(speed), "rig": rig_obj, "controller": ctrl,
            "notes": side.get("notes", ""), "groups": groups}


def _read_csv(csv_path: Path, groups: list[str]) -> dict[str, NDArray[np.float64]]:
    """Parse and check the CSV; returns {"t": (N,), "y": (N, 4), "u": ..., group: ...}."""
    where = f"recording {csv_path}"

    def fail(fld: str, msg: str) -> RecordingError:
        return RecordingError(f"{where}: {fld}: {msg}")

    try:
        with open(csv_path, newline="", encoding="utf-8-sig") as f:
            reader = csv.reader(f)
            rows, lines = [], []
            for row in reader:  # keep the line numbers: quoted cells may span lines
                rows.append(row)
                lines.append(reader.line_num)
    except UnicodeDecodeError as exc:
        raise fail("field <file>", f"not UTF-8 ({exc.reason} at byte {exc.start})") from None
    except csv.Error as exc:
        raise fail("field <csv>", f"not valid CSV ({exc})") from None
    while rows and not any(c.strip() for c in rows[-1]):
        rows.pop()
    if not rows:
        raise fail("field <file>", "empty file (expected a header row)")
    header = [c.strip() for c in rows[0]]
    for j, name in enumerate(header):
        if name not in _COLUMNS:
            raise fail(f"column {name!r} (column {j + 1})", "unknown column (allowed: t, y_*, "
                       f"u_*, eta_*, r2_*, r1_*; * in {'/'.join(CHANNELS)})")
        if header.index(name) != j:
            raise fail(f"column {name}", f"duplicated (columns {header.index(name) + 1}, {j + 1})")
    present = [g for g in EXCITATION_GROUPS if any(f"{g}_{c}" in header for c in CHANNELS)]
    for name in (n for n in _COLUMNS if n.split("_")[0] in ("t", "y", "u", *present)):
        if name not in header:
            raise fail(f"column {name}", "missing" if name[0] in "tyu" else
                       f"missing (excitation group {name.split('_')[0]} needs all 4 channels)")
    if sorted(present) != sorted(groups):
        raise fail("field excitation.columns", f"the sidecar lists {groups} but the CSV has "
                                               f"excitation groups {present}")
    body = rows[1:]
    if len(body) < 2:
        raise fail("field <rows>", f"expected at least 2 data rows, got {len(body)}")
    for i, row in enumerate(body):
        if len(row) != len(header):
            raise fail(_row(i, lines[i + 1]), f"expected {len(header)} cells, got {len(row)}")
    cols: dict[str, NDArray[np.float64]] = {}
    for j, name in enumerate(header):
        cells = [row[j] for row in body]
        try:
            cols[name] = np.asarray(cells).astype(float)  # NaN/inf: Recording rejects them
        except ValueError:
            for i, s in enumerate(cells):
                try:
                    float(s)
                except ValueError:
                    raise fail(f"column {name}: {_row(i, lines[i + 1])}",
                               f"not a number: {short_repr(s)}") from None
            raise fail(f"column {name}", "not numeric") from None
    return {"t": cols["t"], **{g: np.column_stack([cols[f"{g}_{c}"] for c in CHANNELS])
                               for g in ("y", "u", *present)}}


def load_recording(path: str | os.PathLike[str]) -> Recording:
    """Load and fully check a recording (``path``: NAME.csv or NAME.json); never writes.

    Returns a :class:`Recording` whose ``meta`` is the sidecar without ``truth`` (see
    :func:`load_truth`). Raises RecordingError: one line naming file, field/column/row, value.
    """
    csv_path, json_path = recording_paths(path)
    if not csv_path.is_file():
        raise RecordingError(f"recording {csv_path}: field <file>: not found")
    side = read_json(json_path, f"recording sidecar {json_path}", RecordingError)
    args = _parse_sidecar(side, json_path)
    sig = _read_csv(csv_path, args.pop("groups"))
    return Recording(t=sig["t"], y=sig["y"], u=sig["u"],
                     excitation={g: sig[g] for g in EXCITATION_GROUPS if g in sig},
                     meta={k: v for k, v in side.items() if k != "truth"},
                     source=str(csv_path), **args)


def load_truth(path: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The ``truth`` entry of a recording's sidecar (simulated data), or None.

    Kept apart from :func:`load_recording` so identification code cannot see it.
    """
    json_path = recording_paths(path)[1]
    truth = read_json(json_path, f"recording sidecar {json_path}", RecordingError).get("truth")
    if truth is not None and not isinstance(truth, dict):
        raise RecordingError(f"recording sidecar {json_path}: field truth: expected an object, "
                             f"got {short_repr(truth)}")
    return truth
