"""The rig: geometry, materials, discs, bearings and sensors, read from a TOML file.

A rig file is the single description of a machine that every other stage reads. The
reference rig ships inside the package (``reference``); any other rig is a TOML file of
the same form (see README, "Writing a rig file").
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from bayes_amb.errors import RigError
from bayes_amb.rig.reader import FieldReader
from bayes_amb.rig.shaft import Shaft, SteppedShaft, stepped_shaft_from_dict
from bayes_amb.rig.supports import Support, supports_from_list
from bayes_amb.tomlfile import read_toml

CHANNELS: tuple[str, ...] = ("Ax", "Ay", "Bx", "By")
"""Channel names of inputs (currents) and outputs (displacements), in this order."""


def node_label(label: str) -> int | None:
    """j of a shaft-node label 'n<j>' (j >= 1), None for any other label.

    >>> node_label("n12"), node_label("D1"), node_label("n0")
    (12, None, None)
    """
    if label.startswith("n") and label[1:].isdigit() and int(label[1:]) >= 1:
        return int(label[1:])
    return None


@dataclass(frozen=True)
class Disc:
    """Rigid disc at a node: mass in kg, polar ip and diametral id inertia in kg m^2."""

    name: str
    node: int
    mass: float
    ip: float
    id: float


MU0 = 4e-7 * math.pi
"""Permeability of free space, H/m."""
MAGNET_KEYS = {"gap": "nominal air gap g0 (m)", "bias_current": "bias current i0 (A)",
               "pole_area": "pole face area (m^2)", "turns": "turns per coil",
               "pole_angle": "angle of a pole to the bearing's axis (rad)"}
"""The constants of a radial AMB magnet from which ki and ks follow (:func:`magnet_constants`)."""
LAW_KEYS = ("bias_current", "saturation_ratio")
"""The force-law keys a rig file may give beside ki and ks (rig/force_law.py)."""


def magnet_constants(gap: float, bias_current: float, pole_area: float, turns: float,
                     pole_angle: float = math.pi / 8) -> tuple[float, float]:
    """(ki N/A, ks N/m) of a differential pair of electromagnets on one axis, linearised
    about the centre (Schweitzer & Maslen, Magnetic Bearings, 2009, ch. 3 and p. 343).

    Each magnet pulls with F = k (i0 +- i)^2 / (g0 -+ x)^2, k = mu0 n^2 A cos(alpha) / 4;
    the pair's force is ki i + ks x with ki = 4 k i0 / g0^2 and ks = 4 k i0^2 / g0^3 (ks > 0:
    a negative stiffness, as the rest of the chain takes it).

    >>> ki, ks = magnet_constants(4.32e-4, 1.0, 4.703e-4, 138, 0.392)
    >>> round(ki, 4), round(ks, 1)
    (55.7335, 129012.8)
    """
    k = MU0 * turns**2 * pole_area * math.cos(pole_angle) / 4.0
    return 4.0 * k * bias_current / gap**2, 4.0 * k * bias_current**2 / gap**3


@dataclass(frozen=True)
class Magnet:
    """One radial AMB's linear constants, the same on its x and y axes: ki in N/A and ks in
    N/m (f = ki i + ks s; ks > 0 destabilises). ``constants`` holds the magnet's gap, bias
    current, pole area, turns and pole angle when ki and ks were computed from them."""

    ki: float
    ks: float
    constants: tuple[tuple[str, float], ...] = ()
    bias: float | None = None
    saturation: float | None = None
    """The iron's saturation flux density over the bias flux density (``saturation_ratio``
    beside ``bias_current``): the force law then saturates (rig/force_law.py)."""

    @property
    def bias_current(self) -> float | None:
        """The bias current i0 (A) when the rig file gives it (with the constants, or as
        ``bias_current`` beside ki and ks): the magnets' force law then follows, with the
        gap i0 ki / ks that makes its linearisation ki and ks (discrepancy/nonlinear.py)."""
        return dict(self.constants).get("bias_current", self.bias)


@dataclass(frozen=True)
class Rig:
    """A rotor-AMB rig. Node numbers are 1-based as in the rig file.

    bearing_nodes and sensor_nodes map the bearing names ("A", "B") to nodes; each has an
    x and a y axis, giving the channels Ax, Ay, Bx, By.
    """

    name: str
    description: str
    shaft: Shaft | SteppedShaft
    discs: tuple[Disc, ...]
    magnets: dict[str, Magnet]
    bearing_nodes: dict[str, int]
    sensor_nodes: dict[str, int]
    first_mode_zeta: float
    nominal_speed_rpm: float
    c_ref: float
    k_ref: float
    source: str = "<built-in>"
    limits: dict[str, float] = field(default_factory=dict)
    """What the hardware cannot exceed, from the optional [limits] table (LIMIT_KEYS):
    the linearity check fails on a record that reaches them."""
    modal_zeta: float = 0.0
    """Modal damping (the optional [damping] modal_zeta): this ratio on every free-free
    bending mode of the shaft with its discs, non-rotating (rotor/assembly.py)."""
    supports: tuple[Support, ...] = ()
    """Fixed-coefficient supports besides the magnetic bearings (fluid-film bearings,
    seals; the optional [[supports]], rig/supports.py)."""

    @property
    def n_nodes(self) -> int:
        return self.shaft.n_nodes

    @property
    def ki(self) -> float:
        """The bearings' common ki (N/A); RigError when each bearing has its own (then use
        ``magnets[name].ki``)."""
        return self._shared("ki")

    @property
    def ks(self) -> float:
        """The bearings' common ks (N/m); RigError when each bearing has its own (then use
        ``magnets[name].ks``)."""
        return self._shared("ks")

    @property
    def channel_magnets(self) -> tuple[Magnet, ...]:
        """The magnet of each channel Ax, Ay, Bx, By (its bearing's)."""
        return tuple(self.magnets[ch[0]] for ch in CHANNELS)

    def magnet_text(self) -> str:
        """The bearings' ki and ks in words: 'ki = 250 N/A, ks = 1e+06 N/m' when they share
        them, else per bearing."""
        mags = self.magnets
        if len({(m.ki, m.ks) for m in mags.values()}) == 1:
            m = next(iter(mags.values()))
            return f"ki = {m.ki:g} N/A, ks = {m.ks:g} N/m"
        return "; ".join(f"{b}: ki = {m.ki:.4g} N/A, ks = {m.ks:.4g} N/m"
                         for b, m in mags.items())

    def _shared(self, key: str) -> float:
        vals = {b: getattr(m, key) for b, m in self.magnets.items()}
        first = next(iter(vals.values()))
        if any(v != first for v in vals.values()):
            raise RigError(f"rig {self.source}: each bearing has its own {key} ({vals}); "
                           f"take it per bearing (rig.magnets[name].{key})")
        return first

    def shaft_node(self, label: str) -> int | None:
        """The node j of a shaft-node label 'n<j>' (1-based, checked against the shaft);
        None for any other label (a bearing or disc name)."""
        node = node_label(label)
        if node is not None and node > self.n_nodes:
            raise RigError(f"rig {self.source}: node {label!r} out of range; expected "
                           f"n1 .. n{self.n_nodes}")
        return node

    def disc(self, name: str) -> Disc:
        for d in self.discs:
            if d.name == name:
                return d
        raise RigError(f"rig {self.source}: no disc named {name!r}; discs are "
                       f"{[d.name for d in self.discs]}")

    def to_dict(self) -> dict[str, Any]:
        """The rig as a plain dict in rig-file form (for embedding in JSON sidecars)."""
        return {
            "name": self.name,
            "description": self.description,
            "shaft": self.shaft.to_dict(),
            "discs": [{"name": d.name, "node": d.node, "mass": d.mass, "ip": d.ip,
                       "id": d.id} for d in self.discs],
            "bearings": self._bearings_dict(),
            "sensors": {k: {"node": v} for k, v in self.sensor_nodes.items()},
            "damping": {"first_mode_zeta": self.first_mode_zeta,
                        **({"modal_zeta": self.modal_zeta} if self.modal_zeta else {})},
            "operation": {"nominal_speed_rpm": self.nominal_speed_rpm},
            "uncertainty": {"c_ref": self.c_ref, "k_ref": self.k_ref},
            **({"limits": dict(self.limits)} if self.limits else {}),
            **({"supports": [s.to_dict() for s in self.supports]} if self.supports else {}),
        }

    def _bearings_dict(self) -> dict[str, Any]:
        """[bearings] as a rig file has it: one ki and ks for both when they share them
        (the shorthand), else per bearing (its magnet's constants where it was given so)."""
        mags = self.magnets
        shared = (all(not m.constants for m in mags.values())
                  and len({(m.ki, m.ks, m.bias, m.saturation) for m in mags.values()}) == 1)
        if shared:
            m = next(iter(mags.values()))
            return {"ki": m.ki, "ks": m.ks, **_law_keys(m),
                    **{k: {"node": v} for k, v in self.bearing_nodes.items()}}
        out: dict[str, Any] = {}
        for b, node in self.bearing_nodes.items():
            m = mags[b]
            out[b] = ({"node": node, "magnet": dict(m.constants)} if m.constants
                      else {"node": node, "ki": m.ki, "ks": m.ks, **_law_keys(m)})
        return out


def _law_keys(m: Magnet) -> dict[str, float]:
    """A magnet's force-law keys as the rig file has them (none for a linear magnet)."""
    return {**({} if m.bias is None else {"bias_current": m.bias}),
            **({} if m.saturation is None else {"saturation_ratio": m.saturation})}


SHIPPED_RIGS = ("reference", "small_rotor", "ross_test_rig")
"""Rig files shipped in bayes_amb/rig/data/, loadable by name."""
_TOP_KEYS = {"name", "description", "shaft", "discs", "bearings", "sensors", "damping",
             "operation", "uncertainty", "limits", "supports"}
_SHAFT_KEYS = {"youngs_modulus", "density", "poisson", "diameter", "length", "n_nodes"}
_DISC_KEYS = {"name", "node", "mass", "ip", "id"}


def rig_from_dict(data: dict[str, Any], source: str = "<dict>") -> Rig:
    """Build and validate a Rig from a rig-file dict; raises RigError naming the field."""
    r = FieldReader(source)
    if not isinstance(data, dict):
        raise r.fail("<top>", f"expected a table, got {type(data).__name__}")
    extra = sorted(set(data) - _TOP_KEYS)
    if extra:
        raise r.fail(extra[0], f"unknown key (allowed: {sorted(_TOP_KEYS)})")
    name = data.get("name", Path(source).stem)
    if not isinstance(name, str) or not name:
        raise r.fail("name", f"expected a non-empty string, got {name!r}")
    sh = r.table(data, "shaft", "shaft")
    shaft: Shaft | SteppedShaft
    if "elements" in sh:
        shaft = stepped_shaft_from_dict(sh, r)
    else:
        r.row(sh, "shaft", _SHAFT_KEYS)
        n_nodes = sh.get("n_nodes")
        if isinstance(n_nodes, bool) or not isinstance(n_nodes, int) or n_nodes < 2:
            raise r.fail("shaft.n_nodes", f"expected an integer >= 2, got {n_nodes!r}")
        shaft = Shaft(
            youngs_modulus=r.number(sh, "youngs_modulus", "shaft.youngs_modulus"),
            density=r.number(sh, "density", "shaft.density"),
            poisson=r.number(sh, "poisson", "shaft.poisson", nonneg=True, upper=0.5),
            diameter=r.number(sh, "diameter", "shaft.diameter"),
            length=r.number(sh, "length", "shaft.length"),
            n_nodes=n_nodes,
        )
    n_nodes = shaft.n_nodes
    discs = []
    for f, d, dname in r.named_rows(data.get("discs", []), "discs", _DISC_KEYS, "D"):
        discs.append(Disc(
            name=dname,
            node=r.node(d, "node", f"{f}.node", n_nodes),
            mass=r.number(d, "mass", f"{f}.mass"),
            ip=r.number(d, "ip", f"{f}.ip", nonneg=True),
            id=r.number(d, "id", f"{f}.id", nonneg=True),
        ))
    r.unique_names([d.name for d in discs], "discs", "disc")
    bt = r.table(data, "bearings", "bearings", {"ki", "ks", *LAW_KEYS, "A", "B"})
    bearing_nodes = {}
    sensor_nodes = {}
    magnets = {}
    st = r.table(data, "sensors", "sensors", {"A", "B"})
    for b in ("A", "B"):
        tb = r.table(bt, b, f"bearings.{b}", {"node", "ki", "ks", *LAW_KEYS, "magnet"})
        bearing_nodes[b] = r.node(tb, "node", f"bearings.{b}.node", n_nodes)
        magnets[b] = _magnet(r, bt, tb, b)
        sensor_nodes[b] = r.node(r.table(st, b, f"sensors.{b}", {"node"}), "node",
                                 f"sensors.{b}.node", n_nodes)
    if bearing_nodes["A"] == bearing_nodes["B"]:
        raise r.fail("bearings.B.node", f"bearings A and B share node {bearing_nodes['A']}")
    zeta, modal = _damping(r, data, isinstance(shaft, SteppedShaft))
    op = r.table(data, "operation", "operation", {"nominal_speed_rpm"})
    speed = r.number(op, "nominal_speed_rpm", "operation.nominal_speed_rpm", nonneg=True)
    un = data.get("uncertainty", {"c_ref": 1000.0, "k_ref": 1.0e5})
    if not isinstance(un, dict):
        raise r.fail("uncertainty", f"expected a table, got {un!r}")
    bad = sorted(set(un) - {"c_ref", "k_ref"})
    if bad:
        raise r.fail(f"uncertainty.{bad[0]}", "unknown key (allowed: ['c_ref', 'k_ref'])")
    c_ref = r.number({"c_ref": 1000.0, **un}, "c_ref", "uncertainty.c_ref")
    k_ref = r.number({"k_ref": 1.0e5, **un}, "k_ref", "uncertainty.k_ref")
    limits = _limits(r, data.get("limits", {}))
    supports = supports_from_list(data.get("supports", []), r, n_nodes)
    desc = data.get("description", "")
    if not isinstance(desc, str):
        raise r.fail("description", f"expected a string, got {desc!r}")
    return Rig(name=name, description=desc, shaft=shaft, discs=tuple(discs), magnets=magnets,
               bearing_nodes=bearing_nodes, sensor_nodes=sensor_nodes, first_mode_zeta=zeta,
               nominal_speed_rpm=speed, c_ref=c_ref, k_ref=k_ref, source=source,
               limits=limits, modal_zeta=modal, supports=supports)


def _damping(r: Any, data: dict, stepped: bool) -> tuple[float, float]:
    """[damping]: (first_mode_zeta, modal_zeta), one of them or neither (a stepped shaft's
    elements carry their own Rayleigh damping, and the table may be left out)."""
    if stepped and "damping" not in data:
        return 0.0, 0.0
    dt_ = r.table(data, "damping", "damping", {"first_mode_zeta", "modal_zeta"})
    if "modal_zeta" not in dt_:
        return r.number(dt_, "first_mode_zeta", "damping.first_mode_zeta", nonneg=True,
                        upper=1.0), 0.0
    modal = r.number(dt_, "modal_zeta", "damping.modal_zeta", nonneg=True, upper=1.0)
    first = (r.number(dt_, "first_mode_zeta", "damping.first_mode_zeta", nonneg=True,
                      upper=1.0) if "first_mode_zeta" in dt_ else 0.0)
    if first and modal:
        raise r.fail("damping.modal_zeta", "give first_mode_zeta or modal_zeta, not both")
    return first, modal


def _magnet(r: Any, bt: dict, tb: dict, b: str) -> Magnet:
    """Bearing b's ki and ks: its own (ki, ks, or a magnet table), else the [bearings]
    table's shared ki and ks."""
    f = f"bearings.{b}"
    if "magnet" in tb:
        if "ki" in tb or "ks" in tb or any(k in tb for k in LAW_KEYS):
            raise r.fail(f"{f}.magnet", "give ki and ks (and bias_current) or the magnet's "
                         "constants, not both")
        mt = r.table(tb, "magnet", f"{f}.magnet", set(MAGNET_KEYS))
        vals = {k: r.number(mt, k, f"{f}.magnet.{k}", nonneg=k == "pole_angle",
                            upper=math.pi / 2 if k == "pole_angle" else None)
                for k in MAGNET_KEYS if k != "pole_angle" or k in mt}
        ki, ks = magnet_constants(**vals)
        return Magnet(ki=ki, ks=ks, constants=tuple(vals.items()))
    src, where = (tb, f) if ("ki" in tb or "ks" in tb) else (bt, "bearings")
    bsrc, bwhere = (tb, f) if "bias_current" in tb else (bt, "bearings")
    bias = (r.number(bsrc, "bias_current", f"{bwhere}.bias_current")
            if "bias_current" in bsrc else None)
    ssrc, swhere = (tb, f) if "saturation_ratio" in tb else (bt, "bearings")
    saturation = None
    if "saturation_ratio" in ssrc:
        key = f"{swhere}.saturation_ratio"
        saturation = r.number(ssrc, "saturation_ratio", key)
        if bias is None:
            raise r.fail(key, "a saturation ratio needs the magnets' bias_current beside it")
        if not saturation > 1.0:
            raise r.fail(key, f"{saturation} is not above 1 (the bias flux density would "
                         "already be past saturation)")
    return Magnet(ki=r.number(src, "ki", f"{where}.ki"),
                  ks=r.number(src, "ks", f"{where}.ks", nonneg=True), bias=bias,
                  saturation=saturation)


LIMIT_KEYS = {"current_a": "the largest control current the amplifiers deliver, |u| (A)",
              "slew_a_per_s": "the amplifiers' largest current slew rate, |du/dt| (A/s)",
              "sensor_range_m": "the probes' measuring range, |y| (m)"}
"""The optional [limits] of a rig file (each a positive number, any subset)."""


def _limits(r: Any, table: Any) -> dict[str, float]:
    if not isinstance(table, dict):
        raise r.fail("limits", f"expected a table, got {table!r}")
    bad = sorted(set(table) - set(LIMIT_KEYS))
    if bad:
        raise r.fail(f"limits.{bad[0]}", f"unknown key (allowed: {sorted(LIMIT_KEYS)})")
    return {k: r.number(table, k, f"limits.{k}") for k in LIMIT_KEYS if k in table}


def load_rig(path: str | Path | None = None) -> Rig:
    """Load a rig: None or "reference" gives the shipped reference rig, a name in
    ``SHIPPED_RIGS`` (e.g. "small_rotor", the example of docs/your_rig.md) another shipped
    rig, anything else is a TOML path.

    Examples
    --------
    >>> rig = load_rig()
    >>> rig.n_nodes, rig.bearing_nodes["B"]
    (40, 33)
    >>> load_rig("small_rotor").bearing_nodes
    {'A': 5, 'B': 29}
    """
    if path is None or str(path) in SHIPPED_RIGS:
        name = "reference" if path is None else str(path)
        text = resources.files("bayes_amb.rig").joinpath(f"data/{name}.toml").read_text()
        return rig_from_dict(tomllib.loads(text), source=name)
    return rig_from_dict(read_toml(path, "rig file", RigError), source=str(Path(path)))


def check_speed_rpm(rig: Rig, speed_rpm: float | None = None) -> float:
    """The operating speed in rpm: ``speed_rpm``, or the rig's nominal speed when None.

    Raises RigError (naming ``--speed-rpm``) unless 0 <= speed_rpm <= 2 x nominal, the
    range over which the model and the controller are checked.

    Examples
    --------
    >>> rig = load_rig()
    >>> check_speed_rpm(rig), check_speed_rpm(rig, 1000)
    (31500.0, 1000.0)
    >>> check_speed_rpm(rig, -5)
    Traceback (most recent call last):
    ...
    bayes_amb.errors.RigError: option --speed-rpm: value -5 out of range: must be in 0..63000 rpm
    """
    speed = rig.nominal_speed_rpm if speed_rpm is None else float(speed_rpm)
    top = 2 * rig.nominal_speed_rpm
    if not 0 <= speed <= top:                       # also refuses nan
        raise RigError(f"option --speed-rpm: value {speed:g} out of range: must be in "
                       f"0..{top:g} rpm")
    return speed


def _flat(d: Any, prefix: str = "") -> dict[str, Any]:
    """{"shaft.length": 0.45, "discs[0].mass": 6.0, ...} of a rig-file dict."""
    if isinstance(d, dict):
        out: dict[str, Any] = {}
        for k, v in d.items():
            out.update(_flat(v, f"{prefix}.{k}" if prefix else str(k)))
        return out
    if isinstance(d, (list, tuple)):
        out = {f"{prefix}.count": len(d)}
        for i, v in enumerate(d):
            out.update(_flat(v, f"{prefix}[{i}]"))
        return out
    return {prefix: d}


def rig_difference(a: Rig, b: Rig, rtol: float = 1e-9) -> str | None:
    """The first field in which two rigs differ as models, ``"shaft.length: 0.6 against
    0.65"``, or None when they describe the same rotor. The name and description are labels
    and not compared; numbers agree to ``rtol`` (relative).

    Examples
    --------
    >>> rig_difference(load_rig(), load_rig()) is None
    True
    >>> rig_difference(load_rig(), load_rig("small_rotor"))
    'shaft.youngs_modulus: 211000000000.0 against 205000000000.0'
    """
    fa, fb = _flat(a.to_dict()), _flat(b.to_dict())
    for key in [*fa, *(k for k in fb if k not in fa)]:
        if key in ("name", "description"):
            continue
        va, vb = fa.get(key), fb.get(key)
        same = (va == vb if not (isinstance(va, float) and isinstance(vb, (int, float)))
                else abs(va - vb) <= rtol * max(abs(va), abs(vb)))
        if not same:
            return f"{key}: {va!r} against {vb!r}"
    return None


def check_rig_matches(path: str | Path, embedded: Rig, where: str) -> None:
    """Refuse (RigError, one line naming both) when the rig file ``path`` (or a shipped
    rig's name) is not the rig embedded in ``where`` (a recording): a model is always built
    from the recording's own rig, and ``--rig`` only checks that it is the one meant."""
    given = load_rig(path)
    diff = rig_difference(given, embedded)
    if diff is not None:
        raise RigError(f"option --rig: rig file {path} is not the rig embedded in {where} "
                       f"({given.name!r} against {embedded.name!r}); first difference "
                       f"{diff} (file against recording)")
