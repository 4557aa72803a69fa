"""The report's figures: each section's matplotlib figures rendered to PNG and SVG.

Numbers come from :mod:`bayes_amb.report.derived` and the run itself; drawing from
:mod:`bayes_amb.plots`. Model figures are derived from the rig embedded in the recording.
"""

from __future__ import annotations

import base64
import io
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from bayes_amb.control.robustness import SensitivityData
from bayes_amb.inference.priors import parse_prior
from bayes_amb.plots import control as pc
from bayes_amb.plots import data as pd
from bayes_amb.plots import discrepancy as pdisc
from bayes_amb.plots import model as pm
from bayes_amb.plots import posterior as pp
from bayes_amb.plots.style import style_context
from bayes_amb.reduction.fidelity import singular_value_data
from bayes_amb.report.collect import RunData
from bayes_amb.report.derived import Derived, ResidualTests, time_window, welch
from bayes_amb.results.diagnosis import Diagnosis
from bayes_amb.rotor import campbell_data

__all__ = ["ReportFigure", "controller_figures", "data_figures", "discrepancy_figures",
           "file_figure",
           "identification_figures", "model_figures", "render_figure", "validation_figure"]


@dataclass
class ReportFigure:
    """One figure: PNG (HTML, and PDF fallback) and SVG (vector PDF) bytes, and the
    matplotlib Figure itself (None for figures read from files, e.g. studies)."""

    key: str
    title: str
    caption: str
    png: bytes
    svg: bytes | None = None
    fig: Figure | None = field(default=None, repr=False)

    @property
    def png_uri(self) -> str:
        return "data:image/png;base64," + base64.b64encode(self.png).decode("ascii")

    @property
    def pdf_uri(self) -> str:
        if self.svg is None:
            return self.png_uri
        return "data:image/svg+xml;base64," + base64.b64encode(self.svg).decode("ascii")


def render_figure(fig: Figure, key: str, title: str, caption: str,
                  vector: bool = True) -> ReportFigure:
    """Render a Figure to PNG (130 dpi) and, when ``vector``, to SVG (text as paths, so
    the PDF looks the same whatever fonts the PDF renderer finds)."""
    buf = io.BytesIO()
    with style_context():
        fig.savefig(buf, format="png", dpi=130, metadata={"Software": None})
        svg = None
        if vector:
            sbuf = io.BytesIO()
            import matplotlib as mpl
            with mpl.rc_context({"svg.fonttype": "path"}):
                fig.savefig(sbuf, format="svg", metadata={"Date": None})
            svg = sbuf.getvalue()
    return ReportFigure(key, title, caption, buf.getvalue(), svg, fig)


def file_figure(path: str | Path, key: str, title: str, caption: str = "") -> ReportFigure:
    """A PNG file as a report figure (study figures)."""
    return ReportFigure(key, title, caption, Path(path).read_bytes())


# -------------------------------------------------------------------- sections
def model_figures(run: RunData, d: Derived, campbell_speeds: int = 13
                  ) -> list[ReportFigure]:
    rig = run.recording.rig
    red = d.forward.reduced
    speeds = np.linspace(0, 1.2 * max(rig.nominal_speed_rpm, d.full.speed_rpm),
                         campbell_speeds)
    cd = replace(campbell_data(rig, speeds), nominal_speed_rpm=d.full.speed_rpm)
    sv = singular_value_data(red)
    return [
        render_figure(pm.plot_rotor_sketch(rig), "sketch", "Rotor geometry",
                      "Shaft, FE nodes, discs (as equivalent cylinders), AMBs and sensors, "
                      "from the rig embedded in the recording."),
        render_figure(pm.plot_campbell(cd), "campbell", "Campbell diagram",
                      "Open-loop flexible-mode frequencies against speed; dotted: the "
                      f"recording's speed ({d.full.speed_rpm:.0f} rpm)."),
        render_figure(pm.plot_singular_values(sv), "sv_reduction",
                      "Full against reduced model (paper Fig. 5)",
                      f"Singular values of the {d.full.n_states}-state FE model and the "
                      f"{red.n_states}-state pseudo-modal reduction; largest gap "
                      f"{sv.max_gap_db():.3f} dB below the dotted marker."),
    ]


