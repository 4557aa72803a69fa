"""Assemble and render a report: the sections of :mod:`bayes_amb.report.sections` in
reading order behind an executive summary; one Jinja2 template for HTML (self-contained,
figures as base64 PNG) and PDF (WeasyPrint, figures as SVG), with a matplotlib PdfPages
fallback when WeasyPrint is unavailable.

    run = collect_run("runs/paper")
    result = write_report(run, "reports/paper")      # report.html and report.pdf
"""

from __future__ import annotations

import logging
import math
import sys
import textwrap
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from bayes_amb import __version__
from bayes_amb.control.robustness import iso14839_zone
from bayes_amb.discrepancy.story import closest_clause, closest_unnamed
from bayes_amb.io.atomic import atomic_path, write_text_atomic
from bayes_amb.report import sections as sc
from bayes_amb.report.collect import ReportError, RunData
from bayes_amb.report.derived import derive
from bayes_amb.report.discrepancy import discrepancy_section
from bayes_amb.report.sections import SECTION_TITLES, ReportOptions, Section, g, gsd
from bayes_amb.results.diagnosis import Coefficient, Diagnosis
from bayes_amb.results.identification import Posterior
from bayes_amb.rig import CHANNELS
from bayes_amb.threads import limited_threads
from bayes_amb.uncertainty import get_spec

__all__ = ["PDF_BACKENDS", "ReportResult", "build_sections", "render_html", "summary_section",
           "write_pdf", "write_report"]

log = logging.getLogger(__name__)

PDF_BACKENDS = ("auto", "weasyprint", "matplotlib")


@dataclass
class ReportResult:
    """Where the report went, which PDF backend made it, and what it holds."""

    html: Path
    pdf: Path | None
    pdf_backend: str | None
    sections: list[str]
    n_figures: int
    wall_s: float
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"html": str(self.html), "pdf": None if self.pdf is None else str(self.pdf),
                "pdf_backend": self.pdf_backend, "sections": self.sections,
                "n_figures": self.n_figures, "wall_s": self.wall_s, "notes": self.notes}


def _environment():
    import jinja2

    return jinja2.Environment(
        loader=jinja2.PackageLoader("bayes_amb.report", "templates"),
        autoescape=True, trim_blocks=True, lstrip_blocks=True,
        undefined=jinja2.StrictUndefined)


def render_html(sections: list[Section], meta: dict[str, Any], pdf: bool = False) -> str:
    """The report as one HTML string (``pdf``: the paginated variant with SVG figures)."""
    return _environment().get_template("report.html.j2").render(
        sections=sections, meta=meta, pdf=pdf)


def write_page(sections: list[Section], title: str, run_dir: str | Path,
               out_dir: str | Path | None, name: str, pdf_backend: str | None = None
               ) -> Path:
    """Write one HTML page of ``sections`` to OUT/name (OUT defaults to the run folder),
    titled ``title`` with the run folder and the time it was made; returns its path. With
    ``pdf_backend`` (see :func:`write_pdf`) the same page as a PDF beside it (NAME.pdf)."""
    now = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    meta = {"title": title, "subtitle": f"Run folder {Path(run_dir).name}; made {now} by "
                                        f"bayes-amb {__version__}", "notes": []}
    out = Path(out_dir or run_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / name
    write_text_atomic(path, render_html(sections, meta))
    if pdf_backend is not None:
        write_pdf(sections, meta, path.with_suffix(".pdf"), pdf_backend)
    return path


class _QuietFonts(logging.Filter):
    """Drop WeasyPrint's advice to install HarfBuzz-Subset (fonts are embedded anyway)."""

    def filter(self, record: logging.LogRecord) -> bool:
        return "HarfBuzz" not in record.getMessage()


def _weasyprint_pdf(html: str, path: Path) -> None:
    import weasyprint

    wlog = logging.getLogger("weasyprint")
    quiet = _QuietFonts()
    wlog.addFilter(quiet)
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=".*HarfBuzz", category=DeprecationWarning)
            doc = weasyprint.HTML(string=html, base_url=None)
            with atomic_path(path) as tmp:
                doc.write_pdf(str(tmp))
    finally:
        wlog.removeFilter(quiet)


