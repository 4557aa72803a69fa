"""Candidate physics: every member of the family, against the simulator's physics.

Identity tests: a candidate at its null value is the nominal model; with the true effect
parameters, the extended model reproduces noise-free simulated data (reduced truth plus the
hidden effect) sample by sample; the observer form of the loop equals the general loop;
rows of different integer delay in one batch equal their separate evaluation.
"""

from __future__ import annotations

import numpy as np
import pytest

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.discrepancy import (
    ActuatorLag,
    CrossCoupling,
    FlexibleMode,
    SensorGain,
    TimeDelay,
    Unbalance,
    all_candidates,
)
from bayes_amb.discrepancy.library import VOCABULARY, Candidate
from bayes_amb.discrepancy.likelihood import scale_shift
from bayes_amb.discrepancy.model import ExtendedForwardModel
from bayes_amb.inference.offline import dual_youla_eps
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, parse_effect, simulate_recording
from tests.helpers import rel_signal

THETA = {"k_By": 0.3, "c_By": 0.1}


@pytest.fixture(scope="module")
def rig():
    return load_rig()


@pytest.fixture(scope="module")
def ctrl(rig):
    return export_controller(reference_controller(rig, 1e-4), rig)


def _sim(rig, ctrl, effects=(), duration=0.03):
    cfg = SimulationConfig(truth="reduced", params=THETA, dt=1e-4, duration=duration,
                           effects=tuple(parse_effect(e) for e in effects), seed=4)
    rec, _ = simulate_recording(rig, ctrl, cfg)
    return rec


@pytest.fixture(scope="module")
def nominal_rec(rig, ctrl):
    return _sim(rig, ctrl)


def test_family_covers_the_vocabulary_and_shares_one_interface():
    cands = all_candidates(representatives=False)
    assert {c.effect for c in cands} == set(VOCABULARY)
    assert len({c.key for c in cands}) == len(cands)
    hooks = ("params", "lft_names", "bending_pairs", "modal", "continuous", "discretise",
             "structure", "discrete", "line_force", "line_output", "physical", "describe")
    for c in cands:
        assert isinstance(c, Candidate) and c.fingerprint
        for h in hooks:                       # same signature as the base class
            assert getattr(type(c), h).__code__.co_argcount == \
                getattr(Candidate, h).__code__.co_argcount, (c.key, h)


@pytest.mark.parametrize("cand", [c for c in all_candidates(representatives=False)
                                  if c.effect != "flexible_mode"],
                         ids=lambda c: c.key)
def test_candidate_at_its_null_is_the_nominal_model(nominal_rec, cand):
    nom = ExtendedForwardModel(nominal_rec, ("k_By", "c_By"))
    ext = ExtendedForwardModel(nominal_rec, ("k_By", "c_By"), (cand,))
    th = [THETA["k_By"], THETA["c_By"]]
    a = nom.simulate(np.array([th]))
    b = ext.simulate(np.array([[*th, *(p.null for p in ext.effect_params)]]))
    assert rel_signal(b, a) < 1e-6
    # and the nominal model reproduces the nominal data exactly (reduced truth, no noise)
    eps = dual_youla_eps(nom.parts, np.asarray(nominal_rec.y), np.asarray(nominal_rec.u))
    assert rel_signal(a, eps) < 1e-8


CASES = [
    ("actuator_lag:bandwidth_hz=1500,bearing=A", ActuatorLag("actuator_lag", "A"),
     lambda ctx: [1e3 / (2 * np.pi * 1500)]),
    ("actuator_lag:bandwidth_hz=2500", ActuatorLag("actuator_lag", "both"),
     lambda ctx: [1e3 / (2 * np.pi * 2500)]),
    ("time_delay:delay_s=3.7e-5", TimeDelay("time_delay", "controller"), lambda ctx: [0.037]),
    ("time_delay:delay_s=2.37e-4", TimeDelay("time_delay", "controller"), lambda ctx: [0.237]),
    ("cross_coupling:kxy=3e5,location=D2", CrossCoupling("cross_coupling", "D2"),
     lambda ctx: [3.0]),
    ("flexible_mode:n_modes=1", FlexibleMode("flexible_mode", "bending pair 1", pair=1),
     lambda ctx: [0.0, 0.0]),
    ("sensor_gain:gain=0.04,channel=Bx", SensorGain("sensor_gain", "Bx"), lambda ctx: [0.04]),
    ("unbalance:u_kgm=5e-6,disc=D2,phase_deg=30", Unbalance("unbalance", "D2"),
     lambda ctx: [0.5 * np.cos(np.pi / 6), 0.5 * np.sin(np.pi / 6)]),
]


