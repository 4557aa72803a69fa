"""Checks of the data before any physics is blamed, and the removal of record habits.

A real recording breaks the simulator's habits: the sensors have offsets, the record starts
while the rotor is running, the firmware may not be the documented controller. None of that
is rotor physics, and none of it may be named as such. Each check here reports in one line;
a failed check is reported as such (the diagnosis then names no physics, see diagnose.py).

controller   Is the recorded u what the documented controller makes from the recorded y
             and excitation? The recorded u is the current at the plant input and includes
             an injected r2 (the convention of io/recording.py): u = K_u([y + r1; eta]) + r2.
             The controller file is run from rest on [y + r1; eta] and r2 is added to its u
             output (never fed to its eta port: a generic controller's eta port adds to its
             output, so r2 through it as well would count it twice); the difference to the
             recorded u must be at rounding level once the controller's own initial state
             has died out (x = Vt u - Ut y equals eta only for the documented controller).
start        Does the record start at rest? If the difference above is large in the first
             samples and then dies out, the controller (and so the loop) was running before
             the record began.
offsets      Sensor offsets and slow drift: the mean and linear trend of each y and u channel
             against the standard error of a mean of that series (batch means). They are
             removed from y and u before eps = Mt y - Nt u is formed (eps is linear in y and
             u, so this removes their response except for its start-up transient).
excitation   Is there an excitation to identify from, on which channels?

Whenever the record does not start at rest or a trend was removed, the start-up transient
of the eps filter and of S(theta) from its unknown initial state is kept out of the
likelihood: the first ``start`` samples become *pre-history* (the model is driven by the
excitation from sample 0, so its state at ``start`` is exact; only the bins of the window
[start, N) are compared; see likelihood.RobustWhittle). ``start`` follows from the slowest
pole of the nominal loop (decay to 1e-3).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.signal import detrend

from bayes_amb.control.discrete import ss_response
from bayes_amb.discrepancy.flat_tops import held_samples
from bayes_amb.discrepancy.locate import _coherence
from bayes_amb.io.recording import Recording, require_excitation
from bayes_amb.rig import CHANNELS

CONTROLLER_TOL = 1e-4
"""Relative RMS difference between recorded and re-computed u at the first samples below
which the record counts as starting at rest (CSV at full precision gives ~1e-15)."""

CONTROLLER_SHARE = 1e-6
"""Share of the power of u that may follow the excitation in u - K(y, eta) - r2 before the
documented controller counts as not the one that ran (a 0.1 % gain change gives ~1e-6)."""

DECAY = 1e-3
"""Start-up transients are kept out until the slowest loop pole has decayed by this factor."""

MAX_START_SHARE = 0.2
"""At most this share of the record is used as pre-history."""


@dataclass(frozen=True)
class Check:
    """One data check: name, ok, and one line saying what was found."""

    name: str
    ok: bool
    line: str
    values: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"check": self.name, "ok": self.ok, "line": self.line, **self.values}


@dataclass(frozen=True)
class DataChecks:
    """All checks of a recording, the cleaned signals and the pre-history length.

    y, u: the recorded signals with significant offsets/trends removed (N, 4); start: the
    first sample of the compared window; at_rest: whether the record starts at rest;
    failed: names of the checks that failed (the diagnosis names no physics then).
    """

    checks: tuple[Check, ...]
    y: NDArray
    u: NDArray
    start: int
    at_rest: bool

    @property
    def failed(self) -> list[str]:
        return [c.name for c in self.checks if not c.ok]

    def to_list(self) -> list[dict[str, Any]]:
        return [c.to_dict() for c in self.checks]


def _controller_inputs(rec: Recording) -> NDArray:
    y = np.asarray(rec.y, dtype=float)
    r1 = rec.excitation.get("r1")
    eta = rec.excitation.get("eta")
    v = np.zeros((y.shape[0], 8))
    v[:, :4] = y if r1 is None else y + np.asarray(r1)
    if eta is not None:
        v[:, 4:] = eta
    return v


def recompute_u(rec: Recording) -> NDArray:
    """The current the documented controller puts at the plant input, (N, 4) in A.

    u = K_u([y + r1; eta]) + r2: the controller file run from rest on the recorded
    [y + r1; eta], plus the recorded r2 excitation added after its output. This is the one
    rule for every controller kind; r2 never enters the file's eta port (a generic
    controller adds its eta input to its output, so the same excitation through both would
    be counted twice). Groups absent from the recording count as zero.
    """
    ctrl = rec.controller
    v = _controller_inputs(rec)
    A, B, C, D = (np.asarray(m, dtype=float) for m in (ctrl.A, ctrl.B, ctrl.C, ctrl.D))
    out = ss_response(A, B, C[:4], D[:4], v)
    r2 = rec.excitation.get("r2")
    return out if r2 is None else out + np.asarray(r2, dtype=float)


def settle_samples(poles: NDArray, n: int, decay: float = DECAY) -> int:
    """Samples until the slowest of the discrete poles has decayed by ``decay``, capped at
    MAX_START_SHARE of the record n."""
    rho = float(np.max(np.abs(poles))) if np.size(poles) else 0.0
    rho = min(max(rho, 1e-6), 1 - 1e-9)
    return int(min(np.ceil(np.log(decay) / np.log(rho)), MAX_START_SHARE * n))


def _batch_se(v: NDArray, n_batches: int = 20) -> NDArray:
    """Standard error of the mean of each column of v by batch means (robust to colour)."""
    m = v.shape[0] // n_batches * n_batches
    means = v[:m].reshape(n_batches, -1, v.shape[1]).mean(axis=1)
    return means.std(axis=0, ddof=1) / np.sqrt(n_batches)


def check_excitation(rec: Recording) -> Check:
    """Which excitation channels carry a signal; refuses a recording with none."""
    require_excitation(rec)
    rms = {g: np.sqrt(np.mean(np.asarray(v) ** 2, axis=0)) for g, v in rec.excitation.items()}
    live = {g: [c for c, r in zip(CHANNELS, v, strict=True) if r > 0] for g, v in rms.items()}
    parts = [f"{g} on {','.join(ch)} (rms {np.max(rms[g]):.3g})" for g, ch in live.items() if ch]
    return Check("excitation", True, "excitation present: " + "; ".join(parts),
                 {"rms": {g: [float(x) for x in v] for g, v in rms.items()}})


def _coherent_share(d: NDArray, x: NDArray, u: NDArray, min_bins: int = 32
                    ) -> tuple[float, float]:
    """Share of the power of u that a per-band linear regression of d on the excitation x
    explains (locate's coherence F-test, bands of >= min_bins bins), and the smallest
    Bonferroni-adjusted p-value of that regression."""
    D, X = np.fft.rfft(d, axis=0)[1:], np.fft.rfft(x, axis=0)[1:]
    U = np.fft.rfft(u - u.mean(axis=0), axis=0)[1:]
    n_b = max(1, D.shape[0] // max(min_bins, 2 * X.shape[1] + 2))
    bands = np.array_split(np.arange(D.shape[0]), n_b)
    coh, p = _coherence(D, X, bands)
    ss0 = np.array([np.sum(np.abs(D[b]) ** 2, axis=0) for b in bands])
    expl = float(np.sum(coh * ss0))              # least squares: ss0 - ss1 = |fit|^2
    p_adj = float(min(1.0, p.min() * p.size))
    return expl / max(float(np.sum(np.abs(U) ** 2)), 1e-300), p_adj


@dataclass(frozen=True)
class StartState:
    """How the record starts, from the controller's side: u, the difference d = u - K(y +
    r1, eta) - r2 (K run from rest), the samples n_settle the slowest of the controller's and
    the loop's poles needs to die out (to 1e-6), the tail after it, d's RMS there and in
    the first samples (rel_tail, rel_head, relative to u's RMS in the tail) and at_rest:
    the head's difference is no larger than ten times the tail's (or 1e-3 of u)."""

    u: NDArray
    d: NDArray
    n_settle: int
    tail: slice
    rel_tail: float
    rel_head: float

    @property
    def at_rest(self) -> bool:
        return self.rel_head <= max(10 * CONTROLLER_TOL, 10 * self.rel_tail)

    @property
    def told(self) -> bool:
        """Whether the check can tell. It cannot when it finds the record at rest only
        because the difference after the start-up is as large as the one at the start
        (a clipping amplifier, a measured current: a start-up difference no larger than
        ten times it is not seen) and the start's is above 10 CONTROLLER_TOL. A start-up
        difference below that is at rest whatever follows (a controller with unstable
        poles, run alone, lets rounding grow in the tail)."""
        return not self.at_rest or self.rel_head <= 10 * CONTROLLER_TOL

    def without(self, held: NDArray) -> StartState:
        """The same with d zero on ``held`` ((N, 4) samples of a recorded coil current held
        at the amplifier's limit, where the difference is the limit's, not the start's)."""
        d = np.where(held, 0.0, self.d)
        return replace(self, d=d, **_relative(self.u, d, self.tail))


def _relative(u: NDArray, d: NDArray, tail: slice) -> dict[str, float]:
    """rel_tail, rel_head of StartState: d's RMS after the start-up and in the first
    samples, relative to u's RMS after it."""
    n = u.shape[0]
    scale = float(np.sqrt(np.mean((u[tail] - u[tail].mean(axis=0)) ** 2))) or 1.0
    head = slice(0, max(1, min(20, n // 50)))
    return {"rel_tail": float(np.sqrt(np.mean(d[tail] ** 2)) / scale),
            "rel_head": float(np.sqrt(np.mean(d[head] ** 2)) / scale)}


def start_state(rec: Recording, poles: NDArray) -> StartState:
    """Does the record start at rest? (StartState; ``poles``: the loop's discrete poles,
    adequacy.loop_poles.) A controller started from rest on the recorded signals
    reproduces the recorded u only after the controller's initial state has died out, so a
    record that starts mid-operation shows a start-up difference. The diagnosis then uses
    the first samples as pre-history (run_checks), and identify fits the start transient
    (IdentifyOptions.initial_state)."""
    u = np.asarray(rec.u, dtype=float)
    d = u - recompute_u(rec)
    n = u.shape[0]
    ctrl_poles = np.linalg.eigvals(np.asarray(rec.controller.A, dtype=float)) \
        if rec.controller.A.size else np.zeros(0)
    n_settle = settle_samples(np.concatenate([ctrl_poles, poles]), n, 1e-6)
    tail = slice(min(n_settle, n // 2), n)
    return StartState(u=u, d=d, n_settle=n_settle, tail=tail, **_relative(u, d, tail))


def _documented(share: float, p_adj: float) -> bool:
    """No significant part of the difference, above CONTROLLER_SHARE of u's power, follows
    the excitation."""
    return not (p_adj < 1e-3 and share > CONTROLLER_SHARE)


def check_controller(rec: Recording, poles: NDArray) -> tuple[Check, Check, int]:
    """Controller consistency and start at rest; returns both checks and the samples the
    controller's initial state needs to die out.

    The difference d = u - K(y + r1, eta) - r2 is the controller's own start-up transient (when
    the record starts mid-operation), plus K applied to any unrecorded sensor-side
    disturbance, plus - if the firmware is not the documented controller - a part driven by
    the excitation. Only the last counts against the documentation: the check fails when a
    regression of d on the excitation (after the start-up) is significant and explains
    more than 1e-6 of the power of u.
    """
    st = start_state(rec, poles)
    u, d, tail, rel_tail, rel_head = st.u, st.d, st.tail, st.rel_tail, st.rel_head
    x = np.concatenate(list(rec.excitation.values()), axis=1)[tail]
    share, p_adj = _coherent_share(d[tail], x, u[tail])
    ok = _documented(share, p_adj)
    coil = False
    held = held_samples(rec) if not ok else None
    if held is not None and held.any():
        # a DAQ that records the coil current records the amplifier's output: where the
        # amplifier held it at its limit it is not the command, and nowhere else
        masked = st.without(held)
        share_o, p_o = _coherent_share(masked.d[tail], x, u[tail])
        coil = ok = _documented(share_o, p_o)
        if coil:
            share, p_adj, st = share_o, p_o, masked
            rel_tail, rel_head = st.rel_tail, st.rel_head
    if coil:
        line = (f"controller: the recorded u is what the documented controller makes from the "
                f"recorded y and excitation except where u is held at its extremes "
                f"({100 * held.any(axis=1).mean():.2g} % of the samples; elsewhere a share "
                f"{share:.1e} follows the excitation): the recorded current is the "
                "amplifier's output after its limit, and the command is the controller's")
    elif ok:
        line = (f"controller: the recorded u is what the documented controller makes from the "
                f"recorded y and excitation (difference {rel_tail:.1e} of u, of which a share "
                f"{share:.1e} follows the excitation)")
    else:
        line = (f"controller: FAILED - the recorded u differs from the documented controller's "
                f"output by {100 * rel_tail:.2g} % RMS, driven by the excitation (share "
                f"{share:.1e}, p {p_adj:.1e}); the controller that ran is not the one in the "
                "recording's sidecar, so the model cannot be compared with the data and no "
                "physics is named")
    at_rest = st.at_rest
    if not at_rest:
        start_line = (f"start: the record starts mid-operation (the controller's initial state "
                      f"gives a start-up difference of {100 * rel_head:.2g} % in u); the first "
                      "samples are used as pre-history only")
    elif st.told:
        start_line = ("start: the record starts at rest (the controller's state is zero at "
                      "the first sample)")
    else:
        start_line = (f"start: cannot be told - the recorded u differs from the documented "
                      f"controller's output by {100 * rel_tail:.2g} % throughout, which hides "
                      "a start-up difference; the record is taken as starting at rest")
    values = {"relative_difference": rel_tail, "excitation_share": share,
              "p_adjusted": p_adj, **({"limited_coil_current": True} if coil else {})}
    return (Check("controller", ok, line, values),
            Check("start", True, start_line, {"at_rest": bool(at_rest),
                                              "start_difference": rel_head}),
            st.n_settle)


def check_offsets(rec: Recording) -> tuple[Check, NDArray, NDArray, bool]:
    """Mean and linear trend of y and u, removed where significant (|value| > 5 standard
    errors of a batch mean). Returns the check, cleaned y and u, and whether anything was
    removed."""
    y = np.asarray(rec.y, dtype=float)
    u = np.asarray(rec.u, dtype=float)
    t = np.linspace(-1.0, 1.0, y.shape[0])[:, None]
    found, removed = [], False
    out = []
    for name, v, unit, scale in (("y", y, "um", 1e6), ("u", u, "mA", 1e3)):
        mean = v.mean(axis=0)
        slope = np.sum((v - mean) * t, axis=0) / np.sum(t**2)
        se = _batch_se(v)
        se_slope = _batch_se((v - mean) * t * 3.0)          # var of the LS slope ~ 3 var/N
        sig_m = np.abs(mean) > 5 * se
        sig_s = np.abs(slope) > 5 * se_slope
        if np.any(sig_m | sig_s):
            removed = True
            v = detrend(v, axis=0, type="linear")
            for c in np.flatnonzero(sig_m):
                found.append(f"{name}_{CHANNELS[c]} offset {scale * mean[c]:+.3g} {unit}")
            for c in np.flatnonzero(sig_s & ~sig_m):
                found.append(f"{name}_{CHANNELS[c]} drift {scale * 2 * slope[c]:+.3g} {unit}")
        out.append(v)
    line = ("offsets: none significant" if not found else
            "offsets: " + ", ".join(found) + " - removed (a measurement habit, not physics)")
    return Check("offsets", True, line, {"removed": found}), out[0], out[1], removed


def run_checks(rec: Recording, loop_poles: NDArray) -> DataChecks:
    """Every check of a recording. loop_poles: the discrete poles of the nominal x -> eps
    system (S at theta = 0), whose slowest one sets the pre-history length."""
    exc = check_excitation(rec)
    ctrl, start_chk, _ = check_controller(rec, loop_poles)
    off, y, u, removed = check_offsets(rec)
    at_rest = bool(start_chk.values["at_rest"])
    start = 0
    if removed or not at_rest:
        start = settle_samples(loop_poles, y.shape[0])
    return DataChecks(checks=(exc, ctrl, start_chk, off), y=y, u=u, start=start,
                      at_rest=at_rest)
