"""Unbalance: synchronous forcing at the running speed, at a disc or any shaft node."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayes_amb.discrepancy.library.base import (
    EffectEntry,
    Quantity,
    Sampled,
    SynchronousLine,
)
from bayes_amb.inference.priors import Prior
from bayes_amb.rig import Rig
from bayes_amb.rotor import dof_index

NODE_SCAN = ("n14", "n20", "n27")
"""Shaft nodes tried besides the discs on the reference rig (between the bearings, at
1/4, 1/2 and 3/4 of the span); on any rig :func:`scan_nodes` gives its own."""


def scan_nodes(rig: Rig) -> tuple[str, ...]:
    """The default shaft nodes of ``rig`` tried besides the discs: the nodes nearest 1/4,
    1/2 and 3/4 of the way from bearing A to bearing B (``NODE_SCAN`` on the reference rig,
    whose bearings sit at nodes 8 and 33), without repeats.

    >>> from bayes_amb.rig import load_rig
    >>> scan_nodes(load_rig("reference")), scan_nodes(load_rig("small_rotor"))
    (('n14', 'n20', 'n27'), ('n11', 'n17', 'n23'))
    """
    a, b = rig.bearing_nodes["A"], rig.bearing_nodes["B"]
    nodes = (round(a + k * (b - a) / 4) for k in (1, 2, 3))
    return tuple(dict.fromkeys(f"n{j}" for j in nodes))


def node_of(rig: Rig, location: str) -> int:
    """The FE node of a disc name ('D1') or a node label ('n12', 1-based)."""
    node = rig.shaft_node(location)
    return rig.disc(location).node if node is None else node


@dataclass(frozen=True)
class Unbalance(SynchronousLine):
    """Synchronous forcing at the running speed by an unbalance u e^{j phase} (kg m) at a
    disc or shaft node: f_x = u Omega^2 cos(Omega t + phase), f_y = u Omega^2 sin(Omega t +
    phase), phase at t = 0, a continuous force (sampled exactly, not held). Sampled:
    a = u cos(phase), b = u sin(phase) in units of 1e-5 kg m (null 0). Two planes are two
    instances at two locations."""

    UNIT = 1e-5

    def line_force(self, ctx):
        node = node_of(ctx.rig, self.location)
        mats = ctx.assembled()
        n_q = mats.n_q
        Bf = np.zeros((2 * n_q, 2))
        for col, ax in enumerate(("x", "y")):
            Bf[n_q:, col] = mats.M_inv[:, dof_index(node, ax)]
        return Bf

    def physical(self, draws, ctx):
        a, b = draws[:, 0] * self.UNIT, draws[:, 1] * self.UNIT
        return {"u_kgm": (np.hypot(a, b), "kg m"),
                "phase_deg": (np.rad2deg(np.arctan2(b, a)), "deg")}

    def describe(self, values):
        where = (f"node {self.location[1:]}" if self.location.startswith("n")
                 else f"disc {self.location}")
        return (f"unbalance {values['u_kgm']:.2g} kg m at {where} "
                f"(phase {values['phase_deg']:.0f} deg)")


ENTRY = EffectEntry(
    name="unbalance", title="unbalance",
    description=("a mass unbalance u (kg m) at a disc or shaft node: a forward force "
                 "u Omega^2 at the running speed; two planes are two instances (on a rotor the "
                 "model treats as rigid, any two planes nearly span the same forces)"),
    fingerprint=("a line at 1x the running speed that does not depend on the excitation, "
                 "entering at the plant input (through N~, like r2), its pattern across the "
                 "channels set by the axial position"),
    side="plant", locations=("D1", "D2", *NODE_SCAN),
    sampled=(Sampled("unb_a_{location}", Prior("normal", 0.0, 20.0), 0.0, "1e-5 kg m",
                     "u cos(phase)"),
             Sampled("unb_b_{location}", Prior("normal", 0.0, 20.0), 0.0, "1e-5 kg m",
                     "u sin(phase)")),
    physical=(Quantity("u_kgm", "kg m", "unbalance"),
              Quantity("phase_deg", "deg", "angle at t = 0 of the record")),
    repeatable=True, scan="n1 .. n<number of nodes> (any shaft node)",
    make=lambda loc: Unbalance("unbalance", loc),
    rig_locations=lambda rig: ("D1", "D2", *scan_nodes(rig)))
Unbalance.entry = ENTRY
