"""The magnets' force law of a rig whose file gives their bias current (bearings.
bias_current): the differential pair f = F0 [(1 + i/i0)^2 / (1 - x/g0)^2 - (1 - i/i0)^2 /
(1 + x/g0)^2] with g0 = i0 ki / ks and F0 = ki i0 / 4 (its linearisation is ki and ks), as
the current beyond ki i + ks x it adds, d = (f - ki i - ks x) / ki. Shared by the
simulator (which plays it) and the diagnosis (which models it, discrepancy/nonlinear.py)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from bayes_amb.rig.rig import Rig


def bias_per_gap(rig: Rig) -> NDArray:
    """ks / ki per channel (A/m): the bias current over the gap of a consistent magnet."""
    return np.array([m.ks / m.ki for m in rig.channel_magnets])


def actuator_displacement(rig: Rig, y: NDArray) -> NDArray:
    """The rotor displacement at the two actuator planes (N, 4: Ax, Ay, Bx, By), from the
    probes by rigid-body kinematics along the shaft (linear between the sensor planes)."""
    z = rig.shaft.node_z
    zs = {b: z[rig.sensor_nodes[b] - 1] for b in "AB"}
    zb = {b: z[rig.bearing_nodes[b] - 1] for b in "AB"}
    span = zs["B"] - zs["A"]
    y = np.atleast_2d(np.asarray(y, dtype=float))
    out = np.empty_like(y)
    for k in range(2):                               # x, y axes
        ya, yb = y[:, k], y[:, 2 + k]
        for j, b in enumerate("AB"):
            w = (zb[b] - zs["A"]) / span if span else float(j)
            out[:, 2 * j + k] = (1.0 - w) * ya + w * yb
    return out


def saturated(v: NDArray, r: float | None) -> NDArray:
    """The flux density over the bias one, T(v) = r tanh(v / r), for an unsaturated v
    (v itself when r is None: linear iron).

    >>> float(saturated(np.array(1.0), None)), round(float(saturated(np.array(10.0), 2.0)), 3)
    (1.0, 2.0)
    """
    return v if r is None else r * np.tanh(v / r)


def law_current(rig: Rig, u: NDArray, x: NDArray, gaps: dict[str, float],
                saturation: dict[str, float] | None = None) -> NDArray:
    """d (N, 4) for currents u and actuator displacements x about the magnets' centre, per
    bearing gap (m; a bearing not in ``gaps`` is linear). The iron saturates where
    ``saturation`` (default: the rig file's ratios) gives a bearing its ratio r (module
    docstring). Where |x| reaches the gap the law is that of 0.99 of it (the rotor on its
    catcher is not this law's business)."""
    u = np.atleast_2d(np.asarray(u, dtype=float))
    x = np.atleast_2d(np.asarray(x, dtype=float))
    rho = bias_per_gap(rig)
    sat = rig_saturation(rig) if saturation is None else saturation
    d = np.zeros_like(u)
    for j, b in enumerate("AB"):
        if b not in gaps:
            continue
        sl = slice(2 * j, 2 * j + 2)
        g0 = float(gaps[b])
        i0 = rho[sl] * g0
        io, xi = u[:, sl] / i0, np.clip(x[:, sl] / g0, -0.99, 0.99)
        r = sat.get(b)
        if r is None:
            law = (1 + io) ** 2 / (1 - xi) ** 2 - (1 - io) ** 2 / (1 + xi) ** 2
        else:
            law = (saturated((1 + io) / (1 - xi), r) ** 2
                   - saturated((1 - io) / (1 + xi), r) ** 2) / (
                       r * np.tanh(1.0 / r) / np.cosh(1.0 / r) ** 2)
        d[:, sl] = i0 / 4.0 * (law - 4 * io - 4 * xi)
    return d


def rig_saturation(rig: Rig) -> dict[str, float]:
    """The saturation ratio r of the bearings whose rig file gives one (beside the bias)."""
    return {b: m.saturation for b, m in rig.magnets.items() if m.saturation is not None}


def rig_gaps(rig: Rig) -> dict[str, float]:
    """The gaps of the bearings whose rig file states the bias current (``bias_current``
    beside ki and ks): i0 ki / ks. A magnet given by its constants states a bias too, but
    the law is modelled only where the user wrote it as such: {} for the shipped rigs."""
    return {b: m.bias * m.ki / m.ks for b, m in rig.magnets.items() if m.bias}
