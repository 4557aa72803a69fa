"""Issue 29: several recordings in one posterior. Two records of one rig at two speeds
(the model built at each record's speed), shared coefficients: the joint sd is the
records' precisions added; a parameter declared per record gets one estimate per record."""

import json

import numpy as np
import pytest

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.inference.joint import identify_joint
from bayes_amb.io.recording import save_recording
from bayes_amb.results.identification import Identification
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, simulate_recording
from tests.helpers import run_cli

TRUTH = {"k_By": 0.2, "c_By": 0.1}
OPT = IdentifyOptions(map_only=True, adequacy=False)


@pytest.fixture(scope="module")
def records():
    rig = load_rig()
    out = []
    for speed, seed in ((31500.0, 1), (20000.0, 2)):
        ctrl = export_controller(reference_controller(rig, 1e-4, speed), rig)
        cfg = SimulationConfig(truth="reduced", params=TRUTH, noise_rms=5e-8, duration=0.5,
                               speed_rpm=speed, seed=seed)
        out.append(simulate_recording(rig, ctrl, cfg)[0])
    return out


def test_shared_coefficients_add_the_records_precisions(records):
    own = [identify(r, "k_By,c_By", options=OPT).parameters for r in records]
    joint = identify_joint(records, "k_By,c_By", options=OPT).to_dict()
    assert [r["speed_rpm"] for r in joint["records"]] == [31500.0, 20000.0]
    for n, true in TRUTH.items():
        expect = 1 / np.sqrt(sum(1 / o[n].sd ** 2 for o in own))
        got = joint["parameters"][n]
        assert got["sd"] == pytest.approx(expect, rel=0.15)
        assert abs(got["mean"] - true) < 3.3 * got["sd"]     # two-sided p 0.001


def test_a_parameter_per_record(records):
    s = identify_joint(records, "k_By,c_By", options=OPT, per_record=("c_By",)).to_dict()
    assert set(s["parameters"]) == {"k_By", "c_By@1", "c_By@2"}
    for r in (1, 2):
        v = s["parameters"][f"c_By@{r}"]
        assert abs(v["mean"] - TRUTH["c_By"]) < 3.3 * v["sd"]
    with pytest.raises(BayesAmbError, match="per-record"):
        identify_joint(records, "k_By", options=OPT, per_record=("c_By",))


def test_joint_cli(records, tmp_path, capsys):
    paths = [str(save_recording(tmp_path / f"r{i}.csv", r)[0]) for i, r in enumerate(records)]
    code, out, _ = run_cli(["identify", *paths, "--params", "k_By,c_By", "--map-only",
                            "--out", str(tmp_path / "run"), "--json"], capsys)
    assert code == 0
    s = json.loads(out)
    assert len(s["records"]) == 2 and "k_By" in s["parameters"]
    assert json.loads((tmp_path / "run" / "summary.json").read_text())["recordings"] == paths
    page = (tmp_path / "run" / "joint.html").read_text()
    assert "The joint posterior" in page and "Each record and the joint posterior" in page
    (tmp_path / "run" / "joint.html").unlink()
    code, out, _ = run_cli(["report", str(tmp_path / "run"), "--pdf-backend", "matplotlib"],
                           capsys)
    assert code == 0 and "joint.html" in out and (tmp_path / "run" / "joint.html").is_file()
    assert (tmp_path / "run" / "joint.pdf").read_bytes()[:5] == b"%PDF-"
    (tmp_path / "run" / "joint.pdf").unlink()
    code, out, _ = run_cli(["report", str(tmp_path / "run"), "--no-pdf"], capsys)
    assert code == 0 and not (tmp_path / "run" / "joint.pdf").exists()
    code, out, _ = run_cli(["identify", *paths, "--params", "k_By", "--steps", "100",
                            "--no-progress", "--out", str(tmp_path / "sampled")], capsys)
    assert code == 0 and "R-hat" in out and "posterior.nc" in out
    assert Identification.load(tmp_path / "sampled").posterior is not None
    code, _, err = run_cli(["identify", paths[0], "--params", "k_By", "--per-record", "k_By",
                            "--map-only", "--out", str(tmp_path / "x")], capsys)
    assert code == 2 and "--per-record" in err


