"""The candidate family's interface, its registry record, and helpers shared by members.

Every candidate has the same hooks, all vectorised over a batch of parameter rows phi
(nb, q). The extended model (discrepancy/model.py) applies them in a fixed order:

1. ``lft_names``    extra LFT parameters (cross-coupled stiffness, eqs. 48-52)
2. ``bending_pairs`` bending-mode pairs the reduction must keep (flexible modes); the
                    model keeps the union of them, and no others
3. ``modal``        change of the nominal modal blocks before the LFT (bending frequency)
4. ``continuous``   change of the continuous plant (A, B, C): actuator and sensor dynamics
                    as added states, actuator gain; every hook appends its states after the
                    ones it receives, so that they compose in any order
5. ``discretise``   its own exact sampling of the plant (fractional delay; at most one such
                    candidate per model: delays on both sides add up to one delay)
6. ``discrete``     change of the sampled plant (sensor gain; the static contribution of
                    the modes the model leaves out, ``ctx.static_residual``)
7. ``line_force`` / ``line_output``   a deterministic 1x line not driven by the excitation:
                    a force at the plant input (unbalance) or a signal added to the
                    measurement (runout)

Each member module also defines the effect's :class:`EffectEntry` (its registry record:
names, parameters, units, priors, nulls, fingerprint, equivalences, description); the
registry (registry.py) collects them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from bayes_amb.inference.batched import expm_batched
from bayes_amb.inference.priors import Prior
from bayes_amb.rig import CHANNELS, Rig
from bayes_amb.rotor.assembly import RotorMatrices, assemble


@dataclass(frozen=True)
class EffectParam:
    """One sampled parameter of a candidate: name, prior, null value, unit of the sample."""

    name: str
    prior: Prior
    null: float
    unit: str


@dataclass(frozen=True)
class Quantity:
    """A physical quantity an effect reports: name, SI unit, meaning, and where its physics
    allows it to lie (``plausible``, (low, high), None where it does not say). An effect
    whose whole 90 % interval falls outside that range is a stand-in: it fits something the
    library lacks, and the diagnosis says so (discrepancy/stand_ins.py). ``why`` gives the
    physics of the range in one clause. ``relative``: the range's top is at least this many
    times the quantity's value in the rig's own model (its sampled parameters at zero): a
    bending mode's damping is judged against the damping the rig's FE model gives it."""

    name: str
    unit: str
    meaning: str
    plausible: tuple[float, float] | None = None
    why: str = ""
    relative: float | None = None


@dataclass(frozen=True)
class Sampled:
    """A sampled parameter as the registry declares it. ``name`` may hold ``{location}``;
    ``prior_text`` replaces the printed prior where it depends on the recording (dt)."""

    name: str
    prior: Prior
    null: float
    unit: str
    meaning: str
    prior_text: str = ""

    def at(self, location: str, prior: Prior | None = None) -> EffectParam:
        """The EffectParam at a location (optionally with a recording-dependent prior);
        spaces in the location become underscores in the name."""
        return EffectParam(self.name.format(location=location.replace(" ", "_")),
                           prior or self.prior,
                           self.null, self.unit)

    def describe_prior(self) -> str:
        if self.prior_text:
            return self.prior_text
        p = self.prior
        if p.kind == "uniform":
            return f"U({p.a:g}, {p.b:g})"
        return f"{'N' if p.kind == 'normal' else 'LogN'}({p.a:g}, {p.b:g}^2)"


@dataclass(frozen=True)
class Equivalence:
    """``this`` (a location of the declaring effect, or '*' for any) gives the same
    u -> y map as ``other`` (a candidate key) whenever ``when`` holds, so that u, y and the
    excitation cannot tell them apart (METHOD.md section 8)."""

    this: str
    other: str
    when: str


@dataclass(frozen=True)
class EffectEntry:
    """The registry record of one effect.

    name: the public name (diagnosis.json, the CLI, studies); title: a few plain words;
    description: what it is physically; fingerprint: what it leaves in the residual
    eps - S(theta_hat) x; side: where it acts in the loop ('actuator', 'sensor', 'plant',
    'model'); locations: where the diagnosis tries it by default, and ``scan`` further
    locations it accepts (e.g. any shaft node); sampled: its sampled parameters (priors,
    nulls); physical: what it reports; equivalences; repeatable: whether the greedy search
    may add it a second time at another location; nominal_family: a coefficient of the
    nominal model, not physics; make: the candidate at a location; rig_locations: the
    default locations on a given rig, where they depend on it (shaft nodes), else None
    (``locations`` everywhere).
    """

    name: str
    title: str
    description: str
    fingerprint: str
    side: str
    locations: tuple[str, ...]
    sampled: tuple[Sampled, ...]
    physical: tuple[Quantity, ...]
    make: Callable[[str], Candidate]
    equivalences: tuple[Equivalence, ...] = ()
    repeatable: bool = False
    nominal_family: bool = False
    scan: str = ""
    rig_locations: Callable[[Rig], tuple[str, ...]] | None = None

    def locations_on(self, rig: Rig | None) -> tuple[str, ...]:
        """The default locations on ``rig`` (``locations`` without a rig)."""
        if rig is None or self.rig_locations is None:
            return self.locations
        return tuple(dict.fromkeys(self.rig_locations(rig)))


@dataclass(frozen=True)
class ModelContext:
    """What candidates need to know about the recording and the model: rig, sample time
    (s), speed (rpm), the nominal bending frequencies (Hz) and damping ratios of the FE model
    at that speed, lowest first (backward and forward whirl of pair 1, then pair 2, ...);
    per model: the bending pairs it keeps (1-based) and ``static_residual`` (4, 4), the
    static contribution in m/A of every FE mode the model leaves out, from actuator current
    to sensor displacement (G_FE(0) - G_model(0) with G(0) = -C A^-1 B, nominal bearings);
    ``static_in_nominal``: the nominal model holds that static path (ForwardModel.static;
    a model that keeps bending pairs), so residual_flexibility scales it;
    ``matrices``: the rig's assembled FE matrices (the forces candidates place on nodes).
    """

    rig: Rig
    dt: float
    speed_rpm: float
    bending_hz: tuple[float, ...]
    bending_zeta: tuple[float, ...]
    kept_pairs: tuple[int, ...] = ()
    static_residual: NDArray | None = field(default=None, compare=False, repr=False)
    static_in_nominal: bool = False
    matrices: RotorMatrices | None = field(default=None, compare=False, repr=False)

    def assembled(self) -> RotorMatrices:
        """The rig's assembled FE matrices: the model's own (``matrices``, assembled once
        with its FE model), or assembled here (a context made without them)."""
        return self.matrices if self.matrices is not None else assemble(self.rig)

    @property
    def omega_rot(self) -> float:
        """Running speed in rad/s."""
        return self.speed_rpm * 2 * math.pi / 60


@dataclass(frozen=True)
class Candidate:
    """Base of the candidate family; every hook has the same signature in every member."""

    effect: str
    location: str

    entry: ClassVar[EffectEntry]
    own_sampling: ClassVar[bool] = False   # samples the plant itself (one per model)
    scales_static: ClassVar[bool] = False  # its first parameter scales the nominal static path

    @property
    def fingerprint(self) -> str:
        return self.entry.fingerprint

    @property
    def nominal_family(self) -> bool:
        """A parameter of the nominal model left out of the fit: tried first, and
        preferred to physics unless the physics is stronger by the threshold (select.py)."""
        return self.entry.nominal_family

    @property
    def key(self) -> str:
        """A unique label, e.g. 'cross_coupling@D1'."""
        return f"{self.effect}@{self.location}"

    def params(self, ctx: ModelContext) -> tuple[EffectParam, ...]:
        """The sampled parameters with their priors (the registry's, at this location)."""
        return tuple(s.at(self.location) for s in self.entry.sampled)

    def lft_names(self) -> tuple[str, ...]:
        return ()

    def bending_pairs(self) -> tuple[int, ...]:
        """The FE bending-mode pairs (1-based) the model must keep for this candidate."""
        return ()

    def modal(self, A: NDArray, phi: NDArray, ctx: ModelContext, first: int) -> NDArray:
        """Batched nominal reduced A (nb, n, n) in modal coordinates -> changed A; ``first``
        is the index of the first state of this candidate's bending pair (if it has one)."""
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
        """Integer key per row (0..63): rows with different keys get differently built
        systems (e.g. no added states at the null)."""
        return np.zeros(phi.shape[0], dtype=int)

    def discrete(self, Ad: NDArray, Bd: NDArray, Cd: NDArray, phi: NDArray,
                 ctx: ModelContext) -> tuple[NDArray, NDArray, NDArray]:
        """Batched sampled plant -> changed plant (may append states)."""
        return Ad, Bd, Cd

    def line_force(self, ctx: ModelContext) -> NDArray | None:
        """Full-model force input (2 n_q, 2) of a synchronous line, or None."""
        return None

    def line_output(self, ctx: ModelContext) -> NDArray | None:
        """Measurement channels (4,) a synchronous line is added to (runout), or None."""
        return None

    def physical(self, draws: NDArray, ctx: ModelContext) -> dict[str, tuple[NDArray, str]]:
        """Physical parameters from sampled ones (n, q): name -> (values (n,), unit)."""
        raise NotImplementedError

    def describe(self, values: dict[str, float]) -> str:
        """One phrase naming the effect and its physical size."""
        raise NotImplementedError


@dataclass(frozen=True)
class SynchronousLine(Candidate):
    """Base of the 1x line candidates (unbalance, runout): two sampled coefficients a, b of
    Re((a + j b) e^{j Omega t}), with a phase at t = 0 of the record.

    ``start``: how the record begins: "rest" (the line starts with the record, as when the
    loop is closed at t = 0) or "steady" (the rotor was already spinning: no start
    transient). The diagnosis fits both and keeps the better."""

    start: str = "rest"
    UNIT: ClassVar[float] = 1.0


def channels_of(location: str) -> list[int]:
    """Channel indices of a bearing location: 'both' (all four), 'A', 'B' or a channel."""
    if location == "both":
        return [0, 1, 2, 3]
    if location in ("A", "B"):
        return [i for i, ch in enumerate(CHANNELS) if ch[0] == location]
    return [CHANNELS.index(location)]


def where_text(location: str) -> str:
    return "both bearings" if location == "both" else f"bearing {location}"


def positive_rows(phi: NDArray) -> NDArray:
    """Structure key: 1 where the first parameter (a time constant) is > 0, else 0 (no
    added states: the null is then exactly the nominal model)."""
    return (np.nan_to_num(phi[:, 0], nan=0.0) > 0).astype(int)


def time_constant_s(phi: NDArray) -> NDArray:
    """The hook's time constant (s) from a sampled column in ms: NaN and negatives -> 0."""
    return np.clip(np.nan_to_num(phi[:, 0]), 0.0, None) * 1e-3


def corner_hz(draws: NDArray) -> NDArray:
    """The frequency (Hz) 1 / (2 pi tau) of sampled time constants tau in ms (column 0)."""
    return 1.0 / (2 * np.pi * np.maximum(draws[:, 0], 1e-12) * 1e-3)


def live_inverse(tau: NDArray) -> tuple[NDArray, NDArray]:
    """Rows with a filter (tau > 0) and 1 / tau on them (1 on the others, whose added
    states are inert)."""
    live = tau > 0
    return live, np.where(live, 1.0 / np.where(live, tau, 1.0), 1.0)


def append_states(A: NDArray, B: NDArray, C: NDArray, k: int
                  ) -> tuple[NDArray, NDArray, NDArray, int]:
    """(A, B, C) stacks with k zero states appended; returns them and the first new index."""
    nb, n, _ = A.shape
    A2 = np.zeros((nb, n + k, n + k))
    A2[:, :n, :n] = A
    B2 = np.zeros((nb, n + k, B.shape[-1]))
    B2[:, :n] = B
    C2 = np.zeros((nb, C.shape[-2], n + k))
    C2[:, :, :n] = C
    return A2, B2, C2, n


def zoh_scaled(A: NDArray, B: NDArray, h: NDArray) -> tuple[NDArray, NDArray]:
    """Exact ZOH of a stack over per-row intervals h (nb,): (e^{A h}, int_0^h e^{As} ds B)."""
    nb, n, _ = A.shape
    m = B.shape[-1]
    E = np.zeros((nb, n + m, n + m))
    E[:, :n, :n] = A * h[:, None, None]
    E[:, :n, n:] = B * h[:, None, None]
    Ed = expm_batched(E)
    return Ed[:, :n, :n], Ed[:, :n, n:]
