"""Convert a ROSS rotor (ross-rotordynamics, optional extra ``bayes-amb[ross]``) to a rig.

What maps, one to one (ROSS nodes are 0-based, rig nodes 1-based):

- ``ShaftElement`` -> ``[shaft]``: the rig has a uniform solid shaft, so every element must
  have the same length, zero inner diameter, the same outer diameter at both ends and the
  same material (E, rho, Poisson). Shear deformation is not modelled (Euler-Bernoulli with
  rotary inertia and gyroscopics); a ROSS shaft with ``shear_effects=True`` is converted
  and the conversion notes it.
- ``DiskElement`` -> ``[[discs]]`` (m, Ip, Id), named D1, D2, ... in node order.
- two ``MagneticBearingElement`` -> ``[bearings]``: ki, and ks = -ROSS ks (ROSS writes the
  negative stiffness with its sign; the rig file the magnitude, f = ki i + ks s); both
  bearings must share ki and ks. Each bearing's ``sensor_node`` gives ``[sensors]``.
- ``rated_w`` (rad/s), when set, gives ``nominal_speed_rpm``.
- the shaft's stiffness-proportional material damping ``beta`` (ROSS: C = alpha M + beta K
  per element) -> ``[damping] first_mode_zeta``: the rig's damping is C = beta K_shaft with
  beta = 2 zeta / w1 (w1 the bare shaft's first free-free bending frequency,
  rotor.assembly), so zeta = beta w1 / 2 carries ROSS's beta exactly. An explicit
  ``first_mode_zeta`` (``--zeta``) replaces it, and the conversion notes that.

Refused with one line naming the element and field (the rig would silently differ):
mass-proportional damping (``alpha`` != 0), ``beta`` varying along the shaft, an axial
force or torque on a shaft element, ``rotary_inertia=False`` or ``gyroscopic=False`` (the
rig always has both), point masses. ROSS's own bearing controller (PID gains, transfer
function) is not part of a rig and is noted; seals and other bearings are refused (above);
axial/torsional DOFs are not modelled. The controller is designed or imported separately
(``bayes-amb controller``, ``bayes-amb import-controller``).
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

from bayes_amb.errors import RigError
from bayes_amb.rig.rig import Rig, rig_from_dict

__all__ = ["RossConversion", "rig_from_ross", "rig_to_toml"]

_RTOL = 1e-9


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
        The rotor (uniform solid shaft, discs, two magnetic bearings).
    name, source : str
        Rig name; where the rotor came from (for messages).
    nominal_speed_rpm : float, optional
        Default: the rotor's ``rated_w`` in rpm; required if that is not set.
    first_mode_zeta : float, optional
        Default: from the ROSS shaft's ``beta`` (zeta = beta w1 / 2, module docstring);
        a value given replaces it (noted).
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
    notes = []
    for key, label in (("L", "length"), ("odl", "outer diameter (left)"),
                       ("odr", "outer diameter (right)")):
        vals = [float(getattr(e, key)) for e in shafts]
        if not _same(vals):
            i = next(i for i, v in enumerate(vals) if not math.isclose(v, vals[0], rel_tol=_RTOL))
            raise fail(f"shaft element {shafts[i].n}", f"{label} {vals[i]!r} differs from "
                       f"element {shafts[0].n}'s {vals[0]!r} (a rig has a uniform shaft of "
                       "equal elements)")
    if not math.isclose(float(shafts[0].odl), float(shafts[0].odr), rel_tol=_RTOL):
        raise fail(f"shaft element {shafts[0].n}", "tapered (odl != odr); a rig has a "
                   "uniform shaft")
    for e in shafts:
        if float(e.idl) != 0.0 or float(e.idr) != 0.0:
            raise fail(f"shaft element {e.n}", f"hollow (inner diameter {float(e.idl)!r}); a "
                       "rig has a solid shaft")
    mats = [(float(e.material.E), float(e.material.rho), float(e.material.Poisson))
            for e in shafts]
    for k, label in enumerate(("E", "rho", "Poisson")):
        if not _same([m[k] for m in mats]):
            raise fail("shaft_elements", f"material {label} varies along the shaft")
    for e in shafts:
        for attr, label in (("alpha", "mass-proportional damping alpha"),
                            ("axial_force", "axial force"), ("torque", "torque")):
            v = float(getattr(e, attr, 0.0) or 0.0)
            if v != 0.0:
                raise fail(f"shaft element {e.n}", f"{label} {v!r} has no rig equivalent (a "
                           "rig holds stiffness-proportional damping beta only, and no "
                           "axial load)" if attr == "alpha" else f"{label} {v!r} has no rig "
                           "equivalent (a rig has no axial load or torque stiffening)")
        for attr in ("rotary_inertia", "gyroscopic"):
            if getattr(e, attr, True) is False:
                raise fail(f"shaft element {e.n}", f"{attr}=False; a rig always models "
                           "rotary inertia and gyroscopics (build the ROSS rotor with "
                           f"{attr}=True)")
    betas = [float(getattr(e, "beta", 0.0) or 0.0) for e in shafts]
    if not _same(betas) and not all(b == 0.0 for b in betas):
        i = next(i for i, v in enumerate(betas) if not math.isclose(v, betas[0],
                                                                     rel_tol=_RTOL))
        raise fail(f"shaft element {shafts[i].n}", f"damping beta {betas[i]!r} differs from "
                   f"element {shafts[0].n}'s {betas[0]!r} (a rig has one material damping)")
    points = list(getattr(rotor, "point_mass_elements", None) or [])
    if points:
        raise fail(f"point mass at node {points[0].n}", f"{len(points)} point mass "
                   "element(s); a rig has no point masses (model them as discs)")
    if any(getattr(e, "shear_effects", False) for e in shafts):
        notes.append("shear deformation (ROSS shear_effects=True) is not modelled: "
                     "Euler-Bernoulli beams with rotary inertia")
    n_nodes = len(shafts) + 1
    discs = [{"name": f"D{i + 1}", "node": int(d.n) + 1, "mass": float(d.m),
              "ip": float(d.Ip), "id": float(d.Id)}
             for i, d in enumerate(sorted(rotor.disk_elements, key=lambda d: d.n))]
    mbs = [b for b in rotor.bearing_elements if hasattr(b, "ki") and hasattr(b, "ks")]
    others = [b for b in rotor.bearing_elements if b not in mbs]
    if len(mbs) != 2 or others:
        raise fail("bearing_elements", f"expected exactly 2 MagneticBearingElement, got "
                   f"{len(mbs)} (and {len(others)} other bearings or seals)")
    mbs.sort(key=lambda b: b.n)
    ki, ks = [float(b.ki) for b in mbs], [-float(b.ks) for b in mbs]
    if not (_same(ki) and _same(ks)):
        raise fail(f"bearing at node {mbs[1].n}", f"ki {ki[1]!r}, ks {-ks[1]!r} differ from "
                   f"the bearing at node {mbs[0].n} (ki {ki[0]!r}, ks {-ks[0]!r}); a rig "
                   "has one ki and ks")
    if any(getattr(b, "n_link", None) is not None for b in mbs):
        notes.append("bearing links to support nodes (n_link) are ignored: rigid ground")
    speed = nominal_speed_rpm
    if speed is None:
        rated = getattr(rotor, "rated_w", None)
        if rated is None:
            raise fail("rated_w", "not set; give nominal_speed_rpm")
        speed = float(rated) * 60.0 / (2.0 * math.pi)
    m0 = mats[0]
    beta = betas[0]
    data = _rig_data(name, source, m0, shafts, n_nodes, discs, ki[0], ks[0], mbs, 0.0,
                     speed, c_ref, k_ref)
    zeta_ross = _zeta_of_beta(beta, rig_from_dict(data, source=source))
    if first_mode_zeta is None:
        first_mode_zeta = zeta_ross
        if beta == 0.0:
            notes.append("the ROSS shaft has no material damping (beta = 0): "
                         "first_mode_zeta = 0, undamped bending modes, which a controller "
                         "check can fail on (give --zeta, e.g. 0.005 for steel)")
    elif not math.isclose(first_mode_zeta, zeta_ross, rel_tol=1e-6, abs_tol=1e-12):
        notes.append(f"first_mode_zeta {first_mode_zeta:g} given replaces the ROSS shaft's "
                     f"damping (beta {beta:g} s, i.e. first_mode_zeta {zeta_ross:.6g})")
    if mbs and any(getattr(b, "kp_pid", None) for b in mbs):
        notes.append("the ROSS bearings' controller (kp_pid, kd_pid, k_amp, k_sense) is not "
                     "part of a rig: design one (bayes-amb controller) or import the real "
                     "one (bayes-amb import-controller)")
    data = _rig_data(name, source, m0, shafts, n_nodes, discs, ki[0], ks[0], mbs,
                     float(first_mode_zeta), speed, c_ref, k_ref)
    rig = rig_from_dict(data, source=source)
    return RossConversion(rig=rig, data=data, notes=tuple(notes))


def _rig_data(name: str, source: str, m0: tuple[float, float, float], shafts: list[Any],
              n_nodes: int, discs: list[dict[str, Any]], ki: float, ks: float, mbs: list[Any],
              zeta: float, speed: float, c_ref: float, k_ref: float) -> dict[str, Any]:
    """The rig-file dict of a converted rotor."""
    return {"name": name,
            "description": f"converted from ROSS rotor {Path(source).name}",
            "shaft": {"youngs_modulus": m0[0], "density": m0[1], "poisson": m0[2],
                      "diameter": float(shafts[0].odl),
                      "length": float(sum(float(e.L) for e in shafts)), "n_nodes": n_nodes},
            "discs": discs,
            "bearings": {"ki": ki, "ks": ks, "A": {"node": int(mbs[0].n) + 1},
                         "B": {"node": int(mbs[1].n) + 1}},
            "sensors": {"A": {"node": int(getattr(mbs[0], "sensor_node", mbs[0].n)) + 1},
                        "B": {"node": int(getattr(mbs[1], "sensor_node", mbs[1].n)) + 1}},
            "damping": {"first_mode_zeta": zeta},
            "operation": {"nominal_speed_rpm": float(speed)},
            "uncertainty": {"c_ref": float(c_ref), "k_ref": float(k_ref)}}


def _zeta_of_beta(beta: float, rig: Rig) -> float:
    """first_mode_zeta = beta w1 / 2, w1 the first free-free bending frequency (rad/s) of
    the rig's bare shaft (rotor.assembly.first_free_free_bending)."""
    if beta == 0.0:
        return 0.0
    from bayes_amb.rotor.assembly import first_free_free_bending, shaft_matrices

    M, K, _ = shaft_matrices(rig)
    return 0.5 * beta * first_free_free_bending(M, K)