def controller_figures(cd: dict[str, Any], dt: float) -> list[ReportFigure]:
    sens: tuple[SensitivityData, SensitivityData] = cd["sens"]
    ch = cd["channel"]
    zl = f"zeros {ch}→{ch}"
    return [
        render_figure(pc.plot_pole_zero_continuous(cd["g"], "Poles and zeros of G(θ)", zl),
                      "pz_g", "Plant G(θ): open loop (paper Fig. 6)",
                      "Continuous reduced LFT plant at θ = 0 and at the posterior mean; "
                      f"poles of G and zeros of its {ch}→{ch} channel (the channel S(θ) "
                      "changes most). Poles in the right half-plane: the plant cannot be "
                      "identified in open loop."),
        render_figure(pc.plot_pole_zero_discrete([cd["s"]], "Poles and zeros of S(θ̂)", dt,
                                                 zl),
                      "pz_s", "Dual-Youla parameter S(θ) (paper Fig. 7)",
                      f"Discrete S(θ) at the posterior mean: poles, and zeros of its {ch}→"
                      f"{ch} channel (S has the rank of the LFT channels, so MIMO zeros are "
                      "not defined). Every pole inside the unit circle: eps = S(θ) x is an "
                      "open-loop-stable identification problem."),
        render_figure(pc.plot_sensitivity([("nominal plant", sens[0]),
                                           ("identified plant", sens[1])]),
                      "sensitivity", "Sensitivity per axis (ISO 14839-3)",
                      f"Diagonal of (I − G K)⁻¹ with the {cd['full_states']}-state FE plant "
                      f"of rig '{cd['rig_name']}' and the recorded controller, other loops "
                      "closed."),
        render_figure(pc.plot_plant_singular_values(*cd["sv"]), "sv_plant",
                      "Nominal and identified plant (paper Fig. 8)",
                      "Singular values of the reduced LFT plant at θ = 0, at the posterior "
                      "mean and (simulated data) at the true θ."),
    ]


def data_figures(d: Derived, port: str, band_hz: float | None) -> list[ReportFigure]:
    win = time_window(d.t)
    f, px = welch(d.x, d.dt)
    _, pe = welch(d.eps, d.dt)
    sym, unit, scale = pd.excitation_label(port)
    return [
        render_figure(pd.plot_time_window(d.t, d.x, d.eps, port, win), "time",
                      "Excitation and innovation",
                      f"{win[1] - win[0]:.3g} s window from the middle of the record."),
        render_figure(pd.plot_spectra(f, [(f"excitation {sym}", px * scale ** 2)],
                                      f"PSD ({unit}²/Hz)", f"Excitation {sym} spectrum",
                                      band_hz),
                      "spec_x", "Excitation spectrum", "Welch estimate, per channel."),
        render_figure(pd.plot_spectra(f, [("innovation ε", pe * 1e12)], "PSD (µm²/Hz)",
                                      "Innovation ε spectrum", band_hz),
                      "spec_eps", "Innovation spectrum", "Welch estimate, per channel."),
    ]


def _labels(run: RunData) -> dict[str, str]:
    lab = {n: f"{n} (θ)" for n in run.names}
    lab.update({"log10 sigma_noise": "log10 σ_noise (m)", "log10 sigma_r1": "log10 σ_r1 (m)",
                "log10 sigma_r2": "log10 σ_r2 (A)"})
    return lab


def _centred(draws: dict[str, np.ndarray], labels: dict[str, str], truth: dict[str, float],
             point: dict[str, float]):
    """Draws of variables whose spread is tiny against their value, shown as deviations
    from a round reference (labels say so), so that axes need no offset notation."""
    d, lab, tr, pt = dict(draws), dict(labels), dict(truth), dict(point)
    for n, v in draws.items():
        c, sd = float(np.mean(v)), float(np.std(v))
        if not 0 < sd < 1e-3 * abs(c):
            continue
        ref = round(c, max(0, int(-np.floor(np.log10(sd))) - 1))
        d[n] = v - ref
        lab[n] = f"{labels.get(n, n)} − {ref:g}" if ref > 0 else \
            f"{labels.get(n, n)} + {-ref:g}"
        for m in (tr, pt):
            if n in m:
                m[n] = m[n] - ref
    return d, lab, tr, pt


