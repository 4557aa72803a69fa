"""The result of ``identify``: :class:`Identification`, the typed content of an identify run
folder.

    res = identify(rec, "k_By")            # or Identification.load("runs/paper")
    res.parameters["k_By"].mean, res.parameters["k_By"].hdi90, res.converged
    print(res.summary())
    res.plot("trace")
    res.save("runs/paper")                 # summary.json (and posterior.nc after sampling)

``summary.json`` (format ``bayes-amb-summary/1``) is this object serialised (see
results/blocks.py for the rules). One recording's fit has ``recording``, its noise and the
sampler; a joint fit of several (inference/joint.py) has ``recordings`` and each record's
own fit under ``records``.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Self

import numpy as np

from bayes_amb.errors import BayesAmbError
from bayes_amb.results.blocks import Block, block, omitted, runtime
from bayes_amb.results.diagnosis import Adequacy, Agreement
from bayes_amb.results.files import (
    POSTERIOR_GROUPS,
    read_block,
    read_posterior,
    write_result,
)

if TYPE_CHECKING:
    import xarray as xr
    from matplotlib.figure import Figure

    from bayes_amb.inference.estimate import MapResult
    from bayes_amb.inference.whittle import WhittleLikelihood

FORMAT = "bayes-amb-summary/1"
FILE = "summary.json"


@block
class Posterior(Block):
    """A parameter's posterior: normalised theta (mean, sd, 90 % HDI), its sampler
    diagnostics (None for a Laplace approximation) and its physical value."""

    mean: float
    sd: float
    hdi90: list[float]
    ess_bulk: float | None = None
    ess_tail: float | None = None
    r_hat: float | None = None
    tau: float | None = None
    unit: str
    physical: str | None = omitted()
    physical_mean: float
    physical_sd: float | None = omitted()
    physical_hdi90: list[float]
    true: float | None = omitted()


@block
class NoiseValue(Block):
    """A noise intensity (MAP) and its unit."""

    value: float
    unit: str


@block
class NoisePosterior(Block):
    """A noise intensity's posterior: mean, 5 and 95 % quantiles, unit, autocorrelation time."""

    mean: float
    q05: float
    q95: float
    unit: str
    tau: float | None = None


@block
class NoiseCheck(Block):
    """Is the residual as white as the noise model has it (inference/noise_check.py)? The
    whiteness test (statistic, degrees of freedom, p value; ``doubted`` below 1e-3), the
    segments of most and least colour [f_lo, f_hi, residual power over the model's], and
    where doubted, each parameter's sandwich sd over the white model's (``sd_ratio``; the
    intervals are then the sandwich's)."""

    doubted: bool
    p_value: float
    statistic: float
    dof: int
    bands_hz: list[list[float]]
    line: str
    sd_ratio: dict[str, float] | None = omitted()


@block
class NoiseSpectrum(Block):
    """The noise colour learned from the record (inference/spectrum.py): whether it beat
    the white sources (``adopted``; the likelihood-ratio statistic and its degrees of
    freedom), each source's level (log10 sigma) and its gain in dB per channel at the
    knots ``knot_hz``; ``colour`` whether the colour the sources still missed was folded
    in, with its power over theirs (``colour_power``) at the segments' ``colour_hz``;
    ``lines`` the narrowband lines (not at a multiple of the running speed) the spectrum
    has as noise: frequency, level over the noise in dB, channels."""

    adopted: bool
    log10_sigma: list[float]
    lr_statistic: float
    dof: int
    knot_hz: list[float]
    gain_db: dict[str, dict[str, list[float]]]
    colour: bool
    notes: list[str]
    lines: list[dict[str, Any]] | None = omitted()
    colour_hz: list[float] | None = omitted()
    colour_power: list[float] | None = omitted()

    @property
    def line(self) -> str:
        """One line for the summary: what was learned."""
        parts = []
        if self.adopted:
            spans = []
            for src, per in self.gain_db.items():
                vals = [v for row in per.values() for v in row]
                spans.append(f"{src} {min(vals):+.0f} to {max(vals):+.0f} dB")
            parts.append("each source's intensity per channel, smooth in frequency "
                         f"(likelihood ratio {self.lr_statistic:.3g} on {self.dof} against "
                         f"the white sources; gains {', '.join(spans)})")
        if self.colour and self.colour_power:
            parts.append(f"the colour they missed, over {len(self.colour_power)} segments "
                         f"(power x{min(self.colour_power):.2g} to "
                         f"x{max(self.colour_power):.2g} theirs)")
        if self.lines:
            shown = ", ".join(f"{ln['f_hz']:.4g} Hz (+{ln['level_db']:.0f} dB, "
                              f"{','.join(ln['channels'])})" for ln in self.lines[:6])
            more = f" and {len(self.lines) - 6} more" if len(self.lines) > 6 else ""
            parts.append(f"lines taken as noise: {shown}{more}")
        return "noise spectrum learned from the record: " + "; ".join(parts)


