"""A support's coefficients off the rig file's: identified where the user asks for them.

A fluid-film bearing's or a seal's coefficients ([[supports]], rig/supports.py) are part of
the known plant, held fixed. Where the machine's differ from the file's, the user adds the
deviation at the support's node to the parameters (kxy_n<j>, kd_n<j>, cd_n<j>, the
vocabulary's cross-coupled and direct terms at a shaft node): on the reference rig with a
seal at node 20 whose real direct stiffness is 0.5 k_ref and cross-coupling 0.2 k_ref above
the file's, both are recovered and the eight bearing coefficients stay covered; left out,
the seal's error is read as bearing stiffness.
"""

from __future__ import annotations

import dataclasses

import pytest

from bayes_amb import IdentifyOptions, SimulationConfig, identify, simulate_recording
from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.discrepancy.library import BEARING_COEFFICIENTS
from bayes_amb.rig import load_rig, rig_from_dict

SEAL = {"name": "seal", "node": 20, "kxx": 2e5, "kxy": 5e4, "kyx": -5e4, "kyy": 2e5,
        "cxx": 150.0, "cyy": 150.0}
TRUTH = {"k_Ax": 0.1, "c_By": 0.2}


def _rig(**seal) -> object:
    return rig_from_dict({**load_rig().to_dict(), "supports": [{**SEAL, **seal}]},
                         source="seal.toml")


@pytest.fixture(scope="module")
def record():
    rig = _rig()
    real = _rig(kxx=2.5e5, kyy=2.5e5, kxy=7e4, kyx=-7e4)   # kd +0.5, kxy +0.2 (k_ref 1e5)
    ctrl = export_controller(reference_controller(rig, 1e-4), rig)
    rec, _ = simulate_recording(real, ctrl, SimulationConfig(
        truth="full", params=dict(TRUTH), noise_rms=1e-7, duration=1.0, dt=1e-4, seed=3))
    return dataclasses.replace(rec, rig=rig)      # the model the user has: the file's seal


def _inside(par, name: str, truth: float) -> bool:
    lo, hi = par[name].hdi90
    return lo <= truth <= hi


def test_a_supports_deviation_is_identified_at_its_node(record):
    names = [*BEARING_COEFFICIENTS, "kxy_n20", "kd_n20"]
    fit = identify(record, names, options=IdentifyOptions(map_only=True))
    par = fit.parameters
    assert _inside(par, "kxy_n20", 0.2) and _inside(par, "kd_n20", 0.5)
    assert par["kd_n20"].sd < 0.1 and par["kxy_n20"].sd < 0.1     # and they are informed
    assert all(_inside(par, n, TRUTH.get(n, 0.0)) for n in BEARING_COEFFICIENTS)


def test_left_out_the_supports_error_moves_the_bearing_stiffnesses(record):
    fit = identify(record, list(BEARING_COEFFICIENTS), options=IdentifyOptions(map_only=True))
    par = fit.parameters
    outside = [n for n in ("k_Ax", "k_Ay", "k_Bx", "k_By")
               if not _inside(par, n, TRUTH.get(n, 0.0))]
    assert len(outside) >= 2, outside
