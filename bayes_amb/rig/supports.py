"""Fixed-coefficient supports: fluid-film bearings, seals, dampers, a pedestal's spring.

A real AMB machine often has more on its shaft than the two magnetic bearings: a seal at an
impeller, a touch-down bearing in contact, an auxiliary fluid-film bearing or a squeeze-film
damper. Each is a linear support of the shaft at one node, given by its 2 x 2 stiffness,
damping and (for seals) added-mass coefficients in the lateral plane, the convention of
ROSS's ``BearingElement`` and ``SealElement`` (Childs, Turbomachinery Rotordynamics, 1993):
the support's force on the shaft is

    f = -K q - C q' - M q'',   q = (x, y),   K = [[kxx, kxy], [kyx, kyy]]   (likewise C, M)

with cross-coupled terms (kxy != kyx) as a seal or a fluid-film bearing has them. A rig
file lists them as ``[[supports]]`` (every coefficient optional, 0 by default):

    [[supports]]
    name = "seal"            # optional, S1, S2, ... by default
    node = 12
    kxx = 2.0e5              # N/m
    kxy = 5.0e4
    kyx = -5.0e4
    kyy = 2.0e5
    cxx = 150.0              # N s/m
    cyy = 150.0
    mxx = 0.1                # kg

The coefficients are fixed: a fluid-film bearing's or a seal's coefficients depend on the
running speed, and a rig holds them at one speed (``rig from-ross`` takes ROSS's at the
rig's nominal speed). They are part of the known plant, like the shaft; the eight bearing
coefficients the tool identifies stay the magnetic bearings' (a support's own coefficients
are not identified).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

COEFFICIENTS = ("kxx", "kxy", "kyx", "kyy", "cxx", "cxy", "cyx", "cyy",
                "mxx", "mxy", "myx", "myy")
"""The coefficients of a support, in N/m, N s/m and kg (each optional, 0 by default)."""
_KEYS = {"name", "node", *COEFFICIENTS}


@dataclass(frozen=True)
class Support:
    """A linear support of the shaft at a node (1-based): stiffness k, damping c and added
    mass m, each 2 x 2 over (x, y) as nested tuples [[xx, xy], [yx, yy]]."""

    name: str
    node: int
    k: tuple[tuple[float, float], tuple[float, float]]
    c: tuple[tuple[float, float], tuple[float, float]]
    m: tuple[tuple[float, float], tuple[float, float]]

    def matrix(self, which: str) -> NDArray:
        """'k', 'c' or 'm' as a 2 x 2 array."""
        return np.array(getattr(self, which), dtype=float)

    def to_dict(self) -> dict[str, Any]:
        """The support as a rig file's [[supports]] entry (zero coefficients left out)."""
        return {"name": self.name, "node": self.node,
                **{k: v for p in "kcm" for k, v in nonzero_coefficients(
                    p, getattr(self, p)).items()}}


def nonzero_coefficients(prefix: str, matrix: Any) -> dict[str, float]:
    """A 2 x 2 block over (x, y) as its nonzero named coefficients.

    >>> nonzero_coefficients("k", [[1e5, 0.0], [-2e4, 3e5]])
    {'kxx': 100000.0, 'kyx': -20000.0, 'kyy': 300000.0}
    """
    return {f"{prefix}{a}{b}": float(matrix[i][j]) for i, a in enumerate("xy")
            for j, b in enumerate("xy") if matrix[i][j] != 0.0}


def support_from_coefficients(name: str, node: int, values: dict[str, float]) -> Support:
    """A Support from a dict of the COEFFICIENTS (missing ones 0).

    >>> s = support_from_coefficients("seal", 3, {"kxx": 1e5, "kxy": 2e4, "kyx": -2e4})
    >>> s.matrix("k").tolist(), s.to_dict()["kyx"]
    ([[100000.0, 20000.0], [-20000.0, 0.0]], -20000.0)
    """
    def block(p: str) -> tuple[tuple[float, float], tuple[float, float]]:
        g = [[float(values.get(f"{p}{a}{b}", 0.0)) for b in "xy"] for a in "xy"]
        return (g[0][0], g[0][1]), (g[1][0], g[1][1])
    return Support(name=name, node=node, k=block("k"), c=block("c"), m=block("m"))


def supports_from_list(raw: Any, reader: Any, n_nodes: int) -> tuple[Support, ...]:
    """The [[supports]] of a rig file, each checked (reader: a rig.reader.FieldReader, whose
    errors name the file and the field)."""
    out = []
    for f, t, name in reader.named_rows(raw, "supports", _KEYS, "S"):
        node = reader.node(t, "node", f"{f}.node", n_nodes)
        values = {k: reader.number(t, k, f"{f}.{k}", positive=False)
                  for k in COEFFICIENTS if k in t}
        out.append(support_from_coefficients(name, node, values))
    reader.unique_names([s.name for s in out], "supports", "support")
    return tuple(out)
