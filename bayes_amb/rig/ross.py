"""Convert a ROSS rotor (ross-rotordynamics, optional extra ``bayes-amb[ross]``) to a rig.

What maps, one to one (ROSS nodes are 0-based, rig nodes 1-based):

- ``ShaftElement`` -> ``[shaft]``. A shaft of equal, solid, Euler-Bernoulli elements of one
  material with no mass-proportional damping becomes the uniform shorthand (its
  stiffness-proportional ``beta`` -> ``[damping] first_mode_zeta = beta w1 / 2``, w1 the bare
  shaft's first free-free bending frequency, rotor.assembly). Any other shaft becomes the
  element table ``[[shaft.elements]]``: each element's length, outer and inner diameter at
  both ends, material and Rayleigh damping (alpha, beta) as ROSS has them, and Timoshenko
  shear (``[shaft] shear``) where ROSS has ``shear_effects=True``.
- ``DiskElement`` -> ``[[discs]]`` (m, Ip, Id): D1 and D2 the two heaviest (the planes the
  diagnosis tries first), then D3, D4, ... in node order; ``PointMass`` -> a disc without
  inertia, named P1, P2, ...
- two ``MagneticBearingElement`` -> ``[bearings] A, B``, each its own magnet: gap g0, bias
  current i0, pole area ag, turns nw and pole angle alpha, from which ki and ks follow
  (rig.magnet_constants; ROSS writes ks with its sign, the rig the magnitude). Each
  bearing's ``sensor_node`` gives ``[sensors]``.
- any other ``BearingElement`` or ``SealElement`` (a fluid-film bearing, a seal) ->
  ``[[supports]]`` (rig/supports.py): its lateral stiffness, damping and added-mass
  coefficients as ROSS evaluates them at the nominal speed, held fixed.
- ``rated_w`` (rad/s), when set, gives ``nominal_speed_rpm``.

Refused with one line naming the element and field (the rig would silently differ): an
axial force or torque on a shaft element, ``rotary_inertia=False`` or ``gyroscopic=False``
(the rig always has both), Timoshenko on some elements and not others, a point mass with
mx != my, damping set on the whole rotor (ROSS's global or modal damping), a bearing or
seal linked to another node (``n_link``: a pedestal). ROSS's own bearing controller (PID
gains, transfer function) is not part of a rig and is noted: the controller is designed
or imported separately (``bayes-amb controller``, ``bayes-amb import-controller``).
"""

from __future__ import annotations

import contextlib
import io
import logging
import math
import os
import sys
import tomllib
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bayes_amb.errors import RigError
from bayes_amb.rig.rig import Rig, magnet_constants, rig_from_dict
from bayes_amb.rig.supports import nonzero_coefficients

__all__ = ["RossConversion", "magnetic_bearings", "pid_gains", "rig_from_ross", "rig_to_toml"]

_RTOL = 1e-9
MAGNET_ATTRS = ("g0", "i0", "ag", "nw")
"""The attributes that make a ROSS bearing a magnetic one (with ``alpha``, the pole angle)."""
PID_ATTRS = ("kp_pid", "ki_pid", "kd_pid")


def magnetic_bearings(rotor: Any) -> list[Any]:
    """The rotor's magnetic bearings in node order: bearing A first, then B."""
    return sorted((b for b in rotor.bearing_elements
                   if all(hasattr(b, k) for k in MAGNET_ATTRS)), key=lambda b: b.n)


def pid_gains(bearing: Any) -> tuple[float, float, float]:
    """(Kp, Ki, Kd) of a ROSS magnetic bearing's PID controller (zeros: none)."""
    kp, ki, kd = (float(getattr(bearing, k, 0.0) or 0.0) for k in PID_ATTRS)
    return kp, ki, kd


@dataclass(frozen=True)
class RossConversion:
    """A converted rig, its rig-file dict and notes on what the conversion left out."""

    rig: Rig
    data: dict[str, Any]
    notes: tuple[str, ...]


