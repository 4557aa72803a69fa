"""Records over time: has a bearing coefficient changed since an earlier run? (issue 29)

An operator records the machine again after a month, or after a retrofit, and asks "has
k_By changed, by how much, and how sure are we?". Each run's posterior of a coefficient,
mean m and sd s (identify's summary.json, or a diagnosis' parameters_after), is read as
its Gaussian; the records are independent, so the change d = theta_after - theta_before
has the posterior N(m_a - m_b, s_a^2 + s_b^2), its 90 % interval the answer to "by how
much".

"How sure" is a comparison of two models: unchanged (d = 0) and changed, with d drawn
from N(0, tau^2), tau the size of change the engineer would act on (``change_scale``, in
the parameter's units; default CHANGE_SCALE). Its Bayes factor is the ratio of the two
models' predictions of the observed difference (Savage-Dickey, Gaussian case):

    BF = N(m_a - m_b; 0, s^2 + tau^2) / N(m_a - m_b; 0, s^2),   s^2 = s_a^2 + s_b^2,

and with even prior odds the probability that it changed is BF / (1 + BF). A difference
well inside the records' own noise gives a probability below 1/2 (the data favour no
change); a change far beyond it gives nearly 1. A smaller tau asks about smaller changes
and needs more precise records to answer.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from bayes_amb.errors import BayesAmbError
from bayes_amb.results.diagnosis import FORMAT as DIAGNOSIS
from bayes_amb.results.diagnosis import Coefficient, Diagnosis
from bayes_amb.results.files import read_result
from bayes_amb.results.identification import FORMAT as IDENTIFICATION
from bayes_amb.results.identification import Identification, Posterior

CHANGE_SCALE = 0.1
"""Default size of a change that matters, in the parameters' own units (0.1: 10 % of ks
for k_<axis>, 100 N s/m for c_<axis> at the reference c_ref of 1000 N s/m)."""

Z90 = 1.6449


@dataclass(frozen=True)
class Change:
    """One parameter's change between two runs: before and after (mean, sd), the change's
    mean, sd and 90 % interval (parameter units, and physical units where known), the
    scale tau asked about, the log Bayes factor of changed against unchanged and the
    probability that it changed (even prior odds)."""

    name: str
    before: tuple[float, float]
    after: tuple[float, float]
    change: float
    sd: float
    hdi90: tuple[float, float]
    physical_change: float | None
    physical_hdi90: tuple[float, float] | None
    unit: str
    change_scale: float
    log_bayes_factor: float
    p_changed: float

    def line(self) -> str:
        phys = ("" if self.physical_change is None else
                f" ({self.physical_change:+.4g} [{self.physical_hdi90[0]:+.4g}, "
                f"{self.physical_hdi90[1]:+.4g}] {self.unit})")
        return (f"{self.name} changed by {self.change:+.4f} [{self.hdi90[0]:+.4f}, "
                f"{self.hdi90[1]:+.4f}]{phys}; P(changed) {self.p_changed:.2f} (a change "
                f"of ~{self.change_scale:g} against none)")


@dataclass(frozen=True)
class Comparison:
    """The changes of every parameter both runs estimated, and where the runs came from."""

    before: str
    after: str
    changes: dict[str, Change]

    def to_dict(self) -> dict[str, Any]:
        return {"format": "bayes-amb-comparison/1", "before": self.before, "after": self.after,
                "changes": {n: asdict(c) for n, c in self.changes.items()}}

    def summary(self) -> str:
        return "\n".join(c.line() for c in self.changes.values())


def _log_normal0(x: float, var: float) -> float:
    return -0.5 * (math.log(2 * math.pi * var) + x * x / var)


def change(name: str, before: Posterior | Coefficient, after: Posterior | Coefficient,
           change_scale: float = CHANGE_SCALE) -> Change:
    """The change of one parameter from its two posteriors (mean, sd; module doc)."""
    mb, sb, ma, sa = before.mean, before.sd, after.mean, after.sd
    if not all(math.isfinite(v) for v in (mb, sb, ma, sa)) or sb <= 0 or sa <= 0:
        raise BayesAmbError(f"compare: parameter {name} has no finite positive sd in both "
                            f"runs (before sd {sb}, after sd {sa})")
    if not change_scale > 0:
        raise BayesAmbError(f"option --change-scale: value {change_scale} out of range: "
                            "must be > 0")
    d, var = ma - mb, sa * sa + sb * sb
    sd = math.sqrt(var)
    log_bf = _log_normal0(d, var + change_scale ** 2) - _log_normal0(d, var)
    p = 1.0 / (1.0 + math.exp(-log_bf)) if log_bf > -700 else 0.0
    psd = getattr(after, "physical_sd", None)          # (a diagnosis' coefficients: none)
    phys = None if psd is None or not math.isfinite(psd / sa) else psd / sa
    return Change(name=name, before=(mb, sb), after=(ma, sa), change=d, sd=sd,
                  hdi90=(d - Z90 * sd, d + Z90 * sd),
                  physical_change=None if phys is None else d * phys,
                  physical_hdi90=None if phys is None else ((d - Z90 * sd) * phys,
                                                            (d + Z90 * sd) * phys),
                  unit=after.unit, change_scale=change_scale,
                  log_bayes_factor=log_bf, p_changed=p)


def parameters_of(run: Identification | Diagnosis) -> dict[str, Posterior | Coefficient]:
    """The parameters of an identification, or a diagnosis' coefficients after it."""
    return run.parameters if isinstance(run, Identification) else run.parameters_after


def read_run(path: str | Path) -> tuple[Identification | Diagnosis, str]:
    """A run: a run directory (its summary.json, else diagnosis.json) or the JSON file
    itself, as its typed result."""
    p = Path(path)
    if p.is_dir():
        for name in ("summary.json", "diagnosis.json"):
            if (p / name).is_file():
                p = p / name
                break
        else:
            raise BayesAmbError(f"{path}: no summary.json or diagnosis.json in this directory")
    data = read_result(p)
    kind = {IDENTIFICATION: Identification, DIAGNOSIS: Diagnosis}.get(data.get("format"))
    if kind is None:
        raise BayesAmbError(f"{p}: field format: expected {IDENTIFICATION!r} or "
                            f"{DIAGNOSIS!r}, got {data.get('format')!r}")
    return kind.from_dict(data, str(p)), str(p)


def compare(before: Identification | Diagnosis, after: Identification | Diagnosis,
            change_scale: float | dict[str, float] = CHANGE_SCALE,
            sources: tuple[str, str] = ("before", "after")) -> Comparison:
    """The change of every parameter both runs estimated (module doc). ``change_scale``:
    one tau for all, or per parameter (missing ones take CHANGE_SCALE)."""
    pb, pa = parameters_of(before), parameters_of(after)
    common = [n for n in pa if n in pb]
    if not common:
        raise BayesAmbError(f"compare: {sources[0]} and {sources[1]} share no parameter "
                            f"({sorted(pb)} against {sorted(pa)})")
    tau = (change_scale if isinstance(change_scale, dict)
           else dict.fromkeys(common, change_scale))
    return Comparison(sources[0], sources[1],
                      {n: change(n, pb[n], pa[n], tau.get(n, CHANGE_SCALE)) for n in common})


def compare_runs(before: str | Path, after: str | Path,
                 change_scale: float | dict[str, float] = CHANGE_SCALE) -> Comparison:
    """:func:`compare` of two run directories or summary files."""
    b, sb = read_run(before)
    a, sa = read_run(after)
    return compare(b, a, change_scale, (sb, sa))
