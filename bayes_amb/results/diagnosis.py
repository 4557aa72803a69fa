"""The result of ``diagnose``: :class:`Diagnosis`, the typed content of a diagnosis run folder.

    d = diagnose(rec)                      # or Diagnosis.load("runs/realistic_diag")
    d.verdict, d.mismatch.detected
    [(e.effect, e.location, e.params["bandwidth_hz"].hdi90) for e in d.explanations]
    d.parameters_after["k_By"].hdi90
    print(d.summary())
    d.plot("candidates")
    d.save("runs/realistic_diag")          # diagnosis.json, residuals.nc, models/*.nc

``diagnosis.json`` (format ``bayes-amb-diagnosis/1``) is this object serialised: each key
is a field below, nested objects are the blocks of this module (see results/blocks.py for
the rules). A diagnosis just computed also carries its fitted models (``selection``) and
location arrays (``location``); a loaded one has the residual spectra and posterior draws
the run folder holds (``residuals``, ``models``).
"""

from __future__ import annotations

from dataclasses import field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Self

from bayes_amb.errors import BayesAmbError
from bayes_amb.results.blocks import Block, block, keyed, omitted, runtime
from bayes_amb.results.files import read_block, write_result

if TYPE_CHECKING:
    import xarray as xr
    from matplotlib.figure import Figure

    from bayes_amb.discrepancy.locate import Location
    from bayes_amb.discrepancy.select import Selection

FORMAT = "bayes-amb-diagnosis/1"
FILE = "diagnosis.json"


@block
class Estimate(Block):
    """A physical quantity's posterior: mean, MAP, 90 % HDI, unit."""

    mean: float
    map: float
    hdi90: list[float]
    unit: str


@block
class Coefficient(Block):
    """A bearing coefficient's posterior (normalised theta) and its physical value."""

    map: float
    mean: float
    sd: float
    hdi90: list[float]
    unit: str
    physical_mean: float
    physical_hdi90: list[float]
    at_prior_bound: bool = False
    true: float | None = omitted()


@block
class Check(Block):
    """One data check: its name, whether it passed, its line; its numbers in ``values``."""

    check: str
    ok: bool
    line: str

    @property
    def values(self) -> dict[str, Any]:
        return self.extra


@block
class RecordWindow(Block):
    """The part of the record compared with the model: samples before ``start_s`` drive it only."""

    start_s: float
    at_rest: bool
    meaning: str = ""


@block
class Adequacy(Block):
    """Whether the fitted model is adequate for its intervals (discrepancy/adequacy.py); a
    joint fit's names the inadequate ``records`` (1-based) instead of channels and bands."""

    adequate: bool
    line: str
    channels: list[str] | None = omitted()
    bands_hz: list[list[float]] | None = omitted()
    failed_checks: list[str] | None = omitted()
    nonlinear: bool | None = omitted()
    records: list[int] | None = omitted()


@block
class Finding(Block):
    """One significant location test (coherence, line, crosscorr, windows, floor,
    whiteness); its statistic in ``extra``."""

    test: str
    band_hz: list[float] | None = omitted()
    channels: list[str] | None = omitted()
    time_s: list[float] | None = omitted()
    p_adjusted: float | None = omitted()


@block
class SpectralLine(Block):
    """A line in the residual spectrum, and whether it sits at the running speed (1x)."""

    freq_hz: float
    channels: list[str]
    p_value: float
    power_ratio: float
    synchronous: bool


@block
class Evidence(Block):
    """How strong the location tests' evidence of a mismatch is (Holm-adjusted, family-wise)."""

    p_adjusted_min: float | None = None
    strength: str = ""
    family_min_p_adjusted: dict[str, float] | None = omitted()
    n_tests: int | None = omitted()
    alpha: float | None = omitted()
    posterior_predictive_p: dict[str, float] | None = omitted()
    max_coherence: float | None = omitted()
    log_bayes_factor: float | None = omitted()


@block
class Improvement(Block):
    """Where the chosen model fits better than the nominal one."""

    bands_hz: list[list[float]]
    channels: list[str]
    share: float | None = omitted()
    gain_by_band: list[list[float]]


@block
class Mismatch(Block):
    """Where the nominal model's residual holds structure (discrepancy/locate.py)."""

    detected: bool
    channels: list[str]
    bands_hz: list[list[float]]
    time_s: list[float] | None = None
    evidence: Evidence
    findings: list[Finding]
    noise_findings: list[Finding]
    lines: list[SpectralLine]
    improvement: Improvement | None = omitted()


@block
class EffectFit(Block):
    """A candidate of a fitted model: its physical parameters and its sampled ones."""

    effect: str
    location: str
    params: dict[str, Estimate]
    description: str
    sampled: dict[str, float]

    @property
    def key(self) -> str:
        return f"{self.effect}@{self.location}"


