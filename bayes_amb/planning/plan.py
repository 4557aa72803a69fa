"""``plan``: what a test will tell before it is run (issue 30).

A design (excitation, amplitude, band, channels, duration, sample time) and the noise the
rig has (given, or fitted on an earlier recording) give the Fisher information of the
Whittle likelihood (fisher.py), and from it the posterior sd each parameter will have, in
the units identify reports. Checked against studies (README, Test design).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import signal as sps

from bayes_amb.discrepancy.library.bearing_coefficient import BEARING_COEFFICIENTS
from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.priors import Prior, PriorSet
from bayes_amb.io.controller_file import ControllerFile
from bayes_amb.io.recording import Recording
from bayes_amb.planning.colour import NoiseColour, measure_colour, spectrum_colour
from bayes_amb.planning.fisher import (
    Information,
    defect_shift,
    fisher_information,
    log10_sigma_of,
    white_fit,
)
from bayes_amb.rig import Rig
from bayes_amb.simulate import SimulationConfig, simulate_recording
from bayes_amb.uncertainty import get_spec, parse_param_list

NOT_INFORMED = 0.5
"""A predicted sd (or spread of the estimates) above this share of the prior sd: the
record will not inform the parameter, its posterior stays near the prior, and the
first-order prediction does not hold there."""

FIRST_ORDER = 0.3
"""A predicted sd (or spread) between this share of the prior sd and NOT_INFORMED: the
record informs the parameter weakly, and the first-order prediction is rough. On 160
foreign process-force records every informed coefficient fell there (0.3-0.5 x the prior
sd); the estimates' scatter about the truth was 0.67-1.12 of the predicted sd, heavy
tailed (robust scale 0.51-0.84). Below it, on 200 one-channel records, 0.82-1.00 against
the white model's sd; against the sandwich identify now reports, 0.70-0.92 (conservative)."""


@dataclass(frozen=True)
class Design:
    """A test: excitation kind (random-binary, prbs, multisine, odd-multisine), amplitude
    (A) on the excited ``channels`` (None: all four), multisine ``band_hz``, ``duration``
    (s), ``dt`` (s), excitation ``port`` (None: eta for an observer controller, else r2)."""

    excitation: str = "random-binary"
    amplitude: float = 0.5
    band_hz: tuple[float, float] | None = None
    channels: tuple[str, ...] | None = None
    duration: float = 2.0
    dt: float = 1e-4
    port: str | None = None


@dataclass(frozen=True)
class Noise:
    """The rig's noise: sensor noise (m RMS, white), sensor-side r1 (m) and actuator-side
    r2 (A) RMS, each white or low-pass band-limited (``*_band_hz``, 4th-order Butterworth,
    as ``simulate`` makes it); ``colour`` the colour measured on an earlier recording
    (colour.py, :func:`noise_from`), which then replaces the band limits."""

    noise_rms: float = 5e-8
    r1_rms: float = 0.0
    r2_rms: float = 0.0
    r1_band_hz: float | None = None
    r2_band_hz: float | None = None
    colour: NoiseColour | None = field(default=None, repr=False, compare=False)

    def to_dict(self) -> dict[str, Any]:
        out = {k: v for k, v in asdict(self).items() if k != "colour"}
        if self.colour is not None:
            out["colour"] = self.colour.summary()
        return out


@dataclass(frozen=True)
class Plan:
    """The prediction for one design: per parameter the posterior sd (theta units and
    physical), the prior sd, and whether the record will inform it."""

    design: Design
    noise: Noise
    speed_rpm: float
    parameters: dict[str, dict[str, Any]]
    f_max_hz: float
    n_bins: int
    notes: list[str] = field(default_factory=list)
    theta: dict[str, float] = field(default_factory=dict)

    def sd(self, name: str) -> float:
        return float(self.parameters[name]["sd"])

    def to_dict(self) -> dict[str, Any]:
        return {"format": "bayes-amb-plan/1", "design": asdict(self.design),
                "noise": self.noise.to_dict(), "speed_rpm": self.speed_rpm,
                "parameters": self.parameters, "f_max_hz": self.f_max_hz,
                "n_bins": self.n_bins, "notes": self.notes, "at_theta": self.theta,
                "method": "first-order (Fisher information of the Whittle likelihood)"}

    def table(self) -> str:
        """The prediction as a text table."""
        lines = [f"{'parameter':<10} {'sd (theta)':>11} {'sd (physical)':>16} "
                 f"{'spread':>9} {'prior sd':>9}  informed"]
        for n, v in self.parameters.items():
            lines.append(f"{n:<10} {v['sd']:>11.3g} {v['physical_sd']:>12.3g} {v['unit']:<4}"
                         f"{v['sd_of_estimates']:>9.3g} {v['prior_sd']:>9.3g}  "
                         f"{informed_word(v)}")
        return "\n".join(lines + self.notes)


