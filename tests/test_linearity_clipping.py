"""The linearity check on the foreign generator's amplifier current limit (issue 27).

A clipping amplifier is a nonlinearity the tool must report, never absorb: the check
fails, the limit it estimates is the generator's, and with the clip modelled the eight
bearing coefficients come back inside their intervals. The same draws without the limit
pass the check. The generator is benchmarks/foreign (written apart from the tool); its truth is
read only here, after the tool has answered."""

import json
from dataclasses import replace

import numpy as np
import pytest

from bayes_amb.discrepancy.adequacy import nominal_assessment
from bayes_amb.discrepancy.library.bearing_coefficient import BEARING_COEFFICIENTS
from bayes_amb.io.recording import load_recording
from benchmarks.foreign.cases import draw_case, write_case


def _record(tmp_path, controller_file, recorded: str | None, seed: int = 31):
    rng = np.random.default_rng(seed)
    spec = draw_case("current_limit", rng, controller_file=controller_file, duration_s=1.0)
    effect = spec.effects[0]
    if recorded is None:
        spec = replace(spec, effects=())
    else:
        spec = replace(spec, effects=(replace(effect, params={
            **effect.params, "recorded": recorded, "clipped_share_target": 0.02}),))
    paths = write_case(spec, tmp_path, f"clip_{recorded}", rng)
    return load_recording(paths["csv"]), json.loads(paths["truth"].read_text())


def _z(nominal, truth):
    theta = np.array([truth["theta"][n] for n in BEARING_COEFFICIENTS])
    sd = np.sqrt(np.diag(nominal.cov)[:8])
    return (nominal.params - theta) / sd


@pytest.mark.parametrize("recorded", ["command", "coil"])
def test_a_clipping_amplifier_fails_the_check_and_is_modelled(tmp_path, controller_file,
                                                              recorded):
    rec, truth = _record(tmp_path, controller_file, recorded)
    checks, nominal, _ = nominal_assessment(rec, BEARING_COEFFICIENTS)
    lin = next(c for c in checks.checks if c.name == "linearity")
    assert not lin.ok and "FAILED" in lin.line
    i_max = truth["effects"][0]["params"]["i_max_a"]
    if recorded == "command":       # no flat top: found in the residual, limit estimated
        assert not lin.values["flat_tops"]
        assert abs(lin.values["clipping_limit_a"] / i_max - 1) < 0.03
        # the limit re-estimated with the coefficients refitted (clip_model.
        # _reestimate_clip), the clip's path through the loop explains the residual: gain
        # near 1 (0.81 here, 0.51 from the nominal fit's residual alone, where the limit
        # was 1.25 % high on another record), and each channel's centre is where the
        # amplifier clips, minus
        # its offset, in the current as the fit sees it (mean removed by the offsets
        # check), within 10 mA (2 % clipped on each channel's two sides, 4-9 mA of
        # amplifier noise before the limit: 0.8-5.2 mA off here; the offsets reach 50 mA)
        assert 0.75 < lin.values["clipping_gain"] < 1.25
        centre = -np.asarray(truth["habits"]["amp_offset_a"]) - np.mean(rec.u, axis=0)
        assert np.max(np.abs(np.asarray(lin.values["clipping_centre_a"]) - centre)) < 0.01
    else:
        assert lin.values["flat_tops"]
    # with the clip modelled the coefficients are honest again: 8 z-scores of a correct
    # model exceed 4 in absolute value with probability 5e-4
    assert np.max(np.abs(_z(nominal, truth))) < 4.0


def test_the_same_draws_without_a_limit_pass(tmp_path, controller_file):
    rec, _ = _record(tmp_path, controller_file, None)
    checks, _, _ = nominal_assessment(rec, BEARING_COEFFICIENTS)
    lin = next(c for c in checks.checks if c.name == "linearity")
    assert lin.ok, lin.line
    assert lin.values["clipping_z"] < 4.0