@block
class ParameterAgreement(Block):
    """Cochran's Q of one parameter's estimates across records, Holm-adjusted p, the
    between-record sd tau and the random-effects mean and sd (inference/consistency.py)."""

    Q: float
    dof: int
    p: float
    p_adjusted: float | None = omitted()
    tau: float
    random_effects_mean: float
    random_effects_sd: float
    record_means: list[float]
    record_sds: list[float]


@block
class Agreement(Block):
    """Whether several records agree on what they share: the test, its level, per
    parameter its statistics, the parameters they disagree on, in one line."""

    test: str
    alpha: float
    parameters: dict[str, ParameterAgreement]
    disagree: list[str]
    line: str


@block
class Explanation(EffectFit):
    """An effect the diagnosis named, with its evidence."""

    title: str
    side: str
    score: float
    log_posterior_odds: float | None = None
    kind: str
    equivalence_class: list[str]
    confidence: str
    node_range: list[str] | None = omitted()
    evidence: str


@block
class Unexplained(Block):
    """What the chosen model still leaves, with its nonparametric estimate."""

    present: bool
    channels: list[str]
    bands_hz: list[list[float]]
    findings: list[Finding]
    estimate: dict[str, Any] | None = omitted()
    meaning: str | None = omitted()


@block
class StandIn(Block):
    """A named effect whose interval lies outside what its physics allows."""

    effect: str
    location: str
    quantity: str
    hdi90: list[float]
    plausible: list[float]
    why: str
    line: str


@block
class Nonlinearity(Block):
    """The magnets' or amplifier's nonlinearity the linearity check found and modelled
    (discrepancy/nonlinear.py): its parameter per location with a 90 % interval, and the
    amplitude answer (where the linearisation holds within the coefficients' intervals)."""

    name: str
    title: str
    where: list[str]
    parameter: str
    unit: str
    estimate: dict[str, float]
    hdi90: dict[str, list[float]]
    z: float
    linear_range: str = ""
    derived: dict[str, Any] | None = omitted()
    saturation: dict[str, float] | None = omitted()
    """The iron's saturation ratio per bearing, where the rig file gives it."""


@block
class BalancingPlane(Block):
    """One correction plane: unbalance magnitude and phase with their intervals."""

    plane: str
    z_m: float
    u_kgm: Estimate
    phase_deg: Estimate
    ab_kgm: dict[str, Any]
    nonzero: bool


@block
class Balancing(Block):
    """The unbalance named, refitted in two correction planes (discrepancy/balancing.py)."""

    planes: list[BalancingPlane]
    from_: list[str] = keyed("from")
    log_likelihood_change: float | None = omitted()
    inference: str | None = omitted()
    meaning: str | None = omitted()
    note: str | None = omitted()


@block
class CandidateScore(Block):
    """One row of the search: a candidate's screen and, when fitted, its evidence; the
    revisit's rows also name the choice they were compared with."""

    effect: str
    location: str
    round: int | str
    screen_gain: float | None = omitted()
    screen: str | None = omitted()
    linear_gain: float | None = omitted()
    log_bayes_factor: float | None = omitted()
    log_posterior_odds: float | None = omitted()
    instead_of: str | None = omitted()
    chosen_log_bayes_factor: float | None = omitted()

    @property
    def key(self) -> str:
        return f"{self.effect}@{self.location}"


@block
class FitQuality(Block):
    """Per channel: NRMSE of the residual and the Ljung-Box p-value of its whitened form."""

    nrmse: dict[str, float]
    whiteness_p: dict[str, float]


@block
class FitComparison(Block):
    """The fit of the nominal and the chosen model, per channel, and the log-likelihood gain."""

    before: FitQuality
    after: FitQuality
    log_likelihood_gain: float


@block
class ModelError(Block):
    """The band-wise model error integrated out of a posterior (discrepancy/model_error.py)."""

    method: str
    tau: list[float]
    group_hz: list[list[float]]
    sd_ratio: dict[str, float]
    widened: bool
    sandwich_ratio: dict[str, float] | None = omitted()
    sandwich: str | None = omitted()


@block
class ModelErrors(Block):
    """The model error integrated out of the nominal (before) and reported (after) posteriors."""

    before: ModelError | None = None
    after: ModelError | None = None


