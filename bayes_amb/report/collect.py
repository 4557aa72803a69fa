"""Read what a run left behind into one small data object, :class:`RunData`.

Inputs (only ``summary.json`` is required)::

    RUN_DIR/summary.json      identification summary (bayes-amb-summary/1)
    RUN_DIR/posterior.nc      ArviZ DataTree (absent after --map-only)
    RUN_DIR/diagnosis.json    model-discrepancy diagnosis (optional)
    NAME.csv + NAME.json      the recording named in summary.json (or --recording)
    STUDY_DIR/study.json      studies given with --study (conclusions, figures/*.png)

Nothing estimated is recomputed here; the recording's ``truth`` (simulated data) is read
with :func:`bayes_amb.io.recording.load_truth` only to show "true value when known".
"""

from __future__ import annotations

import csv
import hashlib
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bayes_amb.errors import BayesAmbError, ResultError
from bayes_amb.io.recording import Recording, load_recording, load_truth, recording_paths
from bayes_amb.results.diagnosis import Diagnosis
from bayes_amb.results.files import read_posterior, read_result
from bayes_amb.results.identification import Identification
from bayes_amb.results.study import FORMAT as STUDY_FORMAT
from bayes_amb.results.study import Study
from bayes_amb.uncertainty import get_spec

__all__ = ["InputFile", "ReportError", "RunData", "StudyData", "collect_run", "sha256_file"]

log = logging.getLogger(__name__)

SUMMARY_FORMAT = "bayes-amb-summary/1"
_SUMMARY_KEYS = ("parameters_estimated", "parameters", "map", "recording")


class ReportError(BayesAmbError):
    """A run folder, recording or study folder cannot be turned into a report."""


@dataclass(frozen=True)
class InputFile:
    """One file the report was made from: role, path, size in bytes and SHA-256 (hex)."""

    role: str
    path: Path
    size: int
    sha256: str


@dataclass(frozen=True)
class StudyData:
    """A finished study folder: its name, description, conclusions and figure files."""

    path: Path
    name: str
    description: str
    conclusions: tuple[str, ...]
    figures: tuple[Path, ...]
    seed: int | None
    n_rows: int | None
    summary_rows: tuple[dict[str, str], ...] = ()


@dataclass
class RunData:
    """Everything a report shows about one identification run.

    ``summary`` is summary.json as an :class:`Identification`; ``posterior`` the DataTree
    of posterior.nc (None after a MAP-only run); ``recording`` the loaded recording (None
    when it cannot be found, with the reason in ``recording_note``); ``truth`` the
    simulated truth (None for real data); ``diagnosis`` diagnosis.json as a
    :class:`Diagnosis` (None when absent) and ``diagnosis_residuals`` its residuals.nc.
    """

    run_dir: Path
    summary: Identification
    posterior: Any = None
    recording: Recording | None = None
    recording_path: Path | None = None
    recording_note: str = ""
    truth: dict[str, Any] | None = None
    diagnosis: Diagnosis | None = None
    diagnosis_residuals: Any = None
    studies: tuple[StudyData, ...] = ()
    inputs: list[InputFile] = field(default_factory=list)

    @property
    def names(self) -> tuple[str, ...]:
        """Estimated parameter names, in order."""
        return tuple(self.summary.parameters_estimated)

    def draws(self, name: str) -> NDArray:
        """Posterior draws of one variable, shape (n_walkers, n_draws)."""
        if self.posterior is None:
            raise ReportError(f"run {self.run_dir}: no posterior.nc (MAP-only run)")
        return np.asarray(self.posterior["posterior"][name].values, dtype=float)

    def theta_point(self) -> NDArray:
        """Posterior mean of theta (the MAP after a MAP-only run), shape (p,)."""
        src = self.summary.parameters
        return np.array([float(src[n].mean) for n in self.names])

    def theta_map(self) -> NDArray:
        return np.array([float(self.summary.map[n]) for n in self.names])

    def physical_scale(self, name: str) -> float:
        """Physical value per unit theta (N/m or N s/m) of a parameter."""
        if self.recording is not None:
            return get_spec(name).physical_scale(self.recording.rig)
        p = self.summary.parameters[name]
        return p.physical_mean / p.mean if p.mean else float("nan")

    def band_hz(self) -> float | None:
        """Upper edge of the frequency band the likelihood used (Hz), when recorded."""
        if self.posterior is None or "band_freq_hz" not in self.posterior["constant_data"]:
            return None
        return float(np.max(self.posterior["constant_data"]["band_freq_hz"].values))

    def prior_bound_hits(self, tol: float = 0.01) -> list[tuple[str, float]]:
        """(name, bound) where a 90 % HDI reaches a uniform prior's bound (within ``tol``
        of the prior's width)."""
        out = []
        for n in self.names:
            text = str(self.summary.priors.get(n, ""))
            if not (text.startswith("uniform(") and text.endswith(")")):
                continue
            a, b = (float(v) for v in text[8:-1].split(","))
            lo, hi = self.summary.parameters[n].hdi90
            out += [(n, bound) for bound, end in ((a, lo), (b, hi))
                    if abs(end - bound) <= tol * (b - a)]
        return out

    def true_theta(self) -> dict[str, float]:
        """True theta of the estimated parameters (simulated data), else {}.

        A parameter the simulation left at its nominal value is true at 0.
        """
        if not self.truth:
            return {}
        params = self.truth.get("params") or {}
        return {n: float(params.get(n, 0.0)) for n in self.names}


