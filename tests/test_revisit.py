"""The revisit step (discrepancy/revisit.py): an earlier greedy choice is replaced by an
alternative of its round when, with the later effects held in the model, the alternative's
Bayes factor is larger; otherwise nothing changes. The fits are stubbed (their Bayes factors
given) so that the bookkeeping is tested on its own; the foreign benchmark measures the
effect on real recordings (pair_03: a 38 us delay first named as a second-order actuator)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from bayes_amb.discrepancy import revisit as rv
from bayes_amb.discrepancy.library import make_candidate
from bayes_amb.discrepancy.select import Selection


def _fm(cands, log_bf=None, log_odds=None):
    return SimpleNamespace(candidates=tuple(cands), log_bf=log_bf, log_odds=log_odds,
                           forward=SimpleNamespace(params=(), slices=[slice(0, 0)] * len(cands)),
                           value=lambda n: 0.0)


@pytest.fixture
def setup(monkeypatch):
    first = make_candidate("actuator_2nd@both")
    second = make_candidate("sensor_lag@B")
    r1 = _fm((first,), 11306.0, 11306.0 - np.log(34))
    r2 = _fm((first, second), 1859.0, 1859.0 - np.log(34))
    scores = [{"effect": "actuator_2nd", "location": "both", "round": 1,
               "log_bayes_factor": 11306.0},
              {"effect": "time_delay", "location": "controller", "round": 1,
               "log_bayes_factor": 11055.0},
              {"effect": "actuator_gain", "location": "Ax", "round": 1,
               "log_bayes_factor": None},
              {"effect": "sensor_lag", "location": "B", "round": 2,
               "log_bayes_factor": 1859.0}]
    sel = Selection(nominal=_fm(()), final=r2, accepted=[r1, r2], scores=scores)
    sel.rest_starts = []                    # the model each rest's refit also starts from
    monkeypatch.setattr(rv, "_without", lambda final, i, before: (
        sel.rest_starts.append(before), _fm((second,)))[1])
    monkeypatch.setattr(rv, "screen", lambda parent, cand, priors=None:
                        rv.Screen(cand, 0.0, {}))
    return sel, first, second


def _refine_with(bfs, monkeypatch):
    tried = []

    def refine(parent, sc, priors=None):
        tried.append(sc.candidate.key)
        return _fm((*parent.candidates, sc.candidate), bfs[sc.candidate.key])
    monkeypatch.setattr(rv, "refine", refine)
    return tried


def test_a_better_alternative_replaces_the_first_choice(setup, monkeypatch):
    sel, _, _ = setup
    tried = _refine_with({"actuator_2nd@both": 3525.1, "time_delay@controller": 3536.8},
                         monkeypatch)
    out = rv.revisit(sel)
    assert tried == ["actuator_2nd@both", "time_delay@controller"]   # never actuator_gain
    assert [c.key for c in out.final.candidates] == ["sensor_lag@B", "time_delay@controller"]
    assert [f.candidates[-1].key for f in out.accepted] == ["sensor_lag@B",
                                                            "time_delay@controller"]
    assert out.accepted[1].log_odds == pytest.approx(3536.8 - np.log(34))
    row = [s for s in out.scores if s["round"] == "revisit"]
    assert row[0]["instead_of"] == "actuator_2nd@both"
    assert row[0]["chosen_log_bayes_factor"] == 3525.1
    assert sel.rest_starts == [sel.nominal]   # round 1's choice: the rest from the nominal


def test_a_worse_alternative_changes_nothing(setup, monkeypatch):
    sel, first, second = setup
    final = sel.final
    _refine_with({"actuator_2nd@both": 3540.0, "time_delay@controller": 3536.8}, monkeypatch)
    out = rv.revisit(sel)
    assert out.final is final
    assert [f.candidates[-1] for f in out.accepted] == [first, second]


def test_an_unrefined_candidate_screened_near_the_choice_is_an_alternative():
    """The round refined only its best few; one screened within 90 % of the choice (a
    delay 3 % below) is compared too, one far below (an actuator gain) is not."""
    scores = [{"effect": "actuator_2nd", "location": "both", "round": 1,
               "screen_gain": 12383.5, "log_bayes_factor": 14350.4},
              {"effect": "actuator_lag", "location": "both", "round": 1,
               "screen_gain": 12190.1, "log_bayes_factor": 14111.0},
              {"effect": "time_delay", "location": "controller", "round": 1,
               "screen_gain": 12058.8, "log_bayes_factor": None},
              {"effect": "actuator_2nd", "location": "B", "round": 1,
               "screen_gain": 3588.2, "log_bayes_factor": None},
              {"effect": "sensor_lag", "location": "A", "round": 2,
               "screen_gain": 1670.3, "log_bayes_factor": 3702.0}]
    assert rv._alternatives(scores, 1, "actuator_2nd@both") == ["actuator_lag@both",
                                                                "time_delay@controller"]


def test_one_effect_is_not_revisited(monkeypatch):
    c = make_candidate("sensor_lag@B")
    sel = Selection(nominal=_fm(()), final=_fm((c,), 10.0), accepted=[_fm((c,), 10.0)],
                    scores=[])
    monkeypatch.setattr(rv, "refine", lambda *a, **k: pytest.fail("no refit expected"))
    assert rv.revisit(sel) is sel


def test_a_swap_is_told_in_the_paragraph_and_drawn_without_the_revisit_rows():
    from types import SimpleNamespace

    from bayes_amb.discrepancy.story import _swaps
    from bayes_amb.plots.discrepancy import plot_candidates
    from bayes_amb.results import CandidateScore
    rows = [{"effect": "actuator_2nd", "location": "both", "round": 1, "screen_gain": 10.0,
             "log_bayes_factor": 11306.0, "log_posterior_odds": 11302.5},
            {"effect": "time_delay", "location": "controller", "round": 1, "screen_gain": 9.0,
             "log_bayes_factor": 11055.0, "log_posterior_odds": 11051.5},
            {"effect": "time_delay", "location": "controller", "round": "revisit",
             "screen_gain": None, "log_bayes_factor": 3536.8, "log_posterior_odds": None,
             "instead_of": "actuator_2nd@both", "chosen_log_bayes_factor": 3525.1}]
    text = _swaps([CandidateScore.from_dict(r) for r in rows])
    assert "time_delay@controller" in text and "actuator_2nd@both" in text and "3536.8" in text
    assert _swaps([CandidateScore.from_dict(r) for r in rows[:2]]) == ""
    rows[2]["log_bayes_factor"] = 3500.0                 # the choice stood: nothing to tell
    assert _swaps([CandidateScore.from_dict(r) for r in rows]) == ""
    fig = plot_candidates(SimpleNamespace(
        candidates=[CandidateScore.from_dict(r) for r in rows], criterion="",
        explanations=[SimpleNamespace(key="time_delay@controller")]))
    assert len(fig.axes) >= 1


def test_an_unrefined_alternative_must_win_by_the_threshold(setup, monkeypatch):
    """time_delay was fitted in round 1 (no margin); an actuator_lag that only screened
    near the choice must beat it by 3 nats: +0.7 changes nothing (+3.5 replaces it: below)."""
    sel, _, _ = setup
    sel.scores[0]["screen_gain"] = 10000.0
    sel.scores.append({"effect": "actuator_lag", "location": "both", "round": 1,
                       "screen_gain": 9800.0, "log_bayes_factor": None})
    final = sel.final
    _refine_with({"actuator_2nd@both": 3525.1, "time_delay@controller": 3500.0,
                  "actuator_lag@both": 3525.8}, monkeypatch)
    out = rv.revisit(sel)
    assert out.final is final


def test_an_unrefined_alternative_that_wins_clearly_replaces(setup, monkeypatch):
    sel, _, _ = setup
    sel.scores[0]["screen_gain"] = 10000.0
    sel.scores.append({"effect": "actuator_lag", "location": "both", "round": 1,
                       "screen_gain": 9800.0, "log_bayes_factor": None})
    _refine_with({"actuator_2nd@both": 3525.1, "time_delay@controller": 3500.0,
                  "actuator_lag@both": 3528.6}, monkeypatch)
    out = rv.revisit(sel)
    assert [c.key for c in out.final.candidates] == ["sensor_lag@B", "actuator_lag@both"]