def _same(values: list[float]) -> bool:
    return all(math.isclose(v, values[0], rel_tol=_RTOL, abs_tol=0.0) for v in values)


def rig_from_ross(rotor: Any, *, name: str = "from_ross", source: str = "<ross rotor>",
                  nominal_speed_rpm: float | None = None,
                  first_mode_zeta: float | None = None,
                  c_ref: float = 1000.0, k_ref: float = 1.0e5) -> RossConversion:
    """Convert a ``ross.Rotor`` to a :class:`~bayes_amb.rig.Rig` (module docstring).

    Parameters
    ----------
    rotor : ross.Rotor
        The rotor: shaft elements, discs and point masses, two magnetic bearings. A live
        object (the notebook path) or one loaded by :func:`load_ross_rotor`.
    name, source : str
        Rig name; where the rotor came from (for messages).
    nominal_speed_rpm : float, optional
        Default: the rotor's ``rated_w`` in rpm; required if that is not set.
    first_mode_zeta : float, optional
        A uniform shaft's damping, default from its elements' ``beta``. Given, it replaces
        the ROSS shaft's own damping (every element's alpha and beta; noted).
    c_ref, k_ref : float
        Rig values ROSS does not hold (parameter scales).

    Raises
    ------
    RigError
        Naming the ROSS element and the value that has no rig equivalent.
    """
    where = f"ROSS rotor {source}"

    def fail(what: str, msg: str) -> RigError:
        return RigError(f"{where}: {what}: {msg}")

    shafts = sorted(rotor.shaft_elements, key=lambda e: e.n)
    if not shafts:
        raise fail("shaft_elements", "none")
    notes: list[str] = []
    _refuse_unmapped(shafts, rotor, fail)
    uniform = _is_uniform(shafts)
    speed = nominal_speed_rpm
    if speed is None:
        rated = getattr(rotor, "rated_w", None)
        if rated is None:
            raise fail("rated_w", "not set; give nominal_speed_rpm (--speed-rpm)")
        speed = float(rated) * 60.0 / (2.0 * math.pi)
    discs = _discs(rotor, fail)
    mbs = magnetic_bearings(rotor)
    others = [b for b in rotor.bearing_elements if b not in mbs]
    if len(mbs) != 2:
        raise fail("bearing_elements", f"expected exactly 2 MagneticBearingElement, got "
                   f"{len(mbs)}")
    bearings = {"A": _magnet_entry(mbs[0], fail), "B": _magnet_entry(mbs[1], fail)}
    if any(getattr(b, "n_link", None) is not None for b in mbs):
        notes.append("bearing links to support nodes (n_link) are ignored: rigid ground")
    has_tf = [getattr(b, "controller_transfer_function_num", None) is not None for b in mbs]
    has_pid = [any(pid_gains(b)) for b in mbs]
    if any(has_tf) or any(has_pid):
        notes.append("the ROSS bearings' controller (kp_pid, kd_pid, transfer function, "
                     "k_amp, k_sense) is not part of a rig: design one (bayes-amb controller) "
                     "or import the real one (bayes-amb import-controller)")
    if any(hasattr(b, "kxx") and not tf and not pid
           for b, tf, pid in zip(mbs, has_tf, has_pid, strict=True)):
        notes.append("the saved ROSS file holds the bearings' controller only as "
                     "frequency-dependent stiffness and damping (kxx, cxx), not the "
                     "controller itself: import the real one (bayes-amb import-controller)")
    sensors = {k: {"node": int(getattr(b, "sensor_node", None) or b.n) + 1}
               for k, b in zip(("A", "B"), mbs, strict=True)}
    data: dict[str, Any] = {"name": name,
                            "description": f"converted from ROSS rotor {Path(source).name}"}
    if others:
        data["supports"] = _supports(others, speed, fail, notes)
    if uniform:
        shaft, zeta = _uniform_shaft(shafts, first_mode_zeta, notes)
        data |= {"shaft": shaft, "discs": discs, "bearings": bearings, "sensors": sensors,
                 "damping": {"first_mode_zeta": 0.0}}
        if zeta is None:          # from beta: w1 of the bare shaft the rig will build
            zeta = _zeta_of_beta(float(shafts[0].beta or 0.0), _rig(data, speed, c_ref,
                                                                      k_ref, source))
            if zeta == 0.0:
                notes.append("the ROSS shaft has no material damping (beta = 0): "
                             "first_mode_zeta = 0, undamped bending modes, which a "
                             "controller check can fail on (give --zeta, e.g. 0.005 for "
                             "steel)")
        data["damping"] = {"first_mode_zeta": zeta}
    else:
        data |= {"shaft": _element_table(shafts, first_mode_zeta is not None),
                 "discs": discs, "bearings": bearings, "sensors": sensors}
        if first_mode_zeta is not None:
            data["damping"] = {"first_mode_zeta": float(first_mode_zeta)}
            notes.append(f"first_mode_zeta {first_mode_zeta:g} given replaces the ROSS "
                         "shaft elements' own damping (alpha, beta)")
    rig = _rig(data, speed, c_ref, k_ref, source)
    return RossConversion(rig=rig, data=rig.to_dict(), notes=tuple(notes))


