"""Decentralised PID controller of an AMB rig, as an industrial rig would run it.

Each axis (Ax, Ay, Bx, By) has its own PID from the sensor displacement y (m) to the coil
current u (A) of the same axis. It is designed in continuous time from physical targets and
discretised with the bilinear (Tustin) transform, without frequency prewarping.

Per axis (bearing b with rotor-mass share m_b from the lever rule), the physical law is
i = -C(s) y with

    C(s) = kp + kI / (s + w_I) + kd w_d s / (s + w_d)

* kp = (ks + k_net) / ki, in A/m: the bearing's net stiffness ki kp - ks equals the target
  k_net = ``net_stiffness_ratio`` * ks (so the electromagnetic stiffness ki kp is 2 ks for a
  ratio of 1);
* kd = 2 zeta sqrt(k_net m_b) / ki, in A s/m: damping ratio ``damping_ratio`` of the
  suspended rigid-body mode of that bearing (mass m_b, stiffness k_net);
* kI = kp 2 pi f_int, in A/(m s): integral action exceeds kp below ``integral_hz``;
* w_I = 2 pi ``integrator_leak_hz``: a leaky integrator, so the discrete controller has no
  marginal pole at z = 1 (its DC gain is kp (1 + f_int / f_leak));
* w_d = 2 pi ``derivative_rolloff_hz``: first-order roll-off of the derivative term.

In the positive-feedback convention of the package (u = K y, METHOD.md section 2) the
controller is K(s) = -C(s) I_4 per axis: note the sign.

Tuning (reference rig, full 320-state plant, ZOH at dt = 1e-4 s)
----------------------------------------------------------------
The defaults (net stiffness ks, so ki kp = 2 ks and kp = 8000 A/m; damping ratio 0.7,
kd = 23.4 / 22.3 A s/m on A / B; integral 2 Hz with the leak at 1 Hz; roll-off 1.8 kHz)
give closed-loop spectral radii 0.99819 at 31500 rpm and 0.99797 at 0 rpm (bending modes)
and sensitivity peaks of 3.8-3.9 dB (31500 rpm) and 4.1 dB (0 rpm), ISO 14839-3 zone A.
With less damping (ratio 0.25) or more integral action (5 Hz) the backward conical mode,
which falls to about 21 Hz at 31500 rpm, is destabilised by the integrator's phase lag.
The first bending modes (1.0-1.3 kHz) are neither damped nor destabilised.

References
----------
Schweitzer & Maslen (eds.), Magnetic Bearings, Springer 2009, ch. 7 (decentralised PID of
AMBs, net stiffness and damping from ki, ks). ISO 14839-3 (sensitivity zones).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import scipy.signal as sig
from numpy.typing import NDArray

from bayes_amb.errors import ControllerError
from bayes_amb.rig import CHANNELS, Rig


@dataclass(frozen=True)
class PIDSettings:
    """Physical targets of the decentralised PID (module docstring gives the gain formulas).

    net_stiffness_ratio : k_net / ks, dimensionless (net bearing stiffness ki kp - ks).
    damping_ratio : zeta of each bearing's suspended rigid-body mode, dimensionless.
    integral_hz : frequency in Hz below which integral action exceeds kp (kI = kp 2 pi f).
    integrator_leak_hz : pole of the leaky integrator, Hz (keeps the pole off z = 1).
    derivative_rolloff_hz : first-order roll-off of the derivative term, Hz.
    """

    net_stiffness_ratio: float = 1.0
    damping_ratio: float = 0.7
    integral_hz: float = 2.0
    integrator_leak_hz: float = 1.0
    derivative_rolloff_hz: float = 1800.0

    def validate(self, dt: float) -> None:
        """Raise ControllerError for a non-positive setting or a roll-off above Nyquist."""
        for k, v in asdict(self).items():
            if not (np.isfinite(v) and v > 0):
                raise ControllerError(f"PID setting {k}: expected a positive number, got {v!r}")
        nyquist = 0.5 / dt
        for k in ("integrator_leak_hz", "integral_hz", "derivative_rolloff_hz"):
            if getattr(self, k) >= nyquist:
                raise ControllerError(f"PID setting {k}: expected below the Nyquist frequency "
                                      f"{nyquist:g} Hz at dt = {dt:g} s, got {getattr(self, k)!r}")


@dataclass(frozen=True)
class PIDGains:
    """Continuous gains of one axis: kp in A/m, kI in A/(m s), kd in A s/m, w_I, w_d in rad/s."""

    kp: float
    kI: float
    kd: float
    w_I: float
    w_d: float


@dataclass(frozen=True)
class GenericController:
    """A discrete controller u = K y with K = (A, B, C, D) at sample time ``dt`` (s).

    A (n, n), B (n, 4) from displacements in m, C (4, n) to currents in A, D (4, 4) in A/m.
    ``kind`` names the design ("pid"); ``settings`` are the design targets; ``gains`` maps each
    channel to its continuous gains (empty for a controller that is not a PID).
    It has no observer, so its Youla port's eps rows are zero.
    """

    A: NDArray
    B: NDArray
    C: NDArray
    D: NDArray
    dt: float
    kind: str = "pid"
    settings: PIDSettings = field(default_factory=PIDSettings)
    gains: dict[str, PIDGains] = field(default_factory=dict)

    @property
    def n_states(self) -> int:
        return self.A.shape[0]

    def controller_matrices(self) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        """K = (A, B, C, D) in the positive-feedback convention u = K y."""
        return self.A, self.B, self.C, self.D

    def youla_port_matrices(self) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        """Exportable form with inputs [y; eta] and outputs [u; eps].

        u = K y + eta (eta is an excitation added at the plant input, i.e. r2 of Fig. 2) and
        eps = 0 (no observer, no innovation).
        """
        n = self.A.shape[0]
        m, p = self.D.shape
        Bk = np.hstack([self.B, np.zeros((n, m))])
        Ck = np.vstack([self.C, np.zeros((p, n))])
        Dk = np.block([[self.D, np.eye(m)], [np.zeros((p, p)), np.zeros((p, m))]])
        return self.A.copy(), Bk, Ck, Dk


def bearing_mass_shares(rig: Rig) -> dict[str, float]:
    """Rigid rotor mass carried by each bearing (lever rule about the bearing axes), kg."""
    z = rig.shaft.node_z
    zA, zB = z[rig.bearing_nodes["A"] - 1], z[rig.bearing_nodes["B"] - 1]
    items = rig.shaft.mass_items()
    items += [(d.mass, z[d.node - 1]) for d in rig.discs]
    span = zB - zA
    mA = sum(m * (zB - zi) for m, zi in items) / span
    mB = sum(m * (zi - zA) for m, zi in items) / span
    return {"A": mA, "B": mB}


def pid_gains(rig: Rig, settings: PIDSettings) -> dict[str, PIDGains]:
    """Continuous gains per channel (Ax, Ay, Bx, By) from the physical targets."""
    shares = bearing_mass_shares(rig)
    out = {}
    for ch in CHANNELS:
        mag = rig.magnets[ch[0]]
        k_net = settings.net_stiffness_ratio * mag.ks
        kp = (mag.ks + k_net) / mag.ki
        m_b = shares[ch[0]]
        if not m_b > 0:
            raise ControllerError(f"rig {rig.name}: bearing {ch[0]} carries a non-positive "
                                  f"rigid mass share ({m_b:g} kg); cannot design its PID")
        kd = 2.0 * settings.damping_ratio * np.sqrt(k_net * m_b) / mag.ki
        out[ch] = PIDGains(kp=kp, kI=kp * 2 * np.pi * settings.integral_hz, kd=kd,
                           w_I=2 * np.pi * settings.integrator_leak_hz,
                           w_d=2 * np.pi * settings.derivative_rolloff_hz)
    return out


def continuous_pid(gains: dict[str, PIDGains]) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Continuous K(s) = -C(s) per axis, block diagonal, states [x_I, x_d] per axis.

    x_I' = -w_I x_I + y,  x_d' = -w_d x_d + y,
    C(s) y = kI x_I - kd w_d^2 x_d + (kp + kd w_d) y.
    """
    chans = list(gains)
    m = len(chans)
    A, B = np.zeros((2 * m, 2 * m)), np.zeros((2 * m, m))
    C, D = np.zeros((m, 2 * m)), np.zeros((m, m))
    for k, ch in enumerate(chans):
        g = gains[ch]
        i, d = 2 * k, 2 * k + 1
        A[i, i], A[d, d] = -g.w_I, -g.w_d
        B[i, k] = B[d, k] = 1.0
        C[k, i], C[k, d] = -g.kI, g.kd * g.w_d**2
        D[k, k] = -(g.kp + g.kd * g.w_d)
    return A, B, C, D


