"""Compile the numba kernels once, so that the first real command does not.

The likelihood's kernels are ``@njit(cache=True)``: numba compiles them on first use and
keeps the machine code in ``__pycache__`` beside each module. Without a warm-up the first
command after an install spends about 30 s compiling. ``make venv`` (and so ``make demo``
and ``make test``) runs ``python -m bayes_amb.warmup`` once after ``pip install``; it runs
the paper's case on a tiny record through every compiled path (MAP, Laplace, the emcee
sampler with the Laplace moves, one diagnosis step, the Schur-form frequency response) and
prints how long it took.

Examples
--------
Run by hand after an install (or after upgrading numba)::

    python -m bayes_amb.warmup
"""

from __future__ import annotations

import sys
import time

__all__ = ["warm_up"]


def warm_up() -> float:
    """Run every compiled path once on a 0.2 s, 1 kHz paper-case record; wall time in s."""
    import numpy as np

    from bayes_amb.control.export import export_controller, reference_controller
    from bayes_amb.control.schur_response import schur_freqresp
    from bayes_amb.discrepancy import DiagnoseOptions, all_candidates, diagnose
    from bayes_amb.inference.identify import IdentifyOptions, identify
    from bayes_amb.rig import load_rig
    from bayes_amb.simulate import SimulationConfig, simulate_recording
    from bayes_amb.threads import configure_process

    configure_process(None)
    t0 = time.perf_counter()
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, 1e-3), rig)
    rec, _ = simulate_recording(rig, ctrl, SimulationConfig(
        truth="reduced", params={"k_By": 0.5}, dt=1e-3, duration=0.2, noise_rms=1e-7))
    identify(rec, "k_By", options=IdentifyOptions(walkers=8, steps=20))
    identify(rec, "k_By,c_By", options=IdentifyOptions(map_only=True))
    diagnose(rec, "k_By", options=DiagnoseOptions(
        max_effects=1, candidates=all_candidates(("actuator_lag",))))
    schur_freqresp(np.array([[0.5, 1.0], [0.0, 0.5]]), np.eye(2), np.eye(2), None,
                   np.array([1j]))      # the noise filters of loops with repeated poles
    return time.perf_counter() - t0


def main() -> int:
    sys.stdout.write("bayes-amb: compiling the numba kernels once (cached for later runs)\n")
    sys.stdout.flush()
    wall = warm_up()
    sys.stdout.write(f"bayes-amb: kernels ready ({wall:.0f} s)\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
