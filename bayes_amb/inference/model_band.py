"""How many bending pairs a recording's model keeps: the control band decides.

The paper's rotor has its first bending mode far above the control band, and its 8-state
rigid-body model holds everything the loop does. A real rotor often has a bending pair
inside the band (ROSS's test rig: 101.6 / 102.9 Hz, with the loop's gain above one up to
about 105 Hz). The likelihood uses the bins up to the model's validity band, half the
frequency of the lowest mode the reduction leaves out (ForwardModel.validity_band_hz), so
an 8-state model of that rig would see only the record below 51 Hz, and in it a loop
whose bending pair it lacks.

The rule: keep the fewest bending pairs k for which the model's validity band covers its
own control band, the highest frequency at which the largest singular value of the loop
gain K(z) G_k(z) still reaches one (G_k: the k-pair reduced plant, exactly sampled;
K: the recording's controller from the displacements to the currents). The loop gain of
each model is its own: a pair kept inside the band can lift the gain near its frequency,
and the band is then read again. On the reference rig the rigid-body loop crosses one
at 244 Hz and the model is valid to 514 Hz, so it stays the paper's 8-state model (k = 0,
bit for bit). On ROSS's test rig k = 0 crosses at 105 Hz against a 51 Hz validity band;
k = 1 crosses at 141 Hz against 193 Hz, and the model keeps pair 1 (12 states). A model
that keeps bending pairs also holds the static compliance of the modes it leaves out
(ForwardModel.static).

Measured on that rig (own simulator, k_Ax 0.1, k_By -0.1, c_Bx 0.05, 1 s at 10 kHz,
three seeds, ``identify --map-only`` with its adequacy test): the eight coefficients
inside their 90 % intervals 4/8 with k = 0 (seed 1), 8/8 on all three seeds with k = 1
(sds 0.001-0.02 in theta, the prior's 0.46), 7/8 with k = 2.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from bayes_amb.control.discrete import ss_freqresp, zoh
from bayes_amb.errors import ReductionError
from bayes_amb.reduction import ReducedModel, reduce_pseudo_modal
from bayes_amb.rotor import FullModel

MAX_PAIRS = 4
"""The most bending pairs a model keeps by this rule (16 + 8 = 24 states)."""

N_GRID = 2000
"""Frequencies (log-spaced, 0.5 Hz to 0.49 of the sampling rate) of the loop-gain scan."""


@dataclass(frozen=True)
class ModelBand:
    """The reduced model a recording's likelihood uses, and why.

    n_bending: bending pairs kept (8 + 4 n_bending states); validity_hz: half the
    frequency of the lowest mode left out (the likelihood's band); control_hz: the highest
    frequency at which the loop gain's largest singular value reaches one, on this model;
    bending_hz: the kept pairs' frequencies (backward and forward whirl, Hz); capped: the
    rule wanted more than MAX_PAIRS, or the reduction could not cut further."""

    n_bending: int
    validity_hz: float
    control_hz: float
    bending_hz: tuple[float, ...] = ()
    capped: bool = False

    @property
    def n_states(self) -> int:
        return 8 + 4 * self.n_bending

    def line(self) -> str:
        """One line for the CLI and the summary."""
        if self.n_bending == 0:
            held = "the rigid-body modes"
        else:
            pairs = ", ".join(f"{a:.1f}/{b:.1f} Hz" for a, b in
                              zip(self.bending_hz[::2], self.bending_hz[1::2], strict=True))
            held = (f"the rigid-body modes and bending pair{'s' if self.n_bending > 1 else ''}"
                    f" 1{f'-{self.n_bending}' if self.n_bending > 1 else ''} ({pairs}), "
                    "with the static compliance of the modes it leaves out")
        out = (f"model: {self.n_states} states, {held}; valid to {self.validity_hz:.0f} Hz, "
               f"the loop's gain reaches one up to {self.control_hz:.0f} Hz")
        if self.capped:
            out += (" (the model keeps no more pairs: the likelihood's band stops short of "
                    "the control band)")
        return out

    def to_dict(self) -> dict[str, object]:
        return {"states": self.n_states, "bending_pairs": self.n_bending,
                "bending_hz": list(self.bending_hz), "validity_band_hz": self.validity_hz,
                "control_band_hz": self.control_hz, "capped": self.capped,
                "line": self.line()}


def validity_hz(full: FullModel, n_states: int) -> float:
    """Half the frequency (|lambda| / 2 pi) of the lowest mode a reduction to n_states
    leaves out (it keeps the eigenvalues of smallest modulus)."""
    moduli = np.sort(np.abs(full.poles))
    return float(0.5 * moduli[n_states] / (2 * np.pi))


def control_band_hz(red: ReducedModel, K: tuple[NDArray, NDArray, NDArray, NDArray],
                    dt: float) -> float:
    """The highest frequency (Hz) at which the largest singular value of K(z) G(z) reaches
    one, G the exactly sampled reduced plant and K = (A, B, C, D) the controller from the
    four displacements to the four currents; 0 when it never does."""
    f = np.geomspace(0.5, 0.49 / dt, N_GRID)
    z = np.exp(2j * np.pi * f * dt)
    Ad, Bd = zoh(red.A, red.B, dt)
    G = ss_freqresp(Ad, Bd, red.C, None, z)
    Kf = ss_freqresp(*K, z)
    top = np.linalg.svd(Kf @ G, compute_uv=False)[:, 0]
    above = f[top >= 1.0]
    return float(above.max()) if above.size else 0.0


def feedback_part(A: NDArray, B: NDArray, C: NDArray, D: NDArray
                  ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """A controller file's (A, B, C, D) on [y; excitation] -> [u; eps], cut to y -> u."""
    return A, B[:, :4], C[:4], D[:4, :4]


def choose_model(full: FullModel, K: tuple[NDArray, NDArray, NDArray, NDArray], dt: float
                 ) -> tuple[ReducedModel, ModelBand]:
    """The reduced model with the fewest bending pairs whose validity band covers its own
    control band (module docstring), and the record of the choice."""
    red = reduce_pseudo_modal(full)
    band = ModelBand(0, validity_hz(full, 8), control_band_hz(red, K, dt))
    while band.control_hz > band.validity_hz:
        k = band.n_bending + 1
        if k > MAX_PAIRS:
            return red, replace(band, capped=True)
        try:
            nxt = reduce_pseudo_modal(full, n_bending=k)
            valid = validity_hz(full, 8 + 4 * k)
        except (ReductionError, IndexError):
            return red, replace(band, capped=True)
        hz = tuple(float(v) for v in np.sort(np.abs(full.poles))[8:8 + 4 * k:2] / (2 * np.pi))
        red, band = nxt, ModelBand(k, valid, control_band_hz(nxt, K, dt), hz)
    return red, band