def design_decentralised_pid(rig: Rig, dt: float = 1e-4,
                             settings: PIDSettings | None = None) -> GenericController:
    """Decentralised PID per axis, designed in continuous time and Tustin-discretised.

    Parameters
    ----------
    rig : Rig
        Supplies ki (N/A), ks (N/m) and the rotor mass distribution.
    dt : float
        Sample time in s, 0 < dt <= 0.01.
    settings : PIDSettings, optional
        Physical targets (default: net stiffness ks, damping ratio 0.7, roll-off 1.8 kHz).

    Returns
    -------
    GenericController
        u = K y with K = -C(s) discretised (positive-feedback convention), 8 states.

    Examples
    --------
    >>> from bayes_amb.rig import load_rig
    >>> pid = design_decentralised_pid(load_rig(), dt=1e-4)
    >>> pid.A.shape, pid.D.shape, bool(pid.D[0, 0] < 0)
    ((8, 8), (4, 4), True)
    """
    if not (np.isfinite(dt) and 0 < dt <= 1e-2):
        raise ControllerError(f"option --dt: value {dt:g} out of range: must be > 0 and <= 0.01 s")
    s = settings or PIDSettings()
    s.validate(dt)
    gains = pid_gains(rig, s)
    Ad, Bd, Cd, Dd, _ = sig.cont2discrete(continuous_pid(gains), dt, method="bilinear")
    return GenericController(A=np.asarray(Ad), B=np.asarray(Bd), C=np.asarray(Cd),
                             D=np.asarray(Dd), dt=float(dt), kind="pid", settings=s,
                             gains=gains)
