"""The "real rig" side: truth plant, hidden physics, signals and the closed-loop simulator."""

from bayes_amb.simulate.effects import EFFECT_DEFAULTS, Effect, make_effect, parse_effect
from bayes_amb.simulate.loop import LoopSignals, simulate_loop
from bayes_amb.simulate.run import SimulationConfig, simulate_recording
from bayes_amb.simulate.signals import EXCITATIONS, excitation, gaussian_noise
from bayes_amb.simulate.truth import TruthPlant, build_truth

__all__ = ["EFFECT_DEFAULTS", "EXCITATIONS", "Effect", "LoopSignals", "SimulationConfig",
           "TruthPlant", "build_truth", "excitation", "gaussian_noise", "make_effect",
           "parse_effect", "simulate_loop", "simulate_recording"]
