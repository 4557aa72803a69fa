"""Records over time (inference/compare.py): the change's interval and the probability
that it changed, calibrated when changes are drawn from the model's own prior; identify
on two records of one rotor and on a changed one; the CLI."""

import json

import numpy as np
import pytest

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.compare import Z90, change, compare, compare_runs
from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.results import Identification, Posterior
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, simulate_recording
from tests.helpers import run_cli


def _p(mean: float, sd: float) -> Posterior:
    return Posterior(mean=mean, sd=sd, hdi90=[mean - Z90 * sd, mean + Z90 * sd], unit="N/m",
                     physical_mean=mean * 1e6, physical_sd=sd * 1e6,
                     physical_hdi90=[(mean - Z90 * sd) * 1e6, (mean + Z90 * sd) * 1e6])


def _run(**params: Posterior) -> Identification:
    return Identification(package_version="test", parameters_estimated=list(params),
                          priors={}, map={n: p.mean for n, p in params.items()},
                          inference="test", parameters=params, converged=True)


def test_the_probability_is_calibrated_on_its_own_prior():
    """Half the pairs unchanged, half changed by N(0, tau^2); among pairs given P(changed)
    in a bin, the share that changed matches the bin's mean P within 4 binomial sds."""
    rng = np.random.default_rng(11)
    tau, n = 0.1, 6000
    changed = rng.uniform(size=n) < 0.5
    delta = np.where(changed, rng.normal(0.0, tau, n), 0.0)
    sds = rng.uniform(0.01, 0.08, (n, 2))
    before = rng.normal(0.2, sds[:, 0])
    after = rng.normal(0.2 + delta, sds[:, 1])
    p = np.array([change("k", _p(b, sb), _p(a, sa), tau).p_changed
                  for b, a, (sb, sa) in zip(before, after, sds, strict=True)])
    for lo, hi in ((0.0, 0.3), (0.3, 0.7), (0.7, 1.0)):
        sel = (p >= lo) & (p < hi)
        assert sel.sum() > 300
        share, expect = changed[sel].mean(), p[sel].mean()
        assert abs(share - expect) < 4 * np.sqrt(expect * (1 - expect) / sel.sum())


def test_the_change_and_its_interval():
    c = change("k_By", _p(0.10, 0.03), _p(0.50, 0.04))
    assert c.change == pytest.approx(0.40) and c.sd == pytest.approx(0.05)
    assert c.hdi90 == pytest.approx((0.40 - 1.6449 * 0.05, 0.40 + 1.6449 * 0.05))
    assert c.physical_change == pytest.approx(0.40e6) and c.p_changed > 0.999
    assert change("k_By", _p(0.10, 0.03), _p(0.11, 0.04)).p_changed < 0.5
    with pytest.raises(BayesAmbError, match="k_By"):
        change("k_By", _p(0.1, float("nan")), _p(0.1, 0.1))
    with pytest.raises(BayesAmbError, match="share no parameter"):
        compare(_run(a=_p(0, 1)), _run(b=_p(0, 1)))


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """identify (MAP) of k_By, c_By on three records: two of one rotor, one after k_By
    moved from 0.2 to 0.45."""
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, 1e-4), rig)
    out = {}
    for label, k, seed in (("month0", 0.2, 1), ("month1", 0.2, 2), ("retrofit", 0.45, 3)):
        cfg = SimulationConfig(truth="reduced", params={"k_By": k, "c_By": 0.1},
                               noise_rms=5e-8, duration=0.5, seed=seed)
        rec = simulate_recording(rig, ctrl, cfg)[0]
        res = identify(rec, "k_By,c_By", options=IdentifyOptions(map_only=True,
                                                                 adequacy=False))
        out[label] = res.save(tmp_path_factory.mktemp(label))
    return out


def test_identify_runs_of_one_rotor_and_of_a_changed_one(runs):
    same = compare_runs(runs["month0"], runs["month1"]).changes
    moved = compare_runs(runs["month0"], runs["retrofit"]).changes
    assert same["k_By"].p_changed < 0.5 and same["c_By"].p_changed < 0.5
    assert moved["k_By"].p_changed > 0.99
    assert moved["k_By"].hdi90[0] < 0.25 < moved["k_By"].hdi90[1]
    assert moved["c_By"].p_changed < 0.5


def test_compare_cli(runs, tmp_path, capsys):
    code, out, _ = run_cli(["compare", str(runs["month0"]), str(runs["retrofit"]),
                            "--json", "--out", str(tmp_path / "c.json")], capsys)
    assert code == 0
    d = json.loads(out)
    assert d["changes"]["k_By"]["p_changed"] > 0.99
    assert json.loads((tmp_path / "c.json").read_text()) == d
    code, out, _ = run_cli(["compare", str(runs["month0"]), str(runs["retrofit"]),
                            "--change-scale", "k_By=0.5"], capsys)
    assert code == 0 and "k_By changed by +0.2" in out and "of ~0.5" in out
    code, _, err = run_cli(["compare", str(runs["month0"]), str(tmp_path / "none")], capsys)
    assert code == 2 and "none" in err
