"""Simulation-based calibration (SBC) of the identification, small version.

Reference: Talts, Betancourt, Simpson, Vehtari & Gelman (2018), "Validating Bayesian
inference algorithms with simulation-based calibration". If theta ~ p(theta), y ~ p(y |
theta) and the sampler draws from p(theta | y), the rank of theta among L independent
posterior draws is uniform on {0, ..., L}, and every central posterior interval of level a
covers theta in a fraction a of the datasets.

Setup: reduced truth (the model is right), reference observer controller, dt = 1e-3 s,
0.5 s records, two parameters (k_By, c_By) drawn from the estimation priors, white sensor
noise (1e-7 m), r1 (1e-5 m, at the controller input; it reaches eps only through S(theta),
so it is large enough here to widen the exact posterior by tens of percent) and r2 (0.02 A).
The noise intensities are fixed across datasets (not drawn from their log-uniform priors)
and estimated by the sampler: their posterior is narrow (500 samples x 4 channels), so
p(theta | y) is, to good accuracy, p(theta | y, sigma_true), for which the fixed sigma is an
exact Bayesian model; the SBC statement holds for theta.

Sampler budget: 16 walkers x 300 steps, not run to 50 tau: SBC needs 99 roughly
independent draws (each walker thinned to one draw per tau, then 99 chosen at random;
rank_draws refuses fewer), not converged summaries, and the walkers start at the Laplace
approximation, so the burn-in (2 tau) is short. Measured wall time alone on 2 idle cores
(Intel Xeon, 2026-11-30): 72 s at 300 steps, 109 s at 400 and 145 s at 600 (2026-11-29),
with the same verdicts (loop: k_By coverage90 0.933 at all three, c_By 0.900 at 300 and
0.867 at 400 and 600; iid c_By coverage90 0.333 at all three); in the full suite, beside
other tests, about twice that. The report (coverages, rank counts, p-values, wall time) is
printed with ``pytest -s``.

A slow variant (``-m slow``) runs 100 datasets with the loop model and also checks the mean
rank (bias).

Checks and tolerances:
(a) coverage of the central 50 % and 90 % intervals, per parameter, inside the central 99 %
    band of Binomial(n, a) / n (scipy.stats.binom.ppf), n datasets;
(b) rank uniformity: chi-square over 5 equal bins of {0..99} (expected n/5 each; the
    approximation is fair for n >= 25), p > 0.01 per parameter.
With 2 parameters and 2 coverage levels plus 2 rank tests, a calibrated sampler fails (a) or
(b) by chance with probability below about 6 %; the seeds are fixed, so the outcome is
reproducible.

Power: the first N_IID = 15 datasets identified with noise_model="iid" (eps white with one
variance, the naive likelihood of METHOD.md section 4). In eps the sensor noise is high-pass
filtered (by Mt) and r2 is shaped by the plant's resonances, so the naive posterior errs in both
directions: the sandwich variance of its estimator at theta = (0.2, 0), computed from the
forward model and the loop noise filters, says c_By's posterior variance is about 4 times too
small and k_By's about 7 times too large. The test asserts that some 90 % coverage falls
below the 99 % band (0.667 for 15 datasets; measured c_By 0.333 on all 30 and on the
first 15, where a calibrated interval covers 5 of 15 or fewer with probability 2e-7).
15 datasets instead of 30 save a quarter of the test's time (72 -> 62 s alone on 2 idle
cores, 2026-11-30).
"""

from __future__ import annotations

import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from multiprocessing import get_context

import numpy as np
import pytest
import scipy.stats as st

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.inference.priors import Prior
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, simulate_recording

NAMES = ("k_By", "c_By")
PRIORS = {"k_By": Prior("normal", 0.2, 0.15), "c_By": Prior("normal", 0.0, 0.3)}
N_DATASETS = 30
N_IID = 15                           # datasets of the power check (the first N_IID)
N_RANK = 99                          # L posterior draws per dataset; ranks in 0..99
N_BINS = 5
WALKERS = 16
STEPS = 300
DT, DURATION = 1e-3, 0.5
NOISE = {"noise_rms": 1e-7, "r1_rms": 1e-5, "r2_rms": 0.02}
NOISE_MODELS = ("loop", "iid")
SEED = 20260


@dataclass(frozen=True)
class DatasetResult:
    """Per dataset: true theta (p,), rank of each among N_RANK draws, whether the central
    50 % / 90 % intervals cover it, the posterior sd, and the wall time."""

    theta: np.ndarray
    rank: np.ndarray
    cover50: np.ndarray
    cover90: np.ndarray
    sd: np.ndarray
    converged: bool
    wall_s: float


