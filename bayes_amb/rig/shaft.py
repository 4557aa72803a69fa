"""The shaft of a rig: a uniform solid tube (the shorthand of the paper's reference rig), or
a table of elements as ROSS describes a real rotor (stepped, hollow, tapered, a material and
a Rayleigh damping per element, Timoshenko shear as an option).

Both give the same things to the rest of the chain: the node positions, the elements'
sections, and the masses along the shaft. rotor.assembly builds M, K, G and C from them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Shaft:
    """Uniform solid shaft, Euler-Bernoulli elements of equal length (the shorthand).

    Attributes are SI: youngs_modulus in Pa, density in kg/m^3, diameter and length in m.
    """

    youngs_modulus: float
    density: float
    poisson: float
    diameter: float
    length: float
    n_nodes: int

    uniform = True
    shear = False

    @property
    def area(self) -> float:
        """Cross-section area, m^2."""
        return math.pi * self.diameter**2 / 4.0

    @property
    def second_moment(self) -> float:
        """Second moment of area I, m^4."""
        return math.pi * self.diameter**4 / 64.0

    @property
    def node_z(self) -> list[float]:
        """Axial node positions, m, node 1 at z = 0."""
        h = self.length / (self.n_nodes - 1)
        return [i * h for i in range(self.n_nodes)]

    @property
    def max_diameter(self) -> float:
        return self.diameter

    def text(self) -> str:
        """'shaft 90 mm x 0.45 m'."""
        return f"shaft {self.diameter * 1e3:g} mm x {self.length:g} m"

    def mass_items(self) -> list[tuple[float, float]]:
        """(mass kg, axial position of its centre m) of the shaft: one item."""
        return [(self.density * self.area * self.length, self.length / 2.0)]

    def to_dict(self) -> dict[str, Any]:
        return {"youngs_modulus": self.youngs_modulus, "density": self.density,
                "poisson": self.poisson, "diameter": self.diameter, "length": self.length,
                "n_nodes": self.n_nodes}


@dataclass(frozen=True)
class Material:
    """A shaft material: youngs_modulus in Pa, density in kg/m^3, poisson (-)."""

    name: str
    youngs_modulus: float
    density: float
    poisson: float


@dataclass(frozen=True)
class ShaftSection:
    """One shaft element between two nodes: length (m), outer and inner diameter at its left
    and right end (m; linear in between), its material, and its Rayleigh damping
    C_e = alpha M_e + beta K_e (alpha in 1/s, beta in s)."""

    length: float
    od: tuple[float, float]
    id: tuple[float, float]
    material: Material
    alpha: float = 0.0
    beta: float = 0.0

    @property
    def mass(self) -> float:
        """kg (a conical frustum of a ring)."""
        (a, b), (c, d) = self.od, self.id
        return (self.material.density * math.pi * self.length / 12.0
                * ((a * a + a * b + b * b) - (c * c + c * d + d * d)))


@dataclass(frozen=True)
class SteppedShaft:
    """A shaft as a table of elements, node j at the left end of element j (1-based).

    ``shear``: Timoshenko elements (shear deformation; Cowper's coefficient) when True,
    Euler-Bernoulli when False. Rotary inertia and gyroscopics always."""

    elements: tuple[ShaftSection, ...]
    shear: bool = False

    uniform = False

    @property
    def n_nodes(self) -> int:
        return len(self.elements) + 1

    @property
    def length(self) -> float:
        return float(sum(e.length for e in self.elements))

    @property
    def node_z(self) -> list[float]:
        z = [0.0]
        for e in self.elements:
            z.append(z[-1] + e.length)
        return z

    @property
    def max_diameter(self) -> float:
        return max(max(e.od) for e in self.elements)

    def text(self) -> str:
        """'stepped shaft of 52 Timoshenko elements, 6.35-54 mm x 0.646 m'."""
        ods = [d for e in self.elements for d in e.od]
        kind = "Timoshenko" if self.shear else "Euler-Bernoulli"
        return (f"stepped shaft of {len(self.elements)} {kind} elements, "
                f"{min(ods) * 1e3:g}-{max(ods) * 1e3:g} mm x {self.length:.4g} m")

    def mass_items(self) -> list[tuple[float, float]]:
        """(mass kg, axial position m) of each element, at its mid-length."""
        z = self.node_z
        return [(e.mass, z[j] + e.length / 2.0) for j, e in enumerate(self.elements)]

    def to_dict(self) -> dict[str, Any]:
        mats: dict[str, Material] = {}
        for e in self.elements:
            mats.setdefault(e.material.name, e.material)
        rows: list[dict[str, Any]] = []
        for e in self.elements:
            row: dict[str, Any] = {"length": e.length,
                                   "od": e.od[0] if e.od[0] == e.od[1] else list(e.od)}
            if any(e.id):
                row["id"] = e.id[0] if e.id[0] == e.id[1] else list(e.id)
            row["material"] = e.material.name
            if e.alpha:
                row["alpha"] = e.alpha
            if e.beta:
                row["beta"] = e.beta
            if rows and {k: v for k, v in rows[-1].items() if k != "repeat"} == row:
                rows[-1]["repeat"] = rows[-1].get("repeat", 1) + 1     # runs of equal ones
            else:
                rows.append(row)
        return {"shear": self.shear,
                "materials": {n: {"youngs_modulus": m.youngs_modulus, "density": m.density,
                                  "poisson": m.poisson} for n, m in mats.items()},
                "elements": rows}


ELEMENT_KEYS = {"length", "od", "id", "material", "alpha", "beta", "repeat"}
MATERIAL_KEYS = {"youngs_modulus", "density", "poisson"}


def stepped_shaft_from_dict(sh: dict[str, Any], r: Any) -> SteppedShaft:
    """The ``[shaft]`` table with ``elements`` (and ``materials``, ``shear``); ``r`` is the
    rig file's reader (rig.reader.FieldReader), which names file and field in every error."""
    allowed = {"elements", "materials", "shear"}
    bad = sorted(set(sh) - allowed)
    if bad:
        raise r.fail(f"shaft.{bad[0]}", f"unknown key beside elements (allowed: "
                     f"{sorted(allowed)})")
    shear = sh.get("shear", False)
    if not isinstance(shear, bool):
        raise r.fail("shaft.shear", f"expected true or false, got {shear!r}")
    mats_raw = sh.get("materials", {})
    if not isinstance(mats_raw, dict) or not mats_raw:
        raise r.fail("shaft.materials", "expected a table of named materials, e.g. steel = "
                     "{ youngs_modulus = 2.1e11, density = 7850, poisson = 0.3 }")
    mats = {}
    for name, m in mats_raw.items():
        f = f"shaft.materials.{name}"
        r.row(m, f, MATERIAL_KEYS)
        mats[name] = Material(name, r.number(m, "youngs_modulus", f"{f}.youngs_modulus"),
                              r.number(m, "density", f"{f}.density"),
                              r.number(m, "poisson", f"{f}.poisson", nonneg=True, upper=0.5))
    rows = sh["elements"]
    if not isinstance(rows, list) or not rows:
        raise r.fail("shaft.elements", f"expected an array of tables, got {rows!r}")
    elements = []
    for i, e in enumerate(rows):
        f = f"shaft.elements[{i}]"
        r.row(e, f, ELEMENT_KEYS)
        mat = e.get("material", next(iter(mats)) if len(mats) == 1 else None)
        if mat not in mats:
            raise r.fail(f"{f}.material", f"expected one of {sorted(mats)}, got {mat!r}")
        od = _pair(r, e, "od", f"{f}.od", positive=True)
        id_ = _pair(r, e, "id", f"{f}.id", positive=False) if "id" in e else (0.0, 0.0)
        for end, (o, i_) in enumerate(zip(od, id_, strict=True)):
            if i_ >= o:
                raise r.fail(f"{f}.id", f"inner diameter {i_!r} at the "
                             f"{('left', 'right')[end]} end is not below the outer {o!r}")
        repeat = e.get("repeat", 1)
        if isinstance(repeat, bool) or not isinstance(repeat, int) or repeat < 1:
            raise r.fail(f"{f}.repeat", f"expected an integer >= 1, got {repeat!r}")
        sec = ShaftSection(length=r.number(e, "length", f"{f}.length"), od=od, id=id_,
                           material=mats[mat],
                           alpha=r.number({"alpha": 0.0, **e}, "alpha", f"{f}.alpha",
                                          nonneg=True),
                           beta=r.number({"beta": 0.0, **e}, "beta", f"{f}.beta",
                                         nonneg=True))
        elements += [sec] * repeat
    return SteppedShaft(elements=tuple(elements), shear=shear)


def _pair(r: Any, e: dict, key: str, field: str, positive: bool) -> tuple[float, float]:
    """A diameter: one number (the same at both ends) or [left, right]."""
    if key not in e:
        raise r.fail(field, "missing")
    v = e[key]
    vals = v if isinstance(v, list) else [v, v]
    if len(vals) != 2:
        raise r.fail(field, f"expected a number or [left, right], got {v!r}")
    out = tuple(r.number({key: x}, key, field, nonneg=not positive) for x in vals)
    return (out[0], out[1])
