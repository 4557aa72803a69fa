"""Equivalence classes of the physics library (METHOD.md section 8).

The x -> eps map of a candidate (eps = S(theta, phi) x, the closed loop with the recorded
controller and the offline filter) is fixed by the plant's u -> y map. Compared here as
frequency responses S(z) on 120 frequencies from 5 Hz to 4.9 kHz, at the reference rig with
all eight bearing coefficients off nominal:

- every equivalence the registry declares gives the same map (to round-off) at the same
  parameter values;
- every other pair is distinguishable: the best fit of B's parameters (a grid over its
  prior, then Nelder-Mead) leaves more than 1 % of A's effect unexplained;
- a 1x line (unbalance, runout) leaves the x -> eps map unchanged, every excitation-driven
  effect changes it, so the two kinds are never confused; lines are told apart from each
  other by their complex pattern over the four channels.
"""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import pytest
import scipy.optimize as so

from bayes_amb.discrepancy.library import REGISTRY, equivalents_of, make_candidate
from bayes_amb.discrepancy.model import ExtendedForwardModel
from bayes_amb.discrepancy.select import _grid
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, simulate_recording

THETA = {"k_Ax": 0.2, "k_Ay": -0.1, "k_Bx": 0.25, "k_By": -0.3, "c_Ax": 0.1, "c_Ay": 0.0,
         "c_Bx": 0.25, "c_By": 0.05}
NAMES = tuple(THETA)
F_HZ = np.geomspace(5.0, 4900.0, 120)
DISTINCT = 0.01

REP = {   # a representative value of each candidate's sampled parameters
    "actuator_lag@A": [0.1], "actuator_lag@both": [0.1], "actuator_2nd@both": [0.12, 0.6],
    "time_delay@controller": [0.06], "sensor_delay@sensors": [0.06],
    "sensor_lag@A": [0.1], "sensor_lag@both": [0.1],
    "actuator_gain@Ax": [0.05], "sensor_gain@Ax": [0.05], "sensor_gain@Bx": [0.05],
    "cross_coupling@D1": [0.4], "cross_coupling@A": [0.4],
    "flexible_mode@bending pair 1": [0.0, 0.0], "flexible_mode@bending pair 2": [0.0, 0.0],
    "flexible_mode@bending pair 3": [0.0, 0.0], "residual_flexibility@truncated modes": [1.0],
}
LINES = ("unbalance@D1", "unbalance@n20", "unbalance@D2", "runout@Ax", "runout@Ay",
         "runout@Bx")


@pytest.fixture(scope="module")
def models():
    rig = load_rig()
    from bayes_amb.control.export import export_controller, reference_controller
    ctrl = export_controller(reference_controller(rig, 1e-4), rig)
    rec, _ = simulate_recording(rig, ctrl, SimulationConfig(truth="reduced", params=THETA,
                                                            dt=1e-4, duration=0.02, seed=1))
    base = ExtendedForwardModel(rec, NAMES)
    out = {"": base}
    for key in (*REP, *LINES, *(k for a in REP for k, _ in equivalents_of(a))):
        if key not in out:
            out[key] = ExtendedForwardModel(rec, NAMES, (make_candidate(key),), template=base)
    return out


def _response(fwd: ExtendedForwardModel, phi: np.ndarray) -> np.ndarray:
    """S(z) (nb, nf, 4, 4) at theta = THETA and rows phi (nb, q); inf where unstable."""
    P = np.hstack([np.tile([THETA[n] for n in NAMES], (phi.shape[0], 1)), phi])
    mb, _ = fwd.modal(P)
    z = np.exp(2j * np.pi * F_HZ * fwd.dt)
    H = np.einsum("bps,bfs,bsi->bfpi", mb.Cm, 1.0 / (z[None, :, None] - mb.lam[:, None, :]),
                  mb.Bm)
    H[~mb.stable] = np.inf
    return H


def _declared() -> list[tuple[str, str]]:
    pairs = set()
    for e in REGISTRY.values():
        for loc in e.locations:
            for other, _ in equivalents_of(f"{e.name}@{loc}"):
                pairs.add(tuple(sorted((f"{e.name}@{loc}", other))))
    return sorted(pairs)