def _value(v: Any) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    return repr(v)


def rig_to_toml(data: dict[str, Any]) -> str:
    """Rig-file TOML text of a rig dict (the form of ``Rig.to_dict()``).

    Examples
    --------
    >>> from bayes_amb.rig import load_rig, rig_from_dict
    >>> import tomllib
    >>> d = load_rig("small_rotor").to_dict()
    >>> tomllib.loads(rig_to_toml(d)) == d
    True
    """
    out = [f"{k} = {_value(v)}" for k, v in data.items() if not isinstance(v, (dict, list))]
    for key, v in data.items():
        if isinstance(v, dict):
            out += ["", f"[{key}]"]
            for k2, v2 in v.items():
                if isinstance(v2, dict):
                    inner = ", ".join(f"{a} = {_value(b)}" for a, b in v2.items())
                    out.append(f"{k2} = {{ {inner} }}")
                else:
                    out.append(f"{k2} = {_value(v2)}")
        elif isinstance(v, list):
            for item in v:
                out += ["", f"[[{key}]]", *(f"{a} = {_value(b)}" for a, b in item.items())]
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
    """``ross.Rotor.load(path)``, with one-line errors (RigError)."""
    p = Path(path)
    if not p.is_file():
        raise RigError(f"ROSS rotor {p}: field <file>: not found")
    ross = import_ross()
    try:
        rotor = ross.Rotor.load(str(p))
        tables = tomllib.loads(p.read_text(encoding="utf-8"))
    except Exception as exc:  # ROSS raises many types on a malformed file
        raise RigError(f"ROSS rotor {p}: field <file>: not a readable ROSS rotor "
                       f"({type(exc).__name__}: {str(exc)[:100]})") from None
    # ROSS 3.1 saves a MagneticBearingElement but loads it as a plain BearingElement:
    # rebuild each one from its saved parameters to recover ki, ks and the sensor node
    keys = ("g0", "i0", "ag", "nw", "alpha", "k_amp", "k_sense", "kp_pid", "kd_pid",
            "ki_pid", "sensor_node")
    magnetic = {t.get("tag"): t for t in tables.values()
                if isinstance(t, dict) and all(k in t for k in ("g0", "i0", "ag", "nw"))}
    for b in rotor.bearing_elements:
        t = magnetic.get(getattr(b, "tag", None))
        if t is not None and not hasattr(b, "ki"):
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    mb = ross.MagneticBearingElement(n=int(t["n"]),
                                                     **{k: t[k] for k in keys if k in t})
            except Exception as exc:  # as above: ROSS's own validation
                raise RigError(f"ROSS rotor {p}: bearing {t.get('tag')!r}: not a valid "
                               f"magnetic bearing ({type(exc).__name__}: {str(exc)[:100]})"
                               ) from None
            b.ki, b.ks, b.sensor_node = mb.ki, mb.ks, mb.sensor_node
            for k in ("kp_pid", "kd_pid", "ki_pid", "k_amp", "k_sense"):
                setattr(b, k, getattr(mb, k, None))
    return rotor