def _rig(data: dict[str, Any], speed: float, c_ref: float, k_ref: float, source: str
         ) -> Rig:
    full = {**data, "operation": {"nominal_speed_rpm": float(speed)},
            "uncertainty": {"c_ref": float(c_ref), "k_ref": float(k_ref)}}
    return rig_from_dict(full, source=source)


def _refuse_unmapped(shafts: list[Any], rotor: Any, fail: Any) -> None:
    """Raise on what a rig cannot hold (module docstring)."""
    for e in shafts:
        for attr, label in (("axial_force", "axial force"), ("torque", "torque")):
            v = float(getattr(e, attr, 0.0) or 0.0)
            if v != 0.0:
                raise fail(f"shaft element {e.n}", f"{label} {v!r} has no rig equivalent (a "
                           "rig has no axial load or torque stiffening)")
        for attr in ("rotary_inertia", "gyroscopic"):
            if getattr(e, attr, True) is False:
                raise fail(f"shaft element {e.n}", f"{attr}=False; a rig always models "
                           "rotary inertia and gyroscopics (build the ROSS rotor with "
                           f"{attr}=True)")
    shear = [bool(getattr(e, "shear_effects", False)) for e in shafts]
    if any(shear) and not all(shear):
        i = shear.index(not shear[0])
        raise fail(f"shaft element {shafts[i].n}", f"shear_effects={shear[i]} differs from "
                   f"element {shafts[0].n}'s {shear[0]} (a rig is Timoshenko or "
                   "Euler-Bernoulli throughout)")
    params = getattr(rotor, "parameters", None) or {}
    for key in ("alpha", "beta", "default_damping_ratio"):
        v = float(params.get(key, 0.0) or 0.0) if isinstance(params, dict) else 0.0
        if v != 0.0:
            raise fail(f"parameters.{key}", f"{v!r}: damping set on the whole rotor has no "
                       "rig equivalent (give it per shaft element, alpha and beta)")
    if getattr(rotor, "modal_damping_ratio", None) is not None:
        raise fail("modal_damping_ratio", "ROSS's modal damping is set on the modes of the "
                   "rotor with its bearings, which a rig has no exact equivalent of: give "
                   "the rig's [damping] modal_zeta (the free-free rotor's modes) or alpha "
                   "and beta per shaft element")


