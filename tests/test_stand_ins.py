"""Stand-ins (discrepancy/stand_ins.py): an effect whose whole 90 % interval lies outside
the range its physics allows is reported and makes the naming tentative."""

from __future__ import annotations

import pytest

from bayes_amb.discrepancy.library.registry import REGISTRY
from bayes_amb.discrepancy.stand_ins import stand_in_sentence, stand_ins
from bayes_amb.results.diagnosis import StandIn


def _effect(effect: str, location: str, **hdi: tuple[float, float]) -> dict:
    return {"effect": effect, "location": location,
            "params": {k: {"hdi90": list(v), "mean": sum(v) / 2, "unit": "-"}
                       for k, v in hdi.items()}}


def test_a_bending_mode_with_the_damping_of_a_lag_is_a_stand_in():
    found = stand_ins([_effect("flexible_mode", "bending pair 3",
                               frequency_hz=(4273.0, 4703.0), damping_ratio=(0.68, 0.86))])
    assert [(s["effect"], s["quantity"]) for s in found] == [("flexible_mode",
                                                               "damping_ratio")]
    assert found[0]["plausible"] == [0.0, 0.2]
    assert "0.68" in found[0]["line"] and "bending pair 3" in found[0]["line"]
    assert "tentative" in stand_in_sentence([StandIn.from_dict(s) for s in found])


def test_a_bending_mode_is_judged_against_the_rigs_own_damping():
    """The real test rig's Rayleigh damping (beta 1e-4 s) gives its third bending pair a
    damping ratio of 0.24 in the FE model: fitted there it is that mode, not a stand-in;
    on a rig whose FE model gives it 0.005 the same interval is one."""
    fitted = _effect("flexible_mode", "bending pair 3", damping_ratio=(0.227, 0.255))
    own = {("flexible_mode", "bending pair 3"): {"damping_ratio": 0.238}}
    assert stand_ins([fitted], own) == []
    light = {("flexible_mode", "bending pair 3"): {"damping_ratio": 0.005}}
    assert [s["plausible"] for s in stand_ins([fitted], light)] == [[0.0, 0.2]]
    heavy = _effect("flexible_mode", "bending pair 3", damping_ratio=(0.75, 0.9))
    assert [s["plausible"] for s in stand_ins([heavy], own)] == [[0.0, 3 * 0.238]]


@pytest.mark.parametrize("hdi", [(0.0029, 0.0032), (0.15, 0.25), (0.19, 0.9)])
def test_a_lightly_damped_mode_or_an_interval_reaching_into_the_range_is_not(hdi):
    assert stand_ins([_effect("flexible_mode", "bending pair 1", damping_ratio=hdi)]) == []


@pytest.mark.parametrize("hdi, flagged", [((0.038, 0.072), True), ((0.48, 0.92), False),
                                          ((0.2, 0.3), False), ((4.5, 6.0), True)])
def test_residual_flexibility_far_from_the_fe_value(hdi, flagged):
    found = stand_ins([_effect("residual_flexibility", "truncated modes", scale=hdi)])
    assert bool(found) is flagged


def test_effects_without_a_range_and_unknown_effects_pass():
    assert stand_ins([_effect("actuator_lag", "both", bandwidth_hz=(10.0, 20.0)),
                      _effect("not_in_the_library", "A", gain=(9.0, 10.0))]) == []
    assert stand_in_sentence([]) == ""


def test_every_declared_range_holds_its_effects_null_and_gives_a_reason():
    """A range is the physics' own: the model without the effect (gain 0, scale 1 x FE,
    the FE damping) lies inside it, and each range says why."""
    inside = {"gain": 0.0, "scale": 1.0, "damping_ratio": 0.01}
    declared = [(e.name, q) for e in REGISTRY.values() for q in e.physical
                if q.plausible is not None]
    assert len(declared) >= 4
    for name, q in declared:
        lo, hi = q.plausible
        assert lo < inside[q.name] < hi, (name, q.name)
        assert len(q.why) > 20, (name, q.name)