@block
class NarrowLine(Block):
    """A narrowband line left out of the likelihood (inference/narrow_lines.py): its
    frequency (Hz, the strongest bin's), the bins left out, its level over the local noise
    (dB), the channels that carry it, and whether it lies at a multiple of the running
    speed (unbalance, runout: physics for a diagnosis, a disturbance to identify)."""

    f_hz: float
    bins: int
    level_db: float
    channels: list[str]
    synchronous: bool

    @property
    def text(self) -> str:
        return (f"{self.f_hz:.4g} Hz (+{self.level_db:.0f} dB, {','.join(self.channels)}"
                f"{', synchronous' if self.synchronous else ''})")


@block
class Noise(Block):
    """The noise model and its intensities (MAP; posterior after sampling), the check of
    its whiteness on the record, the spectrum learned from it, and the narrowband lines left
    out of the likelihood."""

    model: str
    map: dict[str, NoiseValue]
    posterior: dict[str, NoisePosterior] | None = omitted()
    check: NoiseCheck | None = omitted()
    spectrum: NoiseSpectrum | None = omitted()
    lines_left_out: list[NarrowLine] | None = omitted()

    @property
    def lines_line(self) -> str:
        """One line for the summary: the lines left out, or empty."""
        if not self.lines_left_out:
            return ""
        shown = ", ".join(ln.text for ln in self.lines_left_out[:6])
        more = (f" and {len(self.lines_left_out) - 6} more"
                if len(self.lines_left_out) > 6 else "")
        bins = sum(ln.bins for ln in self.lines_left_out)
        return f"narrowband lines left out of the likelihood ({bins} bins): {shown}{more}"


@block
class StartTransient(Block):
    """Whether identify fitted the record's start transient, and why (IdentifyOptions
    .initial_state; by default the data check decides): ``start_difference`` is the
    controller's start-up difference as a share of u's RMS, when it was checked."""

    fitted: bool
    reason: str
    start_difference: float | None = omitted()


@block
class ModelBand(Block):
    """The reduced model the likelihood used, where it keeps bending pairs (the loop's
    control band reaches past the rigid-body model's validity band;
    inference/model_band.py): states, pairs kept and their frequencies (backward and
    forward whirl, Hz), the band the likelihood uses (validity_band_hz), the highest
    frequency at which the loop gain reaches one (control_band_hz), and the line said
    (such a model also holds the static compliance of the modes it leaves out, through
    one lumped mode: [Your rotor](your_rig.md), "Bending modes inside the control
    band")."""

    states: int
    bending_pairs: int
    bending_hz: list[float]
    validity_band_hz: float
    control_band_hz: float
    capped: bool
    line: str


@block
class LaplaceCov(Block):
    """The Laplace covariance of theta at the MAP (normalised units), with its names."""

    names: list[str]
    theta: list[list[float]]


@block
class Sampler(Block):
    """The emcee run: walkers, moves, steps, burn-in, thinning, autocorrelation times and
    acceptance."""

    walkers: int
    moves: str
    steps: int
    burn: int
    thin: int
    n_tau: float
    acceptance_mean: float
    wall_s: float | None = omitted()
    likelihood_evals: int | None = omitted()


@block
class RecordFit(Block):
    """One record's own fit inside a joint posterior."""

    recording: str
    speed_rpm: float
    dt: float
    excitation_port: Any = None
    map: dict[str, float]
    noise: dict[str, NoiseValue]
    adequacy: Adequacy | None = None
    parameters: dict[str, Posterior]
    noise_posterior: dict[str, NoisePosterior] | None = omitted()
    noise_check: NoiseCheck | None = omitted()
    start_transient: StartTransient | None = omitted()


