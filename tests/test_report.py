"""Reports (bayes_amb.report, ``bayes-amb report``).

One small run (reduced truth, k_By = 0.5, 0.3 s at 1 kHz, sensor noise 1e-8 m, 300 steps x
12 walkers) is reported once through the CLI, HTML and PDF (WeasyPrint). A copy of the run
without its recording, with a diagnosis.json and a study folder, checks that sections come
and go with their inputs, and the matplotlib PDF fallback. Input text is escaped: the
recording notes and the diagnosis carry HTML.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import itertools
import json
import re
import shutil

import numpy as np
import pytest

from bayes_amb.cli.main import main
from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.inference.identify import IdentifyOptions, identify
from bayes_amb.io.recording import load_recording, save_recording
from bayes_amb.report import SECTION_TITLES, ReportOptions, collect_run, render_html, write_pdf
from bayes_amb.report.derived import Derived, residual_tests
from bayes_amb.report.render import build_sections
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, simulate_recording
from tests.helpers import diagnosis_json

pypdf = pytest.importorskip("pypdf")
pytest.importorskip("jinja2")

NOTES = "bench test <script>alert('x')</script> & co"
OPTIONAL = ("discrepancy", "studies")


def _simulate(ctrl, rig, seed: int, duration: float = 0.3):
    cfg = SimulationConfig(truth="reduced", params={"k_By": 0.5}, dt=1e-3, duration=duration,
                           noise_rms=1e-8, seed=seed)
    return simulate_recording(rig, ctrl, cfg)


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """The run folder, its recording and the report written by the CLI (--json output)."""
    d = tmp_path_factory.mktemp("report")
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, 1e-3), rig)
    rec, truth = _simulate(ctrl, rig, seed=1)
    rec = dataclasses.replace(rec, notes=NOTES)
    csv = save_recording(d / "tiny.csv", rec, truth=truth)[0]
    other = save_recording(d / "other.csv", _simulate(ctrl, rig, seed=2, duration=0.1)[0])[0]
    result = identify(load_recording(csv), "k_By", options=IdentifyOptions(steps=300,
                                                                           walkers=12))
    run_dir = result.save(d / "run")
    return {"dir": d, "csv": csv, "other": other, "run": run_dir, "summary": result.to_dict()}


@pytest.fixture(scope="module")
def cli_report(made):
    """(exit status, --json output, report.html) of ``bayes-amb report RUN --json``; every
    matplotlib Figure the report rendered is kept in made["figures"] (key, Figure)."""
    from bayes_amb.report import engineering as rep_eng
    from bayes_amb.report import figures as rep_fig

    out = made["dir"] / "out"
    buf = io.StringIO()
    rendered = []
    original = rep_fig.render_figure

    def keep(fig, key, *args, **kwargs):
        rendered.append((key, fig))
        return original(fig, key, *args, **kwargs)

    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(buf):
        mp.setattr(rep_fig, "render_figure", keep)
        mp.setattr(rep_eng, "render_figure", keep)
        rc = main(["report", str(made["run"]), "--out", str(out), "--json"])
    made["figures"] = rendered
    return rc, json.loads(buf.getvalue()), (out / "report.html").read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def bare(made, tmp_path_factory):
    """A copy of the run where the recording cannot be found, with a diagnosis and a study."""
    d = tmp_path_factory.mktemp("bare") / "elsewhere" / "run"
    shutil.copytree(made["run"], d)
    summary = json.loads((d / "summary.json").read_text())
    summary["recording"] = "nowhere/missing.csv"
    (d / "summary.json").write_text(json.dumps(summary))
    (d / "diagnosis.json").write_text(json.dumps(diagnosis_json()))
    study = d.parent / "study"
    (study / "figures").mkdir(parents=True)
    from matplotlib.figure import Figure
    fig = Figure(figsize=(2, 2))
    fig.add_subplot().plot([0, 1], [1, 0])
    fig.savefig(study / "figures" / "noise_rms_k_By.png")
    (study / "study.json").write_text(json.dumps(
        {"study": {"name": "noise", "description": "noise study", "seed": 11},
         "n_rows": 4, "conclusions": ["k_By is identified within 5 % at every noise_rms."]}))
    run = collect_run(d, studies=[study])
    sections, meta = build_sections(run, ["bayes-amb", "report", str(d)],
                                    ReportOptions(sensitivity_points=40, campbell_speeds=3))
    return run, sections, meta, render_html(sections, meta)


def _h2(html: str) -> list[str]:
    return [re.sub(r"^\d+\.\s*", "", h) for h in re.findall(r"<h2[^>]*>(.*?)</h2>", html)]


def test_cli_json_and_files(made, cli_report):
    rc, printed, _ = cli_report
    assert rc == 0
    assert printed["pdf_backend"] == "weasyprint"
    assert printed["n_figures"] >= 15
    assert printed["sections"] == [SECTION_TITLES[k] for k in SECTION_TITLES
                                   if k not in OPTIONAL]


def test_pdf_opens_with_pages_and_figures(made, cli_report):
    reader = pypdf.PdfReader(made["dir"] / "out" / "report.pdf")
    assert len(reader.pages) > 5
    text = "".join(p.extract_text() for p in reader.pages)
    for title in (SECTION_TITLES[k] for k in SECTION_TITLES if k not in OPTIONAL):
        assert title in text
    n_images = sum(len(p.images) for p in reader.pages)     # rasterised artists
    paths = sum(p.get_contents().get_data().count(b" l\n") for p in reader.pages
                if p.get_contents() is not None)             # vector line segments
    assert n_images >= 1 and paths > 1000


def test_html_self_contained(cli_report):
    html = cli_report[2]
    for bad in ("http://", "https://", 'src="//', "<link", "@import", "url("):
        assert bad not in html, bad
    srcs = re.findall(r'src="([^"]*)"', html)
    assert len(srcs) >= 15 and all(s.startswith("data:image/png;base64,") for s in srcs)
    assert 'name="viewport"' in html and "@media (max-width" in html     # phone layout


def test_sections_present_and_absent(cli_report):
    heads = _h2(cli_report[2])
    assert heads[0] == "Contents"
    assert heads[1:] == [SECTION_TITLES[k] for k in SECTION_TITLES if k not in OPTIONAL]
    toc = re.search(r'<nav class="toc".*?</nav>', cli_report[2], re.S).group(0)
    assert all(f'href="#{k}"' in toc for k in SECTION_TITLES if k not in OPTIONAL)


def test_input_text_is_escaped(cli_report):
    html = cli_report[2]
    assert "<script" not in html
    assert "&lt;script&gt;alert(&#39;x&#39;)&lt;/script&gt; &amp; co" in html


def _half_ulp(text: str) -> float:
    """Half a unit of the last digit of a displayed decimal number ('0.50012' -> 5e-6),
    plus float round-off."""
    mant, _, exp = text.lower().partition("e")
    decimals = len(mant.partition(".")[2])
    return 0.5 * 10.0 ** (-decimals + (int(exp) if exp else 0)) * (1 + 1e-9)


def test_numbers_come_from_the_run(made, cli_report):
    """The estimate table shows summary.json's mean and HDI, and the truth (0.5)."""
    html = cli_report[2]
    p = made["summary"]["parameters"]["k_By"]
    row = re.search(r"<td[^>]*>k_By</td>(.*?)</tr>", html, re.S).group(1)
    cells = re.findall(r"<td[^>]*>(.*?)</td>", row)
    shown_mean, shown_sd = (x.strip() for x in cells[1].split("±"))
    # the mean is shown rounded to 2 significant figures of the sd: it may differ from
    # summary.json's by half a unit of its last digit, and no more
    assert abs(float(shown_mean) - p["mean"]) <= _half_ulp(shown_mean)
    assert _half_ulp(shown_mean) <= 0.05 * p["sd"]           # precision follows the sd
    assert abs(float(shown_sd) - p["sd"]) <= _half_ulp(shown_sd)
    assert abs(float(cells[0]) - made["summary"]["map"]["k_By"]) <= _half_ulp(cells[0])
    assert float(cells[-1].split(" (")[0]) == 0.5            # true value, simulated
    assert "bayes-amb report" in html and made["csv"].name in html
    from bayes_amb.report.collect import sha256_file
    assert sha256_file(made["csv"]) in html