def informed_word(v: dict[str, Any]) -> str:
    """'yes', 'weakly' (the prediction rough: FIRST_ORDER) or 'NO' for a parameter row."""
    if not v["informed"]:
        return "NO"
    return "yes" if v.get("first_order", True) else "weakly"


def _band_gain(band_hz: float | None, f: NDArray, dt: float) -> NDArray:
    """Power gain of simulate's band-limiting at f (mean 1 over the band to Nyquist)."""
    if band_hz is None:
        return np.ones_like(f)
    if not 0 < band_hz < 0.5 / dt:
        raise BayesAmbError(f"disturbance bandwidth {band_hz} Hz must lie below Nyquist "
                            f"{0.5 / dt:g} Hz")
    sos = sps.butter(4, band_hz, fs=1.0 / dt, output="sos")
    grid = np.linspace(0, 0.5 / dt, 4097)
    _, h_grid = sps.sosfreqz(sos, worN=grid, fs=1.0 / dt)
    _, h = sps.sosfreqz(sos, worN=f, fs=1.0 / dt)
    return np.abs(h) ** 2 / np.mean(np.abs(h_grid) ** 2)


def design_recording(rig: Rig, controller: ControllerFile, design: Design,
                     noise: Noise, speed_rpm: float | None = None,
                     theta: dict[str, float] | None = None, seed: int = 0
                     ) -> tuple[Recording, SimulationConfig]:
    """A recording of the design on the reduced model (its excitation is what the
    information is computed from; its noise sets only the likelihood's scale)."""
    cfg = SimulationConfig(truth="reduced", params=dict(theta or {}),
                           excitation=design.excitation, amplitude=design.amplitude,
                           excitation_band_hz=design.band_hz, channels=design.channels,
                           noise_rms=noise.noise_rms, r1_rms=noise.r1_rms,
                           r2_rms=noise.r2_rms, r1_band_hz=noise.r1_band_hz,
                           r2_band_hz=noise.r2_band_hz, duration=design.duration,
                           dt=design.dt, speed_rpm=speed_rpm, seed=seed, port=design.port)
    cfg.validate()
    rec, _ = simulate_recording(rig, controller, cfg)
    return rec, cfg


def information(rig: Rig, controller: ControllerFile, design: Design, noise: Noise,
                params: tuple[str, ...], theta: NDArray, speed_rpm: float | None = None,
                seed: int = 0, recording: Recording | None = None) -> Information:
    """The Fisher information of the design about params at theta (fisher.py), with the
    band-limited sources' spectra taken as they are; ``recording`` the design's record if
    already simulated (at theta)."""
    rec = recording or design_recording(rig, controller, design, noise, speed_rpm,
                                        dict(zip(params, theta, strict=True)), seed)[0]
    ls = log10_sigma_of(noise.noise_rms, noise.r1_rms, noise.r2_rms)
    if noise.colour is not None:
        return fisher_information(rec, params, theta, ls, colour=noise.colour)
    if noise.r1_band_hz is None and noise.r2_band_hz is None:
        return fisher_information(rec, params, theta, ls)
    return fisher_information(rec, params, theta, ls,
                              source_gain=lambda f: np.stack(
                                  [np.ones_like(f), _band_gain(noise.r1_band_hz, f, design.dt),
                                   _band_gain(noise.r2_band_hz, f, design.dt)]))


def _prior_sd(prior: Prior) -> float:
    if prior.kind == "uniform":
        return (prior.b - prior.a) / np.sqrt(12.0)
    if prior.kind == "normal":
        return prior.b
    return float("inf")