def sha256_file(path: Path, chunk: int = 1 << 20) -> str:
    """SHA-256 of a file, hex."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


def _input(role: str, path: Path) -> InputFile:
    return InputFile(role, path, path.stat().st_size, sha256_file(path))


def _read_json(path: Path, what: str) -> dict[str, Any]:
    """results.files.read_result, its error a ReportError led by ``what``."""
    try:
        return read_result(path)
    except ResultError as exc:
        raise ReportError(f"{what} {exc}") from None


def _read_summary(run_dir: Path) -> Identification:
    s = _read_json(run_dir / "summary.json", "run summary")
    where = f"run summary {run_dir / 'summary.json'}"
    if s.get("format", SUMMARY_FORMAT) != SUMMARY_FORMAT:
        raise ReportError(f"{where}: field format: expected {SUMMARY_FORMAT!r}, got "
                          f"{s.get('format')!r}")
    for key in _SUMMARY_KEYS:
        if key not in s:
            raise ReportError(f"{where}: field {key}: missing")
    names = s["parameters_estimated"]
    if not isinstance(names, list) or not names:
        raise ReportError(f"{where}: field parameters_estimated: expected a non-empty list")
    for n in names:
        if n not in s["parameters"] or n not in s["map"]:
            raise ReportError(f"{where}: field parameters.{n}: missing")
    return Identification.from_dict(s, where)


def _read_posterior(path: Path) -> Any:
    """results.files.read_posterior, its error a ReportError."""
    try:
        return read_posterior(path)
    except ResultError as exc:
        raise ReportError(f"posterior {exc}") from None


def _recording_candidates(summary_path: str, run_dir: Path) -> list[Path]:
    p = Path(summary_path)
    if p.is_absolute():
        return [p]
    return [p, run_dir / p, run_dir / p.name, run_dir.parent / p.name]


def _find_recording(run: RunData, explicit: str | Path | None) -> None:
    if explicit is not None:
        path = Path(explicit)
        run.recording = load_recording(path)      # a bad --recording is the user's error
    else:
        named = str(run.summary.recording)
        found = [c for c in _recording_candidates(named, run.run_dir)
                 if c.suffix.lower() == ".csv" and c.is_file()]
        if not found:
            run.recording_note = (f"the recording {Path(named).name!r} named in summary.json "
                                  "was not "
                                  "found (give it with --recording); sections that need the "
                                  "rig, controller or signals are left out")
            log.warning("%s", run.recording_note)
            return
        path = found[0]
        run.recording = load_recording(path)
    run.recording_path = Path(run.recording.source)
    _check_recording_matches(run)
    csv_path, json_path = recording_paths(run.recording_path)
    run.inputs += [_input("recording (CSV)", csv_path), _input("recording (JSON)", json_path)]
    run.truth = load_truth(run.recording_path)


def _check_recording_matches(run: RunData) -> None:
    """The recording must be the one the run was identified on (same excitation record)."""
    if run.posterior is None or run.recording is None:
        return
    x = np.asarray(run.posterior["constant_data"]["x"].values)
    port = run.summary.excitation_port or next(iter(run.recording.excitation))
    rx = np.asarray(run.recording.excitation.get(port, np.empty((0, 4))))
    if rx.shape != x.shape or not np.allclose(rx, x, rtol=1e-12, atol=0.0):
        raise ReportError(f"recording {run.recording.source}: field excitation: it is not the "
                          f"recording run {run.run_dir} was identified on (excitation "
                          f"{rx.shape} differs from the posterior's {x.shape})")


def _read_study(path: Path) -> StudyData:
    if not path.is_dir():
        raise ReportError(f"study folder {path}: not found")
    m = _read_json(path / "study.json", "study manifest")
    if "conclusions" not in m:
        raise ReportError(f"study manifest {path / 'study.json'}: field conclusions: missing "
                          "(the study has not finished)")
    st = Study.from_dict({"format": STUDY_FORMAT, "package_version": "?", "study": {},
                          "cells": [], "seeds": {}, **Study.upgrade(m)},
                         f"study manifest {path / 'study.json'}")
    rows: tuple[dict[str, str], ...] = ()
    if (path / "summary.csv").is_file():
        with (path / "summary.csv").open(newline="", encoding="utf-8") as fh:
            rows = tuple(csv.DictReader(fh))
    figs = tuple(sorted((path / "figures").glob("*.png"))) if (path / "figures").is_dir() \
        else ()
    return StudyData(path=path, name=st.name or path.name, description=st.description,
                     conclusions=tuple(str(c) for c in st.conclusions), figures=figs,
                     seed=st.seed, n_rows=st.n_rows, summary_rows=rows)


def collect_run(run_dir: str | Path, recording: str | Path | None = None,
                studies: tuple[str | Path, ...] | list[str | Path] = ()) -> RunData:
    """Read a run folder (and its recording, diagnosis and studies) into a :class:`RunData`.

    Raises ReportError (one line naming the file and field) when RUN_DIR or summary.json is
    missing or malformed, when posterior.nc cannot be read, or when a given recording or
    study folder is unusable. A recording that is merely not found (the path in
    summary.json is relative to where identify ran) is noted, not an error.
    """
    d = Path(run_dir)
    if not d.is_dir():
        raise ReportError(f"run folder {d}: not found (expected a folder with summary.json)")
    run = RunData(run_dir=d, summary=_read_summary(d))
    run.inputs.append(_input("identification summary", d / "summary.json"))
    if (d / "posterior.nc").is_file():
        run.posterior = _read_posterior(d / "posterior.nc")
        run.inputs.append(_input("posterior (ArviZ NetCDF)", d / "posterior.nc"))
    if (d / "diagnosis.json").is_file():
        run.diagnosis = Diagnosis.from_dict(_read_json(d / "diagnosis.json", "diagnosis"),
                                            f"diagnosis {d / 'diagnosis.json'}")
        run.inputs.append(_input("model-discrepancy diagnosis", d / "diagnosis.json"))
        if (d / "residuals.nc").is_file():
            import xarray as xr
            try:
                run.diagnosis_residuals = xr.load_dataset(d / "residuals.nc")
            except (OSError, ValueError) as exc:
                raise ReportError(f"diagnosis residuals {d / 'residuals.nc'}: cannot be read "
                                  f"({exc})") from None
            run.inputs.append(_input("diagnosis residuals (NetCDF)", d / "residuals.nc"))
    _find_recording(run, recording)
    run.studies = tuple(_read_study(Path(s)) for s in studies)
    for st in run.studies:
        run.inputs.append(_input(f"study {st.name} (manifest)", st.path / "study.json"))
        if (st.path / "summary.csv").is_file():
            run.inputs.append(_input(f"study {st.name} (summary)", st.path / "summary.csv"))
    return run
