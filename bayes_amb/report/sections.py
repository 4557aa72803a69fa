"""The report's sections: text, tables and figures (assembled by
:func:`bayes_amb.report.render.build_sections`).

A section appears only when its inputs are present (the recording for the model,
controller, data and validation sections; posterior.nc for the sampler diagnostics;
diagnosis.json for the discrepancy, built in discrepancy.py; --study folders for the
studies).
"""

from __future__ import annotations

import json
import math
import platform
import shlex
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bayes_amb import __version__
from bayes_amb.report import derived as dv
from bayes_amb.report import figures as fg
from bayes_amb.report.collect import RunData
from bayes_amb.rig import CHANNELS
from bayes_amb.rotor import bending_frequencies_hz, unstable_poles
from bayes_amb.uncertainty import get_spec

SECTION_TITLES = {"summary": "Summary", "engineering": "Engineering answers",
                  "model": "Rig and model", "controller": "Controller",
                  "data": "Data", "identification": "Identification",
                  "validation": "Validation", "discrepancy": "Model discrepancy",
                  "studies": "Studies", "provenance": "How this was made"}
"""Section ids and headers, in reading order."""


@dataclass
class Table:
    """A table: caption, header and rows of already formatted strings."""

    caption: str
    header: list[str]
    rows: list[list[str]]
    note: str = ""
    mono: tuple[int, ...] = ()
    """Columns shown in a monospace font (checksums)."""
    compact: bool = False
    """A small table that may sit beside the next one."""
    wrap: tuple[int, ...] = ()
    """Columns whose cells may break across lines (others stay on one line)."""


@dataclass
class Section:
    id: str
    title: str
    paragraphs: list[str] = field(default_factory=list)
    bullets: list[str] = field(default_factory=list)
    tables: list[Table] = field(default_factory=list)
    figures: list[fg.ReportFigure] = field(default_factory=list)
    pre: str | None = None


@dataclass(frozen=True)
class ReportOptions:
    """sensitivity_points: frequencies of the full-plant sensitivity; campbell_speeds:
    speeds of the Campbell diagram; seed: which posterior draws the figures show;
    engineering_draws: posterior draws the engineering answers are propagated through."""

    sensitivity_points: int = 300
    campbell_speeds: int = 13
    seed: int = 0
    engineering_draws: int = 60


def g(v: Any, digits: int = 4) -> str:
    """A number in ``digits`` significant figures, without an exponent between 1e-3 and
    1e7; '–' for missing values.

    Examples
    --------
    >>> g(-300812.4), g(0.0123456), g(2.5e-7), g(None)
    ('-300800', '0.01235', '2.5e-07', '–')
    """
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    if not isinstance(v, (int, float, np.floating)) or isinstance(v, bool):
        return str(v)
    if v != 0 and 1e-3 <= abs(v) < 1e7:
        e = int(np.floor(np.log10(abs(v))))
        r = float(f"{v:.{digits}g}")                      # round to the digits first
        return f"{r:.{max(0, digits - 1 - e)}f}"
    return f"{v:.{digits}g}"


def gsd(v: Any, sd: Any) -> str:
    """A value to the precision its standard deviation supports (2 significant figures of
    the sd, at least 4 of the value)."""
    if v is None or sd is None or not (math.isfinite(v) and math.isfinite(sd)) or sd <= 0:
        return g(v)
    digits = int(np.floor(np.log10(abs(v)))) - int(np.floor(np.log10(sd))) + 2 \
        if v != 0 else 2
    n = int(np.clip(digits, 4, 12))
    return f"{v:#.{n}g}".rstrip(".") if 1e-4 <= abs(v) < 10 ** n else g(v, n)