def predicted_parameters(info: Information, rig: Rig,
                         priors: dict[str, Prior] | None = None) -> dict[str, dict[str, Any]]:
    """Per parameter: the predicted posterior sd (the priors' curvature added: a normal
    prior's 1/sd^2), in theta units and physical, the prior sd and whether informed.

    Noise that is not white as identify's sources have it (``info.B``: a band-limited
    source, a measured colour) is learned by identify where its whiteness test finds it
    (``info.modelled``; inference/spectrum.py): its sd and the spread of its estimates are
    then those of the true spectrum's information, (F_true + P)^-1. Colour too faint for
    the test leaves identify with the white sources: it reports their C = (F + P)^-1,
    widened to the sandwich C (B + P) C where the test rejects, and the estimates spread
    as C B C."""
    ps = PriorSet.build(info.names, priors)
    P = np.diag([1.0 / pr.b ** 2 if pr.kind == "normal" else 0.0 for pr in ps.priors])
    B = info.F if info.B is None else info.B
    try:
        cov = np.linalg.inv(info.F + P)
        white = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        reported = cov if info.B is None else cov @ (B + P) @ cov
        spread_cov = cov @ B @ cov
        if info.modelled and info.F_true is not None:     # identify learns the spectrum
            reported = spread_cov = np.linalg.inv(info.F_true + P)
        sd = np.sqrt(np.clip(np.diag(reported), 0.0, None))
        spread = np.sqrt(np.clip(np.diag(spread_cov), 0.0, None))
    except np.linalg.LinAlgError:
        sd = spread = white = np.full(len(info.names), np.inf)
    out = {}
    for n, s, e, w, pr in zip(info.names, sd, spread, white, ps.priors, strict=True):
        spec = get_spec(n)
        prior_sd = _prior_sd(pr)
        informed = bool(np.isfinite(s) and max(s, e) <= NOT_INFORMED * prior_sd)
        out[n] = {"sd": float(s), "physical_sd": float(s * abs(spec.physical_scale(rig))),
                  "sd_of_estimates": float(e), "unit": spec.unit, "prior_sd": float(prior_sd),
                  "informed": informed,
                  "first_order": bool(informed and max(s, e) <= FIRST_ORDER * prior_sd)}
        if info.B is not None:
            out[n]["sd_white"] = float(w)
    return out


REALISATIONS = 4
"""Excitation records the prediction averages over. identify's interval is that of the
record it gets: its information is the realised excitation's, which scatters around the
design's mean, most where a parameter is informed by a few bins only (a channel seen
through the loop's coupling, on a one-channel design); the mean of the sd over records is
then above the sd of the mean information (Jensen). Measured: one record's prediction put
the one-channel design's stiffness sds 17 % below the mean posterior sd of 100 records."""


def over_realisations(runs: list[dict[str, dict[str, Any]]]) -> dict[str, dict[str, Any]]:
    """Per parameter: the mean over excitation records of the predicted posterior sd
    (what identify reports on each), and the root mean square of the spread of the
    estimates (their variance over records is the mean of each record's); informed when
    informed on every record."""
    out = {}
    for n, first in runs[0].items():
        sd = float(np.mean([r[n]["sd"] for r in runs]))
        out[n] = {**first, "sd": sd,
                  "physical_sd": float(np.mean([r[n]["physical_sd"] for r in runs])),
                  "sd_of_estimates": float(np.sqrt(np.mean([r[n]["sd_of_estimates"] ** 2
                                                            for r in runs]))),
                  **({"sd_white": float(np.mean([r[n]["sd_white"] for r in runs]))}
                     if "sd_white" in first else {}),
                  "informed": all(r[n]["informed"] for r in runs),
                  "first_order": all(r[n].get("first_order", True) for r in runs)}
    return out