def test_optional_sections_when_inputs_present(bare):
    run, _, _, html = bare
    heads = _h2(html)
    assert SECTION_TITLES["discrepancy"] in heads and SECTION_TITLES["studies"] in heads
    for k in ("model", "controller", "data", "validation"):   # need the recording
        assert SECTION_TITLES[k] not in heads
    assert "actuator lag &lt;b&gt;suspected&lt;/b&gt;" in html and "<b>" not in html
    assert "k_By is identified within 5 % at every noise_rms." in html
    assert "was not found (give it with --recording)" in html
    assert run.recording is None and run.diagnosis is not None


def _changed(run, **blocks):
    """The run with its diagnosis changed in the given top-level blocks (JSON form)."""
    from bayes_amb.results import Diagnosis
    return dataclasses.replace(run, diagnosis=Diagnosis.from_dict(
        {**run.diagnosis.to_dict(), **blocks}))


@pytest.mark.parametrize(("unexplained", "shown"), [
    ({"present": True, "channels": ["Ax", "By"], "bands_hz": [[2606.0, 3606.0]],
      "findings": [{"test": "coherence", "p_adjusted": 6e-4}],
      "estimate": {"band_hz": [[2.0, 36.0]], "channels": {"Ax": {"magnitude": [5.9]}}},
      "meaning": "structure coherent with the excitation"},
     "structure coherent with the excitation on channel(s) Ax, By in 2606–3606 Hz that no "
     "model in the library explains"),
    ({"present": False, "channels": [], "bands_hz": [], "findings": []}, None),
])
def test_summary_states_the_unexplained_part_in_words(bare, unexplained, shown):
    """diagnosis.json's "unexplained": the summary names channels and bands in one clause,
    never the block itself (the demo's summary printed its repr over two pages), and says
    nothing when "present" is false."""
    from bayes_amb.report.render import summary_section

    run = bare[0]
    sec = summary_section(_changed(run, unexplained=unexplained), {})
    text = " ".join(sec.bullets + sec.paragraphs)
    assert "{" not in text and "present" not in text
    if shown is None:
        assert "unexplained" not in text
    else:
        assert f"leaves part of the mismatch unexplained: {shown}" in text


