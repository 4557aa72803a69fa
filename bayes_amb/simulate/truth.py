"""The truth plant of a simulation: full FE or reduced model, true parameters, hidden effects.

Continuous-time (A, B, C) with current inputs u in A and displacements y in m, an optional
force input B_f at a disc (x, y) for unbalance, and the effects that act outside the state
matrices (delay, sensor gain, unbalance forcing), which the loop simulator applies.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from bayes_amb.errors import BayesAmbError
from bayes_amb.reduction import reduce_pseudo_modal
from bayes_amb.rig import CHANNELS, Rig
from bayes_amb.rotor import assemble, dof_index, full_model, state_matrices
from bayes_amb.simulate.effects import Effect
from bayes_amb.uncertainty import get_spec, lft_reduced, physical_change


@dataclass(frozen=True)
class TruthPlant:
    """Continuous truth plant and the effects the loop applies.

    A (n, n) 1/s; B (n, 4) per A; C (4, n); B_f (n, 2) per N of force at the unbalance
    disc (x, y), or None; delay_s >= 0; sensor_gain (4,) multiplies y; unbalance
    (force amplitude in N at the running speed, phase in rad) or None.
    """

    A: NDArray
    B: NDArray
    C: NDArray
    B_f: NDArray | None
    delay_s: float
    sensor_gain: NDArray
    unbalance: tuple[float, float] | None
    speed_rpm: float
    kind: str
    n_states: int = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "n_states", self.A.shape[0])


def _lag_channels(bearing: str) -> list[int]:
    return [i for i, ch in enumerate(CHANNELS) if bearing == "both" or ch[0] == bearing]


def build_truth(rig: Rig, speed_rpm: float, kind: str = "full",
                params: dict[str, float] | None = None,
                effects: list[Effect] | tuple[Effect, ...] = ()) -> TruthPlant:
    """Build the truth plant: 'full' (the rig's full-order FE) or 'reduced' (8 + 4k states).

    params maps parameter names (k_By, c_Ax, kxy_D1, ...) to true theta values.

    Examples
    --------
    >>> from bayes_amb.rig import load_rig
    >>> tp = build_truth(load_rig(), 31500.0, "reduced", {"k_By": 0.5})
    >>> tp.A.shape
    (8, 8)
    """
    params = dict(params or {})
    by_name = {e.name: e for e in effects}
    if "cross_coupling" in by_name:
        cc = by_name["cross_coupling"].params
        key = f"kxy_{cc['location']}"
        params[key] = params.get(key, 0.0) + cc["kxy"] / rig.k_ref
    mats = assemble(rig)
    B_f = None
    if kind == "full":
        dK = np.zeros((mats.n_q, mats.n_q))
        dC = np.zeros_like(dK)
        for name, th in params.items():
            k, c = physical_change(get_spec(name), rig, th, mats.n_q)
            dK += k
            dC += c
        A, B, C = state_matrices(mats, speed_rpm, dK, dC)
        T_L = None
    elif kind == "reduced":
        n_bend = by_name["flexible_mode"].params["n_modes"] if "flexible_mode" in by_name else 0
        red = reduce_pseudo_modal(full_model(rig, speed_rpm, mats), n_bending=n_bend)
        if params:
            up = lft_reduced(red, rig, tuple(params))
            A = up.A_theta([params[n] for n in up.names])
        else:
            A = red.A
        B, C, T_L = red.B, red.C, red.T_L
    else:
        raise BayesAmbError(f"option --truth: unknown value {kind!r}; known: full, reduced")
    unb = None
    if "unbalance" in by_name:
        ub = by_name["unbalance"].params
        node = rig.disc(ub["disc"]).node
        n_q = mats.n_q
        Bf_full = np.zeros((2 * n_q, 2))
        for col, ax in enumerate(("x", "y")):
            Bf_full[n_q:, col] = mats.M_inv[:, dof_index(node, ax)]
        B_f = Bf_full if T_L is None else T_L @ Bf_full
        omega = speed_rpm * 2 * np.pi / 60
        unb = (ub["u_kgm"] * omega**2, np.deg2rad(ub["phase_deg"]))
    if "actuator_lag" in by_name:
        al = by_name["actuator_lag"].params
        wc = 2 * np.pi * al["bandwidth_hz"]
        lagged = _lag_channels(al["bearing"])
        n, m, q = A.shape[0], B.shape[1], len(lagged)
        A2 = np.zeros((n + q, n + q))
        A2[:n, :n] = A
        A2[:n, n:] = B[:, lagged]
        A2[n:, n:] = -wc * np.eye(q)
        B2 = np.zeros((n + q, m))
        direct = [i for i in range(m) if i not in lagged]
        B2[:n, direct] = B[:, direct]
        B2[n + np.arange(q), lagged] = wc
        C = np.hstack([C, np.zeros((C.shape[0], q))])
        B_f = None if B_f is None else np.vstack([B_f, np.zeros((q, 2))])
        A, B = A2, B2
    gain = np.ones(len(CHANNELS))
    if "sensor_gain" in by_name:
        sg = by_name["sensor_gain"].params
        gain[CHANNELS.index(sg["channel"])] += sg["gain"]
    delay = by_name["time_delay"].params["delay_s"] if "time_delay" in by_name else 0.0
    return TruthPlant(A=A, B=B, C=C, B_f=B_f, delay_s=float(delay), sensor_gain=gain,
                      unbalance=unb, speed_rpm=float(speed_rpm), kind=kind)
