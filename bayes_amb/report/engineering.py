"""The report's "Engineering answers" section: bearing coefficients, closed-loop modes,
API 617-style margins, ISO 14839-3 peak sensitivity and frequency responses, each with its
90 % interval from the posterior (:mod:`bayes_amb.engineering`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from bayes_amb.control.robustness import iso14839_zone
from bayes_amb.engineering import (
    API617_LOGDEC,
    MODE_LABELS,
    Draws,
    EngineeringResult,
    FrfResult,
    draws_from,
    frequency_responses,
    physical_quantities,
)
from bayes_amb.plots import engineering as pe
from bayes_amb.report.collect import RunData
from bayes_amb.report.figures import render_figure
from bayes_amb.report.sections import SECTION_TITLES, ReportOptions, Section, Table, g
from bayes_amb.rig import CHANNELS

__all__ = ["engineering_facts", "engineering_section"]

SIGN_CONVENTION = ("Sign convention: the bearing force on the rotor is f = ki i + ks s − c ṡ "
                   "(s the rotor displacement at the bearing). ks > 0 is the magnet's "
                   "negative stiffness (destabilising), c > 0 passive damping (stabilising).")


def _iv(q: Any, digits: int = 4) -> str:
    return f"{g(q.value, digits)} [{g(q.lo, digits)}, {g(q.hi, digits)}]"


def _verdict(q: Any, limit: float) -> str:
    if not np.isfinite(q.lo):
        return "–"
    if q.lo > limit:
        return "yes"
    if q.hi <= limit:
        return "NO"
    return "uncertain"


def _rows_modes(res: EngineeringResult) -> list[list[str]]:
    s = res.speeds_rpm[int(np.argmin(np.abs(res.speeds_rpm - res.running_speed_rpm)))]
    q = res.quantities
    rows = []
    for label in MODE_LABELS:
        f = q[f"{label}: frequency @ {s:.0f} rpm"]
        if f.n_valid == 0:
            continue
        z = q[f"{label}: damping ratio @ {s:.0f} rpm"]
        ld = q[f"{label}: log dec @ {s:.0f} rpm"]
        sm = q[f"{label}: separation margin"]
        req = q[f"{label}: required separation margin"]
        sm_ok = "yes" if sm.lo >= req.hi else "NO" if sm.hi < req.lo else "uncertain"
        rows.append([label, _iv(f), _iv(z, 3), _iv(ld, 3), _verdict(ld, API617_LOGDEC),
                     f"{g(sm.value, 3)} (≥ {g(req.hi, 3)})", sm_ok])
    return rows


def engineering_facts(res: EngineeringResult) -> dict[str, Any]:
    """The numbers the summary quotes: minimum log dec at the running speed and the worst
    axis' peak sensitivity (Quantity objects)."""
    s = res.speeds_rpm[int(np.argmin(np.abs(res.speeds_rpm - res.running_speed_rpm)))]
    peaks = [res.quantities[f"peak sensitivity {ch}"] for ch in CHANNELS]
    worst = max(peaks, key=lambda q: q.hi if np.isfinite(q.hi) else -np.inf)
    return {"min_logdec": res.quantities[f"minimum log dec @ {s:.0f} rpm"],
            "worst_peak": worst, "speed_rpm": float(s)}


def final_draws(run: RunData, n: int, seed: int) -> tuple[Any, str]:
    """The posterior the answers use, and its description: after the diagnosis when it
    named physics (normal draws from its parameters_after mean and sd, independent), else
    the identification's own draws."""
    dg = run.diagnosis
    after = dg.parameters_after if dg is not None else {}
    if dg is not None and dg.explanations and all(nm in after for nm in run.names):
        mean = np.array([float(after[nm].mean) for nm in run.names])
        sd = []
        for nm in run.names:
            v = after[nm]
            s = v.sd
            if s is None or not np.isfinite(s):
                lo, hi = v.hdi90
                s = (hi - lo) / 3.29
            sd.append(float(s))
        rng = np.random.default_rng(seed)
        th = mean + np.array(sd) * rng.standard_normal((n, len(run.names)))
        return Draws(run.names, th), ("draws of the final model after the diagnosis "
                                      "(normal, from its parameters' mean and sd)")
    lc = run.summary.laplace_cov
    src = ("posterior draws of the identification (emcee)" if run.posterior is not None
           else "draws of the Laplace approximation of summary.json ("
           + ("normal, with its correlations)" if lc is not None
              else "independent normals)"))
    return draws_from(run, n, seed), src