@pytest.mark.parametrize("effect,cand,phi", CASES, ids=[c[0] for c in CASES])
def test_extended_model_reproduces_the_simulated_effect(rig, ctrl, effect, cand, phi):
    rec = _sim(rig, ctrl, [effect])
    fwd = ExtendedForwardModel(rec, ("k_By", "c_By"), (cand,))
    P = np.array([[THETA["k_By"], THETA["c_By"], *phi(fwd.ctx)]])
    pred = fwd.simulate(P)
    for c, basis in zip(fwd.line_candidates, fwd.line_responses(P), strict=True):
        pred = pred + basis @ P[0, fwd.slices[fwd.candidates.index(c)]]
    eps = dual_youla_eps(fwd.parts, np.asarray(rec.y), np.asarray(rec.u))
    nominal = ExtendedForwardModel(rec, ("k_By", "c_By")).simulate(P[:, :2])
    assert rel_signal(nominal, eps) > 1e-4          # the effect is visible without noise
    assert rel_signal(pred, eps) < 1e-6


@pytest.mark.parametrize("cand,phi", [(ActuatorLag("actuator_lag", "both"), [0.05]),
                                      (TimeDelay("time_delay", "controller"), [0.13]),
                                      (FlexibleMode("flexible_mode", "b", 1), [0.01, 0.3]),
                                      (SensorGain("sensor_gain", "Ay"), [-0.03])],
                         ids=lambda v: getattr(v, "key", ""))
def test_observer_form_equals_the_general_loop(nominal_rec, cand, phi):
    fwd = ExtendedForwardModel(nominal_rec, ("k_By", "c_By"), (cand,))
    assert fwd.observer_form
    P = np.array([[0.2, -0.1, *phi]])
    a = fwd.simulate(P)
    fwd.observer_form = False
    assert rel_signal(a, fwd.simulate(P)) < 1e-8


def test_mixed_integer_delays_in_one_batch(nominal_rec):
    from bayes_amb.inference.forward import dft_response

    fwd = ExtendedForwardModel(nominal_rec, ("k_By", "c_By"),
                               (TimeDelay("time_delay", "controller"),))
    P = np.array([[0.3, 0.1, d] for d in (0.0, 0.05, 0.1, 0.25, 0.399)])
    assert len(set(fwd.structure_keys(P))) == 4
    z = np.exp(2j * np.pi * np.arange(1, 40) / 300)
    X = np.ones((z.size, 4))
    mb, xi = fwd.modal(P)
    together = dft_response(mb, X, z, xi)
    for i in range(P.shape[0]):
        mb1, xi1 = fwd.modal(P[i:i + 1])
        alone = dft_response(mb1, X, z, xi1)[0]
        assert np.max(np.abs(together[i] - alone)) <= 1e-9 * np.max(np.abs(alone))


def test_non_finite_and_destabilising_rows_are_flagged(nominal_rec):
    fwd = ExtendedForwardModel(nominal_rec, ("k_By", "c_By"),
                               (ActuatorLag("actuator_lag", "both"),))
    P = np.array([[0.3, 0.1, 0.05], [np.nan, 0.1, 0.05], [0.3, 0.1, 1.5]])
    mb, _ = fwd.modal(P)
    assert mb.stable.tolist() == [True, False, False]   # a 106 Hz lag is not stabilised


@pytest.mark.parametrize("n_bins", [1, 8, 32])
def test_noise_scale_shift_makes_the_scale_score_vanish(n_bins):
    """E[d log p / d log c] = 0 at the true spectrum (complex Wishart Monte Carlo)."""
    rng = np.random.default_rng(n_bins)
    p, m = 4, 20000
    nu = n_bins + p + 1
    c = nu - scale_shift(np.array([n_bins]))[0]
    R = (rng.normal(size=(m, n_bins, p)) + 1j * rng.normal(size=(m, n_bins, p))) / np.sqrt(2)
    P = np.einsum("mki,mkj->mij", R, R.conj())
    tr = np.trace(np.linalg.inv(c * np.eye(p) + P), axis1=1, axis2=2).real
    score = nu * p - (nu + n_bins) * c * tr
    se = score.std() / np.sqrt(m)
    assert abs(score.mean()) < 4 * se + 0.05 * abs(score).mean()