@pytest.mark.parametrize("pair", _declared(), ids="=".join)
def test_declared_equivalence_gives_the_same_map(models, pair):
    a, b = pair
    assert a in REP and b in REP, f"give {a} and {b} representative values in REP"
    assert REP[a] == REP[b]          # declared equivalences map parameters one to one
    phi = np.array([REP[a]])
    Ha, Hb = _response(models[a], phi), _response(models[b], phi)
    H0 = _response(models[""], np.zeros((1, 0)))
    size = np.linalg.norm(Ha - H0)
    assert size > 1e-2 * np.linalg.norm(H0)
    assert np.linalg.norm(Ha - Hb) < 1e-7 * size


def _best_fit(fwd: ExtendedForwardModel, target: np.ndarray) -> float:
    """min over B's parameters of ||S_B - target|| (grid over the prior, then Nelder-Mead)."""
    eff = fwd.effect_params
    grids = np.meshgrid(*[_grid(e.prior, 30 if len(eff) == 1 else 10) for e in eff])
    G = np.column_stack([g.ravel() for g in grids])
    with np.errstate(invalid="ignore"):
        err = np.linalg.norm((_response(fwd, G) - target).reshape(len(G), -1), axis=1)
    err[~np.isfinite(err)] = np.inf
    start = G[int(np.argmin(err))]

    def f(v: np.ndarray) -> float:
        with np.errstate(invalid="ignore"):
            r = float(np.linalg.norm(_response(fwd, v[None])[0] - target))
        return r if np.isfinite(r) else 1e300

    bnds = [(e.prior.a, e.prior.b) if e.prior.kind == "uniform" else (None, None) for e in eff]
    res = so.minimize(f, start, method="Nelder-Mead", bounds=bnds,
                      options={"maxfev": 50 * len(eff), "xatol": 1e-10, "fatol": 1e-16})
    return min(float(res.fun), float(err.min()))


@pytest.mark.parametrize("a", list(REP))
def test_undeclared_pairs_are_distinguishable(models, a):
    Ha = _response(models[a], np.array([REP[a]]))[0]
    H0 = _response(models[""], np.zeros((1, 0)))[0]
    size = np.linalg.norm(Ha - H0)
    declared = {k for k, _ in equivalents_of(a)}
    worst = {}
    for b in REP:
        if b == a or b in declared:
            continue
        worst[b] = _best_fit(models[b], Ha) / size
    b_min = min(worst, key=worst.get)
    assert worst[b_min] > DISTINCT, f"{b_min} reproduces {a} to {worst[b_min]:.1e}"


def _line_vector(fwd: ExtendedForwardModel) -> np.ndarray:
    """Steady 1x response of a line candidate per unit of its (a + j b) (4 channels)."""
    steady = replace(fwd.candidates[0], start="steady")
    f = ExtendedForwardModel(fwd.recording, NAMES, (steady,), template=fwd)
    P = np.array([[*(THETA[n] for n in NAMES), *f.null[len(NAMES):]]])
    b = f.line_responses(P)[0]
    return b[0, :, 0] - 1j * b[0, :, 1]


def test_lines_do_not_change_the_excitation_map_and_are_told_apart(models):
    H0 = _response(models[""], np.zeros((1, 0)))
    for key in LINES:
        H = _response(models[key], np.array([[1.0, 0.5]]))
        assert np.linalg.norm(H - H0) < 1e-9 * np.linalg.norm(H0)
    for key in REP:                                    # every other effect changes it
        if key != "flexible_mode@bending pair 1":
            H = _response(models[key], np.array([REP[key]]))
            assert np.linalg.norm(H - H0) > 1e-3 * np.linalg.norm(H0), key
    vec = {k: _line_vector(models[k]) for k in LINES}
    for a, b in itertools.permutations(LINES, 2):
        va, vb = vec[a], vec[b]
        c = np.vdot(vb, va) / np.vdot(vb, vb)          # best complex amplitude of b
        assert np.linalg.norm(va - c * vb) > 0.1 * np.linalg.norm(va), (a, b)