def _wrap(text: str, width: int = 95) -> list[str]:
    return textwrap.wrap(text, width) or [""]


def _text_lines(section: Section) -> list[str]:
    lines = [section.title.upper(), ""]
    for p in section.paragraphs:
        lines += [*_wrap(p), ""]
    for b in section.bullets:
        lines += ["- " + s if i == 0 else "  " + s for i, s in enumerate(_wrap(b, 92))]
    for t in section.tables:
        lines += ["", *_wrap(t.caption)]
        cols = [t.header, *t.rows]
        widths = [max(len(str(r[k])) for r in cols) for k in range(len(t.header))]
        for r in cols:
            lines.append("  ".join(str(v).ljust(w) for v, w in zip(r, widths, strict=True)))
        if t.note:
            lines += _wrap(t.note)
    for f in section.figures:
        lines += ["", *_wrap(f"Figure (next pages): {f.title}. {f.caption}")]
    if section.pre:
        lines += ["", *section.pre.splitlines()]
    return lines


def _matplotlib_pdf(sections: list[Section], meta: dict[str, Any], path: Path) -> None:
    """Fallback PDF: text pages (monospace) and one page per figure, via PdfPages."""
    from matplotlib.backends.backend_pdf import PdfPages
    from matplotlib.figure import Figure

    def text_page(pdf, lines: list[str]) -> None:
        per_page = 62
        for i in range(0, max(len(lines), 1), per_page):
            fig = Figure(figsize=(8.27, 11.69))
            fig.text(0.06, 0.96, "\n".join(lines[i:i + per_page]), family="monospace",
                     fontsize=7.0, va="top")
            pdf.savefig(fig)

    with atomic_path(path) as tmp, PdfPages(tmp) as pdf:
        head = [meta["title"], meta["subtitle"], "", "Contents:"]
        head += [f"  {i}. {s.title}" for i, s in enumerate(sections, 1)]
        text_page(pdf, head)
        for s in sections:
            text_page(pdf, _text_lines(s))
            for f in s.figures:
                if f.fig is not None:
                    pdf.savefig(f.fig, bbox_inches="tight")
                else:
                    import io

                    import matplotlib.image as mpimg
                    img = mpimg.imread(io.BytesIO(f.png), format="png")
                    fig = Figure(figsize=(8.27, 11.69))
                    ax = fig.add_axes((0.05, 0.1, 0.9, 0.8))
                    ax.imshow(img)
                    ax.set_axis_off()
                    ax.set_title(f"{s.title}: {f.title}", fontsize=9)
                    pdf.savefig(fig)


def write_pdf(sections: list[Section], meta: dict[str, Any], path: Path,
              backend: str = "auto") -> str:
    """Write the PDF with WeasyPrint (``auto`` falls back to matplotlib when WeasyPrint or
    its system libraries cannot be loaded); returns the backend used."""
    if backend not in PDF_BACKENDS:
        raise ReportError(f"option --pdf-backend: expected one of {PDF_BACKENDS}, got "
                          f"{backend!r}")
    if backend in ("auto", "weasyprint"):
        try:
            with warnings.catch_warnings():
                warnings.filterwarnings("ignore", message=".*HarfBuzz",
                                        category=DeprecationWarning)
                import weasyprint  # noqa: F401
        except (ImportError, OSError) as exc:
            if backend == "weasyprint":
                raise ReportError(f"option --pdf-backend: WeasyPrint is unavailable ({exc})"
                                  ) from None
            log.warning("WeasyPrint unavailable (%s); PDF made with matplotlib instead", exc)
        else:
            _weasyprint_pdf(render_html(sections, meta, pdf=True), path)
            return "weasyprint"
    _matplotlib_pdf(sections, meta, path)
    return "matplotlib"


