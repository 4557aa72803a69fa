"""Issue 27: a seal's direct stiffness and damping are not taken by the bearing coefficients.

A gas seal at a disc (benchmarks/foreign, written apart from the tool) has direct K and C beside
its cross-coupled k. The diagnosis names the cross-coupling; the coefficients are then
reported with K and C fitted at the same node (discrepancy/direct_terms.py). The truth is
read only after the tool has answered."""

import json
from dataclasses import replace

import numpy as np
import pytest

from bayes_amb.discrepancy import diagnose
from bayes_amb.discrepancy.direct_terms import averaged
from bayes_amb.io.recording import load_recording
from benchmarks.foreign import Effect
from benchmarks.foreign.cases import draw_case, write_case


def test_averaging_spans_both_posteriors():
    """The equal mixture of two coefficient posteriors that disagree holds both; the named
    model's own parameters stay its draws."""
    rng = np.random.default_rng(0)
    named = np.column_stack([rng.normal(0.0, 0.01, 1000), rng.normal(5.0, 0.1, 1000)])
    nominal = rng.normal(0.1, 0.01, (1000, 1))
    mix = averaged(named, nominal, 1)
    assert mix.shape == (2000, 2)
    assert abs(np.mean(mix[:, 0] < 0.05) - 0.5) < 0.05
    assert np.array_equal(mix[1000:, 1], named[:, 1])
    # an emcee run of the nominal model may be shorter than the named model's
    assert averaged(named, nominal[:300], 1).shape == (2000, 2)


@pytest.fixture(scope="module")
def seal_case(tmp_path_factory, controller_file):
    rng = np.random.default_rng(4)
    spec = draw_case("control", rng, controller_file=controller_file, duration_s=1.0)
    seal = Effect("seal", {"node": "D2", "k_direct_nm": 2.0e5, "k_cross_nm": 2.5e5,
                           "c_direct_nsm": 200.0, "c_cross_nsm": 10.0})
    out = tmp_path_factory.mktemp("seal")
    paths = write_case(replace(spec, effects=(seal,)), out, "seal", rng,
                       conceal_effects=False)
    report = diagnose(load_recording(paths["csv"])).to_dict()
    return report, json.loads(paths["truth"].read_text())


def test_a_seals_direct_terms_are_fitted_beside_its_cross_coupling(seal_case):
    report, truth = seal_case
    named = [f"{e['effect']}@{e['location']}" for e in report["explanations"]]
    assert "cross_coupling@D2" in named
    direct = {d["location"]: d["params"] for d in report["direct_terms"]}
    assert set(direct) == {"D2"}
    assert "direct stiffness and damping" in report["parameters_after_from"]
    lo, hi = direct["D2"]["K"]["hdi90"]
    assert lo <= 2.0e5 <= hi
    # without the direct terms the bearing coefficients near D2 take K (0.2e6 N/m is a
    # third of ks): with them, the truth of bearing B's stiffness is inside
    for name in ("k_Bx", "k_By"):
        p = report["parameters_after"][name]
        assert p["hdi90"][0] <= truth["theta"][name] <= p["hdi90"][1], (name, p)


def test_a_mid_span_seal_is_moved_to_its_node(controller_file, tmp_path):
    """A seal at node 23, three nodes from the mid-span candidate n20: the search names it
    at n20 and moves it node by node, with its direct terms, to where the fit peaks
    (select.refine_node); the nodes within 2 nats of the best are reported and hold the
    seal's; no second force is named for the remainder."""
    rng = np.random.default_rng(5)
    spec = draw_case("control", rng, controller_file=controller_file, duration_s=1.0)
    seal = Effect("seal", {"node": 23, "k_direct_nm": 2.0e5, "k_cross_nm": 5.0e5,
                           "c_direct_nsm": 300.0, "c_cross_nsm": 20.0})
    paths = write_case(replace(spec, effects=(seal,)), tmp_path, "mid", rng,
                       conceal_effects=False)
    report = diagnose(load_recording(paths["csv"])).to_dict()
    (e,) = report["explanations"]
    assert e["effect"] == "cross_coupling"
    node = int(e["location"][1:])
    a, b = (int(n[1:]) for n in e["node_range"])    # nodes as good as the named one
    assert a <= 23 <= b and a <= node <= b and b - a <= 4
    moves = [c for c in report["candidates"] if str(c["round"]).endswith("node")]
    assert {c["location"] for c in moves} >= {f"n{n}" for n in range(21, node + 1)}
    assert [d["location"] for d in report["direct_terms"]] == [e["location"]]
    lo, hi = e["params"]["kxy"]["hdi90"]
    assert lo <= 5.0e5 <= hi
