"""The exported controller file (JSON, format ``bayes-amb-controller/1``).

A controller file holds the discrete-time controller that runs on the rig, in the form of
METHOD.md section 2 with the Youla port broken open::

    x[k+1] = A x[k] + B [y[k]; eta[k]]
    [u[k]; eps[k]] = C x[k] + D [y[k]; eta[k]]

Keys (all SI; unknown keys are rejected):

- ``format``: ``"bayes-amb-controller/1"``
- ``dt``: sample time, s, > 0
- ``A`` (n x n), ``B`` (n x 8), ``C`` (8 x n), ``D`` (8 x 8): lists of rows of finite
  numbers; n may be 0 (then ``A = B = []`` and ``C`` is 8 empty rows)
- ``inputs``: ``["y_Ax", "y_Ay", "y_Bx", "y_By", "eta_Ax", "eta_Ay", "eta_Bx", "eta_By"]``
  (displacements in m, Youla-port currents in A)
- ``outputs``: ``["u_Ax", "u_Ay", "u_Bx", "u_By", "eps_Ax", "eps_Ay", "eps_Bx", "eps_By"]``
  (currents in A, innovation in m)
- ``kind``: ``"observer"`` (observer-based, eps is the innovation y - C xhat) or
  ``"generic"`` (any stabilising K, e.g. a decentralised PID; its eps rows may be zero)
- ``rig``: name of the rig the controller was designed for, or an embedded rig dict
- ``design``: optional free dict of design settings (weights, poles, gains, ...)
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bayes_amb.errors import ControllerError, RigError
from bayes_amb.io.atomic import json_text, read_json, write_text_atomic
from bayes_amb.rig import CHANNELS, rig_from_dict

__all__ = ["CONTROLLER_FORMAT", "CONTROLLER_INPUTS", "CONTROLLER_OUTPUTS", "ControllerFile",
           "check_fits_rig", "controller_from_dict", "load_controller"]

CONTROLLER_FORMAT = "bayes-amb-controller/1"
CONTROLLER_INPUTS: tuple[str, ...] = (*(f"y_{c}" for c in CHANNELS),
                                      *(f"eta_{c}" for c in CHANNELS))
CONTROLLER_OUTPUTS: tuple[str, ...] = (*(f"u_{c}" for c in CHANNELS),
                                       *(f"eps_{c}" for c in CHANNELS))
CONTROLLER_KINDS = ("observer", "generic")
_REQUIRED = ("format", "dt", "A", "B", "C", "D", "inputs", "outputs", "kind", "rig")
_ALLOWED = {*_REQUIRED, "design"}


# ---------------------------------------------------------------- validation
def is_finite_number(v: Any) -> bool:
    """True for a finite real number (int, float, numpy scalar), False for bool and others."""
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        return False
    try:
        return math.isfinite(float(v))
    except OverflowError:
        return False


def short_repr(v: Any, limit: int = 60) -> str:
    """repr(v), cut to ``limit`` characters, for error messages."""
    s = repr(v)
    return s if len(s) <= limit else s[: limit - 3] + "..."


class _Checker:
    """Raises ControllerError "<where>: field <prefix><field>: <message>"."""

    def __init__(self, where: str, field_prefix: str = ""):
        self.where = where
        self.prefix = field_prefix

    def fail(self, fld: str, msg: str) -> ControllerError:
        return ControllerError(f"{self.where}: field {self.prefix}{fld}: {msg}")

    def matrix(self, data: Any, name: str, rows: int | None, cols: int | None,
               rows_what: str, cols_what: str) -> NDArray[np.float64]:
        """A list of rows; rows/cols None means "any"; returns shape (rows, cols)."""
        if not isinstance(data, list):
            raise self.fail(name, f"expected a list of rows, got {short_repr(data)}")
        if rows is not None and len(data) != rows:
            raise self.fail(name, f"expected {rows} rows ({rows_what}), got {len(data)}")
        for i, row in enumerate(data):
            if not isinstance(row, list):
                raise self.fail(f"{name}[{i}]", f"expected a list of numbers, got "
                                                f"{short_repr(row)}")
            if cols is not None and len(row) != cols:
                raise self.fail(name, f"expected {cols} columns ({cols_what}), got {len(row)}"
                                      f" in row {i}")
            if len(row) != len(data[0]):
                raise self.fail(name, f"row {i} has {len(row)} entries, row 0 has "
                                      f"{len(data[0])}")
            for j, v in enumerate(row):
                if not is_finite_number(v):
                    raise self.fail(f"{name}[{i}][{j}]", f"expected a finite number, got "
                                                         f"{short_repr(v)}")
        n_cols = cols if cols is not None else (len(data[0]) if data else 0)
        return np.array(data, dtype=float).reshape(len(data), n_cols)


def frozen_array(a: Any) -> NDArray[np.float64]:
    """A read-only float64 copy of ``a``."""
    arr = np.array(a, dtype=float)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class ControllerFile:
    """A discrete-time controller with the Youla port open (see module docstring).

    Attributes
    ----------
    dt : float
        Sample time, s.
    A, B, C, D : numpy.ndarray
        State space, shapes (n, n), (n, 8), (8, n), (8, 8); read-only float arrays.
        Input order ``inputs`` (y in m, eta in A), output order ``outputs`` (u in A,
        eps in m).
    inputs, outputs : tuple of str
        Signal names, always CONTROLLER_INPUTS and CONTROLLER_OUTPUTS.
    design : dict
        Free design settings (JSON-serialisable).
    rig : str or dict
        Rig name or embedded rig dict (rig-file form).
    kind : {"observer", "generic"}
        Observer-based controller (eps = innovation) or any other stabilising controller.
    source : str
        Where the controller came from (file name), for messages.

    Examples
    --------
    >>> import numpy as np
    >>> k = ControllerFile(dt=1e-4, A=np.zeros((0, 0)), B=np.zeros((0, 8)),
    ...                    C=np.zeros((8, 0)), D=np.zeros((8, 8)), kind="generic")
    >>> k.n_states, k.to_dict()["format"], k.has_innovation
    (0, 'bayes-amb-controller/1', False)
    """

    dt: float
    A: NDArray[np.float64]
    B: NDArray[np.float64]
    C: NDArray[np.float64]
    D: NDArray[np.float64]
    inputs: tuple[str, ...] = CONTROLLER_INPUTS
    outputs: tuple[str, ...] = CONTROLLER_OUTPUTS
    design: dict[str, Any] = field(default_factory=dict)
    rig: str | dict[str, Any] = "reference"
    kind: str = "observer"
    source: str = "<memory>"

    def __post_init__(self) -> None:
        chk = _Checker(f"controller {self.source}")
        if not is_finite_number(self.dt) or self.dt <= 0:
            raise chk.fail("dt", f"expected a positive finite sample time in s, got "
                                 f"{short_repr(self.dt)}")
        object.__setattr__(self, "dt", float(self.dt))
        arrays = {}
        for name in ("A", "B", "C", "D"):
            a = np.asarray(getattr(self, name))
            if a.ndim != 2 or not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a):
                raise chk.fail(name, f"expected a 2-D real array, got shape {a.shape} "
                                     f"dtype {a.dtype}")
            if not np.all(np.isfinite(a)):
                raise chk.fail(name, "contains NaN or inf")
            arrays[name] = frozen_array(a)
        n = arrays["A"].shape[0]
        ni, no = len(CONTROLLER_INPUTS), len(CONTROLLER_OUTPUTS)
        for name, shape in (("A", (n, n)), ("B", (n, ni)), ("C", (no, n)), ("D", (no, ni))):
            if arrays[name].shape != shape:
                raise chk.fail(name, f"expected shape {shape}, got {arrays[name].shape}")
            object.__setattr__(self, name, arrays[name])
        if tuple(self.inputs) != CONTROLLER_INPUTS:
            raise chk.fail("inputs", f"expected {list(CONTROLLER_INPUTS)}, got "
                                     f"{list(self.inputs)}")
        if tuple(self.outputs) != CONTROLLER_OUTPUTS:
            raise chk.fail("outputs", f"expected {list(CONTROLLER_OUTPUTS)}, got "
                                      f"{list(self.outputs)}")
        object.__setattr__(self, "inputs", CONTROLLER_INPUTS)
        object.__setattr__(self, "outputs", CONTROLLER_OUTPUTS)
        if self.kind not in CONTROLLER_KINDS:
            raise chk.fail("kind", f"expected one of {list(CONTROLLER_KINDS)}, got "
                                   f"{short_repr(self.kind)}")
        if not isinstance(self.design, dict):
            raise chk.fail("design", f"expected a dict, got {short_repr(self.design)}")
        if not ((isinstance(self.rig, str) and self.rig) or isinstance(self.rig, dict)):
            raise chk.fail("rig", f"expected a rig name or a rig dict, got {short_repr(self.rig)}")

    @property
    def n_states(self) -> int:
        """Number of controller states n."""
        return self.A.shape[0]

    @property
    def has_innovation(self) -> bool:
        """True if the eps outputs are not identically zero (rows 4..7 of C and D)."""
        k = len(CHANNELS)
        return bool(np.any(self.C[k:] != 0) or np.any(self.D[k:] != 0))

    def to_dict(self) -> dict[str, Any]:
        """The controller in file form (plain lists, JSON-ready)."""
        return {
            "format": CONTROLLER_FORMAT,
            "kind": self.kind,
            "dt": self.dt,
            "inputs": list(self.inputs),
            "outputs": list(self.outputs),
            "A": self.A.tolist(),
            "B": self.B.tolist(),
            "C": self.C.tolist(),
            "D": self.D.tolist(),
            "rig": self.rig,
            "design": self.design,
        }

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the controller file atomically; same controller, same bytes."""
        try:
            text = json_text(self.to_dict())
        except (TypeError, ValueError) as exc:
            raise ControllerError(f"controller {self.source}: field design: cannot be "
                                  f"written as JSON ({exc})") from None
        write_text_atomic(path, text)