def _prior_grid(text: str):
    pr = parse_prior(text)
    if pr.kind == "uniform":
        pad = 0.05 * (pr.b - pr.a)
        grid = np.linspace(pr.a - pad, pr.b + pad, 600)
    elif pr.kind == "normal":
        lo, hi = pr.support
        grid = np.linspace(max(pr.a - 4 * pr.b, lo), min(pr.a + 4 * pr.b, hi), 600)
    else:
        grid = np.linspace(1e-9, float(np.exp(pr.a + 4 * pr.b)), 600)
    return grid, lambda x: np.exp(pr.logpdf(x))


def identification_figures(run: RunData, d: Derived | None,
                           rng: np.random.Generator) -> list[ReportFigure]:
    """Trace, rank, pair, prior against posterior and posterior predictive."""
    if run.posterior is None:
        return []
    names = run.names
    draws = {n: run.draws(n) for n in names}
    noise = {f"log10 {s}": np.log10(run.draws(s)) for s in ("sigma_noise", "sigma_r1",
                                                              "sigma_r2")
             if s in run.posterior["posterior"]}
    lab, truth = _labels(run), run.true_theta()
    point = {n: float(run.summary.map[n]) for n in names}
    both, lab_c, truth_c, point_c = _centred({**draws, **noise}, lab, truth, point)
    pair_vars = dict(list(both.items())[:6])
    priors = {n: _prior_grid(run.summary.priors[n]) for n in names
              if n in run.summary.priors}
    figs = [
        render_figure(pp.plot_trace(both, lab_c, truth_c, point_c), "trace", "Trace plots",
                      "Every walker against draw index, with the marginal histogram. The "
                      "walkers are drawn as chains; they should overlap and show no trend."),
        render_figure(pp.plot_rank(both, lab_c), "rank", "Rank plots",
                      "Histograms of the ranks of each walker's draws among all draws; a "
                      "well-mixed sampler gives flat histograms inside the grey band."),
        render_figure(pp.plot_pair(pair_vars, lab_c, truth_c, point_c, rng=rng), "pair",
                      "Pair plot", "Joint draws of the parameters and noise intensities "
                      "(log10); correlations show what the data cannot separate."),
    ]
    if priors:
        figs.append(render_figure(
            pp.plot_prior_posterior({n: draws[n] for n in priors}, priors, lab, truth),
            "prior_post", "Prior against posterior",
            "Densities scaled to unit peak; how much the data narrowed each prior."))
    if d is not None:
        flat = np.stack([draws[n].ravel() for n in names], axis=1)
        pick = rng.choice(flat.shape[0], size=min(6, flat.shape[0]), replace=False)
        preds = [d.forward.simulate(flat[i]) for i in pick]
        f, pe = welch(d.eps, d.dt)
        curves = [("data ε", pe * 1e12)]
        curves += [("S(θ) x, posterior draws", welch(p, d.dt)[1] * 1e12) for p in preds]
        curves.append(("residual ε − S(θ̂) x", welch(d.residual, d.dt)[1] * 1e12))
        band = float(np.max(run.posterior["constant_data"]["band_freq_hz"].values)) \
            if "band_freq_hz" in run.posterior["constant_data"] else None
        figs += [
            _predictive_frf(d, flat[rng.choice(flat.shape[0], min(40, flat.shape[0]),
                                               replace=False)], band),
            render_figure(pd.plot_spectra(f, curves, "PSD (µm²/Hz)",
                                          "Posterior predictive spectra", band, styles={
                                              "data ε": {"color": "k", "lw": 0.9,
                                                         "zorder": 3},
                                              "S(θ) x, posterior draws": {"lw": 3.0,
                                                                          "alpha": 0.35},
                                              "residual ε − S(θ̂) x": {
                                                  "color": "#2a9d48", "lw": 1.1, "ls": "--",
                                                  "zorder": 4}}),
                          "ppc_spec", "Posterior predictive spectra",
                          "Where the residual lies below the data, θ explains ε."),
        ]
    return figs