def display_path(path: Any, start: Any = None) -> str:
    """A path as the report prints it: never absolute. Relative to ``start`` (default: the
    working directory) when that needs no more than one '..', else the file name.

    Examples
    --------
    >>> display_path("/data/demo/rec.csv", "/data/demo/run"), display_path("/a/b/rec.csv", "/x/y")
    ('../rec.csv', 'rec.csv')
    """
    import os

    p = str(path)
    if not os.path.isabs(p):
        return p
    try:
        rel = os.path.relpath(p, start or os.getcwd())
    except ValueError:
        return os.path.basename(p)
    return rel if rel.count("..") <= 1 else os.path.basename(p)


def display_argv(argv: list[str]) -> str:
    """The command line with every absolute path shown by :func:`display_path`."""
    return shlex.join([display_path(a) if a.startswith("/") else a for a in argv])


def _section(key: str, **kw: Any) -> Section:
    return Section(key, SECTION_TITLES[key], **kw)


# --------------------------------------------------------------------- sections
def model_section(run: RunData, d: dv.Derived, opts: ReportOptions) -> Section:
    fm, red, rig = d.full, d.forward.reduced, run.recording.rig
    poles = unstable_poles(fm)
    bend = bending_frequencies_hz(fm, 6)
    rows = [[f"{p.real:.2f}", f"{p.imag:+.2f}", f"{abs(p) / (2 * np.pi):.1f}"] for p in poles]
    red_rows = [[f"{p.real:.2f}", f"{p.imag:+.2f}", f"{abs(p) / (2 * np.pi):.1f}"]
                for p in red.poles]
    return _section("model", paragraphs=[
        f"Rig '{rig.name}' ({rig.description}) at the recording's speed of "
        f"{fm.speed_rpm:.0f} rpm: {rig.n_nodes} FE nodes, {fm.n_states} states; AMB "
        f"{rig.magnet_text()}. These figures are derived from the rig "
        "embedded in the recording; they are model properties, not estimates.",
        f"Open-loop flexible modes: {', '.join(f'{f:.0f}' for f in bend)} Hz. The AMB "
        f"negative stiffness puts {len(poles)} poles in the right half-plane (Table below): "
        "the rotor is unstable without control. The reduced model keeps the "
        f"{red.n_states} suspended rigid-body states (pseudo-modal reduction, eqs. "
        "18-45)."],
        tables=[Table(f"Open-loop poles in the right half-plane ({len(poles)})",
                      ["Re (rad/s)", "Im (rad/s)", "|λ|/2π (Hz)"], rows, compact=True),
                Table("Poles of the reduced model", ["Re (rad/s)", "Im (rad/s)",
                                                     "|λ|/2π (Hz)"], red_rows, compact=True)],
        figures=fg.model_figures(run, d, opts.campbell_speeds))


def controller_section(run: RunData, d: dv.Derived, opts: ReportOptions
                       ) -> tuple[Section, dict[str, Any]]:
    c = run.recording.controller
    cd = dv.controller_data(run, d, opts.sensitivity_points)
    nom, ide = cd["sens"]
    rows = [[ch, f"{nom.peak_db[ch]:.2f}", f"{ide.peak_db[ch]:.2f}"] for ch in CHANNELS]
    rows.append(["ISO 14839-3 zone", nom.zone, ide.zone])
    rho_s = float(np.max(np.abs(cd["s"].poles)))
    method = str(c.design.get("method", "not stated in the controller file"))
    sec = _section("controller", paragraphs=[
        f"Controller from the recording: kind '{c.kind}', {c.n_states} states, dt = "
        f"{c.dt:g} s. Design: {method}.",
        f"G(θ) at the posterior mean has {int(np.sum(cd['g'][1].poles.real > 0))} poles in "
        f"the right half-plane; S(θ) at the posterior mean has spectral radius {rho_s:.4f} "
        "(stable below 1)."],
        tables=[Table("Peak output sensitivity per axis (dB), full FE plant with the "
                      "recorded controller", ["axis", "nominal plant", "identified plant"],
                      rows, "ISO 14839-3 zones on the peak |S|: A < 9.5 dB, B < 12 dB, "
                      "C < 14 dB, D above. The identified plant is the full plant with the "
                      "posterior-mean θ.")],
        figures=fg.controller_figures(cd, c.dt))
    return sec, cd