def plan(rig: Rig, controller: ControllerFile, design: Design | None = None,
         noise: Noise | None = None, params: str | tuple[str, ...] | None = None,
         theta: dict[str, float] | None = None, speed_rpm: float | None = None,
         priors: dict[str, Prior] | None = None, seed: int = 0) -> Plan:
    """Predict the posterior sd of ``params`` (default: the eight bearing coefficients)
    that identify will report on a record of ``design`` with the rig's ``noise``, at the
    parameter values ``theta`` (default: nominal, every theta 0)."""
    design = design or Design()
    noise = noise or Noise()
    names = parse_param_list(",".join(BEARING_COEFFICIENTS) if params is None else params)
    th = np.array([(theta or {}).get(n, 0.0) for n in names], dtype=float)
    extra = sorted(set(theta or {}) - set(names))
    if extra:
        raise BayesAmbError(f"option --set: {extra[0]} is not among the planned parameters "
                            f"{list(names)}")
    first = design_recording(rig, controller, design, noise, speed_rpm,
                             dict(zip(names, th, strict=True)), seed)[0]
    infos = [information(rig, controller, design, noise, names, th, speed_rpm, seed + i,
                         first if i == 0 else None)
             for i in range(REALISATIONS)]
    pars = over_realisations([predicted_parameters(i, rig, priors) for i in infos])
    info = infos[0]
    notes = [n for n in (magnet_range_note(rig, np.asarray(first.u), pars),
                         saturation_note(first, names, th, noise, pars)) if n]
    weak = [n for n, v in pars.items() if not v["informed"]]
    if weak:
        notes.append(f"not informed: {', '.join(weak)} (predicted sd above {NOT_INFORMED:g} x "
                     "the prior sd): their posterior will stay near the prior, where this "
                     "first-order prediction does not hold; excite more, longer, or in the "
                     "band they act in")
    rough = [n for n, v in pars.items() if v["informed"] and not v["first_order"]]
    if rough:
        notes.append(f"weakly informed: {', '.join(rough)} (predicted sd {FIRST_ORDER:g}-"
                     f"{NOT_INFORMED:g} x the prior sd): the prior still shapes their "
                     "posterior and this prediction is rough there (on foreign "
                     "process-force records the estimates scattered 0.67-1.12 x it, heavy "
                     "tailed); excite more or longer for a prediction to rely on")
    ratios = [v["sd_white"] / v["sd"] for v in pars.values() if "sd_white" in v]
    if ratios and max(abs(np.log(r)) for r in ratios) > np.log(1.25):
        what = ("identify will learn its spectrum from the record (its noise.spectrum) "
                "and report the sds predicted here, those of the true spectrum's "
                "information" if info.modelled else
                "identify's whiteness test will reject it and report the sandwich sds "
                "predicted here")
        notes.append(f"the noise is not white, as identify's three sources have it: {what}; "
                     f"the white sources' would be {min(ratios):.2f}-{max(ratios):.2f} x "
                     "them (sd_white)")
    if noise.colour is not None and ratios:
        source = noise.colour.source or "the record given"
        notes.append(f"the colour was measured on one record ({source}): identify's sd "
                     "varies between records of one rig, with the white intensities it fits "
                     "on each; on replicate foreign records its mean was 0.93-1.11 x such a "
                     "prediction with their start transient fitted, as identify does by "
                     "default (0.83-1.20 with --no-initial-state; "
                     "studies/plan_replicates.py)")
    speed = rig.nominal_speed_rpm if speed_rpm is None else float(speed_rpm)
    return Plan(design=design, noise=noise, speed_rpm=speed, parameters=pars,
                f_max_hz=info.f_max_hz, n_bins=info.n_bins, notes=notes,
                theta={n: float(v) for n, v in zip(names, th, strict=True)})


def magnet_range_note(rig: Rig, u: NDArray, pars: dict[str, dict[str, Any]]) -> str | None:
    """A warning when the design's coil current leaves a magnet's linear range: for a
    bearing whose rig file gives the magnet's bias current i0, the differential force
    law makes a linear fit read ks (1 + <(i/i0)^2>) (discrepancy/nonlinear.py); the range
    is left when that shift exceeds the predicted 90 % half-width of the bearing's
    stiffness coefficients. None when no bearing leaves it (or none gives its bias)."""
    rms_of = _bearing_rms(u)
    out = []
    for b in "AB":
        i0 = rig.magnets[b].bias_current
        hw = [1.645 * v["sd"] for n, v in pars.items() if n.startswith(f"k_{b}")]
        if not i0 or not hw:
            continue
        rms = rms_of[b]
        shift, half = (rms / i0) ** 2, float(np.median(hw))
        if shift > half:
            out.append(f"bearing {b}: {rms:.3g} A rms against a bias of {i0:g} A makes a "
                       f"linear fit read ks {100 * shift:.2g} % high, beyond the predicted "
                       f"interval (+-{100 * half:.2g} %); the linearisation holds below "
                       f"{i0 * np.sqrt(half):.3g} A rms")
    if not out:
        return None
    return ("the design leaves the magnets' linear range (their force law, from the rig "
            "file's bias current): " + "; ".join(out) + ". diagnose would model the law, "
            "but a smaller amplitude keeps the coefficients' meaning simple")


def _bearing_rms(u: NDArray) -> dict[str, float]:
    """The rms current (A) about its median on each bearing's two axes."""
    u = np.asarray(u, dtype=float)
    u = u - np.median(u, axis=0)
    return {b: float(np.sqrt(np.mean(u[:, 2 * j:2 * j + 2] ** 2))) for j, b in enumerate("AB")}