def test_summary_leads_with_the_final_models_adequacy(bare):
    """After a diagnosis that named physics, the first bullet is the final model's adequacy
    (the nominal one beside it), not the nominal line's "Run `bayes-amb diagnose`": the
    engineer of issue 28 had just run it."""
    from bayes_amb.report.render import summary_section

    run = bare[0]
    changed = _changed(run,
                       adequacy={"adequate": False, "line": "model NOT adequate: nominal."},
                       adequacy_after={"adequate": True, "line": "model adequate: final."})
    sec = summary_section(changed, {})
    assert sec.bullets[0] == ("Adequacy of the final model (after the diagnosis): model "
                              "adequate: final. The nominal model: model NOT adequate: "
                              "nominal.")
    sec = summary_section(_changed(changed, explanations=[]), {})
    assert sec.bullets[0] == "Adequacy of the model: model NOT adequate: nominal."


def test_matplotlib_pdf_fallback(bare, tmp_path):
    _, sections, meta, _ = bare
    path = tmp_path / "fallback.pdf"
    assert write_pdf(sections, meta, path, backend="matplotlib") == "matplotlib"
    reader = pypdf.PdfReader(path)
    assert len(reader.pages) > 3
    assert "Identification" in "".join(p.extract_text() for p in reader.pages)


