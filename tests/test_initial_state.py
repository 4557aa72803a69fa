"""The start transient (WhittleLikelihood.set_initial_state, identify --initial-state).

A rig's record starts mid-operation: the loop's states are not at rest at its first sample.
Here a record of the tool's simulator is cut 0.5 s after its start. Without the transient
fitted, the free response of those states enters the residual as noise: the whiteness test
rejects it, r2 takes mA, and the k_By interval is some 25 times wider (measured 0.023
against 0.0009). Fitted, the interval is the one of a record from rest, and the whiteness
test passes."""

from __future__ import annotations

import dataclasses

import pytest

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.planning import Design, Noise
from bayes_amb.planning.plan import design_recording
from bayes_amb.rig import load_rig

TRUTH = {"k_By": 0.2, "c_By": 0.1}


@pytest.fixture(scope="module")
def records():
    rig = load_rig()
    rig_ctrl = (rig, export_controller(reference_controller(rig, 1e-4), rig))
    rec, _ = design_recording(*rig_ctrl, Design(amplitude=0.5, duration=1.5),
                              Noise(noise_rms=5e-8), theta=TRUTH, seed=7)
    n0 = round(0.5 / rec.dt)
    return rec.part(slice(0, rec.n_samples - n0)), rec.part(slice(n0, None))


def _fit(rec, on, learn=True):
    opt = IdentifyOptions(map_only=True, adequacy=False, initial_state=on,
                          learn_spectrum=learn)
    return identify(rec, "k_By,c_By", options=opt).to_dict()


def test_a_record_from_mid_operation_gets_the_interval_of_one_from_rest(records):
    rest, mid = records
    base = _fit(rest, False)
    # with the white sources: the transient as noise (a learned spectrum takes it in as
    # low-frequency noise instead: the k_By sd 0.0047, 5x the one from rest, not 25x)
    blind, fitted = _fit(mid, False, learn=False), _fit(mid, True)
    sd = {k: base["parameters"][k]["sd"] for k in TRUTH}
    for k, true in TRUTH.items():
        assert blind["parameters"][k]["sd"] > 5 * sd[k]
        got = fitted["parameters"][k]
        assert got["sd"] == pytest.approx(sd[k], rel=0.3)
        assert abs(got["mean"] - true) < 3.3 * got["sd"]          # two-sided p 0.001
    assert blind["noise"]["check"]["doubted"]
    assert not fitted["noise"]["check"]["doubted"]
    assert "start transient fitted" in fitted["noise"]["model"]


def test_a_record_from_rest_is_unchanged(records):
    rest, _ = records
    off, on = _fit(rest, False), _fit(rest, True)
    for k in TRUTH:
        assert on["parameters"][k]["sd"] == pytest.approx(off["parameters"][k]["sd"], rel=0.1)
        # the transient's weights take a few dozen of some 10^4 data; measured 0.5 sd
        assert abs(on["parameters"][k]["mean"] - off["parameters"][k]["mean"]) < \
            off["parameters"][k]["sd"]


def test_by_default_the_data_check_decides(records):
    """initial_state None (the default): the transient is fitted on the record that starts
    mid-operation, not on the one from rest, and the summary says which and why."""
    rest, mid = records
    got = {name: _fit(rec, None) for name, rec in (("rest", rest), ("mid", mid))}
    assert got["rest"]["start_transient"]["fitted"] is False
    assert "starts at rest" in got["rest"]["start_transient"]["reason"]
    assert "start transient fitted" not in got["rest"]["noise"]["model"]
    start = got["mid"]["start_transient"]
    assert start["fitted"] is True and "mid-operation" in start["reason"]
    assert start["start_difference"] > 0.01 > got["rest"]["start_transient"]["start_difference"]
    assert got["mid"]["parameters"] == _fit(mid, True)["parameters"]
    assert _fit(mid, False)["start_transient"]["reason"] == "--no-initial-state"


def test_a_record_whose_u_the_controller_does_not_reproduce_gets_it_fitted(records):
    """A measured current (here u with 1 % noise) differs from the controller's output
    throughout, which hides a start-up difference: the check cannot tell, and says so."""
    import numpy as np

    from bayes_amb.inference.forward import ForwardModel
    from bayes_amb.inference.start import start_transient

    rest, _ = records
    rng = np.random.default_rng(2)
    noisy = dataclasses.replace(rest, u=rest.u + 0.01 * rest.u.std() *
                                rng.standard_normal(rest.u.shape))
    got = start_transient(noisy, ForwardModel(noisy, ("k_By",)))
    assert got["fitted"] is True and "cannot be told" in got["reason"]
    assert start_transient(rest, ForwardModel(rest, ("k_By",)))["fitted"] is False
    # identify then keeps it only where it improves the fit at the MAP: on this record
    # from rest it does not (the likelihood-ratio test, inference/start.transient_kept)
    res = identify(noisy, "k_By,c_By", options=IdentifyOptions(map_only=True, adequacy=False))
    assert res.start_transient.fitted is False
    assert "does not improve the fit" in res.start_transient.reason