def controller_from_dict(data: Any, source: str = "<dict>", *, where: str | None = None,
                         field_prefix: str = "") -> ControllerFile:
    """Validate a controller dict (file form) and build a ControllerFile.

    Parameters
    ----------
    data : dict
        Parsed controller JSON.
    source : str
        Name for messages and ``ControllerFile.source``.
    where, field_prefix : str, optional
        Message prefix (default ``"controller file SOURCE"``) and field prefix (e.g.
        ``"controller."`` when the controller is embedded in a recording sidecar).

    Raises
    ------
    ControllerError
        One line naming the file, the field and the offending value.
    """
    chk = _Checker(where or f"controller file {source}", field_prefix)
    if not isinstance(data, dict):
        raise chk.fail("<top>", f"expected a JSON object, got {type(data).__name__}")
    fmt = data.get("format")
    if "format" not in data:
        raise chk.fail("format", f"missing (expected {CONTROLLER_FORMAT!r})")
    if fmt != CONTROLLER_FORMAT:
        raise chk.fail("format", f"unsupported format {short_repr(fmt)} (expected "
                                 f"{CONTROLLER_FORMAT!r})")
    extra = sorted(set(data) - _ALLOWED)
    if extra:
        raise chk.fail(extra[0], f"unknown key (allowed: {sorted(_ALLOWED)})")
    for key in _REQUIRED:
        if key not in data:
            raise chk.fail(key, "missing")
    dt = data["dt"]
    if not is_finite_number(dt) or dt <= 0:
        raise chk.fail("dt", f"expected a positive sample time in s, got {short_repr(dt)}")
    for key, expected in (("inputs", CONTROLLER_INPUTS), ("outputs", CONTROLLER_OUTPUTS)):
        if not isinstance(data[key], list) or tuple(data[key]) != expected:
            raise chk.fail(key, f"expected {list(expected)}, got {short_repr(data[key], 200)}")
    if data["kind"] not in CONTROLLER_KINDS:
        raise chk.fail("kind", f"expected one of {list(CONTROLLER_KINDS)}, got "
                               f"{short_repr(data['kind'])}")
    ni, no = len(CONTROLLER_INPUTS), len(CONTROLLER_OUTPUTS)
    A = chk.matrix(data["A"], "A", None, None, "", "")
    n = A.shape[0]
    if A.shape[1] != n:
        raise chk.fail("A", f"expected a square matrix, got {A.shape[0]} rows and "
                            f"{A.shape[1]} columns")
    A = A.reshape(n, n)
    B = chk.matrix(data["B"], "B", n, ni, "one per state", "one per input")
    C = chk.matrix(data["C"], "C", no, n, "one per output", "one per state")
    D = chk.matrix(data["D"], "D", no, ni, "one per output", "one per input")
    design = data.get("design", {})
    if not isinstance(design, dict):
        raise chk.fail("design", f"expected a JSON object, got {short_repr(design)}")
    rig = data["rig"]
    if isinstance(rig, dict):
        try:
            rig_from_dict(rig, source=f"{source}#rig")
        except RigError as exc:
            raise chk.fail("rig", str(exc)) from None
    elif not isinstance(rig, str) or not rig:
        raise chk.fail("rig", f"expected a rig name or a rig object, got {short_repr(rig)}")
    return ControllerFile(dt=float(dt), A=A, B=B, C=C, D=D, design=design, rig=rig,
                          kind=data["kind"], source=source)