def data_section(run: RunData, d: dv.Derived) -> tuple[Section, list[dict[str, float]]]:
    rec = run.recording
    port = d.forward.port
    band = run.band_hz()
    snr = dv.snr_table(d, band)
    from bayes_amb.engineering import response_snr_db

    rsnr = response_snr_db(rec, dict(zip(run.names, (float(v) for v in d.theta),
                                         strict=True)))
    for row, v in zip(snr, rsnr, strict=True):
        row["response_snr_db"] = float(v)
    sym, unit, scale = fg.pd.excitation_label(port)
    rows = [[ch, g(s["x_rms"] * scale), f"{s['response_snr_db']:.1f}", g(1e6 * s["eps_rms"]),
             g(1e6 * s["signal_rms"]), g(1e6 * s["residual_rms"]), f"{s['snr_db']:.1f}",
             f"{s['snr_band_db']:.1f}"]
            for ch, s in zip(CHANNELS, snr, strict=True)]
    band_col = f"S(θ̂)x / residual to {band:.0f} Hz (dB)" if band else \
        "S(θ̂)x / residual in band (dB)"
    paras = [f"Recording {display_path(rec.source, run.run_dir)}: {rec.n_samples} samples "
             f"at dt = {rec.dt:g} s "
             f"({rec.n_samples * rec.dt:g} s), {rec.speed_rpm:.0f} rpm, excitation '{port}' "
             f"({rec.meta.get('excitation', {}).get('injected_at', {}).get(port, '?')})."]
    if rec.notes:
        paras.append(f"Notes in the recording: {rec.notes}")
    bullets = []
    if run.truth:
        t = run.truth
        effects = ", ".join(
            str(e.get("effect", e.get("name", "?"))) + " (" + ", ".join(
                f"{k} {v}" for k, v in e.items() if k not in ("effect", "name")) + ")"
            for e in t.get("effects", []) if isinstance(e, dict)) or "none"
        bullets = [f"Simulated data. The truth (known only because the data are simulated; "
                   f"identification never read it): plant '{t.get('plant')}', parameters "
                   f"{t.get('params')}, hidden effects: {effects}; sensor noise "
                   f"{g(t.get('noise_rms'))} m, r1 {g(t.get('r1_rms'))} m, r2 "
                   f"{g(t.get('r2_rms'))} A RMS; seed {t.get('seed')}."]
    sec = _section("data", paragraphs=paras, bullets=bullets, tables=[Table(
        "Signal and noise per channel", ["channel", f"{sym} RMS ({unit})",
                                         "response SNR (dB)", "ε RMS (µm)",
                                         "S(θ̂)x RMS (µm)", "residual RMS (µm)",
                                         "S(θ̂)x / residual (dB)", band_col], rows,
        "Response SNR: power of the part of the displacement y that the excitation drives "
        "through the identified closed loop (full plant, posterior mean) against the rest "
        "(noise, disturbances, unmodelled response); the SNR a test is planned with. "
        "S(θ̂)x / residual: how far θ moves the innovation ε against what θ does not "
        "explain (small by construction: S(θ) is zero at the nominal model); the last "
        "column counts only the frequencies the likelihood uses.", wrap=(2, 6, 7))],
        figures=fg.data_figures(d, port, band))
    return sec, snr


