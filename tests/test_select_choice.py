"""The round's choice between a left-out bearing coefficient and physics (select._choose).

A coefficient the fit held at nominal is the simpler explanation and is preferred, but not
when a physics candidate of the same round is stronger by the acceptance threshold: then
the coefficient has only taken what the physics leaves at its bearing (the concealed
benchmark's delays and sensor gains, docs/diagnose.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest

from bayes_amb.discrepancy.select import _choose

THRESHOLD = 3.0


@dataclass
class _Cand:
    nominal_family: bool


@dataclass
class _Fit:
    """The two attributes _choose reads and the one it writes."""

    candidates: list[_Cand]
    log_odds: float | None = field(default=None)


def _coef() -> _Fit:
    return _Fit([_Cand(nominal_family=True)])


def _physics() -> _Fit:
    return _Fit([_Cand(nominal_family=False)])


def test_nothing_passed_chooses_nothing():
    assert _choose([], THRESHOLD) is None


@pytest.mark.parametrize("physics_odds,expected", [
    (None, "coefficient"),           # physics did not pass
    (5.0, "coefficient"),            # stronger, but not by the threshold
    (8.0, "coefficient"),            # exactly the threshold more: still the coefficient
    (8.01, "physics"),               # beyond it
])
def test_a_coefficient_is_preferred_unless_physics_is_stronger_by_the_threshold(
        physics_odds, expected):
    coef, phys = _coef(), _physics()
    passed = [(coef, 5.0)] + ([] if physics_odds is None else [(phys, physics_odds)])
    chosen = _choose(passed, THRESHOLD)
    assert chosen is (coef if expected == "coefficient" else phys)
    assert chosen.log_odds == (5.0 if expected == "coefficient" else physics_odds)


def test_physics_alone_is_chosen_with_its_odds():
    phys = _physics()
    assert _choose([(phys, 4.0)], THRESHOLD) is phys and phys.log_odds == 4.0