def load_controller(path_or_dict: str | os.PathLike[str] | dict[str, Any],
                    source: str | None = None) -> ControllerFile:
    """Load and validate a controller file (or an already parsed dict).

    Parameters
    ----------
    path_or_dict : path or dict
        A ``bayes-amb-controller/1`` JSON file, or its parsed content.
    source : str, optional
        Name used in messages (default: the path, or ``"<dict>"``).

    Raises
    ------
    ControllerError
        One line naming the file, the field and the value, e.g.
        ``controller file ctl.json: field B: expected 8 columns (one per input), got 7``.

    Examples
    --------
    >>> k = load_controller({"format": "bayes-amb-controller/1", "dt": 1e-4,
    ...     "A": [], "B": [], "C": [[]] * 8, "D": [[0.0] * 8] * 8, "kind": "generic",
    ...     "inputs": list(CONTROLLER_INPUTS), "outputs": list(CONTROLLER_OUTPUTS),
    ...     "rig": "reference"})
    >>> k.D.shape, k.dt
    ((8, 8), 0.0001)
    """
    if isinstance(path_or_dict, dict):
        return controller_from_dict(path_or_dict, source or "<dict>")
    src = source or str(path_or_dict)
    data = read_json(path_or_dict, f"controller file {src}", ControllerError)
    return controller_from_dict(data, src)


