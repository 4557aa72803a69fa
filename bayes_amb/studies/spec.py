"""Study definitions: a TOML file naming the rig, truth, factors, replicates and inference.

A study is a grid of simulated experiments. Example (studies/noise.toml)::

    [study]
    name = "noise"
    description = "Sensor noise from 0 to well past failure"
    seed = 1
    replicates = 10
    inference = "laplace"          # "posterior" (emcee) or "laplace" (MAP + Laplace)

    [truth]
    plant = "reduced"              # "full" or "reduced"
    params = { k_By = 0.5 }        # true theta values
    draw_from_prior = false        # true: draw theta from the estimation priors (SBC)
    effects = []                   # e.g. ["actuator_lag:bandwidth_hz=800"]

    [simulation]                   # defaults of bayes_amb.simulate.SimulationConfig
    dt = 1e-3
    duration = 0.5
    noise_rms = 0.0

    [estimate]
    params = ["k_By"]
    priors = { k_By = "uniform(-0.8, 0.8)" }
    steps = 1500                   # optional: fixed emcee steps (default: run to 50 tau)
    walkers = 24                   # optional

    [factors]                      # each key a list; the cells are their product
    noise_rms = [0.0, 1e-8, 1e-7, 1e-6]

Factor names: any [simulation] key (noise_rms, r1_rms, r2_rms, r1_band_hz, r2_band_hz,
excitation, amplitude, duration, dt, speed_rpm, truth), ``true.NAME`` for a true parameter
value, and ``estimate`` (a comma-separated parameter list). Studies with inference =
"diagnose" (the concealed-effect benchmark, see bayes_amb.studies.concealed) take a factor
``case``: "none", an effect name, or a pair "a+b".
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.priors import parse_prior
from bayes_amb.simulate import SimulationConfig, parse_effect
from bayes_amb.studies.concealed import case_effects
from bayes_amb.tomlfile import read_toml
from bayes_amb.uncertainty import get_spec, parse_param_list


class StudyError(BayesAmbError):
    """A study file is missing, malformed or inconsistent."""


SIM_KEYS = ("truth", "excitation", "amplitude", "noise_rms", "r1_rms", "r2_rms", "r1_band_hz",
            "r2_band_hz", "duration", "dt", "speed_rpm")
_TOP = {"study", "rig", "truth", "simulation", "estimate", "factors"}


@dataclass(frozen=True)
class StudySpec:
    """A resolved study. ``cells`` is the list of factor combinations (dicts)."""

    name: str
    description: str
    seed: int
    replicates: int
    inference: str
    rig: str
    plant: str
    true_params: dict[str, float]
    draw_from_prior: bool
    effects: tuple[str, ...]
    simulation: dict[str, Any]
    estimate: tuple[str, ...]
    priors: dict[str, str]
    steps: int | None
    walkers: int | None
    factors: dict[str, list[Any]]
    source: str = "<dict>"
    cells: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"study": {"name": self.name, "description": self.description, "seed": self.seed,
                          "replicates": self.replicates, "inference": self.inference},
                "rig": {"file": self.rig},
                "truth": {"plant": self.plant, "params": self.true_params,
                          "draw_from_prior": self.draw_from_prior,
                          "effects": list(self.effects)},
                "simulation": self.simulation,
                "estimate": {"params": list(self.estimate), "priors": self.priors,
                             "steps": self.steps, "walkers": self.walkers},
                "factors": self.factors}

    @property
    def n_replicates_total(self) -> int:
        return len(self.cells) * self.replicates


def _fail(src: str, fld: str, msg: str) -> StudyError:
    return StudyError(f"study file {src}: field {fld}: {msg}")


def _table(d: dict, key: str, src: str, required: bool = True) -> dict:
    if key not in d:
        if required:
            raise _fail(src, key, "missing")
        return {}
    if not isinstance(d[key], dict):
        raise _fail(src, key, f"expected a table, got {d[key]!r}")
    return d[key]


def study_from_dict(d: dict[str, Any], source: str = "<dict>") -> StudySpec:
    """Validate and resolve a study dict (the parsed TOML)."""
    extra = sorted(set(d) - _TOP)
    if extra:
        raise _fail(source, extra[0], f"unknown table (allowed: {sorted(_TOP)})")
    st = _table(d, "study", source)
    name = st.get("name", Path(source).stem)
    seed = st.get("seed", 0)
    reps = st.get("replicates", 1)
    inference = st.get("inference", "laplace")
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        raise _fail(source, "study.seed", f"expected a non-negative integer, got {seed!r}")
    if not isinstance(reps, int) or isinstance(reps, bool) or reps < 1:
        raise _fail(source, "study.replicates", f"expected a positive integer, got {reps!r}")
    if inference not in ("posterior", "laplace", "diagnose"):
        raise _fail(source, "study.inference", f"expected 'posterior', 'laplace' or "
                    f"'diagnose', got {inference!r}")
    rig = _table(d, "rig", source, required=False).get("file", "reference")
    tr = _table(d, "truth", source)
    plant = tr.get("plant", "full")
    if plant not in ("full", "reduced"):
        raise _fail(source, "truth.plant", f"expected 'full' or 'reduced', got {plant!r}")
    true_params = {}
    for k, v in tr.get("params", {}).items():
        try:
            get_spec(k)
        except BayesAmbError as exc:
            raise _fail(source, f"truth.params.{k}", str(exc)) from None
        if not isinstance(v, (int, float)) or isinstance(v, bool):
            raise _fail(source, f"truth.params.{k}", f"expected a number, got {v!r}")
        true_params[k] = float(v)
    effects = tuple(tr.get("effects", []))
    for i, e in enumerate(effects):
        try:
            parse_effect(e)
        except BayesAmbError as exc:
            raise _fail(source, f"truth.effects[{i}]", str(exc)) from None
    sim = dict(_table(d, "simulation", source, required=False))
    for k in sim:
        if k not in SIM_KEYS or k == "truth":
            raise _fail(source, f"simulation.{k}", f"unknown key (allowed: {list(SIM_KEYS[1:])})")
    es = _table(d, "estimate", source)
    try:
        estimate = parse_param_list(es.get("params", []))
    except BayesAmbError as exc:
        raise _fail(source, "estimate.params", str(exc)) from None
    priors = {}
    for k, v in es.get("priors", {}).items():
        try:
            get_spec(k)
            parse_prior(v, k)
        except BayesAmbError as exc:
            raise _fail(source, f"estimate.priors.{k}", str(exc)) from None
        priors[k] = v
    draw = bool(tr.get("draw_from_prior", False))
    if draw and set(estimate) - set(priors):
        raise _fail(source, "estimate.priors", "draw_from_prior needs a prior for every "
                    f"estimated parameter; missing {sorted(set(estimate) - set(priors))}")
    factors = _table(d, "factors", source, required=False)
    for k, v in factors.items():
        if not isinstance(v, list) or not v:
            raise _fail(source, f"factors.{k}", f"expected a non-empty list, got {v!r}")
        if k == "case":
            if inference != "diagnose":
                raise _fail(source, "factors.case", "only for inference = 'diagnose'")
            for c in v:
                try:
                    case_effects(c)
                except ValueError as exc:
                    raise _fail(source, "factors.case", str(exc)) from None
            continue
        if not (k in SIM_KEYS or k == "estimate" or (k.startswith("true.") and
                                                      _known(k[5:]))):
            raise _fail(source, f"factors.{k}", "unknown factor (simulation keys, "
                        "true.NAME, estimate, or case for diagnose studies)")
    spec = StudySpec(name=name, description=st.get("description", ""), seed=seed,
                     replicates=reps, inference=inference, rig=rig, plant=plant,
                     true_params=true_params, draw_from_prior=draw, effects=effects,
                     simulation=sim, estimate=estimate, priors=priors,
                     steps=es.get("steps"), walkers=es.get("walkers"),
                     factors={k: list(v) for k, v in factors.items()}, source=source)
    keys = list(spec.factors)
    cells = [dict(zip(keys, combo, strict=True))
             for combo in itertools.product(*spec.factors.values())]
    object.__setattr__(spec, "cells", cells or [{}])
    for i, c in enumerate(spec.cells):          # every cell must make a valid simulation
        try:
            simulation_config(spec, c, seed=0, true_params=spec.true_params).validate()
        except BayesAmbError as exc:
            raise _fail(source, f"factors (cell {i}: {c})", str(exc)) from None
    return spec


def _known(name: str) -> bool:
    try:
        get_spec(name)
        return True
    except BayesAmbError:
        return False


def load_study(path: str | Path) -> StudySpec:
    return study_from_dict(read_toml(path, "study file", StudyError), str(Path(path)))


def cell_estimate(spec: StudySpec, cell: dict[str, Any]) -> tuple[str, ...]:
    return parse_param_list(cell["estimate"]) if "estimate" in cell else spec.estimate


def simulation_config(spec: StudySpec, cell: dict[str, Any], seed: int,
                      true_params: dict[str, float]) -> SimulationConfig:
    """The SimulationConfig of one replicate."""
    kw = dict(spec.simulation)
    kw.update({k: v for k, v in cell.items() if k in SIM_KEYS})
    kw.setdefault("truth", spec.plant)
    return SimulationConfig(params=true_params,
                            effects=tuple(parse_effect(e) for e in spec.effects),
                            seed=seed, **kw)