def _is_uniform(shafts: list[Any]) -> bool:
    """Equal solid Euler-Bernoulli elements of one material, no alpha: the shorthand."""
    e0 = shafts[0]
    return (_same([float(e.L) for e in shafts])
            and _same([float(d) for e in shafts for d in (e.odl, e.odr)])
            and all(float(e.idl) == 0.0 and float(e.idr) == 0.0 for e in shafts)
            and not any(getattr(e, "shear_effects", False) for e in shafts)
            and all(float(getattr(e, "alpha", 0.0) or 0.0) == 0.0 for e in shafts)
            and _same([float(getattr(e, "beta", 0.0) or 0.0) for e in shafts])
            and all(_material(e) == _material(e0) for e in shafts))


def _material(e: Any) -> tuple[float, float, float]:
    return (float(e.material.E), float(e.material.rho), float(e.material.Poisson))


def _uniform_shaft(shafts: list[Any], zeta: float | None, notes: list[str]
                   ) -> tuple[dict[str, Any], float | None]:
    """The uniform shorthand of a uniform ROSS shaft, and the damping ratio if given."""
    E, rho, nu = _material(shafts[0])
    beta = float(getattr(shafts[0], "beta", 0.0) or 0.0)
    if zeta is not None and beta != 0.0:
        notes.append(f"first_mode_zeta {zeta:g} given replaces the ROSS shaft's damping "
                     f"(beta {beta:g} s)")
    return ({"youngs_modulus": E, "density": rho, "poisson": nu,
             "diameter": float(shafts[0].odl),
             "length": float(sum(float(e.L) for e in shafts)),
             "n_nodes": len(shafts) + 1}, zeta)


def _element_table(shafts: list[Any], drop_damping: bool) -> dict[str, Any]:
    """[shaft] with materials and elements, as ROSS has them."""
    names: dict[tuple[float, float, float], str] = {}
    for e in shafts:
        m = _material(e)
        if m not in names:
            base = str(getattr(e.material, "name", "") or "material").replace(" ", "_")
            taken = set(names.values())
            names[m] = base if base not in taken else f"{base}_{len(names) + 1}"
    rows = []
    for e in shafts:
        row: dict[str, Any] = {"length": float(e.L),
                               "od": [float(e.odl), float(e.odr)],
                               "id": [float(e.idl), float(e.idr)],
                               "material": names[_material(e)]}
        if not drop_damping:
            row["alpha"] = float(getattr(e, "alpha", 0.0) or 0.0)
            row["beta"] = float(getattr(e, "beta", 0.0) or 0.0)
        rows.append(row)
    return {"shear": bool(getattr(shafts[0], "shear_effects", False)),
            "materials": {n: {"youngs_modulus": m[0], "density": m[1], "poisson": m[2]}
                          for m, n in names.items()},
            "elements": rows}


def _discs(rotor: Any, fail: Any) -> list[dict[str, Any]]:
    """The discs, D1 and D2 the two heaviest (in node order: the planes the diagnosis
    tries first for unbalance and cross-coupling, an impeller rather than a lamination
    ring), then D3, D4, ... in node order; point masses P1, P2, ..."""
    by_node = sorted(rotor.disk_elements, key=lambda d: (d.n, -float(d.m)))
    heavy = sorted(sorted(by_node, key=lambda d: -float(d.m))[:2], key=lambda d: d.n)
    ordered = heavy + [d for d in by_node if not any(d is h for h in heavy)]
    discs = [{"name": f"D{i + 1}", "node": int(d.n) + 1, "mass": float(d.m),
              "ip": float(d.Ip), "id": float(d.Id)} for i, d in enumerate(ordered)]
    points = sorted(getattr(rotor, "point_mass_elements", None) or [], key=lambda p: p.n)
    for i, p in enumerate(points):
        mx, my = float(getattr(p, "mx", 0.0)), float(getattr(p, "my", 0.0))
        if not math.isclose(mx, my, rel_tol=_RTOL):
            raise fail(f"point mass at node {p.n}", f"mx {mx!r} differs from my {my!r}; a "
                       "rig's masses are the same in x and y")
        if mx > 0:
            discs.append({"name": f"P{i + 1}", "node": int(p.n) + 1, "mass": mx,
                          "ip": 0.0, "id": 0.0})
    return discs


