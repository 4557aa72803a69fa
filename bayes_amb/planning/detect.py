"""Would an effect of a given size show? The expected log Bayes factor of a design (issue 30).

A hidden effect changes the excitation's response by Delta_k (the DFT of eps with the
effect minus without, noise-free, on the likelihood's own prewhitened grid). The nominal
model absorbs what its coefficients can mimic (J, their Jacobian); the rest is the
expected log-likelihood gain of the model with the effect, in nats (complex Whittle terms):

    Q = sum_k Delta_k^H W_k Delta_k - g^T F^-1 g / 2,    g = 2 Re sum_k J_k^H W_k Delta_k,

F the coefficients' information, W the inverse noise spectrum. The diagnosis compares
models by Laplace Bayes factors, so the effect's own Occam factor is taken off: with d_k
the change of Delta per unit of the effect's size p (what the coefficients cannot absorb),
its posterior sd is sigma_p = (2 Re sum d^H W d - h^T F^-1 h)^-1/2, and in the candidate's
sampled parameter phi(p), whose prior the library states,

    log BF = Q - log(w / (sqrt(2 pi) sigma_phi))                 (uniform prior, width w)
    log BF = Q - log(s / sigma_phi) - phi^2 / (2 s^2)            (normal prior N(0, s^2)).

Detected when the log posterior odds log BF - log K pass the diagnosis' threshold, K the
candidates of a round (select.py, Multiplicity). A first-order prediction of the expected
evidence; the noise makes the observed one scatter about it by about sqrt(2 Q).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.forward import ForwardModel
from bayes_amb.inference.noise_check import residual_jacobian
from bayes_amb.inference.offline import dual_youla_eps
from bayes_amb.inference.whittle import WhittleLikelihood
from bayes_amb.io.controller_file import ControllerFile
from bayes_amb.planning.fisher import log10_sigma_of
from bayes_amb.planning.plan import BEARING_COEFFICIENTS, Design, Noise
from bayes_amb.rig import Rig
from bayes_amb.simulate import SimulationConfig, simulate_recording
from bayes_amb.simulate.effects import Effect

THRESHOLD = 3.0
"""The diagnosis' default acceptance: log posterior odds above 3 (DiagnoseOptions)."""


@dataclass(frozen=True)
class SizeMap:
    """How the simulator's size of an effect maps to the candidate's sampled parameter:
    ``size`` the effect parameter, ``phi(p)`` the sampled value, ``prior(dt)`` its prior
    as (kind, a, b)."""

    size: str
    phi: Callable[[float, Rig], float]
    prior: Callable[[float], tuple[str, float, float]]


SIZES: dict[str, SizeMap] = {
    "actuator_lag": SizeMap("bandwidth_hz", lambda p, rig: 1e3 / (2 * math.pi * p),
                            lambda dt: ("uniform", 0.0, 1.6)),
    "time_delay": SizeMap("delay_s", lambda p, rig: 1e3 * p,
                          lambda dt: ("uniform", 0.0, max(4 * dt, 4e-4) * 1e3)),
    "cross_coupling": SizeMap("kxy", lambda p, rig: p / rig.k_ref,
                              lambda dt: ("uniform", -10.0, 10.0)),
    "sensor_gain": SizeMap("gain", lambda p, rig: p, lambda dt: ("normal", 0.0, 0.1)),
}
"""The effects whose detectability is predicted (one sampled parameter each)."""


def _eps_dft(like: WhittleLikelihood, rec: Any) -> NDArray:
    """A record's eps on the likelihood's grid (prewhitened, scaled, its bins)."""
    eps = dual_youla_eps(like.forward.parts, np.asarray(rec.y), np.asarray(rec.u))
    w = lfilter(like.prefilter, [1.0], eps, axis=0)
    return np.fft.rfft(w / like.scale, axis=0)[like.k]