def _sd(v: Coefficient | Posterior) -> float:
    """A parameter's sd, or its 90 % HDI's width / 3.29 when the sd is not finite."""
    if v.sd is not None and math.isfinite(v.sd):
        return float(v.sd)
    lo, hi = v.hdi90
    return float(hi - lo) / 3.29


def _estimate(n: str, v: Coefficient | Posterior, run: RunData,
              truth: dict[str, float]) -> str:
    sd, (lo, hi) = _sd(v), v.hdi90
    spec = get_spec(n)
    sc = run.physical_scale(n)
    t = f"; true value {truth[n]:g}" if n in truth else ""
    return (f"{n} = {gsd(v.mean, sd)} (90 % HDI {gsd(lo, sd)} to {gsd(hi, sd)}), "
            f"physical {spec.physical_label} = {gsd(v.mean * sc, abs(sd * sc))}\u00a0"
            f"{spec.unit.replace('/', '/\u2060')}{t}")


def _flags(run: RunData, dg: Diagnosis, truth: dict[str, float]) -> list[str]:
    """Where the corrected (after-diagnosis) model is less consistent with other evidence
    than the nominal one: a channel it fits worse, an estimate that moves onto a prior
    bound, or (simulated data) an interval that loses the truth the nominal one held."""
    out = []
    for before, after, worse, what in (
            (dg.fit.before.nrmse, dg.fit.after.nrmse, lambda a, b: a > b * 1.001,
             "a larger NRMSE"),
            (dg.fit.before.whiteness_p, dg.fit.after.whiteness_p,
             lambda a, b: a < b and a < 0.01, "a less white residual")):
        bad = [ch for ch in after if ch in before and worse(after[ch], before[ch])]
        if bad:
            out.append(f"FLAG: the corrected model has {what} than the nominal one on "
                       f"{', '.join(bad)}.")
    pb, pa = dg.parameters_before, dg.parameters_after
    for n, a in pa.items():
        text = str(run.summary.priors.get(n, ""))
        if text.startswith("uniform(") and text.endswith(")"):
            lo_b, hi_b = (float(x) for x in text[8:-1].split(","))
            tol = 0.01 * (hi_b - lo_b)
            if any(abs(e - bd) <= tol for e in a.hdi90 for bd in (lo_b, hi_b)):
                out.append(f"FLAG: {n} after the correction presses against its prior "
                           "bound; the correction does not settle it.")
        if n in truth and n in pb:
            t, b = truth[n], pb[n]
            if not a.hdi90[0] <= t <= a.hdi90[1] and b.hdi90[0] <= t <= b.hdi90[1]:
                out.append(f"FLAG: {n}'s corrected 90 % HDI misses the true value {t:g}, "
                           "which the nominal fit's interval held.")
    for c in dg.checks:
        if not c.ok:
            out.append(f"FLAG (diagnosis check): {c.check}: {c.line}")
    return out


def _unexplained(dg: Diagnosis) -> str:
    """One clause for the diagnosis's unexplained structure, with the candidate that came
    closest to being named (story.closest_unnamed); "" when nothing is left."""
    un = dg.unexplained
    if not un.present:
        return ""
    near = closest_unnamed(dg)
    bands = un.bands_hz
    where = ", ".join(f"{g(lo)}–{g(hi)}" for lo, hi in bands[:4])
    where = (f" in {where}" + (f" and {len(bands) - 4} more bands" if len(bands) > 4 else "")
             + " Hz") if bands else ""
    channels = ", ".join(un.channels) or "?"
    return (f"structure coherent with the excitation on channel(s) {channels}{where} that "
            "no model in the library explains" + (
                "" if near is None else
                f" with the evidence to be named; the closest is {closest_clause(near)}"))


