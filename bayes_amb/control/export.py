"""Export a controller to the bayes-amb-controller/1 file format, and build the reference one."""

from __future__ import annotations

from dataclasses import asdict
from typing import Any

import numpy as np

from bayes_amb.control.design import DesignSettings, ObserverController, design_observer_controller
from bayes_amb.io.controller_file import (
    CONTROLLER_INPUTS,
    CONTROLLER_OUTPUTS,
    ControllerFile,
)
from bayes_amb.reduction import reduce_pseudo_modal
from bayes_amb.rig import Rig
from bayes_amb.rotor import full_model


def reference_controller(rig: Rig, dt: float = 1e-4, speed_rpm: float | None = None,
                         settings: DesignSettings | None = None) -> ObserverController:
    """The reference observer-based controller: designed on the 8-state reduced model.

    Examples
    --------
    >>> from bayes_amb.rig import load_rig
    >>> reference_controller(load_rig(), dt=1e-3).dt
    0.001
    """
    red = reduce_pseudo_modal(full_model(rig, speed_rpm))
    return design_observer_controller(red, dt, settings)


def export_controller(ctrl: Any, rig: Rig) -> ControllerFile:
    """ControllerFile (inputs [y; eta], outputs [u; eps]) of an observer-based or generic
    controller (anything with youla_port_matrices() and dt)."""
    Ak, Bk, Ck, Dk = ctrl.youla_port_matrices()
    kind = "observer" if isinstance(ctrl, ObserverController) else "generic"
    design: dict[str, Any] = {"kind": kind, "speed_rpm": getattr(ctrl, "speed_rpm", None)}
    settings = getattr(ctrl, "settings", None)
    if settings is not None:
        design["settings"] = asdict(settings)
    if kind == "observer":
        design["method"] = ("discrete LQR (Q = C'C/y_ref^2, R = I/u_ref^2) + Kalman predictor "
                            "(W = w_ref^2 BB', V = v_ref^2 I) on the ZOH 8-state reduced model")
        design["plant"] = {"A": ctrl.A.tolist(), "B": ctrl.B.tolist(), "C": ctrl.C.tolist()}
        design["F"] = ctrl.F.tolist()
        design["L"] = ctrl.L.tolist()
    return ControllerFile(dt=float(ctrl.dt), A=np.asarray(Ak), B=np.asarray(Bk),
                          C=np.asarray(Ck), D=np.asarray(Dk), inputs=CONTROLLER_INPUTS,
                          outputs=CONTROLLER_OUTPUTS, design=design, rig=rig.name,
                          kind=kind)