def check_fits_rig(ctrl: ControllerFile, n_inputs: int = 4, n_outputs: int = 4) -> None:
    """Check that a controller fits a plant with ``n_inputs`` currents, ``n_outputs`` sensors.

    The controller must take the n_outputs displacements y and the n_inputs Youla-port
    signals eta, and return the n_inputs currents u and the n_outputs innovations eps.

    Raises
    ------
    ControllerError
        Naming the controller and the mismatching dimension.

    Examples
    --------
    >>> import numpy as np
    >>> k = ControllerFile(dt=1e-4, A=np.zeros((0, 0)), B=np.zeros((0, 8)),
    ...                    C=np.zeros((8, 0)), D=np.zeros((8, 8)))
    >>> check_fits_rig(k)
    >>> check_fits_rig(k, n_inputs=2, n_outputs=2)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    bayes_amb.errors.ControllerError: controller <memory>: does not fit a rig with 2 inputs ...
    """
    def count(names: tuple[str, ...], prefix: str) -> int:
        return sum(1 for s in names if s.startswith(prefix))

    checks = (("y inputs", count(ctrl.inputs, "y_"), n_outputs),
              ("eta inputs", count(ctrl.inputs, "eta_"), n_inputs),
              ("u outputs", count(ctrl.outputs, "u_"), n_inputs),
              ("eps outputs", count(ctrl.outputs, "eps_"), n_outputs),
              ("columns of B", ctrl.B.shape[1], n_inputs + n_outputs),
              ("columns of D", ctrl.D.shape[1], n_inputs + n_outputs),
              ("rows of C", ctrl.C.shape[0], n_inputs + n_outputs),
              ("rows of D", ctrl.D.shape[0], n_inputs + n_outputs))
    for what, got, expected in checks:
        if got != expected:
            raise ControllerError(f"controller {ctrl.source}: does not fit a rig with "
                                  f"{n_inputs} inputs and {n_outputs} outputs: it has {got} "
                                  f"{what} (expected {expected})")


SHIPPED_CONTROLLERS = ("ross_test_rig",)
"""Controllers shipped beside their rig files in bayes_amb/rig/data/ (NAME_controller.json):
ross_test_rig's is ROSS's own two controllers of that rig, imported with the bearing
constant its example writes twice taken out (docs/your_rig.md, "ROSS")."""


def shipped_controller(rig_name: str) -> ControllerFile:
    """The controller shipped with a shipped rig.

    >>> shipped_controller("ross_test_rig").kind
    'generic'
    """
    from importlib import resources

    if rig_name not in SHIPPED_CONTROLLERS:
        raise ControllerError(f"shipped controller {rig_name!r}: none shipped; known: "
                              + ", ".join(SHIPPED_CONTROLLERS))
    text = resources.files("bayes_amb.rig").joinpath(
        f"data/{rig_name}_controller.json").read_text()
    return controller_from_dict(json.loads(text), f"{rig_name} (shipped)")