@pytest.mark.parametrize("args, message", [
    (["missing_dir"], "run folder"),
    (["{run}", "--recording", "{other}"], "not the recording"),
    (["{run}", "--study", "{run}"], "study manifest"),
])
def test_cli_user_errors_one_line(made, capsys, args, message):
    argv = ["report", *(a.format(run=made["run"], other=made["other"]) for a in args),
            "--out", str(made["dir"] / "err")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_residual_tests_detect_model_error():
    """Independent white residual: no model error indicated (per-channel false alarm
    below 1 % by construction); a residual holding 0.3 x filtered x: indicated on every
    channel (z of about 0.3 sqrt(4000) = 19 against a limit near 3.9)."""
    rng = np.random.default_rng(5)
    n = 4000
    x = np.sign(rng.standard_normal((n, 4)))
    noise = rng.standard_normal((n, 4))

    def mk(r):
        return Derived(forward=None, full=None, theta=np.zeros(1), t=np.arange(n) * 1e-3,
                       x=x, eps=r, signal=np.zeros_like(r), residual=r)

    clean = residual_tests(mk(noise))
    assert not clean.model_error.any()
    lagged = np.roll(x, 2, axis=0)
    bad = residual_tests(mk(noise + 0.3 * lagged))
    assert bad.model_error.all()
    assert np.all(bad.z_cross > 10)


def _visible_font_sizes(fig, text_width_in: float = 7.17, max_height_in: float = 8.98):
    """Font sizes (pt) of every visible, non-empty text of a Figure as printed. The report
    saves figures with bbox "tight" (pad 0.1 in), and the PDF template shrinks an image to
    the A4 text width (182 mm) and to 228 mm in height: the scale comes from the tight
    box, not from the nominal figure size (legends outside the axes widen it)."""
    fig.canvas.draw()
    box = fig.get_tightbbox(fig.canvas.get_renderer())
    w, h = box.width + 0.2, box.height + 0.2                 # inches, with the pad
    scale = min(1.0, text_width_in / w, max_height_in / h)
    sizes = []
    for t in fig.findobj(lambda a: hasattr(a, "get_fontsize") and hasattr(a, "get_text")):
        if t.get_visible() and t.get_text().strip():
            sizes.append((t.get_fontsize() * scale, t.get_text()))
    return sizes


def test_report_hygiene(made, cli_report):
    """No absolute paths, no "None", the figures all there, the engineering section in."""
    _, printed, html = cli_report
    text = re.sub(r'src="data:[^"]*"', "", html)
    assert str(made["dir"]) not in text
    assert not re.search(r"(?<![\w/])/(tmp|home|work|root|Users)/", text)
    assert not re.search(r"\bNone\b", text)
    assert printed["n_figures"] == len(re.findall(r"<figure ", html))
    assert printed["n_figures"] >= 19          # 15 before, 4 engineering figures
    for key in ("eng_modes", "eng_sens", "eng_plant", "eng_compliance"):
        assert f'id="fig-{key}"' in html
    assert SECTION_TITLES["engineering"] in printed["sections"]


def test_every_report_figure_prints_fonts_of_at_least_7pt(made, cli_report):
    """Every figure of the report (all sections the run has: engineering, model,
    controller, data, identification, validation), every visible text, as printed: >= 7
    pt (issue 17). The prior-posterior inset's ticks were 6.5 pt at 8.4 in, 5.6 pt
    printed."""
    figures = made["figures"]
    assert len(figures) == cli_report[1]["n_figures"]
    small = {key: [(round(s, 2), t[:30]) for s, t in _visible_font_sizes(fig) if s < 7.0]
             for key, fig in figures}
    assert not {k: v for k, v in small.items() if v}


def _candidates_report(n_rounds: int = 3, n_per_round: int = 37) -> dict:
    """A diagnosis with as many candidates as the demo's (37 per round, long labels)."""
    rng = np.random.default_rng(0)
    effects = [("bearing_coefficient", f"{k}_{ch}") for k in "ck" for ch in ("Ax", "Ay", "Bx")]
    effects += [(e, loc) for e in ("actuator_lag", "sensor_lag", "actuator_2nd")
                for loc in ("A", "B", "both")]
    effects += [("flexible_mode", "bending pair 1"), ("time_delay", "controller")]
    effects += [(e, ch) for e in ("sensor_gain", "actuator_gain", "runout")
                for ch in ("Ax", "Ay", "Bx", "By")]
    effects += [("unbalance", n) for n in ("D1", "D2", "n14", "n20", "n27")]
    effects = (effects * 2)[:n_per_round]
    rows = [{"round": r, "effect": e, "location": loc,
             "screen_gain": float(rng.lognormal(0, 2)) * (1 if i % 5 else -1),
             "log_bayes_factor": float(rng.normal(5, 5)) if i < 3 else None}
            for r in range(1, n_rounds + 1) for i, (e, loc) in enumerate(effects)]
    return {"candidates": rows, "criterion": "accept above log posterior odds 3",
            "explanations": [{"effect": effects[0][0], "location": effects[0][1]}]}


def _as_diagnosis(report: dict):
    """The parts of a Diagnosis plot_candidates reads, typed."""
    from types import SimpleNamespace

    from bayes_amb.results import CandidateScore
    return SimpleNamespace(
        candidates=[CandidateScore.from_dict(r) for r in report["candidates"]],
        criterion=report["criterion"],
        explanations=[SimpleNamespace(key=f"{e['effect']}@{e['location']}")
                      for e in report["explanations"]])


def test_candidate_figure_is_legible():
    """The evidence figure of a diagnosis with 37 candidates per round (the demo's): every
    text >= 7 pt as printed, no two candidate labels of a panel overlap (they were ~5 pt
    and overlapping, issue 17), the fitted candidates all shown, the legend outside the
    axes."""
    from bayes_amb.plots.discrepancy import CANDIDATES_SHOWN, plot_candidates

    report = _candidates_report()
    fig = plot_candidates(_as_diagnosis(report))
    small = [(round(size, 2), t[:30]) for size, t in _visible_font_sizes(fig) if size < 7.0]
    assert not small, small
    renderer = fig.canvas.get_renderer()
    panels = [ax for ax in fig.axes if ax.get_visible()]
    assert len(panels) == 3
    for ax in panels:
        labels = [t for t in ax.get_yticklabels() if t.get_text()]
        assert len(labels) == CANDIDATES_SHOWN
        boxes = sorted((t.get_window_extent(renderer) for t in labels), key=lambda b: b.y0)
        assert all(lo.y1 <= hi.y0 for lo, hi in itertools.pairwise(boxes)), ax.get_title()
        assert ax.get_legend() is None
        shown = {t.get_text() for t in labels}
        fitted = [r for r in report["candidates"] if r["log_bayes_factor"] is not None
                  and f"round {r['round']}" in ax.get_title()]
        assert all(f"{r['effect']}@{r['location']}" in shown or r["location"] in shown
                   for r in fitted)
    assert len(fig.legends) == 1


def test_posterior_figure_labels_do_not_collide():
    """The paper case's labels (issue 17 review of the demo PDF): in the pair plot the
    bottom row's x labels, one with its "1e-7" multiplier folded in, do not overlap each
    other; in the trace plot (rows ~1.1 in tall) the y labels do not overlap."""
    from bayes_amb.plots.posterior import plot_pair, plot_trace

    rng = np.random.default_rng(0)
    draws = {"k": 1e-7 * rng.standard_normal((24, 300)), "n": 1e-3 * rng.random((24, 300)),
             "r1": -12 + 0.3 * rng.random((24, 300)), "r2": 1e-2 * rng.random((24, 300))}
    labels = {"k": "k_By (θ) − 0.5", "n": "log10 σ_noise (m) + 12", "r1": "log10 σ_r1 (m)",
              "r2": "log10 σ_r2 (A) + 8"}
    for fig, axis in ((plot_pair(draws, labels, {"k": 0.0}, {"k": 0.0}), "x"),
                      (plot_trace(draws, labels, {"k": 0.0}, {"k": 0.0}), "y")):
        fig.canvas.draw()
        r = fig.canvas.get_renderer()
        boxes = [getattr(ax, f"{axis}axis").label.get_window_extent(r) for ax in fig.axes
                 if ax.get_visible() and getattr(ax, f"get_{axis}label")()]
        lo = (lambda b: b.x0) if axis == "x" else (lambda b: b.y0)
        hi = (lambda b: b.x1) if axis == "x" else (lambda b: b.y1)
        boxes.sort(key=lo)
        assert len(boxes) >= 4
        assert all(hi(a) <= lo(c) for a, c in itertools.pairwise(boxes)), axis
    pair = plot_pair(draws, labels, {"k": 0.0}, {"k": 0.0})
    pair.canvas.draw()
    bottom = [ax for ax in pair.axes if ax.get_visible() and ax.get_xlabel()]
    assert "(×1e−7)" in bottom[0].get_xlabel()
    assert not bottom[0].xaxis.get_offset_text().get_visible()


@pytest.mark.parametrize(("low", "high"), [(0.3, 6.0), (0.9, 1.5), (1e-3, 1e3)])
def test_predictive_frf_tick_labels_do_not_collide(low, high):
    """The paper case's |eps/x| dips and rises within about a decade on some channels
    (0.3 to 6 x 1e-3 um/A): matplotlib labelled the minor ticks of the log axis and 5 of
    the 8 labels ran into each other (issue 17 review of the demo PDF; this test's
    (0.3, 6) case on the old code). Any span: no two y tick labels of a magnitude panel
    overlap, minor or major, and each has at least two."""
    from bayes_amb.plots.engineering import plot_predictive_frf

    f = np.logspace(1.3, 2.7, 60)
    shape = np.concatenate([np.geomspace(1.0, low, 40), np.geomspace(low, high, 20)])
    fig = plot_predictive_frf(f, 1e-9 * shape[:, None] * np.ones((1, 4)), np.ones((60, 4)),
                              1e-9 * np.ones((40, 60, 4)), 400.0)
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    for ax in (a for a in fig.axes if a.get_title()):
        lo, hi = ax.get_ylim()
        labels = [t for t in [*ax.get_yticklabels(), *ax.get_yticklabels(minor=True)]
                  if t.get_text() and lo <= t.get_position()[1] <= hi]
        boxes = sorted((t.get_window_extent(r) for t in labels), key=lambda b: b.y0)
        assert all(a.y1 <= b.y0 for a, b in itertools.pairwise(boxes)), (low, high)
        assert len(boxes) >= 2, (low, high, ax.get_title())


def test_print_css_has_no_text_under_7pt():
    """The PDF style sheet (the template's print media block) sets no font size under 7 pt
    (the <pre> of the command line was 6.5 pt)."""
    from importlib.resources import files

    css = files("bayes_amb.report").joinpath("templates/report.html.j2").read_text("utf-8")
    sizes = [float(v) for v in re.findall(r"font-size:\s*([\d.]+)pt", css)]
    assert sizes and min(sizes) >= 7.0, sizes


def test_study_seed_is_read_from_the_manifest(bare, tmp_path):
    """study.json holds StudySpec.to_dict() under "study" (nested "study" table); the
    flat form of the fixture works too."""
    from bayes_amb.report.collect import _read_study

    assert "seed 11" in bare[3] and "seed None" not in bare[3]
    (tmp_path / "study.json").write_text(json.dumps(
        {"study": {"study": {"name": "noise", "description": "d", "seed": 7}},
         "conclusions": ["c"]}))
    st = _read_study(tmp_path)
    assert (st.seed, st.name) == (7, "noise")


def test_answers_cli(made, capsys, tmp_path):
    """`bayes-amb answers` prints the same numbers as the API and writes JSON; a bad
    option is one line and exit status 2."""
    from bayes_amb.engineering import physical_quantities

    out = tmp_path / "answers.json"
    argv = ["answers", str(made["run"]), "--draws", "5", "--model", "reduced",
            "--speeds", "31500", "--json", "--out", str(out)]
    assert main(argv) == 0
    printed = json.loads(capsys.readouterr().out)
    assert json.loads(out.read_text()) == printed
    run = collect_run(made["run"])
    api = physical_quantities(run, run.recording, [31500.0], n_draws=5, model="reduced")
    q = printed["quantities"]["bearing By: ks"]
    assert q["interval90"] == pytest.approx([api.quantities["bearing By: ks"].lo,
                                        api.quantities["bearing By: ks"].hi])
    assert main(["answers", str(made["run"]), "--speeds", "fast"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--speeds" in err[0]


def test_a_named_unbalance_shows_its_correction_planes(bare):
    """diagnosis.json's "balancing" becomes a table of the two correction planes; without
    it (no unbalance named) there is none."""
    from bayes_amb.report.discrepancy import discrepancy_section

    run = bare[0]
    plane = {"plane": "D2", "z_m": 0.45, "nonzero": True,
             "u_kgm": {"mean": 1.9e-6, "map": 1.92e-6, "hdi90": [1.86e-6, 1.99e-6],
                       "unit": "kg m"},
             "phase_deg": {"mean": 40.0, "map": 39.6, "hdi90": [37.7, 41.5], "unit": "deg"},
             "ab_kgm": {}}
    with_bal = _changed(run, balancing={"planes": [dict(plane, plane="D1", z_m=0.0), plane],
                                        "from": ["unbalance@n20"]})
    tables = {t.caption: t for t in discrepancy_section(with_bal).tables}
    rows = tables["Unbalance as two correction planes"].rows
    assert [r[0] for r in rows] == ["D1", "D2"] and rows[1][2] == "1.92e-06"
    assert rows[0][-1] == "1.92e-06 kg m at 220°"        # D1 here a copy, nonzero
    no = dict(plane, nonzero=False)
    tables = {t.caption: t for t in discrepancy_section(_changed(
        run, balancing={"planes": [no, plane], "from": ["unbalance@n20"]})).tables}
    assert tables["Unbalance as two correction planes"].rows[0][-1] == "none (not told from 0)"
    assert "Unbalance as two correction planes" not in {
        t.caption for t in discrepancy_section(run).tables}