def _supports(elements: list[Any], speed_rpm: float, fail: Any, notes: list[str]
              ) -> list[dict[str, Any]]:
    """[[supports]] of the bearings and seals that are not magnetic (rig/supports.py): each
    one's lateral stiffness, damping and added mass as ROSS evaluates them at the running
    speed (BearingElement.K(frequency), C, M), held fixed."""
    w = speed_rpm * 2.0 * math.pi / 60.0
    out = []
    for i, b in enumerate(sorted(elements, key=lambda e: e.n)):
        what = f"bearing {getattr(b, 'tag', None) or i!r} at node {b.n}"
        if getattr(b, "n_link", None) is not None:
            raise fail(what, f"n_link {b.n_link}: a support linked to another node (a "
                       "pedestal) has no rig equivalent; a rig's supports act on ground")
        entry: dict[str, Any] = {"name": f"S{i + 1}", "node": int(b.n) + 1}
        for p, method in (("k", "K"), ("c", "C"), ("m", "M")):
            try:
                mat = np.asarray(getattr(b, method)(w), dtype=float)[:2, :2]
            except (TypeError, ValueError) as exc:
                raise fail(what, f"its {method} at {w:.6g} rad/s: {exc}") from None
            entry |= nonzero_coefficients(p, mat)
        out.append(entry)
        notes.append(f"{type(b).__name__} {getattr(b, 'tag', '') or ''} at node {b.n} -> "
                     f"support {entry['name']}: its coefficients at {speed_rpm:g} rpm, held "
                     "fixed (not identified)".replace("  ", " "))
    return out


def _magnet_entry(b: Any, fail: Any) -> dict[str, Any]:
    """[bearings] entry of a ROSS magnetic bearing: its node and its magnet's constants."""
    i0 = b.i0
    if isinstance(i0, (list, tuple)) or getattr(i0, "ndim", 0):
        vals = [float(v) for v in (i0 if isinstance(i0, (list, tuple)) else i0.ravel())]
        if not _same(vals):
            raise fail(f"bearing at node {b.n}", f"bias current i0 {vals} differs between "
                       "its axes; a rig's magnet is the same on x and y")
        i0 = vals[0]
    constants = {"gap": float(b.g0), "bias_current": float(i0), "pole_area": float(b.ag),
                 "turns": float(b.nw),
                 "pole_angle": float(getattr(b, "alpha", math.pi / 8))}
    if hasattr(b, "ks") and hasattr(b, "ki"):          # a live element: ROSS's own values
        ki, ks = magnet_constants(**constants)
        if not (math.isclose(ki, float(b.ki), rel_tol=1e-9)
                and math.isclose(ks, -float(b.ks), rel_tol=1e-9)):
            raise fail(f"bearing at node {b.n}", f"ki {float(b.ki)!r}, ks {float(b.ks)!r} "
                       f"are not those of its magnet's constants ({ki!r}, {-ks!r})")
    return {"node": int(b.n) + 1, "magnet": constants}


def _zeta_of_beta(beta: float, rig: Rig) -> float:
    """first_mode_zeta = beta w1 / 2, w1 the first free-free bending frequency (rad/s) of
    the rig's bare shaft (rotor.assembly.first_free_free_bending)."""
    if beta == 0.0:
        return 0.0
    from bayes_amb.rotor.assembly import first_free_free_bending, shaft_matrices

    M, K, _ = shaft_matrices(rig)
    return 0.5 * beta * first_free_free_bending(M, K)


def _value(v: Any) -> str:
    """A TOML value: a string, bool, number, array or (nested) inline table."""
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(a)} = {_value(b)}" for a, b in v.items()) + " }"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return repr(v)


def _key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() else _value(k)