@block
class Identification(Block):
    """Everything ``identify`` (or ``identify_joint``) found: the content of summary.json,
    with the posterior draws (posterior.nc) when it sampled."""

    format: str = FORMAT
    package_version: str
    recording: str | None = omitted()
    recordings: list[str] | None = omitted()
    parameters_estimated: list[str]
    per_record_parameters: list[str] | None = omitted()
    priors: dict[str, Any]
    map: dict[str, float]
    map_method: str | None = omitted()
    map_wall_s: float | None = omitted()
    noise: Noise | None = omitted()
    fast_path: Any = omitted()
    excitation_port: Any = omitted()
    n_bands: int | None = omitted()
    model: ModelBand | None = omitted()
    start_transient: StartTransient | None = omitted()
    seed: int = 0
    adequacy: Adequacy | None = omitted()
    inference: str
    parameters: dict[str, Posterior]
    laplace_cov: LaplaceCov | None = omitted()
    records: list[RecordFit] | None = omitted()
    converged: bool
    sampler: Sampler | None = omitted()
    identifiability: dict[str, Any] | None = omitted()
    agreement: Agreement | None = omitted()
    inference_note: str | None = omitted()
    parameters_white_noise: dict[str, Posterior] | None = omitted()
    parameters_model_only: dict[str, Posterior] | None = omitted()
    parameters_from: str | None = omitted()
    wall_s: float | None = omitted()

    names: tuple[str, ...] | None = runtime()
    map_result: MapResult | None = runtime()
    posterior: xr.DataTree | None = runtime()
    samples: np.ndarray | None = runtime()
    eps: np.ndarray | None = runtime()
    likelihood: WhittleLikelihood | None = runtime()

    where = FILE

    def summary(self) -> str:
        """A table: each parameter's mean, sd and 90 % interval, normalised and physical,
        with the inference, the convergence and the adequacy line."""
        lines = [f"{self.inference}; converged: {self.converged}"]
        if self.model is not None:
            lines.append(self.model.line)
        if self.adequacy is not None:
            lines.append(self.adequacy.line)
        if self.start_transient is not None and self.start_transient.fitted:
            lines.append(f"start transient fitted ({self.start_transient.reason})")
        if self.noise is not None and self.noise.lines_line:
            lines.append(self.noise.lines_line)
        w = max(len(n) for n in self.parameters)
        for n, p in self.parameters.items():
            lines.append(f"{n:<{w}}  {p.mean:+.4f} +- {p.sd:.4f}  "
                         f"[{p.hdi90[0]:+.4f}, {p.hdi90[1]:+.4f}]   {p.physical_mean:.4g} "
                         f"[{p.physical_hdi90[0]:.4g}, {p.physical_hdi90[1]:.4g}] {p.unit}")
        return "\n".join(lines)

    def _repr_html_(self) -> str:
        """The notebook view: inference and adequacy lines, one row per parameter (mean, sd,
        90 % interval, physical), and the posterior's marginals when it was sampled."""
        from bayes_amb.results.html import result_html

        rows = [[n, f"{p.mean:+.4f}", f"{p.sd:.4f}", f"[{p.hdi90[0]:+.4f}, {p.hdi90[1]:+.4f}]",
                 f"{p.physical_mean:.4g}",
                 f"[{p.physical_hdi90[0]:.4g}, {p.physical_hdi90[1]:.4g}]", p.unit]
                for n, p in self.parameters.items()]
        lines = [self.model.line if self.model else "",
                 self.adequacy.line if self.adequacy else "",
                 f"start transient fitted ({self.start_transient.reason})"
                 if self.start_transient is not None and self.start_transient.fitted else "",
                 self.noise.lines_line if self.noise is not None else "",
                 self.inference_note or ""]
        title = (f"Identification of {self.recording}" if self.recording else
                 f"Identification of {len(self.recordings or [])} records")
        return result_html(title, f"{self.inference}; converged: {self.converged}", lines,
                           [(["parameter", "mean", "sd", "90 % HDI", "physical",
                              "physical 90 % HDI", "unit"], rows)],
                           (lambda: self.plot("posterior")) if self.posterior is not None
                           else None)

    def plot(self, kind: str = "posterior") -> Figure:
        """A figure of plots/posterior.py from the draws (after sampling): 'posterior'
        (marginals and pairs) or 'trace'."""
        from bayes_amb.plots import posterior as pp

        if self.posterior is None:
            raise BayesAmbError(f"plot {kind!r}: no posterior draws (a MAP-only fit, or "
                                "posterior.nc was not in its run folder)")
        if kind not in ("posterior", "trace"):
            raise BayesAmbError(f"plot kind {kind!r}: known kinds posterior, trace")
        names = list(self.parameters_estimated)
        draws = {n: np.asarray(self.posterior["posterior"][n].values, dtype=float)
                 for n in names}
        labels = {n: f"{n} [{self.parameters[n].unit}]" for n in names}
        if kind == "trace":
            return pp.plot_trace(draws, labels, {}, self.map)
        return pp.plot_pair(draws, labels, {}, self.map)

    def save(self, run_dir: str | Path) -> Path:
        """Write RUN_DIR/summary.json (and posterior.nc after sampling), atomically."""
        from bayes_amb.inference.posterior import save_datatree

        d = Path(run_dir)
        d.mkdir(parents=True, exist_ok=True)
        if self.posterior is not None:
            save_datatree(self.posterior, d / "posterior.nc")
        write_result(d / FILE, self)
        return d

    @classmethod
    def load(cls, run_dir: str | Path) -> Self:
        """The identification a run folder holds (summary.json; posterior.nc when
        present). A folder without summary.json, or a file of another format, is a one-line
        error naming it."""
        import dataclasses

        d = Path(run_dir)
        out = read_block(cls, d / FILE, FORMAT)
        groups = ("posterior", "sample_stats") if out.recordings else POSTERIOR_GROUPS
        post = (read_posterior(d / "posterior.nc", groups) if (d / "posterior.nc").is_file()
                else None)
        return dataclasses.replace(out, posterior=post,
                                   names=tuple(out.parameters_estimated))