def test_records_that_disagree_get_the_random_effects_interval_and_a_line(records):
    """A third record whose k_By is 0.45 instead of 0.2 (a bearing that changed, or a
    nonlinear loop at another level): the records disagree on k_By, not on c_By; the
    joint k_By interval is widened by their spread and the adequacy line names it."""
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, 1e-4, 31500.0), rig)
    cfg = SimulationConfig(truth="reduced", params={**TRUTH, "k_By": 0.45}, noise_rms=5e-8,
                           duration=0.5, speed_rpm=31500.0, seed=3)
    changed = simulate_recording(rig, ctrl, cfg)[0]
    agree = identify_joint(records, "k_By,c_By", options=OPT).to_dict()
    assert agree["agreement"]["disagree"] == [] and agree["adequacy"]["adequate"]
    s = identify_joint([*records, changed], "k_By,c_By", options=OPT).to_dict()
    assert s["agreement"]["disagree"] == ["k_By"]
    assert not s["adequacy"]["adequate"] and "k_By" in s["adequacy"]["line"]
    assert "--per-record k_By" in s["adequacy"]["line"]
    fixed = s["agreement"]["parameters"]["k_By"]
    assert s["parameters"]["k_By"]["sd"] == pytest.approx(fixed["random_effects_sd"])
    assert s["parameters"]["k_By"]["sd"] > 5 * max(
        agree["parameters"]["k_By"]["sd"], min(fixed["record_sds"]))


def test_a_joint_map_pushed_past_a_prior_bound_gets_the_prior_and_a_note(records):
    """The records say k_By = 0.2, the prior stops at 0.1: the joint MAP sits on the bound,
    where the joint Hessian holds it. As identify reports a record's, its interval is the
    prior's (not the zero width of a held parameter), and the note says the records push
    it past the prior; c_By keeps its Laplace interval."""
    from bayes_amb.inference.priors import parse_prior

    s = identify_joint(records, "k_By,c_By", priors={"k_By": parse_prior("uniform(-0.8, 0.1)")},
                       options=OPT).to_dict()
    k, c = s["parameters"]["k_By"], s["parameters"]["c_By"]
    assert s["map"]["k_By"] == pytest.approx(0.1, abs=1e-6)
    assert k["sd"] == pytest.approx(0.9 / np.sqrt(12), rel=0.02)
    assert k["hdi90"] == pytest.approx([-0.755, 0.055], abs=0.01)
    assert s["identifiability"]["past_prior_bound"] == ["k_By"]
    assert 0 < c["sd"] < 0.2


def test_joint_emcee_samples_the_noise_per_record_and_agrees_with_laplace(records, tmp_path):
    """Sampling (the default without map_only) frees each record's noise intensities that
    the Laplace approximation holds at their MAP: in this linear, well-informed case the
    two must give the same sd (to the sampler's Monte-Carlo error and the noise's first
    order coupling, 15 %), and the truth lies inside the sampled posterior."""
    laplace = identify_joint(records, "k_By,c_By", options=OPT, per_record=("c_By",))
    s = identify_joint(records, "k_By,c_By", per_record=("c_By",),
                       options=IdentifyOptions(adequacy=False, seed=3))
    assert s.inference.startswith("joint emcee") and s.converged
    assert s.sampler is not None and s.sampler.n_tau >= 50
    assert set(s.parameters) == {"k_By", "c_By@1", "c_By@2"}
    for n, v in s.parameters.items():
        assert v.r_hat <= 1.01 and v.ess_bulk >= 400
        assert v.sd == pytest.approx(laplace.parameters[n].sd, rel=0.15)
        assert abs(v.mean - TRUTH[n.split("@")[0]]) < 3.3 * v.sd
    for r in s.records:        # the sampled noise holds the record's MAP inside its 90 %
        post = r.noise_posterior["sigma_noise"]
        assert post.q05 <= r.noise["sigma_noise"].value <= post.q95
        assert post.mean == pytest.approx(5e-8, rel=0.1)
    s.save(tmp_path / "run")
    back = Identification.load(tmp_path / "run")
    assert back.inference == s.inference and back.posterior is not None
    draws = back.posterior["posterior"]
    assert {"k_By", "c_By@2", "sigma_noise@1", "sigma_r2@2"} <= set(draws.data_vars)
    assert float(draws["k_By"].mean()) == pytest.approx(s.parameters["k_By"].mean, abs=1e-9)
    with pytest.raises(BayesAmbError, match="--walkers"):
        identify_joint(records, "k_By,c_By",
                       options=IdentifyOptions(adequacy=False, walkers=8))


def test_identify_and_diagnose_take_a_list_of_recordings(records, monkeypatch):
    """bayes_amb.identify([rec1, rec2], ...) is the joint posterior; bayes_amb.diagnose of a
    list hands it to diagnose_records (stubbed here: the call is what is tested)."""
    import bayes_amb
    import bayes_amb.api as api

    joint = identify_joint(records, "k_By,c_By", options=OPT)
    listed = bayes_amb.identify(records, "k_By,c_By", options=OPT)
    assert listed.recordings == joint.recordings and listed.map == joint.map
    with pytest.raises(BayesAmbError, match="per-record"):
        bayes_amb.identify(records[0], "k_By", options=OPT, per_record=("k_By",))
    seen = {}
    monkeypatch.setattr(api, "diagnose_records", lambda recs, *a: seen.setdefault("n", len(recs)))
    assert bayes_amb.diagnose(records) == 2 and seen == {"n": 2}