def saturation_note(rec: Recording, names: tuple[str, ...], theta: NDArray, noise: Noise,
                    pars: dict[str, dict[str, Any]]) -> str | None:
    """A warning when the iron's saturation the rig file gives (saturation_ratio) would
    move a linear fit of the design's record beyond the predicted intervals. Its static
    shift is small, but in the loop it acts on the controller's feedback too, so the move
    is computed through the loop: the rig's law on the design's record (simulated with
    it) as a current defect, and one Gauss-Newton step of the linear fit
    (fisher.defect_shift; on a saturating record within 15 % of a fit's own move). Each
    move grows as the current squared and each half-width shrinks as its inverse, so the
    linear range is the rms current where their ratio, as the cube, falls to one. None
    when no bearing saturates or every move stays inside."""
    from bayes_amb.discrepancy.nonlinear import force_law_defect
    from bayes_amb.rig.force_law import actuator_displacement, rig_gaps, rig_saturation

    rig = rec.rig
    saturating = rig_saturation(rig)
    if not saturating:
        return None
    u, y = np.asarray(rec.u, dtype=float), np.asarray(rec.y, dtype=float)
    d = force_law_defect(rig, u, actuator_displacement(rig, y), rig_gaps(rig))
    ls = log10_sigma_of(noise.noise_rms, noise.r1_rms, noise.r2_rms)
    shift = defect_shift(rec, names, theta, ls, d)
    rms_of = _bearing_rms(u)
    out = []
    for b in sorted(saturating):
        moved = {n: abs(v) / (1.645 * pars[n]["sd"]) for n, v in zip(names, shift, strict=True)
                 if n[2:3] == b and pars[n]["sd"] > 0}
        if not moved or max(moved.values()) <= 1.0:
            continue
        worst = max(moved, key=moved.get)
        rms = rms_of[b]
        out.append(f"bearing {b}: a linear fit would read {worst} {moved[worst]:.2g} times "
                   f"its predicted 90 % half-width off at {rms:.3g} A rms; the "
                   f"linearisation holds below about {rms / moved[worst] ** (1 / 3):.3g} A rms")
    if not out:
        return None
    return ("the design drives the magnets' iron toward saturation (the rig file's "
            "saturation_ratio): " + "; ".join(out) + ". diagnose and identify model the "
            "saturating law from the rig file; a smaller amplitude keeps the coefficients "
            "independent of its knee")


def noise_from(recording: Recording, initial_state: bool | None = None) -> Noise:
    """The noise of an earlier recording: the white intensities identify fits on it (its
    MAP of the eight bearing coefficients and the three white sources; no sampling, no
    adequacy test; ``initial_state``: the record's start transient fitted or not, None as
    identify decides by default) and the colour of its residual there (colour.py)."""
    return recorded(recording, initial_state)[0]


def recorded(recording: Recording, initial_state: bool | None = None
             ) -> tuple[Noise, dict[str, float]]:
    """:func:`noise_from`, and identify's MAP of the eight bearing coefficients on the
    same fit: the estimate a plan from that record is made at (``plan --noise-from``;
    on the foreign records it predicts identify's sd to 0.94-1.07x, against 0.93-1.66x
    at the nominal)."""
    from bayes_amb.inference.identify import IdentifyOptions, identify
    res = identify(recording, BEARING_COEFFICIENTS,
                   options=IdentifyOptions(map_only=True, adequacy=False,
                                           initial_state=initial_state))
    like, m = res.likelihood, res.map_result
    if like.spectrum is None:
        ls = m.log10_sigma
        colour = measure_colour(like, m.theta, ls, source=str(recording.source))
    else:        # the learned spectrum, as a colour of the white sources that fit it best
        phi = like.noise_spectrum(m.log10_sigma)
        like.set_spectrum(None)
        ls = white_fit(like, phi, m.log10_sigma)
        colour = spectrum_colour(like, phi, ls, source=str(recording.source))
    sig = 10.0 ** np.asarray(ls, dtype=float)
    return (Noise(noise_rms=float(sig[0]), r1_rms=float(sig[1]), r2_rms=float(sig[2]),
                  colour=colour), dict(res.map))


def with_duration(design: Design, duration: float) -> Design:
    """The same design with another record length."""
    return replace(design, duration=float(duration))