def test_a_record_of_milliseconds_fails_the_information_check(tmp_path, controller_file):
    """Issue 27: a 49-sample (4.9 ms) record was accepted, with every coefficient pinned at
    a prior bound by an interval of zero width. Now the information check fails (too few
    frequency bins), no physics can be named, and no interval has zero width."""
    from bayes_amb.discrepancy.fitstats import draws, theta_summary
    rec, _ = _record(tmp_path, controller_file, None)
    csv = tmp_path / "clip_None.csv"
    lines = csv.read_text().splitlines()
    short = tmp_path / "short.csv"
    short.write_text("\n".join(lines[:50]) + "\n")
    (tmp_path / "short.json").write_text((tmp_path / "clip_None.json").read_text())
    checks, nominal, _ = nominal_assessment(load_recording(short), BEARING_COEFFICIENTS)
    info = next(c for c in checks.checks if c.name == "information")
    assert not info.ok and "frequency bins" in info.line
    assert "information" in checks.failed
    summary = theta_summary(nominal, draws(nominal))
    assert min(v["hdi90"][1] - v["hdi90"][0] for v in summary.values()) > 0.1
    # the full record passes it
    checks, _, _ = nominal_assessment(rec, BEARING_COEFFICIENTS)
    assert next(c for c in checks.checks if c.name == "information").ok


def _controller_check(rec):
    from bayes_amb.discrepancy.adequacy import loop_poles
    from bayes_amb.discrepancy.checks import run_checks
    from bayes_amb.inference.forward import ForwardModel

    fwd = ForwardModel(rec, BEARING_COEFFICIENTS)
    return next(c for c in run_checks(rec, loop_poles(fwd)).checks if c.name == "controller")


def test_a_recorded_coil_current_at_its_limit_is_not_a_wrong_controller(tmp_path,
                                                                         controller_file):
    """A DAQ that records the coil current records the amplifier's output: on the samples
    held at the limit it is not the controller's command. With 4 % of the samples clipped
    that difference followed the excitation, and the controller check failed the record
    ('the controller that ran is not the one in the sidecar', current_limit_02 of
    runs/nl58). Now the check passes, says why, and the clip is modelled (coil_defect);
    the same record with a controller 2 % off still fails."""
    rng = np.random.default_rng(58)
    spec = draw_case("current_limit", rng, controller_file=controller_file, duration_s=1.0)
    effect = spec.effects[0]
    spec = replace(spec, effects=(replace(effect, params={
        **effect.params, "recorded": "coil", "clipped_share_target": 0.04}),))
    paths = write_case(spec, tmp_path, "coil4", rng)
    rec, truth = load_recording(paths["csv"]), json.loads(paths["truth"].read_text())
    ctrl = _controller_check(rec)
    assert ctrl.ok and ctrl.values["limited_coil_current"], ctrl.line
    assert "amplifier's output after its limit" in ctrl.line
    checks, nominal, _ = nominal_assessment(rec, BEARING_COEFFICIENTS)
    assert "controller" not in checks.failed
    assert np.max(np.abs(_z(nominal, truth))) < 4.0     # the clip modelled, as above
    k = rec.controller
    wrong = replace(rec, controller=replace(k, C=np.asarray(k.C) * 1.02,
                                            D=np.asarray(k.D) * 1.02))
    bad = _controller_check(wrong)
    assert not bad.ok and "FAILED" in bad.line


def test_the_limit_is_read_off_the_flat_tops_of_a_coil_current():
    """Half the span between a held channel's two flat tops is the limit about the
    amplifier's own centre, whatever offset the amplifier or the DAQ adds; a channel held
    at one end only gives that end's distance from its median."""
    from bayes_amb.discrepancy.flat_tops import held_half_spans

    rng = np.random.default_rng(4)
    cmd = 0.4 * rng.standard_normal((4000, 4))
    amp_offset = np.array([0.02, -0.03, 0.0, 0.01])
    daq_offset = np.array([0.011, 0.0, -0.02, 0.0])
    coil = np.clip(cmd + amp_offset, -0.5, 0.5) + daq_offset
    coil[:, 3] = np.minimum(cmd[:, 3], 0.6)          # held at the top only
    spans = held_half_spans(coil)
    assert np.allclose(spans[:3], 0.5, rtol=0, atol=1e-12)
    assert spans[3] == pytest.approx(0.6 - np.median(coil[:, 3]))
    assert held_half_spans(cmd) == []                # nothing held