def _is_table_array(v: Any) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def rig_to_toml(data: dict[str, Any]) -> str:
    """Rig-file TOML text of a rig dict (the form of ``Rig.to_dict()``): top-level tables as
    ``[key]``, arrays of tables as ``[[key]]`` (``[[shaft.elements]]`` inside a table), other
    tables inline.

    Examples
    --------
    >>> from bayes_amb.rig import load_rig, rig_from_dict
    >>> import tomllib
    >>> d = load_rig("small_rotor").to_dict()
    >>> tomllib.loads(rig_to_toml(d)) == d
    True
    """
    out = [f"{_key(k)} = {_value(v)}" for k, v in data.items()
           if not isinstance(v, dict) and not _is_table_array(v)]
    for key, v in data.items():
        if isinstance(v, dict):
            out += ["", f"[{_key(key)}]"]
            out += [f"{_key(k2)} = {_value(v2)}" for k2, v2 in v.items()
                    if not _is_table_array(v2)]
            for k2, v2 in v.items():
                if _is_table_array(v2):
                    for item in v2:
                        out += ["", f"[[{_key(key)}.{_key(k2)}]]",
                                *(f"{_key(a)} = {_value(b)}" for a, b in item.items())]
        elif _is_table_array(v):
            for item in v:
                out += ["", f"[[{_key(key)}]]",
                        *(f"{_key(a)} = {_value(b)}" for a, b in item.items())]
    return "\n".join(out) + "\n"


@contextlib.contextmanager
def _silenced() -> Any:
    """Silence file descriptors 1 and 2, Python warnings and the pint logger.

    ROSS's dependencies print REFPROP notices from C code and log unit redefinitions on
    import; the CLI's output must stay one line per error.
    """
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    null = os.open(os.devnull, os.O_WRONLY)
    pint = logging.getLogger("pint")
    level = pint.level
    try:
        os.dup2(null, 1)
        os.dup2(null, 2)
        pint.setLevel(logging.ERROR)
        with (contextlib.redirect_stdout(io.StringIO()),
              contextlib.redirect_stderr(io.StringIO()), warnings.catch_warnings()):
            warnings.simplefilter("ignore")
            yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, null):
            os.close(fd)
        pint.setLevel(level)


def import_ross() -> Any:
    """The ``ross`` module, imported quietly; RigError if the extra is not installed."""
    try:
        with _silenced():
            import ross
    except ImportError:
        raise RigError("ROSS rotor: ross-rotordynamics is not installed (pip install "
                       "'bayes-amb[ross]')") from None
    return ross


def load_ross_rotor(path: str | os.PathLike[str]) -> Any:
    """``ross.Rotor.load(path)``, with one-line errors (RigError).

    ROSS 3.1 saves a MagneticBearingElement but loads it as a plain BearingElement, without
    its magnet or controller. The saved tables still hold them: each such bearing gets its
    magnet's constants (g0, i0, ag, nw, alpha), its sensor node and its PID gains back as
    attributes, read from the file; ROSS is not asked to rebuild the element (it refuses one
    whose controller was a transfer function, which the file does not keep)."""
    p = Path(path)
    if not p.is_file():
        raise RigError(f"ROSS rotor {p}: field <file>: not found")
    ross = import_ross()
    try:
        with _silenced():
            rotor = ross.Rotor.load(str(p))
        tables = tomllib.loads(p.read_text(encoding="utf-8"))
    except Exception as exc:  # ROSS raises many types on a malformed file
        raise RigError(f"ROSS rotor {p}: field <file>: not a readable ROSS rotor "
                       f"({type(exc).__name__}: {str(exc)[:100]})") from None
    keys = (*MAGNET_ATTRS, "alpha", "k_amp", "k_sense", *PID_ATTRS, "sensor_node")
    magnetic = {t.get("tag"): t for t in tables.values()
                if isinstance(t, dict) and all(k in t for k in MAGNET_ATTRS)}
    for b in rotor.bearing_elements:
        t = magnetic.get(getattr(b, "tag", None))
        if t is not None and not hasattr(b, "g0"):
            for k in keys:
                if k in t:
                    setattr(b, k, t[k])
    return rotor