def draw_thetas(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.stack([PRIORS[k].sample(rng, n) for k in NAMES], axis=1)


def rank_draws(samples: np.ndarray, tau: float, rng: np.random.Generator) -> np.ndarray:
    """N_RANK roughly independent draws: each walker thinned to one draw per tau (the
    retained chain is already thinned by tau_min / 2), then N_RANK chosen at random."""
    step = max(1, round(tau))
    pool = samples[:, ::step].reshape(-1, samples.shape[-1])
    if pool.shape[0] < N_RANK:
        raise RuntimeError(f"only {pool.shape[0]} thinned draws for {N_RANK} ranks")
    return pool[rng.choice(pool.shape[0], N_RANK, replace=False)]


def _posterior_stats(res, theta: np.ndarray, rng: np.random.Generator) -> DatasetResult:
    p = len(NAMES)
    thin = int(res.sampler.thin)
    tau = np.array([res.parameters[n].tau for n in NAMES])
    flat = res.samples.reshape(-1, res.samples.shape[-1])[:, :p]
    draws = rank_draws(res.samples[..., :p], float(tau.max()) / thin, rng)
    q = np.quantile(flat, [0.05, 0.25, 0.75, 0.95], axis=0)
    return DatasetResult(theta=theta, rank=np.sum(draws < theta, axis=0),
                         cover50=(q[1] <= theta) & (theta <= q[2]),
                         cover90=(q[0] <= theta) & (theta <= q[3]), sd=flat.std(axis=0),
                         converged=bool(res.converged),
                         wall_s=float(res.wall_s))


def run_dataset(i: int, theta: np.ndarray, models: tuple[str, ...] = NOISE_MODELS
                ) -> dict[str, DatasetResult]:
    """Simulate dataset i at theta; identify it with each noise model; rank theta."""
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, DT), rig)
    cfg = SimulationConfig(truth="reduced", params=dict(zip(NAMES, theta.tolist(), strict=True)),
                           dt=DT, duration=DURATION, seed=SEED + i, **NOISE)
    rec, _ = simulate_recording(rig, ctrl, cfg)
    out = {}
    for model in models:
        res = identify(rec, NAMES, PRIORS, IdentifyOptions(
            walkers=WALKERS, steps=STEPS, seed=SEED + 1000 + i, noise_model=model))
        out[model] = _posterior_stats(res, theta, np.random.default_rng(SEED + 2000 + i))
    return out


def run_sbc(n: int = N_DATASETS, models: tuple[str, ...] = NOISE_MODELS,
            n_iid: int = N_IID) -> dict[str, list[DatasetResult]]:
    """All datasets on 2 worker processes; results per noise model, in dataset order. The
    "iid" model (the power check) runs on the first ``n_iid`` datasets only."""
    thetas = draw_thetas(n, SEED)
    per = [tuple(m for m in models if m != "iid" or i < n_iid) for i in range(n)]
    # spawned workers inherit the environment (run with OPENBLAS_NUM_THREADS=1)
    with ProcessPoolExecutor(max_workers=2, mp_context=get_context("spawn")) as pool:
        rows = list(pool.map(run_dataset, range(n), thetas, per))
    return {m: [r[m] for r in rows if m in r] for m in models}


@dataclass(frozen=True)
class SBCStats:
    n: int
    cover50: np.ndarray              # fraction per parameter
    cover90: np.ndarray
    counts: np.ndarray               # (p, N_BINS) rank histogram
    p_chi2: np.ndarray
    mean_rank: np.ndarray            # mean rank / N_RANK per parameter (0.5 if unbiased)
    band50: tuple[float, float]
    band90: tuple[float, float]

    @property
    def mean_rank_z(self) -> np.ndarray:
        """Mean normalised rank against its null distribution: discrete uniform on
        {0..L}/L has sd sqrt(((L + 1)^2 - 1) / 12) / L, divided by sqrt(n)."""
        sd = np.sqrt(((N_RANK + 1) ** 2 - 1) / 12) / N_RANK / np.sqrt(self.n)
        return (self.mean_rank - 0.5) / sd

    def report(self, label: str) -> str:
        lines = [f"SBC {label}: n = {self.n}; 99 % bands: 50 % {self.band50}, "
                 f"90 % {self.band90}"]
        for j, name in enumerate(NAMES):
            lines.append(f"  {name}: coverage50 {self.cover50[j]:.3f}, coverage90 "
                         f"{self.cover90[j]:.3f}, rank counts {self.counts[j].tolist()}, "
                         f"chi2 p = {self.p_chi2[j]:.3g}, mean rank / L "
                         f"{self.mean_rank[j]:.3f} (z = {self.mean_rank_z[j]:+.2f})")
        return "\n".join(lines)


def binomial_band(n: int, a: float) -> tuple[float, float]:
    """Central 99 % band of the covered fraction for n datasets at nominal coverage a."""
    return (float(st.binom.ppf(0.005, n, a)) / n, float(st.binom.ppf(0.995, n, a)) / n)