def _predictive_frf(d: Derived, theta: np.ndarray, band: float | None) -> ReportFigure:
    """eps per unit x, measured (x as instrument) against S(theta) of posterior draws."""
    from bayes_amb.control.discrete import ss_freqresp
    from bayes_amb.engineering import joint_io_frf
    from bayes_amb.plots import engineering as pe

    n = d.x.shape[0]
    nps = int(np.clip(2 ** int(np.floor(np.log2(max(n // 8, 64)))), 64, 4096))
    est = joint_io_frf([(d.x, d.x, d.eps)], d.dt, nps)
    z = np.exp(2j * np.pi * est.freq_hz * d.dt)
    A, B, C = d.forward.excitation_system(theta)
    resp = np.stack([np.abs(np.diagonal(ss_freqresp(A[i], B[i], C[i], None, z), axis1=1,
                                        axis2=2)) for i in range(theta.shape[0])])
    meas = np.abs(np.diagonal(est.G, axis1=1, axis2=2))
    return render_figure(
        pe.plot_predictive_frf(est.freq_hz, meas, est.coherence, resp, band), "ppc_frf",
        "Posterior predictive: excitation to innovation",
        f"|ε/x| per channel: measured from the recording ({est.n_segments} segments, x as "
        f"instrument) against S(θ) for {theta.shape[0]} posterior draws; dotted: the upper "
        "edge of the band the likelihood uses. Where the coherence is high the measured "
        "curve is data; the model must follow it there.")


def validation_figure(tests: ResidualTests, port: str, dt: float) -> ReportFigure:
    return render_figure(
        pd.plot_correlations(tests.lags_auto, tests.acf, tests.bound, tests.lags_cross,
                             tests.ccf, tests.bound_cross, port, dt),
        "correlations", "Residual tests",
        "Left: whiteness. The residual is expected to be coloured when noise or r1/r2 act "
        "(they reach ε through the loop, eq. 14), which the likelihood models. Right: the "
        "residual must not correlate with the excitation if the model is right.")


def discrepancy_figures(diag: Diagnosis, residuals: Any,
                        truth: dict[str, float]) -> list[ReportFigure]:
    """Figures of diagnosis.json and residuals.nc (when present)."""
    figs = []
    mm = diag.mismatch
    if residuals is not None:
        figs.append(render_figure(
            pdisc.plot_location(residuals, diag), "disc_location", "Where the model fails",
            "Nominal fit: coherence of the residual with the excitation per band (the part "
            "the excitation explains; circles: significant) and residual power over the "
            "fitted noise floor. Shaded: the located bands."))
        figs.append(render_figure(
            pdisc.plot_residual_spectra(residuals, mm.bands_hz), "disc_spectra",
            "Residual spectra before and after",
            "Welch spectra of ε and of the residual ε − ε̂ of the nominal model and of the "
            "model with the named physics."))
    if diag.explanations:
        figs.append(render_figure(
            pdisc.plot_improvement(diag), "disc_gain", "Where the named physics helps",
            "Log-likelihood gain of the chosen model over the nominal one per frequency "
            "band; shaded: the bands holding 80 % of the gain."))
    if diag.candidates:
        figs.append(render_figure(
            pdisc.plot_candidates(diag), "disc_candidates", "Evidence per candidate",
            "Bars: screening gain; diamonds: log Bayes factor of the candidates fitted "
            "fully (values at or below 0.01 drawn at 0.01); dashed: acceptance threshold. "
            f"Per round the candidates fitted fully and the best of the others, "
            f"{pdisc.CANDIDATES_SHOWN} in all (every candidate: the table above)."))
    if diag.parameters_before:
        figs.append(render_figure(
            pdisc.plot_parameters(diag, truth), "disc_params",
            "Stiffness and damping before and after",
            "Mean and 90 % HDI with the nominal model and with the named physics; black: "
            "the true value when the recording is simulated."))
    return figs