def summary_section(run: RunData, facts: dict[str, Any]) -> Section:
    """Leads with the final model: after the diagnosis when it named physics (with the
    identification's nominal fit as "before"), else the identification."""
    s, truth, dg = run.summary, run.true_theta(), run.diagnosis
    nominal_adequacy = dg.adequacy if dg is not None and dg.adequacy else s.adequacy
    adequacy = nominal_adequacy.line if nominal_adequacy is not None else None
    final = (dg.adequacy_after.line if dg is not None and dg.explanations
             and dg.adequacy_after is not None else None)
    if final:
        bullets = [f"Adequacy of the final model (after the diagnosis): {final} The nominal "
                   f"model: {adequacy}"]
    else:
        bullets = [f"Adequacy of the model: {adequacy}"] if adequacy else []
    check = s.noise.check if s.noise is not None else None
    if check is not None and check.doubted:
        bullets.append(f"Noise: {check.line}")
    if s.noise is not None and s.noise.lines_line:
        bullets.append(f"Noise: {s.noise.lines_line} (disturbances the model has no part "
                       "for; the coefficients are read from the other bins).")
    named = [e.description for e in dg.explanations] if dg is not None else []
    after = dg.parameters_after if dg is not None else {}
    if named and after:
        bullets.append("Final model: the nominal model with " + "; ".join(named)
                       + " (named by the diagnosis; see Model discrepancy).")
        for n in run.names:
            if n not in after:
                continue
            p = s.parameters[n]
            bullets.append(_estimate(n, after[n], run, truth) + ". Before (nominal model, "
                           f"identification): {gsd(p.mean, p.sd)} (90 % HDI "
                           f"{gsd(p.hdi90[0], p.sd)} to {gsd(p.hdi90[1], p.sd)}).")
            pb = dg.parameters_before.get(n)
            if pb and abs(pb.mean - p.mean) > 0.5 * max(_sd(pb), 1e-12):
                bullets.append(f"{n}: the diagnosis's own nominal fit gives "
                               f"{g(pb.mean)}, not {g(p.mean)}"
                               ": it uses every frequency up to Nyquist with an integrated "
                               "noise spectrum, the identification only the reduced "
                               "model's validity band.")
        bullets += _flags(run, dg, truth)
    else:
        bullets += [_estimate(n, s.parameters[n], run, truth) + "." for n in run.names]
        if dg is not None and dg.nonlinearity is not None:
            bullets.append(f"Model discrepancy: the loop is not linear: "
                           f"{dg.nonlinearity.title}, modelled; no linear physics is named "
                           "(see Model discrepancy).")
        elif dg is not None:
            bullets.append("Model discrepancy: " + ("a mismatch was located but no missing "
                           "physics named" if dg.mismatch.detected
                           else "no mismatch found") + " (see Model discrepancy).")
    unexplained = _unexplained(dg) if dg is not None else ""
    if unexplained:
        bullets.append("The diagnosis leaves part of the mismatch unexplained: "
                       + unexplained + " (see Model discrepancy).")
    bullets += [("Before the diagnosis, " if named and after else "")
                + f"{n}: the posterior presses against the prior bound {b:g}. The data would "
                "move it further than the prior allows, often a sign that the model misses "
                "an effect (see Validation)." for n, b in run.prior_bound_hits()]
    if s.sampler is not None:
        bullets.append("The sampler converged (R-hat ≤ 1.01, ESS ≥ 400, ≥ 50 τ)."
                       if s.converged else "The sampler did NOT converge: treat the "
                       "intervals as provisional (see Identification).")
    bullets += list((s.identifiability or {}).get("notes", []))
    if "eng" in facts:
        ld, pk = facts["eng"]["min_logdec"], facts["eng"]["worst_peak"]
        ok = "met" if ld.lo > 0.1 else "NOT met" if ld.hi <= 0.1 else "uncertain"
        bullets.append(f"Closed-loop stability at {facts['eng']['speed_rpm']:.0f} rpm: "
                       f"smallest log decrement {g(ld.value, 3)} (90 % {g(ld.lo, 3)} to "
                       f"{g(ld.hi, 3)}); API 617-style criterion log dec > 0.1: {ok}. "
                       f"Largest peak sensitivity {g(pk.value, 3)} dB (90 % {g(pk.lo, 3)} "
                       f"to {g(pk.hi, 3)} dB): ISO 14839-3 zone "
                       f"{iso14839_zone(10 ** (pk.value / 20))} (zone "
                       f"{iso14839_zone(10 ** (pk.hi / 20))} at the upper end). See "
                       "Engineering answers.")
    if "snr" in facts:
        v = [x["response_snr_db"] for x in facts["snr"] if "response_snr_db" in x]
        if v:
            bullets.append(f"Response-to-excitation SNR per channel {min(v):.1f} to "
                           f"{max(v):.1f} dB: the power of the part of y the excitation "
                           "drives through the identified loop against the rest (noise, "
                           "disturbances, unmodelled response).")
    if "rt" in facts and min(x["snr_db"] for x in facts["snr"]) <= 120:
        bad = [ch for ch, e in zip(CHANNELS, facts["rt"].model_error, strict=True) if e]
        bullets.append("The residual correlates with the excitation on " + ", ".join(bad)
                       + ": the model misses something the data show (see Validation)."
                       if bad else "The residual does not correlate with the excitation: "
                       "no sign of model error at this noise level.")
    elif "rt" in facts:
        bullets.append("S(θ̂) x reproduces the data to round-off (noise-free data).")
    if run.recording_note:
        bullets.append(f"Note: {run.recording_note}.")
    return Section("summary", SECTION_TITLES["summary"], bullets=bullets)


