"""The library of candidate physics: parametric extensions of the nominal reduced model.

Every candidate has the same interface. Its sampled parameters (``params``) come with
physical priors and a *null* value at which the effect vanishes (or, for the flexible
modes, the FE prediction). The extended model applies the candidates' hooks in a fixed
order, all vectorised over a batch of parameter rows phi (nb, q):

1. ``lft_names``    extra LFT parameters (cross-coupled stiffness, eqs. 48-52)
2. ``n_bending``    bending-mode pairs the reduction must keep (flexible modes)
3. ``modal``        change of the nominal modal blocks before the LFT (bending frequency)
4. ``continuous``   change of the continuous plant (A, B, C)
5. ``discretise``   its own exact sampling of the plant (actuator lag, fractional delay;
                    at most one such candidate per model: they are alternatives)
6. ``discrete``     change of the sampled plant (sensor gain)
7. ``line_force``         a deterministic input not driven by the excitation (unbalance)

Fingerprints (what each effect leaves in the residual eps - S(theta_hat) x) are stated in
``fingerprint``; the diagnosis ranks candidates by how much of the residual a short fit of
each one explains, which is that fingerprint matched quantitatively.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bayes_amb.inference.batched import expm_batched
from bayes_amb.inference.priors import Prior, default_prior
from bayes_amb.rig import CHANNELS, Rig
from bayes_amb.rotor import assemble, dof_index
from bayes_amb.uncertainty import get_spec

VOCABULARY = ("actuator_lag", "time_delay", "cross_coupling", "flexible_mode", "unbalance",
              "sensor_gain")
"""The public names of the effects (the same vocabulary as the simulator's)."""


@dataclass(frozen=True)
class EffectParam:
    """One sampled parameter of a candidate: name, prior, null value, unit of the sample."""

    name: str
    prior: Prior
    null: float
    unit: str


@dataclass(frozen=True)
class ModelContext:
    """What candidates need to know about the recording: rig, sample time (s), speed (rpm),
    and the nominal bending frequencies (Hz) and damping ratios of the FE model at that
    speed, lowest first."""

    rig: Rig
    dt: float
    speed_rpm: float
    bending_hz: tuple[float, ...]
    bending_zeta: tuple[float, ...]

    @property
    def omega_rot(self) -> float:
        """Running speed in rad/s."""
        return self.speed_rpm * 2 * math.pi / 60


@dataclass(frozen=True)
class Candidate:
    """Base of the candidate family; every hook has the same signature in every member."""

    effect: str
    location: str

    fingerprint = ""
    own_sampling = False     # samples the plant itself (one such candidate per model)
    nominal_family = False   # a parameter of the nominal model left out of the fit: tried
                             # before any physics (diagnose.py, select.py)

    def equivalents(self) -> tuple[str, ...]:
        """Explanations that give the same u -> y map as this one and so cannot be told
        apart from u, y and the excitation (a scalar h on all channels: h G = G h);
        reported as its class."""
        return ()

    @property
    def key(self) -> str:
        """A unique label, e.g. 'cross_coupling@D1'."""
        return f"{self.effect}@{self.location}"

    def params(self, ctx: ModelContext) -> tuple[EffectParam, ...]:
        """The sampled parameters with their priors."""
        raise NotImplementedError

    def lft_names(self) -> tuple[str, ...]:
        return ()

    def n_bending(self) -> int:
        return 0

    def modal(self, A: NDArray, phi: NDArray, ctx: ModelContext, n_rigid: int) -> NDArray:
        """Batched nominal reduced A (nb, n, n) in modal coordinates -> changed A."""
        return A

    def continuous(self, A: NDArray, B: NDArray, C: NDArray, phi: NDArray,
                   ctx: ModelContext) -> tuple[NDArray, NDArray, NDArray]:
        """Batched continuous plant (nb, n, n), (nb, n, 4), (nb, 4, n) -> changed plant."""
        return A, B, C

    def discretise(self, A: NDArray, B: NDArray, phi: NDArray, ctx: ModelContext
                   ) -> tuple[NDArray, NDArray, NDArray] | None:
        """Own exact sampling: (Ad, Bd, E) with E (nb, n_aug, n) embedding the plant state,
        or None to use the plain ZOH."""
        return None

    def structure(self, phi: NDArray, ctx: ModelContext) -> NDArray:
        """Integer key per row: rows with different keys get differently built systems."""
        return np.zeros(phi.shape[0], dtype=int)

    def discrete(self, Ad: NDArray, Bd: NDArray, Cd: NDArray, phi: NDArray
                 ) -> tuple[NDArray, NDArray, NDArray]:
        return Ad, Bd, Cd

    def line_force(self, ctx: ModelContext) -> NDArray | None:
        """Full-model force input (2 n_q, 2) of a synchronous line, or None."""
        return None

    def physical(self, draws: NDArray, ctx: ModelContext) -> dict[str, tuple[NDArray, str]]:
        """Physical parameters from sampled ones (n, q): name -> (values (n,), unit)."""
        raise NotImplementedError

    def describe(self, values: dict[str, float]) -> str:
        """One phrase naming the effect and its physical size."""
        raise NotImplementedError


def _lag_channels(location: str) -> list[int]:
    return [i for i, ch in enumerate(CHANNELS) if location == "both" or ch[0] == location]


@dataclass(frozen=True)
class ActuatorLag(Candidate):
    """First-order current-to-force lag 1/(1 + s tau) on the coils of one or both bearings
    (amplifier current loop and coil inductance). Sampled: tau in ms (null 0)."""

    fingerprint = ("phase lag growing with frequency and a magnitude roll-off above the "
                   "actuator bandwidth, on the channels of the lagged bearing(s)")
    own_sampling = True

    def params(self, ctx: ModelContext) -> tuple[EffectParam, ...]:
        # bandwidths from 100 Hz (tau 1.59 ms) upwards; 0 is no lag
        return (EffectParam("lag_ms", Prior("uniform", 0.0, 1.6), 0.0, "ms"),)

    def discretise(self, A, B, phi, ctx):
        """Exact sampling with the lag (no stiff matrix exponential): within a sample the
        force of a lagged coil is f(t) = u + (x_l - u) e^{-t/tau}, so

            x+   = Ad x + Gamma u + J (x_l - u)_lagged
            x_l+ = e^{-dt/tau} x_l + (1 - e^{-dt/tau}) u_lagged
            J    = e^{A dt} (A + I/tau)^-1 (I - e^{-dt/tau} e^{-A dt}) B_lagged,

        which tends to the plain ZOH as tau -> 0."""
        dt = ctx.dt
        tau = np.maximum(phi[:, 0], 0.0) * 1e-3                          # s
        lagged = _lag_channels(self.location)
        nb, n, nu = B.shape
        q = len(lagged)
        Ad, G = _zoh_scaled(A, B, np.full(nb, dt))
        eye = np.eye(n)
        with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
            inv_tau = np.where(tau > 0, 1.0 / np.where(tau > 0, tau, 1.0), np.inf)
            decay = np.exp(-dt * inv_tau)                                # 0 for tau = 0
        J = np.zeros((nb, n, q))
        live = tau > 0
        if np.any(live):
            Ainv = np.linalg.inv(Ad[live])                               # e^{-A dt}
            M = A[live] + inv_tau[live, None, None] * eye
            rhs = (eye - decay[live, None, None] * Ainv) @ B[live][:, :, lagged]
            J[live] = Ad[live] @ np.linalg.solve(M, rhs)
        A_aug = np.zeros((nb, n + q, n + q))
        B_aug = np.zeros((nb, n + q, nu))
        A_aug[:, :n, :n] = Ad
        A_aug[:, :n, n:] = J
        A_aug[:, n + np.arange(q), n + np.arange(q)] = decay[:, None]
        B_aug[:, :n] = G
        B_aug[:, :n, lagged] -= J
        B_aug[:, n + np.arange(q), lagged] = (1.0 - decay)[:, None]
        E = np.zeros((nb, n + q, n))
        E[:, :n, :n] = eye
        return A_aug, B_aug, E

    def equivalents(self):
        # a scalar lag on every actuator commutes with G: the same lag on every sensor
        return ("sensor_lag@all (the same bandwidth on all four sensors)",) \
            if self.location == "both" else ()

    def physical(self, draws, ctx):
        tau = np.maximum(draws[:, 0], 1e-12) * 1e-3
        return {"bandwidth_hz": (1.0 / (2 * np.pi * tau), "Hz")}

    def describe(self, values):
        where = "both bearings" if self.location == "both" else f"bearing {self.location}"
        return f"actuator bandwidth {values['bandwidth_hz']:.0f} Hz at {where}"


@dataclass(frozen=True)
class TimeDelay(Candidate):
    """Control delay between the commanded current and the force, any fraction of samples,
    exact under ZOH: x[k+1] = Ad x[k] + G(dt - f) u[k-m] + e^{A(dt-f)} G(f) u[k-m-1] for a
    delay m dt + f. Sampled: delay in ms (null 0), up to 4 samples or 0.4 ms."""

    fingerprint = ("phase lag growing linearly with frequency, no change of magnitude, on "
                   "every channel")
    own_sampling = True

    def max_delay_ms(self, ctx: ModelContext) -> float:
        return max(4 * ctx.dt, 4e-4) * 1e3

    def params(self, ctx):
        return (EffectParam("delay_ms", Prior("uniform", 0.0, self.max_delay_ms(ctx)), 0.0,
                            "ms"),)

    def structure(self, phi, ctx):
        d = np.clip(phi[:, 0], 0.0, None) * 1e-3
        return np.floor(d / ctx.dt + 1e-12).astype(int)

    def discretise(self, A, B, phi, ctx):
        dt = ctx.dt
        d = np.clip(phi[:, 0], 0.0, None) * 1e-3
        m_all = np.floor(d / dt + 1e-12).astype(int)
        if np.any(m_all != m_all[0]):
            raise ValueError("rows of one batch must share the integer delay")
        m = int(m_all[0])
        f = d - m * dt                                               # (nb,) in [0, dt)
        nb, n, nu = B.shape
        rest = _zoh_scaled(A, B, dt - f)                             # (E1, G_rest)
        _, G_f = _zoh_scaled(A, B, f)
        Ad, _ = _zoh_scaled(A, B, np.full(nb, dt))
        E1, G_now = rest
        G_prev = E1 @ G_f
        slots = m + 1                                                # u[k-1] .. u[k-m-1]
        N = n + nu * slots
        A_aug = np.zeros((nb, N, N))
        B_aug = np.zeros((nb, N, nu))
        A_aug[:, :n, :n] = Ad
        if m == 0:
            B_aug[:, :n] = G_now
        else:
            A_aug[:, :n, n + nu * (m - 1):n + nu * m] = G_now
        A_aug[:, :n, n + nu * m:n + nu * (m + 1)] = G_prev
        B_aug[:, n:n + nu] = np.eye(nu)
        for s in range(1, slots):                                    # shift register
            A_aug[:, n + nu * s:n + nu * (s + 1), n + nu * (s - 1):n + nu * s] = np.eye(nu)
        E = np.zeros((nb, N, n))
        E[:, :n, :n] = np.eye(n)
        return A_aug, B_aug, E

    def equivalents(self):
        # a delay common to all channels commutes with G: actuator side = sensor side
        return ("sensor-side delay of the same length on all four sensors",)

    def physical(self, draws, ctx):
        return {"delay_s": (np.clip(draws[:, 0], 0.0, None) * 1e-3, "s")}

    def describe(self, values):
        return f"control delay {values['delay_s'] * 1e6:.1f} us"


def _zoh_scaled(A: NDArray, B: NDArray, h: NDArray) -> tuple[NDArray, NDArray]:
    """Exact ZOH of a stack over per-row intervals h (nb,): (e^{A h}, int_0^h e^{As} ds B)."""
    nb, n, _ = A.shape
    m = B.shape[-1]
    E = np.zeros((nb, n + m, n + m))
    E[:, :n, :n] = A * h[:, None, None]
    E[:, :n, n:] = B * h[:, None, None]
    Ed = expm_batched(E)
    return Ed[:, :n, :n], Ed[:, :n, n:]


@dataclass(frozen=True)
class CrossCoupling(Candidate):
    """Cross-coupled stiffness kxy at a bearing or disc (f_x = -kxy y, f_y = +kxy x), through
    the LFT parameter kxy_LOCATION. Sampled: theta = kxy / k_ref (null 0)."""

    fingerprint = ("x-y coupling at one location: the residual of one axis is driven by the "
                   "excitation of the other, with opposite signs (forward/backward whirl "
                   "asymmetry)")

    def params(self, ctx):
        return (EffectParam(f"kxy_{self.location}", Prior("uniform", -10.0, 10.0), 0.0, "-"),)

    def lft_names(self):
        return (f"kxy_{self.location}",)

    def physical(self, draws, ctx):
        return {"kxy": (draws[:, 0] * ctx.rig.k_ref, "N/m")}

    def describe(self, values):
        return f"cross-coupled stiffness {values['kxy']:.3g} N/m at {self.location}"


@dataclass(frozen=True)
class FlexibleMode(Candidate):
    """The reduced model extended with the first ``n_pairs`` bending-mode pairs of the FE
    model (the reduction keeping 8 + 4k states). Sampled: the log of a common frequency
    scale of the added modes (prior sd 3 %) and the log of a damping multiplier (prior
    lognormal, sd a factor e). The FE prediction is the null (0, 0)."""

    n_pairs: int = 1

    fingerprint = ("a narrow band near a bending frequency of the FE model, on the channels "
                   "where the mode shape is seen")

    def params(self, ctx):
        return (EffectParam("log_freq_scale", Prior("normal", 0.0, 0.03), 0.0, "-"),
                EffectParam("log_damping_scale", Prior("normal", 0.0, 1.0), 0.0, "-"))

    def n_bending(self):
        return self.n_pairs

    def modal(self, A, phi, ctx, n_rigid):
        s = np.exp(np.clip(phi[:, 0], -0.5, 0.5))
        md = np.exp(np.clip(phi[:, 1], -6.0, 6.0))
        A = A.copy()
        for i in range(n_rigid, n_rigid + 4 * self.n_pairs, 2):
            sig, om = A[:, i, i], A[:, i + 1, i]
            mod = np.hypot(sig, om)
            zeta = np.clip(-sig / mod * md, -0.99, 0.99)
            mod2 = mod * s
            sig2 = -zeta * mod2
            om2 = np.sign(om) * mod2 * np.sqrt(1 - zeta**2)
            A[:, i, i] = A[:, i + 1, i + 1] = sig2
            A[:, i + 1, i] = om2
            A[:, i, i + 1] = -om2
        return A

    def physical(self, draws, ctx):
        return {"frequency_hz": (ctx.bending_hz[0] * np.exp(draws[:, 0]), "Hz"),
                "damping_ratio": (ctx.bending_zeta[0] * np.exp(draws[:, 1]), "-")}

    def describe(self, values):
        return (f"bending mode near {values['frequency_hz']:.0f} Hz (damping ratio "
                f"{values['damping_ratio']:.2g}) missing from the model")


@dataclass(frozen=True)
class Unbalance(Candidate):
    """Synchronous forcing at the running speed by an unbalance u e^{j phase} (kg m) at a
    disc: f_x = u Omega^2 cos(Omega t + phase), f_y = u Omega^2 sin(Omega t + phase), phase
    at t = 0. Sampled: a = u cos(phase), b = u sin(phase) in units of 1e-5 kg m (null 0)."""

    start: str = "rest"
    """How the record begins: "rest" (the forcing starts with the record, as when the loop
    is closed at t = 0) or "steady" (the rotor was already spinning: no start transient).
    The diagnosis fits both and keeps the better."""

    fingerprint = ("a line at 1x the running speed that does not depend on the excitation, "
                   "strongest on the channels near the disc")

    UNIT = 1e-5

    def params(self, ctx):
        return (EffectParam("unb_a", Prior("normal", 0.0, 20.0), 0.0, "1e-5 kg m"),
                EffectParam("unb_b", Prior("normal", 0.0, 20.0), 0.0, "1e-5 kg m"))

    def line_force(self, ctx):
        mats_node = ctx.rig.disc(self.location).node
        mats = assemble(ctx.rig)
        n_q = mats.n_q
        Bf = np.zeros((2 * n_q, 2))
        for col, ax in enumerate(("x", "y")):
            Bf[n_q:, col] = mats.M_inv[:, dof_index(mats_node, ax)]
        return Bf

    def physical(self, draws, ctx):
        a, b = draws[:, 0] * self.UNIT, draws[:, 1] * self.UNIT
        return {"u_kgm": (np.hypot(a, b), "kg m"),
                "phase_deg": (np.rad2deg(np.arctan2(b, a)), "deg")}

    def describe(self, values):
        return (f"unbalance {values['u_kgm']:.2g} kg m at disc {self.location} "
                f"(phase {values['phase_deg']:.0f} deg)")


@dataclass(frozen=True)
class SensorGain(Candidate):
    """A calibration error of one displacement sensor: y_meas = (1 + g) y on that channel.
    Sampled: g (null 0), prior normal(0, 0.1)."""

    fingerprint = "a broadband scale error on one channel only"

    def params(self, ctx):
        return (EffectParam(f"gain_{self.location}", Prior("normal", 0.0, 0.1), 0.0, "-"),)

    def discrete(self, Ad, Bd, Cd, phi):
        j = CHANNELS.index(self.location)
        Cd = np.array(np.broadcast_to(Cd, (phi.shape[0], *Cd.shape[-2:])))
        Cd[:, j, :] *= 1.0 + phi[:, 0][:, None]
        return Ad, Bd, Cd

    def physical(self, draws, ctx):
        return {"gain": (draws[:, 0], "-")}

    def describe(self, values):
        return f"sensor gain error {100 * values['gain']:+.1f} % on channel {self.location}"


@dataclass(frozen=True)
class BearingCoefficient(Candidate):
    """A stiffness or damping coefficient of the nominal model that was left out of the fit
    (``location`` is its name, e.g. k_Ax): before any physics is blamed, the nominal model
    with that coefficient freed is tried. Sampled: theta (null 0), the parameter's default
    prior, through its LFT column (eqs. 48-52)."""

    nominal_family = True
    fingerprint = ("a frequency-dependent change of the loop at one bearing axis, like the "
                   "fitted coefficients'")

    def params(self, ctx):
        return (EffectParam(self.location, default_prior(self.location), 0.0, "-"),)

    def lft_names(self):
        return (self.location,)

    def physical(self, draws, ctx):
        spec = get_spec(self.location)
        scale = spec.physical_scale(ctx.rig)
        return {"value": (draws[:, 0] * scale, spec.unit)}

    def describe(self, values):
        return (f"{self.location} differs from nominal by {values['value']:.3g} "
                "(a coefficient left out of the fit)")


BEARING_COEFFICIENTS = ("k_Ax", "k_Ay", "k_Bx", "k_By", "c_Ax", "c_Ay", "c_Bx", "c_By")
"""The eight bearing coefficients the diagnosis fits by default."""


def left_out_coefficients(fitted: tuple[str, ...]) -> tuple[Candidate, ...]:
    """A BearingCoefficient candidate for every bearing coefficient not in ``fitted``."""
    return tuple(BearingCoefficient("bearing_coefficient", n) for n in BEARING_COEFFICIENTS
                 if n not in fitted)


def all_candidates() -> tuple[Candidate, ...]:
    """Every candidate the diagnosis tries, each effect at each location it can act."""
    out: list[Candidate] = [ActuatorLag("actuator_lag", loc) for loc in ("both", "A", "B")]
    out.append(TimeDelay("time_delay", "controller"))
    out += [CrossCoupling("cross_coupling", loc) for loc in ("A", "B", "D1", "D2")]
    out.append(FlexibleMode("flexible_mode", "bending pair 1", 1))
    out += [Unbalance("unbalance", d) for d in ("D1", "D2")]
    out += [SensorGain("sensor_gain", ch) for ch in CHANNELS]
    return tuple(out)