def sbc_stats(results: list[DatasetResult]) -> SBCStats:
    n = len(results)
    ranks = np.array([r.rank for r in results])                      # (n, p)
    edges = np.linspace(0, N_RANK + 1, N_BINS + 1)
    counts = np.array([np.histogram(ranks[:, j], bins=edges)[0] for j in range(len(NAMES))])
    p_chi2 = np.array([st.chisquare(c).pvalue for c in counts])
    return SBCStats(n=n, cover50=np.mean([r.cover50 for r in results], axis=0),
                    cover90=np.mean([r.cover90 for r in results], axis=0), counts=counts,
                    p_chi2=p_chi2, mean_rank=ranks.mean(axis=0) / N_RANK,
                    band50=binomial_band(n, 0.5), band90=binomial_band(n, 0.9))


def test_prior_draws_are_valid_simulation_parameters():
    """The simulator accepts |theta| <= 0.95 only. The datasets follow the prior (no
    rejection, no truncation) only if the prior's mass beyond that range is negligible:
    computed from the normal priors themselves (not from one seeded draw), the expected
    number of draws outside the range over the N_DATASETS datasets must be below 0.05
    (computed: k_By 2.9e-7 per draw, 5 sd from its mean; c_By 1.5e-3, 3.2 sd: 0.046 over
    30 datasets, so c_By's prior sets this bound)."""
    import scipy.stats as sst

    expected = 0.0
    for name in NAMES:
        pr = PRIORS[name]
        assert pr.kind == "normal"
        mu, sd = pr.a, pr.b
        outside = sst.norm.sf(0.95, mu, sd) + sst.norm.cdf(-0.95, mu, sd)
        expected += N_DATASETS * outside
    assert expected < 0.05
    assert np.all(np.abs(draw_thetas(N_DATASETS, SEED)) <= 0.95)   # and this run's draws


def run_and_report(n: int, models: tuple[str, ...]) -> dict[str, SBCStats]:
    t0 = time.perf_counter()
    results = run_sbc(n, models)
    stats = {m: sbc_stats(r) for m, r in results.items()}
    wall = time.perf_counter() - t0
    print(f"\nSBC of {n} datasets, noise models {models}, {WALKERS} walkers x {STEPS} steps:"
          f" {wall:.0f} s wall on 2 workers")
    for m, r in results.items():
        print(stats[m].report(f"noise_model={m}"))
        print(f"  mean posterior sd {np.round(np.mean([x.sd for x in r], axis=0), 4).tolist()},"
              f" identify wall per dataset {np.mean([x.wall_s for x in r]):.1f} s")
    return stats


def assert_calibrated(s: SBCStats) -> None:
    for j, name in enumerate(NAMES):
        assert s.band50[0] <= s.cover50[j] <= s.band50[1], (name, s.report("loop"))
        assert s.band90[0] <= s.cover90[j] <= s.band90[1], (name, s.report("loop"))
        assert s.p_chi2[j] > 0.01, (name, s.report("loop"))


@pytest.fixture(scope="module")
def sbc():
    return run_and_report(N_DATASETS, NOISE_MODELS)


def test_sbc_loop_noise_model_is_calibrated(sbc):
    assert_calibrated(sbc["loop"])


def test_sbc_iid_noise_model_is_miscalibrated(sbc):
    """Power: the same datasets under the naive white-eps likelihood. Predicted from the
    sandwich variance of the iid estimator at theta = (0.2, 0): c_By's posterior variance is
    about 4 times too small (90 % coverage near 0.58), k_By's about 7 times too large."""
    s = sbc["iid"]
    assert s.n == N_IID
    assert np.any(s.cover90 < s.band90[0]), s.report("iid")


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "measured (seed 20260; 892 s at commit 8bcdf52, 213 s at 7dfce00 with the fixed "
    "sampler): k_By mean rank / 99 = 0.584 (z = +2.89), rank counts [14, 15, 20, 19, 32]; "
    "c_By 0.507 (z = +0.24); coverages inside the bands. Not the sampler (fixed, unchanged "
    "result) and not the MAP's sigma_r1 (test_identify::test_map_is_not_below_the_truth_with"
    "_an_r1_disturbance passes). Open hypothesis: with r1 = 1e-5 m the r1 part of eps scales "
    "with S(theta), so the plug-in noise filters (fixed at the MAP) drop a first-order "
    "dependence of the residual spectrum on k_By. The 8-parameter SBC study (r1 = 1e-7 m) "
    "is calibrated"))
def test_sbc_loop_noise_model_is_calibrated_100_datasets():
    """The default test with 100 datasets (loop model only): the same checks, and the mean
    normalised rank within its 99 % band (|z| < 2.576), which detects a posterior shifted by
    about 0.3 sd on average."""
    s = run_and_report(100, ("loop",))["loop"]
    assert_calibrated(s)
    assert np.all(np.abs(s.mean_rank_z) < st.norm.ppf(0.995)), s.report("loop")