def engineering_section(run: RunData, opts: ReportOptions
                        ) -> tuple[Section, EngineeringResult, FrfResult]:
    """Section, and the results it shows (for the summary)."""
    rec = run.recording
    run_rpm = rec.speed_rpm
    speeds = np.array([0.8, 0.9, 1.0, 1.05]) * run_rpm if run_rpm > 0 else np.array([0.0])
    draws, source = final_draws(run, opts.engineering_draws, opts.seed)
    res = physical_quantities(draws, rec, speeds, n_draws=opts.engineering_draws)
    frf = frequency_responses(draws, rec, n_draws=min(opts.engineering_draws, 50))
    before = None
    if source.startswith("draws of the final model"):
        before = physical_quantities(draws_from(run, opts.engineering_draws, opts.seed), rec,
                                     [run_rpm], n_draws=opts.engineering_draws,
                                     model="reduced")
    q = res.quantities
    bear = []
    for ch in CHANNELS:
        k, c = q[f"bearing {ch}: ks"], q[f"bearing {ch}: c"]
        est = "estimated" if k.estimated or c.estimated else "nominal (not estimated)"
        if before is not None and (k.estimated or c.estimated):
            kb, cb = (before.quantities[f"bearing {ch}: {w}"] for w in ("ks", "c"))
            est = f"before the diagnosis: ks {_iv(kb)}, c {_iv(cb)}"
        bear.append([ch, _iv(k) if k.estimated else g(k.value),
                     _iv(c) if c.estimated else g(c.value), est])
    for key, v in q.items():
        if v.group == "bearing" and key.endswith("kxy"):
            bear.append([key.split(":")[0], "–", "–", f"kxy {_iv(v)} N/m"])
    iso = []
    for ch in CHANNELS:
        p = q[f"peak sensitivity {ch}"]
        iso.append([ch, _iv(p, 3), g(p.nominal, 3),
                    iso14839_zone(10 ** (p.value / 20)) if np.isfinite(p.value) else "–",
                    iso14839_zone(10 ** (p.hi / 20)) if np.isfinite(p.hi) else "–"])
    paras = [
        f"Each number is a function of θ, evaluated at {res.draws.theta.shape[0]} "
        f"{source}; the value is the median and the brackets the 90 % interval: the 5 % and "
        "95 % quantiles, widened to the quantity's range over the posterior's central "
        "region (within 1.645 standard deviations, Mahalanobis, of its mean), so that a "
        "quantity with a maximum or minimum near the estimate (a mode frequency on a "
        "ridge) is not cut short. The "
        "plant is the full FE model with the identified parameters, "
        "sampled at the recording's dt and closed with the controller that ran. "
        "'Nominal' is the same calculation with θ = 0 (the plant as designed). "
        + SIGN_CONVENTION,
        "Modes: continuous equivalents λ = ln(z)/dt of the closed-loop eigenvalues z "
        "(aliasing undone for modes above the Nyquist frequency); damping ratio ζ = −Re λ/|λ|; "
        "log decrement = 2πζ/√(1 − ζ²). API 617-style checks: log dec > 0.1, and a "
        "separation margin |f − f_run|/f_run at least 17 (1 − 1/(AF − 1.5)) % below and "
        "min(10 + 17 (1 − 1/(AF − 1.5)), 26) % above the running speed, AF = 1/(2ζ) (none "
        "required for AF < 2.5). 'uncertain': the 90 % interval straddles the limit.",
    ]
    named = [e.effect for e in run.diagnosis.explanations] if run.diagnosis else []
    if named:
        paras.append("The physics the diagnosis named (" + ", ".join(named) + ") is not part "
                     "of these closed-loop models: they use the identified stiffness and "
                     "damping only.")
    tables = [
        Table("Bearing stiffness ks (N/m) and damping c (N s/m) per axis, as identified",
              ["axis", "ks (N/m)", "c (N s/m)", ""], bear, compact=False, wrap=(1, 2, 3)),
        Table(f"Closed-loop modes at the running speed ({run_rpm:.0f} rpm, "
              f"{run_rpm / 60:.1f} Hz)",
              ["mode", "frequency (Hz)", "damping ratio", "log dec", "log dec > 0.1",
               "separation margin (required) %", "margin met"], _rows_modes(res),
              "Rigid-body modes (most of their kinetic energy in rigid-body motion) in "
              "order of frequency; bending 1: the closed-loop modes "
              "with most of their shape in the first bending pair (backward and forward "
              "whirl).", wrap=(1, 2, 3)),
        Table("Peak output sensitivity per axis (dB), ISO 14839-3",
              ["axis", "identified [90 %]", "nominal", "zone (median)",
               "zone (upper end)"], iso,
              "Zones: A < 9.5 dB, B < 12 dB, C < 14 dB, D above. The peak of the "
              "diagonal of (I − G K)⁻¹, the other loops closed.", compact=True),
    ]
    figs = [
        render_figure(pe.plot_modes_vs_speed(res), "eng_modes",
                      "Closed-loop modes against speed",
                      "Median and 90 % interval over posterior draws; the recorded "
                      "controller at every speed. Dotted: the recording's speed."),
        render_figure(pe.plot_sensitivity_band(res), "eng_sens",
                      "Sensitivity per axis with its posterior band",
                      "The identified plant's 90 % band against the nominal plant and the "
                      "ISO 14839-3 zone limits."),
        render_figure(pe.plot_frf(frf, "plant"), "eng_plant",
                      "Plant frequency response per bearing axis",
                      f"|G| in m/A: identified model ({frf.n_draws} draws), nominal model "
                      "and the nonparametric estimate from the recording (excitation as "
                      f"instrument: G = S_yx S_ux⁻¹, {frf.n_segments} segments), with the "
                      "coherence of each displacement with the excitation."),
        render_figure(pe.plot_frf(frf, "compliance"), "eng_compliance",
                      "Closed-loop compliance per bearing axis",
                      "Displacement per unit force at the bearing with the loop closed, "
                      "(I − G K)⁻¹ G / ki in m/N; measured: from the nonparametric G and the "
                      "recorded controller."),
    ]
    return (Section("engineering", SECTION_TITLES["engineering"], paragraphs=paras,
                    tables=tables, figures=figs), res, frf)