def identification_section(run: RunData, d: dv.Derived | None, opts: ReportOptions
                           ) -> Section:
    s = run.summary
    truth = run.true_theta()
    est, conv = [], []
    for n in run.names:
        p, sc = s.parameters[n], run.physical_scale(n)
        lo, hi = p.hdi90
        plo, phi = p.physical_hdi90
        sd, psd = p.sd, p.physical_sd
        u = "\u00a0" + p.unit.replace("/", "/\u2060")   # no line break inside "3 N/m"
        true = f"{truth[n]:g} ({truth[n] * sc:g}{u})" if n in truth else "–"
        est.append([n, gsd(s.map[n], sd), f"{gsd(p.mean, sd)} ± {g(sd, 2)}",
                    f"[{gsd(lo, sd)}, {gsd(hi, sd)}]",
                    f"{gsd(p.physical_mean, psd)}{u}",
                    f"[{gsd(plo, psd)}, {gsd(phi, psd)}]{u}", true])
        conv.append([n, g(p.r_hat), g(p.ess_bulk, 3), g(p.ess_tail, 3), g(p.tau, 3)])
    meanings = "; ".join(f"{n}: {get_spec(n).meaning}" for n in run.names)
    tables = [Table("Estimates: θ is dimensionless, the physical value beside it (90 % HDI: "
                    "highest-density interval)", ["parameter", "MAP", "mean ± sd",
                                                  "90 % HDI", "physical mean",
                                                  "physical 90 % HDI", "true (simulated)"],
                    est, meanings, wrap=(2, 3, 5, 6))]
    if s.sampler is not None:
        sm = s.sampler
        tables.append(Table(
            f"Convergence ({sm.walkers} walkers, {sm.steps} steps, burn-in "
            f"{sm.burn}, thin {sm.thin}, {g(sm.n_tau, 3)} autocorrelation times, "
            f"acceptance {g(sm.acceptance_mean, 2)})",
            ["parameter", "R-hat", "ESS bulk", "ESS tail", "τ (steps)"], conv,
            "Converged means R-hat ≤ 1.01, bulk ESS ≥ 400 and at least 50 τ."))
    noise = s.noise
    post = (noise.posterior or {}) if noise is not None else {}
    nrows = [[k, g(v.value, 3), g(post[k].mean if k in post else None, 3),
              f"[{g(post[k].q05 if k in post else None, 3)}, "
              f"{g(post[k].q95 if k in post else None, 3)}]",
              v.unit] for k, v in (noise.map if noise is not None else {}).items()]
    if nrows:
        tables.append(Table("Noise intensities", ["source", "MAP", "posterior mean",
                                                  "5–95 %", "unit"], nrows, noise.model))
    ident = s.identifiability or {}
    corr = ident.get("correlation", {})
    if len(corr.get("names", [])) > 1:
        tables.append(Table("Posterior correlation", ["", *corr["names"]],
                            [[a, *(f"{v:+.2f}" for v in row)]
                             for a, row in zip(corr["names"], corr["matrix"], strict=True)]))
    verdict = "converged" if s.converged else "NOT converged"
    paras = [f"Inference: {s.inference} ({verdict}; {g(s.wall_s, 3)} s). "
             f"MAP by {s.map_method or '?'}. Priors: "
             + ", ".join(f"{k} ~ {v}" for k, v in s.priors.items()) + "."]
    if run.posterior is None:
        paras.append("No posterior.nc in the run folder (MAP-only run): the intervals are "
                     "the Laplace approximation, and no sampler diagnostics are shown.")
    elif s.parameters_white_noise is not None:
        paras.append("The residual's noise is not white as the likelihood models it (see "
                     "Summary): the intervals in the tables are the sandwich's, while the "
                     "figures show the draws as sampled under the white model.")
    return _section("identification", paragraphs=paras, bullets=list(ident.get("notes", [])),
                    tables=tables, figures=fg.identification_figures(
                        run, d, np.random.default_rng(opts.seed)))


