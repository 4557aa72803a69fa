"""The report's sections: text, tables and figures (assembled by
:func:`bayes_amb.report.render.build_sections`).

A section appears only when its inputs are present (the recording for the model,
controller, data and validation sections; posterior.nc for the sampler diagnostics;
diagnosis.json for the discrepancy; --study folders for the studies).
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
        f"ki = {rig.ki:g} N/A, ks = {rig.ks:g} N/m. These figures are derived from the rig "
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
        p, sc = s["parameters"][n], run.physical_scale(n)
        lo, hi = p["hdi90"]
        plo, phi = p["physical_hdi90"]
        sd, psd = p.get("sd"), p.get("physical_sd")
        u = "\u00a0" + p["unit"].replace("/", "/\u2060")   # no line break inside "3 N/m"
        true = f"{truth[n]:g} ({truth[n] * sc:g}{u})" if n in truth else "–"
        est.append([n, gsd(s["map"][n], sd), f"{gsd(p['mean'], sd)} ± {g(sd, 2)}",
                    f"[{gsd(lo, sd)}, {gsd(hi, sd)}]",
                    f"{gsd(p['physical_mean'], psd)}{u}",
                    f"[{gsd(plo, psd)}, {gsd(phi, psd)}]{u}", true])
        conv.append([n, g(p.get("r_hat")), g(p.get("ess_bulk"), 3), g(p.get("ess_tail"), 3),
                     g(p.get("tau"), 3)])
    meanings = "; ".join(f"{n}: {get_spec(n).meaning}" for n in run.names)
    tables = [Table("Estimates: θ is dimensionless, the physical value beside it (90 % HDI: "
                    "highest-density interval)", ["parameter", "MAP", "mean ± sd",
                                                  "90 % HDI", "physical mean",
                                                  "physical 90 % HDI", "true (simulated)"],
                    est, meanings, wrap=(2, 3, 5, 6))]
    if s.get("sampler"):
        sm = s["sampler"]
        tables.append(Table(
            f"Convergence ({sm['walkers']} walkers, {sm['steps']} steps, burn-in "
            f"{sm['burn']}, thin {sm['thin']}, {g(sm['n_tau'], 3)} autocorrelation times, "
            f"acceptance {g(sm['acceptance_mean'], 2)})",
            ["parameter", "R-hat", "ESS bulk", "ESS tail", "τ (steps)"], conv,
            "Converged means R-hat ≤ 1.01, bulk ESS ≥ 400 and at least 50 τ."))
    noise = s.get("noise", {})
    post = noise.get("posterior", {})
    nrows = [[k, g(v["value"], 3), g(post.get(k, {}).get("mean"), 3),
              f"[{g(post.get(k, {}).get('q05'), 3)}, {g(post.get(k, {}).get('q95'), 3)}]",
              v["unit"]] for k, v in noise.get("map", {}).items()]
    if nrows:
        tables.append(Table("Noise intensities", ["source", "MAP", "posterior mean",
                                                  "5–95 %", "unit"], nrows,
                            noise.get("model", "")))
    ident = s.get("identifiability", {})
    corr = ident.get("correlation", {})
    if len(corr.get("names", [])) > 1:
        tables.append(Table("Posterior correlation", ["", *corr["names"]],
                            [[a, *(f"{v:+.2f}" for v in row)]
                             for a, row in zip(corr["names"], corr["matrix"], strict=True)]))
    verdict = "converged" if s.get("converged") else "NOT converged"
    paras = [f"Inference: {s.get('inference', '?')} ({verdict}; {g(s.get('wall_s'), 3)} s). "
             f"MAP by {s.get('map_method', '?')}. Priors: "
             + ", ".join(f"{k} ~ {v}" for k, v in s.get("priors", {}).items()) + "."]
    if run.posterior is None:
        paras.append("No posterior.nc in the run folder (MAP-only run): the intervals are "
                     "the Laplace approximation, and no sampler diagnostics are shown.")
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


def _hdi(v: dict[str, Any]) -> str:
    return f"[{g(v['hdi90'][0])}, {g(v['hdi90'][1])}]"


def _correction(plane: dict[str, Any]) -> str:
    """The correction of one balancing plane: m r (kg m) at the opposite angle, or none."""
    if not plane.get("nonzero"):
        return "none (not told from 0)"
    return f"{g(plane['u_kgm']['map'])} kg m at {(plane['phase_deg']['map'] + 180) % 360:.0f}°"


def discrepancy_section(run: RunData) -> Section:
    """The diagnosis: verdict, where it failed, the named physics, the fit before/after."""
    dg = run.diagnosis or {}
    mm = dg.get("mismatch", {})
    truth = run.true_theta()
    tables = []
    rows = [["detected", "yes" if mm.get("detected") else "no"],
            ["channels", ", ".join(mm.get("channels", [])) or "–"],
            ["bands", ", ".join(f"{g(a)}–{g(b)} Hz" for a, b in mm.get("bands_hz", [])) or "–"],
            ["time window", "–" if not mm.get("time_s") else
             f"{g(mm['time_s'][0])}–{g(mm['time_s'][1])} s"],
            ["evidence", str(mm.get("evidence", {}).get("strength", "–"))]]
    tables.append(Table("Where the nominal model fails", ["", ""], rows, compact=True))
    found = ([(f, f["test"]) for f in mm.get("findings", [])]
             + [(f, f"{f['test']} (noise, not a mismatch)")
                for f in mm.get("noise_findings", [])])
    if found:
        tables.append(Table("Location tests (Holm-adjusted, family-wise 1 %)",
                            ["test", "band (Hz)", "channels", "adjusted p"],
                            [[name, "–" if "band_hz" not in f else
                              f"{g(f['band_hz'][0])}–{g(f['band_hz'][1])}",
                              ", ".join(f.get("channels", [])), g(f["p_adjusted"], 2)]
                             for f, name in found[:20]]))
    if dg.get("explanations"):
        tables.append(Table("Named physics (posterior of its parameters)",
                            ["effect", "location", "parameter", "mean", "90 % HDI", "unit",
                             "log BF", "cannot be told from"],
                            [[_effect_title(e["effect"]), e["location"], k, g(v["mean"]),
                              _hdi(v), v["unit"], g(e["score"], 3),
                              "; ".join(e.get("equivalence_class", [])[1:]) or "–"]
                             for e in dg["explanations"] for k, v in e["params"].items()],
                            "Effect names and units from the physics library "
                            "(`bayes-amb library`); the last column is the effect's "
                            "equivalence class: explanations with the same u → y map.",
                            wrap=(0, 1, 4, 7)))
    bal = (dg.get("balancing") or {}).get("planes", [])
    if bal:
        tables.append(Table("Unbalance as two correction planes", [
            "plane", "z (m)", "u (kg m)", "90 % HDI", "phase (deg)", "90 % HDI",
            "correction m r"],
            [[pl["plane"], g(pl["z_m"], 3), g(pl["u_kgm"]["map"]), _hdi(pl["u_kgm"]),
              g(pl["phase_deg"]["map"], 3), _hdi(pl["phase_deg"]), _correction(pl)]
             for pl in bal],
            "The unbalance named, refitted as unbalance in two planes: the pair with the "
            "same 1x response at the sensors (the influence-coefficient answer). A "
            "correction mass m at radius r removes it when m r = u, placed at the phase + "
            "180° (phase at t = 0 of the record). 'none' where 0 lies inside the plane's "
            "90 % credible ellipse (the interval of u, a magnitude, never holds 0)."))
    fit = dg.get("fit", {})
    if fit:
        tables.append(Table("Fit before and after", [
            "channel", "NRMSE before", "NRMSE after", "whiteness p before",
            "whiteness p after"],
            [[c, g(fit["before"]["nrmse"][c]), g(fit["after"]["nrmse"][c]),
              g(fit["before"]["whiteness_p"][c], 2), g(fit["after"]["whiteness_p"][c], 2)]
             for c in fit["before"]["nrmse"]],
            "NRMSE = RMS(ε − ε̂)/RMS(ε); whiteness: Ljung–Box (20 lags) on the residual "
            "whitened by each model's fitted noise spectrum."))
    pb, pa = dg.get("parameters_before", {}), dg.get("parameters_after", {})
    if pb:
        tables.append(Table("Stiffness and damping before and after", [
            "parameter", "before: mean", "before: 90 % HDI", "after: mean", "after: 90 % HDI",
            "true"],
            [[n, g(pb[n]["mean"]) + (" (prior bound)" if pb[n].get("at_prior_bound") else ""),
              _hdi(pb[n]), g(pa[n]["mean"])
              + (" (prior bound)" if pa[n].get("at_prior_bound") else ""), _hdi(pa[n]),
              g(truth.get(n)) if n in truth else "–"] for n in pb],
            "A MAP on a prior bound means the data pushed the parameter against its range: "
            "with the nominal model it often absorbs the missing physics."))
    cands = dg.get("candidates", [])
    greedy = [c for c in cands if c["round"] != "revisit"]
    if greedy:
        tables.append(_candidate_table(greedy))
    revisited = [c for c in cands if c["round"] == "revisit"]
    if revisited:
        tables.append(Table("Earlier choices revisited", [
            "choice", "alternative", "log BF of the choice", "log BF of the alternative"],
            [[c["instead_of"], f"{c['effect']}@{c['location']}",
              g(c.get("chosen_log_bayes_factor"), 5), g(c["log_bayes_factor"], 5)]
             for c in revisited],
            "Each earlier choice and the other candidates its round fitted fully, refitted "
            "with the later effects held in the model; a larger log Bayes factor replaces "
            "the choice."))
    paras = [str(dg.get("summary", ""))]
    if dg.get("criterion"):
        paras.append(f"Criterion: {dg['criterion']}. Inference: {dg.get('inference', '?')}.")
    return _section("discrepancy", paragraphs=paras, tables=tables,
                    figures=fg.discrepancy_figures(dg, run.diagnosis_residuals, truth))


def _candidate_table(cands: list[dict[str, Any]]) -> Table:
    """Every candidate tried, one row per effect and location (in the order of first
    trial) and two columns per round: screening gain and log Bayes factor ("–": not
    fitted fully; blank: not tried in that round, e.g. after it was accepted)."""
    rounds = sorted({int(c["round"]) for c in cands})
    keys: dict[tuple[str, str], dict[int, dict[str, Any]]] = {}
    for c in cands:
        keys.setdefault((c["effect"], c["location"]), {})[int(c["round"])] = c
    header = ["effect", "location"]
    for r in rounds:
        header += [f"round {r}: gain (nats)", f"round {r}: log BF"]
    rows = []
    for (effect, loc), by_round in keys.items():
        row = [effect, loc]
        for r in rounds:
            c = by_round.get(r)
            row += ["", ""] if c is None else [
                g(c["screen_gain"], 3)
                + {"pruned": " (predicted)", "outranked": " (predicted)",
                   "family": " (scan)"}.get(c.get("screen"), ""),
                g(c["log_bayes_factor"], 3)]
        rows.append(row)
    return Table("Every candidate tried", header, rows,
                 "Gain: the screening fit of the candidate's own parameters (its fingerprint "
                 "against the residual), in nats; the best are fitted fully and scored by "
                 "their log Bayes factor (–: not fitted fully). Blank: not tried in that "
                 "round. 'predicted': the linearised screen put the candidate well below the "
                 "bar or below the best of the round, and it was not fitted. 'scan': a "
                 "location of a node scan, its screen projected from one linearisation of "
                 "the whole scan.")


def _effect_title(name: str) -> str:
    """'actuator_lag (actuator lag)' from the registry; the bare name if it is unknown."""
    from bayes_amb.discrepancy.library.registry import NOMINAL_FAMILY, REGISTRY
    e = REGISTRY.get(name) or NOMINAL_FAMILY.get(name)
    return f"{name} ({e.title})" if e is not None else name


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
               f"{s.get('package_version', '?')}); Python {platform.python_version()}, "
               f"numpy {np.__version__}, arviz {arviz.__version__}, matplotlib "
               f"{matplotlib.__version__}",
               f"Identification seed {s.get('seed', '?')}; MAP {s.get('map_method', '?')}; "
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
