"""The registry of the physics library: one vocabulary, read by every reader.

Every entry's declared parameters are those its candidate samples and reports; declared
equivalences point at real candidates and hold from both sides; the README table is the
registry's; the CLI, the simulator, the studies and the foreign generator speak its names.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from bayes_amb.discrepancy.library import (
    NOMINAL_FAMILY,
    REGISTRY,
    VOCABULARY,
    all_candidates,
    equivalents_of,
    make_candidate,
    markdown_table,
)
from bayes_amb.discrepancy.library.base import ModelContext
from bayes_amb.discrepancy.library.registry import admissible
from bayes_amb.rig import load_rig
from tests.helpers import run_cli

README = Path(__file__).parent.parent / "docs" / "diagnose.md"     # the library table
FOREIGN_ALIASES = {"actuator_delay": "time_delay"}
"""Foreign-generator names for which the library uses another name (same physics)."""


@pytest.fixture(scope="module")
def ctx():
    return ModelContext(rig=load_rig(), dt=1e-4, speed_rpm=31500.0,
                        bending_hz=(1027.0, 1286.0, 2542.0, 3095.0, 4466.0, 5051.0),
                        bending_zeta=(0.003,) * 6, static_residual=np.eye(4) * 1e-8)


@pytest.mark.parametrize("name", list(REGISTRY) + list(NOMINAL_FAMILY))
def test_entry_matches_its_candidates(ctx, name):
    e = REGISTRY.get(name) or NOMINAL_FAMILY[name]
    assert e.title and e.description and e.fingerprint and e.locations
    assert e.side in ("actuator", "sensor", "plant", "model")
    for loc in e.locations:
        c = e.make(loc)
        assert (c.effect, c.location, c.entry) == (name, loc, e)
        ps = c.params(ctx)
        assert [p.name for p in ps] == [s.at(loc).name for s in e.sampled]
        assert [p.null for p in ps] == [s.null for s in e.sampled]
        draws = np.array([[p.null + 0.01 if p.null == 0 else p.null for p in ps]])
        phys = c.physical(draws, ctx)
        assert list(phys) == [q.name for q in e.physical]
        assert [u for _, u in phys.values()] == [q.unit for q in e.physical] \
            or e.nominal_family
        assert c.describe({k: float(v[0][0]) for k, v in phys.items()})


def test_sampled_names_are_unique_across_the_library(ctx):
    names = [p.name for c in all_candidates(representatives=False) for p in c.params(ctx)]
    assert len(names) == len(set(names))


def test_equivalences_point_at_candidates_and_hold_both_ways():
    for c in all_candidates(representatives=False):
        for other, when in equivalents_of(c.key):
            assert when
            o = make_candidate(other)
            assert c.key in {k for k, _ in equivalents_of(o.key)}, (c.key, other)
    assert "sensor_lag@both" in {k for k, _ in equivalents_of("actuator_lag@both")}
    assert not equivalents_of("actuator_lag@A")      # a lag at one bearing does not commute


def test_representatives_leave_out_declared_equivalents():
    keys = [c.key for c in all_candidates()]
    assert "time_delay@controller" in keys and "sensor_delay@sensors" not in keys
    assert "actuator_lag@both" in keys and "sensor_lag@both" not in keys
    assert [c.key for c in all_candidates(["sensor_delay"])] == ["sensor_delay@sensors"]


def test_greedy_may_repeat_an_effect_at_another_place_only():
    sg = make_candidate("sensor_gain@Ax")
    assert admissible(make_candidate("sensor_gain@By"), [sg])
    assert not admissible(make_candidate("sensor_gain@Ax"), [sg])
    assert admissible(make_candidate("unbalance@n20"), [make_candidate("unbalance@D1")])
    lag = make_candidate("actuator_lag@A")
    assert admissible(make_candidate("time_delay@controller"), [lag])      # lag with delay
    assert not admissible(make_candidate("sensor_delay@sensors"),
                          [make_candidate("time_delay@controller")])
    assert not admissible(make_candidate("sensor_lag@both"),
                          [make_candidate("actuator_lag@both")])            # same class
    assert not admissible(make_candidate("flexible_mode@bending pair 1"),
                          [make_candidate("flexible_mode@bending pair 1")])


def test_readme_table_is_the_registrys():
    text = README.read_text()
    m = re.search(r"<!-- library-table[^>]*-->\n(.*?)\n\s*<!-- /library-table -->", text,
                  re.DOTALL)
    assert m, "docs/diagnose.md has no library table"
    table = "\n".join(line.strip() for line in m.group(1).splitlines())
    assert table == markdown_table(), ("docs/diagnose.md table differs: run `bayes-amb library "
                                       "--markdown`")


def test_cli_lists_the_library(capsys):
    code, out, _ = run_cli(["library", "--json"], capsys)
    assert code == 0
    rows = json.loads(out)["effects"]
    assert [r["effect"] for r in rows] == list(VOCABULARY)
    assert all(r["parameters"] and r["fingerprint"] for r in rows)
    code, out, _ = run_cli(["library"], capsys)
    assert code == 0 and all(n in out for n in VOCABULARY)
    code, out, _ = run_cli(["diagnose", "--help"], capsys)
    assert code == 0
    assert all(n in out.replace("\n", "").replace(" ", "") for n in VOCABULARY)


def test_other_vocabularies_are_the_registrys():
    from bayes_amb.simulate import EFFECT_DEFAULTS
    from bayes_amb.studies.concealed import SINGLE
    from benchmarks.foreign import HELD_OUT, IN_FAMILY
    assert set(EFFECT_DEFAULTS) <= set(VOCABULARY)
    assert set(SINGLE) == set(EFFECT_DEFAULTS)
    foreign = {FOREIGN_ALIASES.get(n, n) for n in IN_FAMILY}
    assert foreign <= set(VOCABULARY)
    assert not set(HELD_OUT) & set(VOCABULARY)       # the held-out family stays out