def validation_section(d: dv.Derived, snr: list[dict[str, float]]
                       ) -> tuple[Section, dv.ResidualTests]:
    rt = dv.residual_tests(d)
    err = rt.model_error
    roundoff = min(x["snr_db"] for x in snr) > 120
    rows = [[ch, f"{100 * rt.frac_auto[j]:.0f} %", f"{100 * rt.frac_cross[j]:.0f} %",
             f"{rt.z_cross[j]:.1f}",
             "n/a (round-off)" if roundoff else "yes" if err[j] else "no"]
            for j, ch in enumerate(CHANNELS)]
    paras = [f"Residual ε − S(θ̂) x at the posterior mean, {d.residual.shape[0]} samples. "
             f"Whiteness bounds ±{rt.bound:.3g} (99 %, white data). Cross-correlation bounds "
             "allow for the colour of residual and excitation (Bartlett). Clean data exceed "
             f"them at about 1 % of lags: at most {100 * rt.limit_cross:.0f} % of the "
             f"cross-correlation lags, with a largest |r|/sd below {rt.z_limit:.1f} (99 %)."]
    if roundoff:
        paras.append("The residual is at the level of floating-point round-off (SNR above "
                     "120 dB): S(θ̂) x reproduces the data exactly and these tests carry no "
                     "information.")
    return _section("validation", paragraphs=paras, tables=[Table(
        "Residual tests per channel", [
            "channel", "autocorrelation: lags outside", "cross-correlation with x (all 4 "
            "channels): lags outside", "largest |r|/sd", "model error indicated"], rows)],
        figures=[fg.validation_figure(rt, d.forward.port, d.dt)]), rt


def studies_section(run: RunData) -> Section:
    sec = _section("studies")
    for st in run.studies:
        sec.paragraphs.append(f"Study '{st.name}' ({st.path.name}): {st.description} "
                              f"{st.n_rows if st.n_rows is not None else '?'} replicates, "
                              f"seed {st.seed}.")
        sec.bullets += [f"{st.name}: {c}" for c in st.conclusions]
        if st.summary_rows and "case" in st.summary_rows[0]:
            sec.tables.append(Table(
                f"Study {st.name}: result table", [
                    "case", "recordings", "hidden effect(s) named", "nothing else named",
                    "wrong names", "parameter in 90 % HDI", "located right",
                    "concealment (max)"],
                [[r["case"], r["n"], r["right_named"] if r["case"] != "none" else "–",
                  r["exact"], r["false_names"],
                  f"{r['covered']}/{r['checked']}" if r["case"] != "none" else "–",
                  r["located"] if r["case"] != "none" else "–",
                  g(float(r["concealment_max"]), 2)] for r in st.summary_rows],
                "Concealment: RMS of the hidden effect's contribution to the displacements "
                "over the RMS of the noise contribution, worst channel (below 1: hidden in "
                "the noise)."))
        sec.figures += [fg.file_figure(p, f"study_{st.name}_{p.stem}",
                                       f"Study {st.name}: {p.stem.replace('_', ' ')}",
                                       f"From {p.name} of the study folder.")
                        for p in st.figures]
    return sec


def provenance_section(run: RunData, argv: list[str]) -> Section:
    import arviz
    import matplotlib

    s = run.summary
    prov = (run.recording.meta.get("provenance") if run.recording is not None else None) or {}
    bullets = [f"Report command: {display_argv(argv) if argv else '(Python API)'}",
               f"bayes-amb {__version__} (identification ran with "
               f"{s.package_version}); Python {platform.python_version()}, "
               f"numpy {np.__version__}, arviz {arviz.__version__}, matplotlib "
               f"{matplotlib.__version__}",
               f"Identification seed {s.seed}; MAP {s.map_method or '?'}; "
               f"recording provenance: {json.dumps(prov) if prov else 'none given'}",
               *(f"Study {st.name}: seed {st.seed}" for st in run.studies),
               "Figures of posterior draws use a fixed seed, so the same inputs give the "
               "same report."]
    rows = [[f.role, display_path(f.path, run.run_dir), f"{f.size:,}", f.sha256]
            for f in run.inputs]
    return _section("provenance", bullets=bullets, tables=[Table(
        "Input files (SHA-256); paths relative to the run folder "
        f"'{run.run_dir.name}'", ["role", "path", "bytes", "SHA-256"], rows,
        mono=(3,), wrap=(0, 1, 3))])
