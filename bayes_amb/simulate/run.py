"""Simulate a recording the way a test rig would produce one.

:func:`simulate_recording` is the Python API behind ``bayes-amb simulate``. The truth it
used is returned separately and stored only under the sidecar's ``truth`` key.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from bayes_amb import __version__
from bayes_amb.errors import BayesAmbError
from bayes_amb.io.controller_file import ControllerFile, check_fits_rig
from bayes_amb.io.recording import Recording, make_recording
from bayes_amb.rig import CHANNELS, Rig, check_speed_rpm
from bayes_amb.rig.force_law import actuator_displacement, law_current, rig_gaps
from bayes_amb.simulate.effects import Effect
from bayes_amb.simulate.loop import simulate_loop
from bayes_amb.simulate.signals import excitation, gaussian_noise
from bayes_amb.simulate.truth import build_truth
from bayes_amb.uncertainty import get_spec


@dataclass(frozen=True)
class SimulationConfig:
    """What to simulate. SI units: amplitude in A, noise_rms and r1_rms in m, r2_rms in A.

    Defaults: full-order FE truth, 0.5 s at 10 kHz, random binary excitation of 0.5 A
    (about 10 % of a 5 A saturation current), no noise or disturbances, nominal speed.
    ``r1_band_hz``/``r2_band_hz`` None means white; otherwise low-pass band-limited.
    ``excitation_band_hz`` (lo, hi) sets the band of a multisine excitation (default 5 Hz to
    min(1 kHz, 0.8 Nyquist)); a narrow band is how a test that informs only a combination of
    parameters is simulated.

    ``port`` is where the excitation enters: ``"eta"``, the controller's Youla port (an
    observer-based controller only); ``"r2"``, added to the controller's output current at
    the plant input (any controller kind). None (default) takes ``eta`` for an observer
    controller and ``r2`` otherwise. The recording stores the excitation under the group of
    that name, and its u is the plant current including an r2 excitation.
    """

    truth: str = "full"
    params: dict[str, float] = field(default_factory=dict)
    effects: tuple[Effect, ...] = ()
    excitation: str = "random-binary"
    amplitude: float = 0.5
    excitation_band_hz: tuple[float, float] | None = None
    noise_rms: float = 0.0
    r1_rms: float = 0.0
    r2_rms: float = 0.0
    r1_band_hz: float | None = None
    r2_band_hz: float | None = None
    duration: float = 0.5
    dt: float = 1e-4
    speed_rpm: float | None = None
    seed: int = 0
    port: str | None = None
    channels: tuple[str, ...] | None = None
    """The excited channels (of Ax, Ay, Bx, By; None: all four); the others get none."""

    def validate(self) -> None:
        if not (np.isfinite(self.amplitude) and self.amplitude > 0):
            raise BayesAmbError(f"option --amplitude: value {self.amplitude:g} out of range: "
                                "must be > 0 A (without excitation nothing can be identified)")
        for name, unit in (("noise_rms", "m"), ("r1_rms", "m"), ("r2_rms", "A")):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise BayesAmbError(f"option --{name.replace('_', '-')}: value {v:g} out of "
                                    f"range: must be >= 0 {unit}")
        for name in ("r1_band_hz", "r2_band_hz"):
            v = getattr(self, name)
            if v is not None and not (np.isfinite(v) and v > 0):
                raise BayesAmbError(f"option --{name.replace('_', '-')}: value {v:g} out of "
                                    "range: must be > 0 Hz")
        if not (np.isfinite(self.duration) and 0 < self.duration <= 600):
            raise BayesAmbError(f"option --duration: value {self.duration:g} out of range: "
                                "must be > 0 and <= 600 s")
        if not (np.isfinite(self.dt) and 0 < self.dt <= 1e-2):
            raise BayesAmbError(f"option --dt: value {self.dt:g} out of range: must be > 0 "
                                "and <= 0.01 s")
        if round(self.duration / self.dt) < 2:
            raise BayesAmbError(f"option --duration: {self.duration:g} s is shorter than 2 "
                                f"samples of --dt {self.dt:g} s")
        for name, th in self.params.items():
            get_spec(name)
            if not (np.isfinite(th) and -0.95 <= th <= 0.95):
                raise BayesAmbError(f"option --set: {name}: value {th:g} out of range: must "
                                    "be in -0.95..0.95")
        if self.excitation_band_hz is not None:
            band = self.excitation_band_hz
            if self.excitation not in ("multisine", "odd-multisine", "random-binary"):
                raise BayesAmbError(f"option --band: only the multisine and random-binary "
                                    f"excitations have a band "
                                    f"(excitation is {self.excitation!r})")
            if not (len(band) == 2 and all(np.isfinite(band))
                    and 0 < band[0] < band[1] <= 0.5 / self.dt):
                raise BayesAmbError(f"option --band: value {band[0]:g},{band[1]:g} out of "
                                    f"range: must be 0 < LO < HI <= {0.5 / self.dt:g} Hz "
                                    "(Nyquist)")
        if self.channels is not None and (not self.channels or
                                          not set(self.channels) <= set(CHANNELS)
                                          or len(set(self.channels)) != len(self.channels)):
            raise BayesAmbError(f"option --channels: value {','.join(self.channels)!r} "
                                f"must name distinct channels of {','.join(CHANNELS)}")
        if self.port not in (None, "eta", "r2"):
            raise BayesAmbError(f"option --port: value {self.port!r} not one of eta, r2")
        if not 0 <= self.seed < 2**32:
            raise BayesAmbError(f"option --seed: value {self.seed} out of range: must be in "
                                "0..4294967295")

    def truth_dict(self, speed_rpm: float) -> dict[str, Any]:
        d = asdict(self)
        d["effects"] = [e.to_dict() for e in self.effects]
        d["speed_rpm"] = speed_rpm
        d["plant"] = d.pop("truth")
        d["package_version"] = __version__
        return d


def simulate_recording(rig: Rig, controller: ControllerFile, config: SimulationConfig
                       ) -> tuple[Recording, dict[str, Any]]:
    """Simulate one closed-loop recording; returns (recording, truth).

    The excitation enters at ``config.port``: the controller's Youla port (column group
    ``eta``, observer-based controllers only) or the plant input after the controller
    (column group ``r2``, any controller; a generic controller's eta port is that same
    sum). The recorded u is the plant current and includes an r2 excitation.
    """
    config.validate()
    check_fits_rig(controller)
    port = config.port or ("eta" if controller.kind == "observer" else "r2")
    if port == "eta" and controller.kind != "observer":
        raise BayesAmbError(f"option --port: eta needs an observer-based controller; "
                            f"controller {controller.source} is kind {controller.kind!r}, "
                            "which has no Youla port (use --port r2)")
    if abs(controller.dt - config.dt) > 1e-12 * config.dt:
        raise BayesAmbError(f"controller {controller.source}: field dt: {controller.dt} s "
                            f"does not match the simulation dt {config.dt} s")
    speed = check_speed_rpm(rig, config.speed_rpm)
    n = round(config.duration / config.dt)
    streams = np.random.default_rng(config.seed).spawn(4)
    exc = excitation(config.excitation, n, 4, config.amplitude, streams[0], config.dt,
                     config.excitation_band_hz)
    if config.channels is not None:
        exc[:, [c not in config.channels for c in CHANNELS]] = 0.0
    noise = gaussian_noise(n, 4, config.noise_rms, streams[1], config.dt)
    r1 = gaussian_noise(n, 4, config.r1_rms, streams[2], config.dt, config.r1_band_hz)
    r2 = gaussian_noise(n, 4, config.r2_rms, streams[3], config.dt, config.r2_band_hz)
    truth_plant = build_truth(rig, speed, config.truth, config.params, config.effects)
    gaps = rig_gaps(rig)
    law = None
    if gaps:
        def law(u: np.ndarray, y: np.ndarray) -> np.ndarray:
            return law_current(rig, u, actuator_displacement(rig, y), gaps)[0]
    sig = simulate_loop(truth_plant, (controller.A, controller.B, controller.C, controller.D),
                        config.dt, exc, noise=noise, r1=r1, r2=r2, port=port, law=law)
    if sig.unstable:
        raise BayesAmbError("simulation: the closed loop is unstable for this truth "
                            f"(params {config.params}, effects "
                            f"{[e.name for e in config.effects]}); the controller does not "
                            "stabilise it")
    rec = make_recording(sig.y, sig.u, {port: exc}, config.dt, controller, speed_rpm=speed,
                         rig=rig, notes=f"simulated by bayes-amb {__version__}",
                         provenance={"software": f"bayes-amb {__version__}",
                                     "simulator": "bayes_amb.simulate", "seed": config.seed})
    return rec, config.truth_dict(speed)