def build_sections(run: RunData, argv: list[str], opts: ReportOptions,
                   progress: Callable[[str], None] | None = None
                   ) -> tuple[list[Section], dict[str, Any]]:
    """All sections in reading order, and the report's metadata (title, subtitle)."""
    say = progress or (lambda _msg: None)
    facts: dict[str, Any] = {}
    body: list[Section] = []
    d = None
    if run.recording is not None:
        from bayes_amb.report.engineering import engineering_facts, engineering_section

        say("engineering answers: modes, margins, sensitivities, frequency responses")
        sec, eng, _frf = engineering_section(run, opts)
        facts["eng"] = engineering_facts(eng)
        body.append(sec)
        say("model figures")
        d = derive(run)
        body.append(sc.model_section(run, d, opts))
        say("controller: poles, zeros and sensitivities")
        sec, facts["cd"] = sc.controller_section(run, d, opts)
        body.append(sec)
        say("data")
        sec, facts["snr"] = sc.data_section(run, d)
        body.append(sec)
    say("identification figures")
    body.append(sc.identification_section(run, d, opts))
    if d is not None:
        sec, facts["rt"] = sc.validation_section(d, facts["snr"])
        body.append(sec)
    if run.diagnosis is not None:
        body.append(discrepancy_section(run))
    if run.studies:
        body.append(sc.studies_section(run))
    body.append(sc.provenance_section(run, argv))
    name = Path(str(run.summary.recording)).stem
    now = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    meta = {"title": f"Identification report: {name}",
            "subtitle": f"Run folder {run.run_dir.name}; made {now} by bayes-amb "
                        f"{__version__}",
            "notes": [run.recording_note] if run.recording_note else []}
    return [summary_section(run, facts), *body], meta


@limited_threads
def write_report(run: RunData, out_dir: str | Path, *, argv: list[str] | None = None,
                 options: ReportOptions | None = None, pdf: bool = True,
                 pdf_backend: str = "auto",
                 progress: Callable[[str], None] | None = None) -> ReportResult:
    """Build every section of ``run`` and write OUT/report.html (and OUT/report.pdf).

    ``argv`` is the command line recorded under "How this was made" (default sys.argv).
    """
    t0 = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    opts = options or ReportOptions()
    sections, meta = build_sections(run, list(sys.argv if argv is None else argv), opts,
                                    progress)
    html = render_html(sections, meta)
    write_text_atomic(out / "report.html", html)
    backend = None
    if pdf:
        if progress:
            progress("writing the PDF")
        backend = write_pdf(sections, meta, out / "report.pdf", pdf_backend)
    n_fig = sum(len(s.figures) for s in sections)
    return ReportResult(out / "report.html", out / "report.pdf" if pdf else None, backend,
                        [s.title for s in sections], n_fig, time.perf_counter() - t0,
                        meta.get("notes", []))
