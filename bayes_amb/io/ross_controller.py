"""Import the controllers of a ROSS rotor's magnetic bearings (optional extra
``bayes-amb[ross]``), each bearing its own, checked on the rig's full FE plant.

A ROSS ``MagneticBearingElement`` holds its controller C(s) as a transfer function
(``controller_transfer_function``), or as PID gains with a filtered derivative,
C(s) = Kp + Ki / s + Kd s / (1 + s / n_f), and an amplifier and a sensor gain (``k_amp`` in
A per controller unit, ``k_sense`` in sensor units per m; one number, or one per axis). The
coil current is i = -k_amp C(s) k_sense y on each axis of the bearing (negative feedback):
ROSS's own frequency-domain coefficients are k_eq = ks + ki k_amp k_sense Re C(jw), with
ks < 0 the magnet's negative stiffness. So each channel of bearing A (Ax, Ay) gets bearing
A's k_amp C(s) k_sense, bearing B's likewise, and the decentralised controller goes through
the same discretisation and stability check as a MATLAB one (io.controller_import).

ROSS's time-domain simulation adds the magnet's ks as a restoring spring, so a controller
tuned there can look stable in ROSS and not stabilise the real magnet: the check says so.

A rotor saved with ``Rotor.save`` keeps PID gains but not a transfer function (only the
frequency-dependent kxx and cxx it gives); such a controller is imported from the live
rotor (Python) or from a .mat file.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bayes_amb.errors import DataImportError
from bayes_amb.io.controller_import import (
    ControllerImport,
    checked_controller,
    diagonal_state_space,
)
from bayes_amb.rig import CHANNELS, Rig
from bayes_amb.rig.ross import magnetic_bearings, pid_gains

__all__ = ["ROSS_HINT", "controller_from_ross", "ross_bearing_controllers"]

ROSS_HINT = (" (ROSS's time-domain simulation adds the magnet's ks as a restoring spring, so "
             "a controller tuned there can look stable in ROSS; here, as in ROSS's own "
             "frequency-domain coefficients k_eq = ks + ki k_amp k_sense C, ks destabilises)")


def _per_axis(v: Any, axis: int) -> float:
    a = np.atleast_1d(np.asarray(v, dtype=float)).ravel()
    return float(a[axis] if a.size > 1 else a[0])


def _poly(c: Any) -> NDArray:
    return np.trim_zeros(np.atleast_1d(np.asarray(c, dtype=float).squeeze()).ravel(), "f")


def _pid(kp: float, ki: float, kd: float, n_f: float) -> tuple[NDArray, NDArray]:
    """Kp + Ki/s + Kd s / (1 + s/n_f) as (num, den), without a pole at 0 when Ki = 0 (a
    cancelled integrator would be a marginal state of the discrete loop)."""
    num, den = np.array([kp]), np.array([1.0])
    if kd:
        lag = np.array([1.0 / n_f, 1.0])                        # 1 + s / n_f
        num, den = np.polyadd(np.polymul(num, lag), [kd, 0.0]), lag
    if ki:
        num, den = np.polyadd(np.polymul(num, [1.0, 0.0]), ki * den), np.polymul(den,
                                                                               [1.0, 0.0])
    return num, den


def ross_bearing_controllers(rotor: Any, where: str = "ROSS rotor"
                             ) -> dict[str, tuple[NDArray, NDArray]]:
    """Per channel Ax, Ay, Bx, By: (num, den) of k_amp C(s) k_sense, from y (m) to i (A),
    negative feedback (module docstring). Bearing A is the magnetic bearing at the lower
    node, as in the converted rig (rig.ross)."""
    mbs = magnetic_bearings(rotor)
    if len(mbs) != 2:
        raise DataImportError(f"{where}: bearing_elements: expected 2 magnetic bearings, got "
                              f"{len(mbs)}")
    out = {}
    for name, b in zip(("A", "B"), mbs, strict=True):
        num = getattr(b, "controller_transfer_function_num", None)
        den = getattr(b, "controller_transfer_function_den", None)
        gains = pid_gains(b)
        if num is not None and den is not None:
            cn, cd = _poly(num), _poly(den)
        elif any(gains):
            cn, cd = _pid(*gains, float(getattr(b, "n_f", 1e4)))
        else:
            raise DataImportError(
                f"{where}: bearing {name} (ROSS node {b.n}): no controller (no PID gains, no "
                "transfer function; a saved ROSS file keeps a transfer-function controller "
                "only as kxx and cxx): import it from the live rotor or a .mat file")
        for axis, ch in enumerate((f"{name}x", f"{name}y")):
            gain = _per_axis(getattr(b, "k_amp", 1.0), axis) * _per_axis(
                getattr(b, "k_sense", 1.0), axis)
            out[ch] = (gain * cn, cd)
    return {ch: out[ch] for ch in CHANNELS}


def controller_from_ross(rotor: Any, rig: Rig, *, dt: float, method: str = "tustin",
                         prewarp_hz: float | None = None, speed_rpm: float | None = None,
                         source: str | os.PathLike[str] = "<ross rotor>",
                         scale: dict[str, float] | None = None) -> ControllerImport:
    """The ROSS rotor's bearing controllers as a generic controller file for ``rig`` (the
    rotor converted, rig.ross.rig_from_ross), discretised at ``dt`` and checked on the full
    FE plant at ``speed_rpm``.

    ``scale`` multiplies a bearing's controller (``{"A": 1 / 0.0062}``: a gain written twice
    in the source, say), recorded in the file's design.

    Raises
    ------
    DataImportError
        No controller on a bearing, an improper transfer function, or a loop the controller
        does not stabilise (the spectral radius and the unstable modes named, and why ROSS
        may have shown it stable).
    """
    where = f"controller of ROSS rotor {source}"
    tfs = ross_bearing_controllers(rotor, where)
    scale = dict(scale or {})
    bad = sorted(set(scale) - {"A", "B"})
    if bad:
        raise DataImportError(f"{where}: option scale: unknown bearing {bad[0]!r} (A or B)")
    tfs = {ch: (num * float(scale.get(ch[0], 1.0)), den) for ch, (num, den) in tfs.items()}
    K = diagonal_state_space(tfs, where)
    return checked_controller(K, 0.0, "ROSS bearing controllers", where, rig, dt=dt,
                              method=method, prewarp_hz=prewarp_hz, feedback="negative",
                              speed_rpm=speed_rpm, hint=ROSS_HINT,
                              source={"imported_from": str(source),
                                      "ross_scale": scale or None},
                              source_name=str(source))
