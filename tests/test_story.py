"""The diagnosis' plain-language paragraph (bayes_amb.discrepancy.story) says which
candidate came closest where structure is left unexplained: the last round's best fit that
the data favour (log Bayes factor above 0) but not by the naming threshold, and only where
that round named nothing. Read from the golden diagnoses (tests/golden/)."""

from __future__ import annotations

import gzip
import json
from dataclasses import replace

from bayes_amb.discrepancy.story import closest_unnamed, plain_language
from bayes_amb.results import Diagnosis
from tests.golden.cases import HERE


def _golden(name: str) -> Diagnosis:
    return Diagnosis.from_dict(json.loads(gzip.open(HERE / f"{name}.diagnosis.json.gz").read()))


def test_the_closest_unnamed_candidate_is_said_beside_what_is_unexplained():
    d = _golden("runout_02")             # a runout named; structure left at 419-595 Hz on By
    near = closest_unnamed(d)
    assert near is not None and near.key == "sensor_gain@By"
    assert 0.0 < near.log_bayes_factor and near.log_posterior_odds < 3.0
    assert near.round == max(c.round for c in d.candidates if isinstance(c.round, int))
    text = plain_language(d)
    assert "one comes close, the sensor gain at By (log Bayes factor 2.2" in text
    assert text == d.story
    from bayes_amb.report.render import _unexplained  # the report's headline clause

    assert _unexplained(d).endswith("that no model in the library explains with the evidence "
                                    "to be named; the closest is the sensor gain at By (log "
                                    "Bayes factor 2.2, log posterior odds -1.3)")


def test_no_closest_candidate_where_none_is_favoured_or_the_search_hit_its_limit():
    seal = _golden("seal_07")            # unexplained, its last round's best disfavoured
    assert seal.unexplained.present and closest_unnamed(seal) is None
    assert "no model in the library explains it (see" in plain_language(seal)
    # the same record with its last round counted as named: the search stopped at its
    # limit of effects, not for want of evidence, so nothing is said of a closest one
    last = max(c.round for c in seal.candidates if isinstance(c.round, int))
    full = replace(seal, explanations=seal.explanations * last)
    assert closest_unnamed(full) is None
    runout = _golden("runout_02")
    flat = replace(runout, candidates=[replace(c, log_bayes_factor=-0.5)
                                       if c.log_bayes_factor is not None else c
                                       for c in runout.candidates])
    assert closest_unnamed(flat) is None