@block
class Diagnosis(Block):
    """Everything ``diagnose`` found (the content of a diagnosis run folder)."""

    format: str = FORMAT
    package_version: str
    recording: str
    parameters_estimated: list[str]
    checks: list[Check]
    record_window: RecordWindow
    verdict: str
    adequacy: Adequacy | None = omitted()          # (files before issue 27 lack these three)
    adequacy_after: Adequacy | None = omitted()
    mismatch: Mismatch
    explanations: list[Explanation]
    unexplained: Unexplained
    stand_ins: list[StandIn] = field(default_factory=list)
    balancing: Balancing | None = None
    candidates: list[CandidateScore]
    fit: FitComparison
    parameters_before: dict[str, Coefficient]
    parameters_after: dict[str, Coefficient]
    parameters_after_from: str = ""
    direct_terms: list[EffectFit] = field(default_factory=list)
    model_error: ModelErrors | None = omitted()
    nonlinearity: Nonlinearity | None = omitted()
    criterion: str
    inference: str
    seed: int
    story: str = keyed("summary", default="")
    wall_s: float | None = omitted()

    residuals: xr.Dataset | None = runtime()
    models: dict[str, xr.Dataset] | None = runtime()
    location: Location | None = runtime()
    selection: Selection | None = runtime()

    where = FILE

    @property
    def effects(self) -> list[str]:
        """The named effects, in the order they were accepted."""
        return [e.effect for e in self.explanations]

    @property
    def checks_failed(self) -> bool:
        return any(not c.ok for c in self.checks)

    def summary(self) -> str:
        """The verdict and the plain-language paragraph."""
        return f"verdict: {self.verdict}\n{self.story}"

    def _repr_html_(self) -> str:
        """The notebook view: verdict, story, named effects, the bearing coefficients
        before and after, and the key figure (where the mismatch is, when the residuals are
        at hand; else the coefficients)."""
        from bayes_amb.results.html import result_html

        def coef(c: Coefficient | None) -> str:
            if c is None:
                return "-"
            lo, hi = c.physical_hdi90
            return f"{c.physical_mean:.4g} [{lo:.4g}, {hi:.4g}]"

        names = list(self.parameters_before) or list(self.parameters_after)
        rows = [[n, coef(self.parameters_before.get(n)), coef(self.parameters_after.get(n)),
                 (self.parameters_before.get(n) or self.parameters_after[n]).unit]
                for n in names]
        effects = [[e.title, e.location, e.confidence, e.description]
                   for e in self.explanations]
        tables = ([(["effect named", "where", "confidence", "estimate"], effects)]
                  if effects else [])
        tables.append((["coefficient", "before (90 % HDI)", "after (90 % HDI)", "unit"], rows))
        kind = "location" if self.residuals is not None else "parameters"
        return result_html(f"Diagnosis of {self.recording}", f"verdict: {self.verdict}",
                           [self.story, self.adequacy.line if self.adequacy else ""], tables,
                           lambda: self.plot(kind))

    def plot(self, kind: str = "location") -> Figure:
        """A figure of plots/discrepancy.py: location, residuals, candidates, improvement
        or parameters (location and residuals need the residuals: a diagnosis just computed
        or one loaded from a folder with residuals.nc)."""
        from bayes_amb.plots import discrepancy as pd

        if kind in ("candidates", "improvement", "parameters"):
            return {"candidates": pd.plot_candidates, "improvement": pd.plot_improvement,
                    "parameters": pd.plot_parameters}[kind](self)
        if kind not in ("location", "residuals"):
            raise BayesAmbError(f"plot kind {kind!r}: known kinds location, residuals, "
                                "candidates, improvement, parameters")
        if self.residuals is None:
            raise BayesAmbError(f"plot {kind!r}: this diagnosis has no residuals "
                                "(residuals.nc was not in its run folder)")
        if kind == "location":
            return pd.plot_location(self.residuals, self)
        return pd.plot_residual_spectra(self.residuals, self.mismatch.bands_hz)

    def save(self, out_dir: str | Path) -> Path:
        """Write OUT/diagnosis.json, OUT/residuals.nc and OUT/models/<model>.nc (posterior
        draws of each fitted model: emcee or Laplace, as their attrs say), atomically."""
        from bayes_amb.io.atomic import write_netcdf_atomic

        d = Path(out_dir)
        (d / "models").mkdir(parents=True, exist_ok=True)
        if self.residuals is not None:
            write_netcdf_atomic(self.residuals, d / "residuals.nc")
        for tag, ds in self.model_datasets().items():
            write_netcdf_atomic(ds, d / "models" / f"{tag}.nc")
        write_result(d / FILE, self)
        return d

    def model_datasets(self) -> dict[str, xr.Dataset]:
        """Posterior draws of the nominal and each accepted model, by file tag."""
        if self.selection is None:
            return dict(self.models or {})
        from bayes_amb.discrepancy.fitstats import posterior_dataset

        sel = self.selection
        return {tag: posterior_dataset(fm) for tag, fm in [("nominal", sel.nominal)] + [
            (f"step{i + 1}_{fm.candidates[-1].effect}", fm)
            for i, fm in enumerate(sel.accepted)]}

    @classmethod
    def load(cls, run_dir: str | Path) -> Self:
        """The diagnosis a run folder holds (diagnosis.json; residuals.nc and models/*.nc
        when present). A folder without diagnosis.json, or a file of another format, is a
        one-line error naming it."""
        import xarray as xr
        d = Path(run_dir)
        out = read_block(cls, d / FILE, FORMAT)
        res = d / "residuals.nc"
        models = {p.stem: xr.load_dataset(p) for p in sorted((d / "models").glob("*.nc"))}
        return replace(out, residuals=xr.load_dataset(res) if res.is_file() else None,
                       models=models)
