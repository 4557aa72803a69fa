"""The benchmark recordings: the reference rig under its reference controller, simulated
(shared by the benchmark cases, cases.py and the *_case.py modules)."""

from __future__ import annotations

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.io.recording import Recording
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, simulate_recording

PARAMS_8 = ("k_Ax", "k_Ay", "k_Bx", "k_By", "c_Ax", "c_Ay", "c_Bx", "c_By")
TRUE_8 = dict(zip(PARAMS_8, (0.1, -0.1, 0.2, 0.5, 0.3, -0.2, 0.1, 0.0), strict=True))
"""The benchmarks' eight bearing coefficients and their true values."""


def make_recording(truth: str, params: dict[str, float], dt: float, duration: float,
                   seed: int = 1, **noise: float) -> Recording:
    """Closed-loop recording of the reference rig under its reference controller.

    Parameters
    ----------
    truth : {"full", "reduced"}
        Truth plant of the simulation.
    params : dict
        True theta values by parameter name.
    dt, duration : float
        Sample time and record length, in s.
    seed : int
        Seed of the simulation's random streams.
    **noise : float
        noise_rms, r1_rms (m), r2_rms (A) (and effects, a tuple of hidden effects),
        passed to SimulationConfig.

    Returns
    -------
    Recording
    """
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, dt), rig)
    cfg = SimulationConfig(truth=truth, params=params, dt=dt, duration=duration, seed=seed,
                           **noise)
    return simulate_recording(rig, ctrl, cfg)[0]
