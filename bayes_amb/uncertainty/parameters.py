"""The public vocabulary of uncertain physical parameters.

Each name is a change of the physical model that changes one or two columns of A_f
(eqs. 48-50). theta is dimensionless; the physical value is reported beside it.

Sign conventions
----------------
k_Ax, k_Ay, k_Bx, k_By
    Relative *reduction* of the bearing's position stiffness ks on that axis:
    ks_true = (1 - theta) * ks. theta = 0.5 is "a stiffness reduction of 50 %" (the paper's
    case), theta = 1 removes ks (a 100 % change), theta < 0 makes the bearing more unstable.
    Physical value: delta_ks = ks_true - ks = -theta * ks, in N/m.
c_Ax, c_Ay, c_Bx, c_By
    Viscous damping added at that bearing axis: c = theta * c_ref, in N s/m.
kxy_A, kxy_B, kxy_D1, kxy_D2
    Destabilising cross-coupled stiffness at bearing A, B or disc D1, D2 (seal or
    aerodynamic kind): f_x = -kxy*y, f_y = +kxy*x with kxy = theta * k_ref, in N/m. Each uses
    two columns of A_f (the x and y DOFs of its node).
kd_<loc>, cd_<loc> (loc a disc D1, D2 or a shaft node n<j>; not at a bearing, where they
    would be the bearing's own k and c)
    Isotropic direct stiffness and damping at a node: f_x = -K x - C vx, f_y = -K y - C vy
    with K = theta * k_ref (N/m), C = theta * c_ref (N s/m). A seal's or impeller's force
    carries them beside its cross-coupled stiffness; the diagnosis fits them beside an
    accepted cross-coupling at a node so that the bearing coefficients do not take them
    (discrepancy/direct_terms.py). Two columns of A_f each.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bayes_amb.errors import ParameterError
from bayes_amb.rig import Rig, node_label
from bayes_amb.rotor import RotorMatrices, dof_index


@dataclass(frozen=True)
class ParameterSpec:
    """One named parameter: what it changes, its physical scale and unit."""

    name: str
    kind: str          # "k", "c", "kxy", or "kd" / "cd" (direct, isotropic, at a node)
    location: str      # "A", "B", "D1", "D2" or "n<j>"
    axis: str | None   # "x"/"y" for k and c; None for kxy, kd, cd
    meaning: str
    unit: str
    physical_label: str

    def physical_scale(self, rig: Rig) -> float:
        """Physical value per unit theta (N/m or N s/m)."""
        if self.kind == "k":        # theta is the relative change of this bearing's ks
            return -rig.magnets[self.location].ks
        if self.kind in ("c", "cd"):
            return rig.c_ref
        return rig.k_ref

    def to_physical(self, theta: float | NDArray, rig: Rig) -> float | NDArray:
        return np.asarray(theta) * self.physical_scale(rig)


def _build_vocabulary() -> dict[str, ParameterSpec]:
    vocab: dict[str, ParameterSpec] = {}
    for b in ("A", "B"):
        for ax in ("x", "y"):
            vocab[f"k_{b}{ax}"] = ParameterSpec(
                f"k_{b}{ax}", "k", b, ax,
                f"relative reduction of bearing {b} ks on axis {ax}: ks_true = (1-theta) ks",
                "N/m", "delta_ks")
    for b in ("A", "B"):
        for ax in ("x", "y"):
            vocab[f"c_{b}{ax}"] = ParameterSpec(
                f"c_{b}{ax}", "c", b, ax,
                f"viscous damping added at bearing {b} axis {ax}: c = theta c_ref",
                "N s/m", "c")
    for loc, what in (("A", "bearing A"), ("B", "bearing B"), ("D1", "disc D1"),
                      ("D2", "disc D2")):
        vocab[f"kxy_{loc}"] = ParameterSpec(
            f"kxy_{loc}", "kxy", loc, None,
            f"cross-coupled stiffness at {what}: f_x = -kxy y, f_y = +kxy x, kxy = theta k_ref",
            "N/m", "kxy")
    return vocab


PARAMETERS: dict[str, ParameterSpec] = _build_vocabulary()
"""All parameter names in their canonical order."""


_DIRECT = {"kd": ("direct stiffness", "f = -K q, K = theta k_ref", "N/m"),
           "cd": ("direct damping", "f = -C dq/dt, C = theta c_ref", "N s/m")}


def _direct_spec(name: str) -> ParameterSpec | None:
    """kd_<loc> / cd_<loc> at a disc or shaft node (None if the name is not of that form)."""
    kind, _, loc = name.partition("_")
    if kind not in _DIRECT or not loc:
        return None
    node = node_label(loc)
    if loc not in ("D1", "D2") and node is None:
        return None
    where = f"disc {loc}" if node is None else f"shaft node {node}"
    what, law, unit = _DIRECT[kind]
    return ParameterSpec(name, kind, loc if node is None else f"n{node}", None,
                         f"isotropic {what} at {where}: {law}", unit, kind)


def get_spec(name: str) -> ParameterSpec:
    """The spec of a parameter name: one of PARAMETERS, kxy_n<j>, a cross-coupled
    stiffness at shaft node j (1-based; checked against the rig where it is used), or
    kd_<loc> / cd_<loc>, direct stiffness / damping at a disc or shaft node."""
    direct = None if name in PARAMETERS else _direct_spec(name)
    if direct is not None:
        return direct
    if name not in PARAMETERS:
        node = node_label(name.removeprefix("kxy_")) if name.startswith("kxy_") else None
        if node is not None:
            return ParameterSpec(name, "kxy", f"n{node}", None,
                                 f"cross-coupled stiffness at shaft node {node}: "
                                 "f_x = -kxy y, f_y = +kxy x, kxy = theta k_ref", "N/m", "kxy")
        raise ParameterError(f"unknown parameter name {name!r}; known: {', '.join(PARAMETERS)}"
                             ", kxy_n<node>, kd_<disc or node>, cd_<disc or node>")
    return PARAMETERS[name]


def parse_param_list(text: str | list[str] | tuple[str, ...]) -> tuple[str, ...]:
    """'k_By,c_By' -> ('k_By', 'c_By'), checking names and duplicates."""
    names = [s.strip() for s in text.split(",")] if isinstance(text, str) else list(text)
    names = [n for n in names if n]
    if not names:
        raise ParameterError("parameter list is empty")
    for n in names:
        get_spec(n)
    if len(set(names)) != len(names):
        raise ParameterError(f"parameter list {names} has duplicates")
    return tuple(names)


def node_of(spec: ParameterSpec, rig: Rig) -> int:
    """1-based node where a parameter acts (a bearing, a disc or 'n<j>', shaft node j)."""
    if spec.location in rig.bearing_nodes:
        return rig.bearing_nodes[spec.location]
    node = rig.shaft_node(spec.location)
    return rig.disc(spec.location).node if node is None else node


def physical_change(spec: ParameterSpec, rig: Rig, theta: float,
                    n_q: int) -> tuple[NDArray, NDArray]:
    """(dK, dC), each (n_q, n_q): the change of the second-order matrices at theta.

    This is the physical definition; the LFT columns are derived from it and tested
    against it.
    """
    dK = np.zeros((n_q, n_q))
    dC = np.zeros((n_q, n_q))
    node = node_of(spec, rig)
    if spec.kind == "k":
        j = dof_index(node, spec.axis)
        dK[j, j] = theta * rig.magnets[spec.location].ks   # K_b = -(1 - theta) ks
    elif spec.kind == "c":
        j = dof_index(node, spec.axis)
        dC[j, j] = theta * rig.c_ref
    elif spec.kind in ("kd", "cd"):
        M = dK if spec.kind == "kd" else dC
        for ax in ("x", "y"):
            j = dof_index(node, ax)
            M[j, j] = theta * spec.physical_scale(rig)
    else:
        jx, jy = dof_index(node, "x"), dof_index(node, "y")
        kxy = theta * rig.k_ref
        dK[jx, jy] = kxy                   # f_x = -kxy y
        dK[jy, jx] = -kxy                  # f_y = +kxy x
    return dK, dC


def lft_columns(spec: ParameterSpec, rig: Rig, mats: RotorMatrices) -> tuple[NDArray, NDArray]:
    """(B_w_f, C_z_f) of one parameter (eqs. 49-50): shapes (2 n_q, r) and (r, 2 n_q).

    A_f(theta) = A_f + B_w_f * theta * C_z_f, with r = 1 (k, c) or 2 (kxy, kd, cd).
    """
    n_q = mats.n_q
    Mi = mats.M_inv
    node = node_of(spec, rig)
    cols, rows = [], []
    if spec.kind in ("k", "c"):
        j = dof_index(node, spec.axis)
        value = rig.magnets[spec.location].ks if spec.kind == "k" else rig.c_ref
        col = np.zeros(2 * n_q)
        col[n_q:] = -Mi[:, j] * value
        row = np.zeros(2 * n_q)
        row[j if spec.kind == "k" else n_q + j] = 1.0
        cols.append(col)
        rows.append(row)
    elif spec.kind in ("kd", "cd"):
        for ax in ("x", "y"):
            j = dof_index(node, ax)
            col = np.zeros(2 * n_q)
            col[n_q:] = -Mi[:, j] * spec.physical_scale(rig)
            row = np.zeros(2 * n_q)
            row[j if spec.kind == "kd" else n_q + j] = 1.0
            cols.append(col)
            rows.append(row)
    else:
        jx, jy = dof_index(node, "x"), dof_index(node, "y")
        for src, dst, sign in ((jy, jx, 1.0), (jx, jy, -1.0)):
            # dK[dst, src] = sign * k_ref -> A column src gets -M^-1 e_dst sign k_ref
            col = np.zeros(2 * n_q)
            col[n_q:] = -Mi[:, dst] * sign * rig.k_ref
            row = np.zeros(2 * n_q)
            row[src] = 1.0
            cols.append(col)
            rows.append(row)
    return np.column_stack(cols), np.vstack(rows)