def detectability(rig: Rig, controller: ControllerFile, design: Design, noise: Noise,
                  effect: Effect, params: tuple[str, ...] = BEARING_COEFFICIENTS,
                  n_candidates: int | None = None, speed_rpm: float | None = None,
                  seed: int = 0) -> dict[str, Any]:
    """The expected evidence for ``effect`` (the simulator's, e.g. Effect('actuator_lag',
    {'bandwidth_hz': 2000, 'bearing': 'both'})) on a record of ``design`` with the rig's
    ``noise`` (module docstring)."""
    if effect.name not in SIZES:
        raise BayesAmbError(f"plan --effect: detectability is predicted for "
                            f"{', '.join(SIZES)}; got {effect.name!r}")
    sm = SIZES[effect.name]
    p = float(effect.params[sm.size])
    if p == 0:
        raise BayesAmbError(f"plan --effect: {effect.name}: {sm.size} must not be 0")

    def record(e: Effect | None):
        cfg = SimulationConfig(truth="reduced", effects=() if e is None else (e,),
                               excitation=design.excitation, amplitude=design.amplitude,
                               excitation_band_hz=design.band_hz, channels=design.channels,
                               duration=design.duration, dt=design.dt, speed_rpm=speed_rpm,
                               seed=seed, port=design.port)
        return simulate_recording(rig, controller, cfg)[0]

    rec0 = record(None)
    fwd = ForwardModel(rec0, params)
    eps0 = dual_youla_eps(fwd.parts, np.asarray(rec0.y), np.asarray(rec0.u))
    like = WhittleLikelihood(fwd, eps0 + 1e-12 * np.random.default_rng(0).standard_normal(
        eps0.shape))
    theta = np.zeros(len(params))
    ls = log10_sigma_of(noise.noise_rms, noise.r1_rms, noise.r2_rms)
    like.set_model_prewhitening(theta, ls)
    E0 = _eps_dft(like, rec0)
    h = 1e-2 * abs(p)
    delta = _eps_dft(like, record(effect)) - E0
    d = (_eps_dft(like, record(replace(effect, params={**effect.params, sm.size: p + h})))
         - E0 - delta) / h
    J = residual_jacobian(like, theta)
    W = like.curvature_weights(theta, ls)[np.repeat(np.arange(like.starts.size),
                                                    like.counts)]
    F = 2 * np.einsum("kci,kcd,kdj->ij", J.conj(), W, J).real

    def quad(a: NDArray, b: NDArray) -> float:
        return float(np.einsum("kc,kcd,kd->", a.conj(), W, b).real)

    g = 2 * np.einsum("kci,kcd,kd->i", J.conj(), W, delta).real
    hv = 2 * np.einsum("kci,kcd,kd->i", J.conj(), W, d).real
    Finv = np.linalg.inv(F)
    gain = quad(delta, delta) - 0.5 * g @ Finv @ g
    info = 2 * quad(d, d) - hv @ Finv @ hv
    sd_p = 1.0 / math.sqrt(info) if info > 0 else math.inf
    phi = sm.phi(p, rig)
    dphi = abs(sm.phi(p + h, rig) - phi) / h
    sd_phi = dphi * sd_p
    kind, a, b = sm.prior(design.dt)
    if kind == "uniform":
        occam = math.log((b - a) / (math.sqrt(2 * math.pi) * sd_phi))
    else:
        occam = math.log(b / sd_phi) + (phi - a) ** 2 / (2 * b * b)
    log_bf = gain - occam
    if n_candidates is None:
        from bayes_amb.discrepancy.library.registry import all_candidates
        n_candidates = len(all_candidates(rig=rig))
    odds = log_bf - math.log(n_candidates)
    scatter = math.sqrt(max(2 * gain, 0.0))
    prob = (0.5 * math.erfc(-(odds - THRESHOLD) / (scatter * math.sqrt(2)))
            if scatter > 0 else float(odds > THRESHOLD))
    return {"effect": effect.name, "params": dict(effect.params), "size": sm.size,
            "expected_log_likelihood_gain": gain, "expected_log_bayes_factor": log_bf,
            "log_prior_odds": -math.log(n_candidates),
            "expected_log_posterior_odds": odds, "threshold": THRESHOLD,
            "detected": bool(odds > THRESHOLD), "probability_detected": prob,
            "posterior_sd_of_size": sd_p, "scatter_of_log_bf": scatter}


WEAKER = {"actuator_lag": lambda p, f: p / f, "time_delay": lambda p, f: p * f,
          "cross_coupling": lambda p, f: p * f, "sensor_gain": lambda p, f: p * f}
"""The effect made weaker by a factor f < 1 (a lag by a higher bandwidth)."""


def smallest_detectable(rig: Rig, controller: ControllerFile, design: Design, noise: Noise,
                        effect: Effect, params: tuple[str, ...] = BEARING_COEFFICIENTS,
                        speed_rpm: float | None = None, seed: int = 0, steps: int = 10
                        ) -> dict[str, Any]:
    """The weakest version of ``effect`` (its size scaled in log steps from the given one)
    whose expected log posterior odds still pass the threshold: bisection over the factor,
    ``steps`` evaluations."""
    sm = SIZES.get(effect.name)
    if sm is None:
        raise BayesAmbError(f"plan --effect: detectability is predicted for "
                            f"{', '.join(SIZES)}; got {effect.name!r}")
    p0 = float(effect.params[sm.size])

    def at(f: float) -> dict[str, Any]:
        e = replace(effect, params={**effect.params, sm.size: WEAKER[effect.name](p0, f)})
        return detectability(rig, controller, design, noise, e, params, None, speed_rpm,
                             seed)

    lo, hi = 1e-4, 1.0                     # factors: lo undetected (assumed), hi the given
    best = at(hi)
    if not best["detected"]:
        return {**best, "smallest_detectable": None,
                "note": "the given size is not detected; give a larger one"}
    for _ in range(steps):
        mid = math.sqrt(lo * hi)
        r = at(mid)
        if r["detected"]:
            hi, best = mid, r
        else:
            lo = mid
    return {**best, "smallest_detectable": {sm.size: best["params"][sm.size]}}
