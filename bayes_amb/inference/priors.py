"""Priors on the physical parameters theta and the noise intensities.

Defaults (documented stability-safe ranges; the reference controller is tested to stabilise
the full plant over |theta| <= 0.5 on each k_* and c_* parameter, and the likelihood is -inf
wherever it does not):

* k_*, c_*:  uniform(-0.8, 0.8)
* kxy_*:     uniform(-1.0, 1.0)
* noise intensities (log-uniform): sigma_noise in [1e-12, 1e-3] m, sigma_r1 in
  [1e-12, 1e-3] m, sigma_r2 in [1e-8, 10] A.

Syntax, on the command line (``--prior k_By=normal(0.3,0.2)``) or in a TOML file::

    [priors]
    k_By = "uniform(-0.9, 0.9)"
    c_By = "normal(0.0, 0.3)"
    k_Bx = "normal(0.0, 0.3, -0.95, 0.95)"   # truncated to [lo, hi] (renormalised)
    c_Ax = "lognormal(-1.0, 0.5)"   # log(theta) ~ N(mu, sigma), theta > 0

A truncated normal is what a simulation-based calibration needs when the simulator accepts
only part of the real line (|theta| <= 0.95): the datasets and the posterior then use the
same prior.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
from numba import njit
from numpy.typing import NDArray
from scipy import stats

from bayes_amb.errors import ParameterError
from bayes_amb.tomlfile import read_toml
from bayes_amb.uncertainty import get_spec

NOISE_LOG10_BOUNDS = {"sigma_noise": (-12.0, -3.0), "sigma_r1": (-12.0, -3.0),
                      "sigma_r2": (-8.0, 1.0)}


@dataclass(frozen=True)
class Prior:
    """A 1-D prior: kind in {uniform, normal, lognormal} with parameters (a, b); a normal
    may be truncated to [lo, hi]."""

    kind: str
    a: float
    b: float
    lo: float = -math.inf
    hi: float = math.inf

    def __post_init__(self) -> None:
        if self.kind not in ("uniform", "normal", "lognormal"):
            raise ParameterError(f"unknown prior kind {self.kind!r}; known: uniform, normal, "
                                 "lognormal")
        if not (math.isfinite(self.a) and math.isfinite(self.b)):
            raise ParameterError(f"prior {self}: parameters must be finite")
        if self.kind == "uniform" and not self.a < self.b:
            raise ParameterError(f"prior uniform({self.a}, {self.b}): expected lo < hi")
        if self.kind in ("normal", "lognormal") and not self.b > 0:
            raise ParameterError(f"prior {self.kind}({self.a}, {self.b}): expected sigma > 0")
        if (self.lo, self.hi) != (-math.inf, math.inf):
            if self.kind != "normal":
                raise ParameterError(f"prior {self.kind}: only a normal prior takes bounds")
            if not self.lo < self.hi or self._mass <= 1e-12:
                raise ParameterError(f"prior {self}: expected lo < hi with prior mass between")

    @property
    def _z(self) -> tuple[float, float]:
        return (self.lo - self.a) / self.b, (self.hi - self.a) / self.b

    @property
    def _mass(self) -> float:
        """Probability of the untruncated normal inside [lo, hi]."""
        za, zb = self._z
        return float(stats.norm.cdf(zb) - stats.norm.cdf(za))

    @property
    def support(self) -> tuple[float, float]:
        """(lo, hi) outside which the density is zero."""
        if self.kind == "uniform":
            return self.a, self.b
        if self.kind == "lognormal":
            return 0.0, math.inf
        return self.lo, self.hi

    @property
    def truncated(self) -> bool:
        return self.kind == "normal" and (self.lo, self.hi) != (-math.inf, math.inf)

    def logpdf(self, x: NDArray) -> NDArray:
        x = np.asarray(x, dtype=float)
        if self.kind == "uniform":
            inside = (x >= self.a) & (x <= self.b)
            return np.where(inside, -np.log(self.b - self.a), -np.inf)
        if self.kind == "normal":
            out = -0.5 * ((x - self.a) / self.b) ** 2 - np.log(self.b * np.sqrt(2 * np.pi))
            if self.truncated:
                inside = (x >= self.lo) & (x <= self.hi)
                out = np.where(inside, out - np.log(self._mass), -np.inf)
            return out
        with np.errstate(divide="ignore", invalid="ignore"):
            lx = np.log(np.where(x > 0, x, np.nan))
            out = -0.5 * ((lx - self.a) / self.b) ** 2 - lx - np.log(self.b * np.sqrt(2 * np.pi))
        return np.where(x > 0, out, -np.inf)

    def sample(self, rng: np.random.Generator, size: int) -> NDArray:
        if self.kind == "uniform":
            return rng.uniform(self.a, self.b, size)
        if self.kind == "normal" and self.truncated:
            return stats.truncnorm.rvs(*self._z, loc=self.a, scale=self.b, size=size,
                                       random_state=rng)
        if self.kind == "normal":
            return rng.normal(self.a, self.b, size)
        return np.exp(rng.normal(self.a, self.b, size))

    @property
    def mean(self) -> float:
        if self.kind == "uniform":
            return 0.5 * (self.a + self.b)
        if self.kind == "normal" and self.truncated:
            return float(stats.truncnorm.mean(*self._z, loc=self.a, scale=self.b))
        if self.kind == "normal":
            return self.a
        return math.exp(self.a + 0.5 * self.b**2)

    @property
    def sd(self) -> float:
        if self.kind == "uniform":
            return (self.b - self.a) / math.sqrt(12)
        if self.kind == "normal" and self.truncated:
            return float(stats.truncnorm.std(*self._z, loc=self.a, scale=self.b))
        if self.kind == "normal":
            return self.b
        return math.sqrt((math.exp(self.b**2) - 1) * math.exp(2 * self.a + self.b**2))

    def __str__(self) -> str:
        bounds = f", {self.lo:g}, {self.hi:g}" if self.truncated else ""
        return f"{self.kind}({self.a:g}, {self.b:g}{bounds})"


def bound_arrays(bounds: list[tuple[float | None, float | None]]
                 ) -> tuple[NDArray, NDArray]:
    """Lower and upper bounds (LogPosterior.bounds(): None where a side is open) as float
    arrays, +-inf where a side is open.

    Examples
    --------
    >>> bound_arrays([(-0.8, 0.8), (None, 2)])
    (array([-0.8, -inf]), array([0.8, 2. ]))
    """
    lo = np.array([-np.inf if b[0] is None else b[0] for b in bounds], dtype=float)
    hi = np.array([np.inf if b[1] is None else b[1] for b in bounds], dtype=float)
    return lo, hi


def default_prior(name: str) -> Prior:
    """Default prior of a parameter name (see module docstring)."""
    spec = get_spec(name)
    return Prior("uniform", -1.0, 1.0) if spec.kind == "kxy" else Prior("uniform", -0.8, 0.8)


_PRIOR_RE = re.compile(r"^\s*(uniform|normal|lognormal)\s*\(([^()]*)\)\s*$")


def parse_prior(text: str, name: str = "?") -> Prior:
    """'uniform(-0.9, 0.9)' or 'normal(0, 0.3, -0.95, 0.95)' (truncated) -> Prior."""
    m = _PRIOR_RE.match(text)
    args = m.group(2).split(",") if m else []
    if not m or len(args) not in ((2, 4) if m.group(1) == "normal" else (2,)):
        raise ParameterError(f"prior for {name}: cannot parse {text!r}; expected e.g. "
                             "uniform(-0.9,0.9), normal(0,0.3), normal(0,0.3,-0.95,0.95) or "
                             "lognormal(-1,0.5)")
    try:
        values = [float(v) for v in args]
    except ValueError:
        raise ParameterError(f"prior for {name}: non-numeric value in {text!r}") from None
    try:
        return Prior(m.group(1), *values)
    except ParameterError as exc:
        raise ParameterError(f"prior for {name}: {exc}") from None


def parse_prior_assignment(text: str) -> tuple[str, Prior]:
    """'k_By=uniform(-0.9,0.9)' -> ('k_By', Prior)."""
    name, eq, rest = text.partition("=")
    if not eq:
        raise ParameterError(f"option --prior: expected NAME=kind(a,b), got {text!r}")
    name = name.strip()
    get_spec(name)
    return name, parse_prior(rest, name)


def load_prior_file(path: str | Path) -> dict[str, Prior]:
    """Priors from a TOML file with a [priors] table of NAME = "kind(a, b)"."""
    p = Path(path)
    data = read_toml(p, "prior file", ParameterError)
    table = data.get("priors")
    if not isinstance(table, dict):
        raise ParameterError(f"prior file {p}: field priors: missing or not a table")
    out = {}
    for name, text in table.items():
        if not isinstance(text, str):
            raise ParameterError(f"prior file {p}: field priors.{name}: expected a string, "
                                 f"got {text!r}")
        get_spec(name)
        out[name] = parse_prior(text, name)
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _log_prior(theta, ls, kind, a, b, lo, hi, trunc, const, log_mass, nlo, nhi, nconst,
               out):  # pragma: no cover - compiled
    # PriorSet.log_prior for uniform and (truncated) normal priors: per row, the terms of
    # Prior.logpdf summed in parameter order, then the log-uniform noise intensities
    for r in range(theta.shape[0]):
        lp = 0.0
        for j in range(theta.shape[1]):
            x = theta[r, j]
            if kind[j] == 0:
                v = const[j] if (x >= a[j]) & (x <= b[j]) else -np.inf
            else:
                v = -0.5 * ((x - a[j]) / b[j]) ** 2 - const[j]
                if trunc[j]:
                    v = v - log_mass[j] if (x >= lo[j]) & (x <= hi[j]) else -np.inf
            lp = lp + v
        for j in range(ls.shape[1]):
            inside = (ls[r, j] >= nlo[j]) & (ls[r, j] <= nhi[j])
            lp = lp - nconst[j] if inside else -np.inf
        out[r] = lp


def noise_log_prior(log10_sigma: NDArray) -> NDArray:
    """Log prior of a batch of log10 noise intensities (nb, 3): uniform on
    NOISE_LOG10_BOUNDS, -inf outside."""
    lp = np.zeros(log10_sigma.shape[0])
    for j, (lo, hi) in enumerate(NOISE_LOG10_BOUNDS.values()):
        inside = (log10_sigma[:, j] >= lo) & (log10_sigma[:, j] <= hi)
        lp = np.where(inside, lp - np.log(hi - lo), -np.inf)
    return lp


@dataclass(frozen=True)
class PriorSet:
    """Priors of theta (in parameter order) and the log-uniform noise intensities."""

    names: tuple[str, ...]
    priors: tuple[Prior, ...]

    @classmethod
    def build(cls, names: tuple[str, ...], overrides: dict[str, Prior] | None = None
              ) -> PriorSet:
        overrides = dict(overrides or {})
        extra = sorted(set(overrides) - set(names))
        if extra:
            raise ParameterError(f"prior given for {extra[0]!r}, which is not among the "
                                 f"estimated parameters {list(names)}")
        return cls(names, tuple(overrides.get(n, default_prior(n)) for n in names))

    def log_prior(self, theta: NDArray, log10_sigma: NDArray) -> NDArray:
        """Joint log prior for a batch: theta (nb, p), log10_sigma (nb, 3)."""
        table = self._table
        if table is not None:                       # compiled: the same operations
            out = np.empty(theta.shape[0])
            _log_prior(np.require(theta, np.float64, ("C", "W")),   # one compiled signature
                       np.require(log10_sigma, np.float64, ("C", "W")), *table, out)
            return out
        lp = np.zeros(theta.shape[0])
        for j, pr in enumerate(self.priors):
            lp = lp + pr.logpdf(theta[:, j])
        return lp + noise_log_prior(log10_sigma)

    @cached_property
    def _table(self) -> tuple[NDArray, ...] | None:
        """The priors as arrays for _log_prior (kind 0 uniform, 1 normal; the constants
        computed as Prior.logpdf computes them), or None if one is lognormal (its log of
        theta is left to numpy)."""
        if any(pr.kind == "lognormal" for pr in self.priors):
            return None
        kind = np.array([0 if pr.kind == "uniform" else 1 for pr in self.priors], np.int64)
        a = np.array([pr.a for pr in self.priors], dtype=float)
        b = np.array([pr.b for pr in self.priors], dtype=float)
        lo = np.array([pr.lo for pr in self.priors], dtype=float)
        hi = np.array([pr.hi for pr in self.priors], dtype=float)
        trunc = np.array([pr.truncated for pr in self.priors])
        const = np.array([-np.log(pr.b - pr.a) if pr.kind == "uniform"
                          else np.log(pr.b * np.sqrt(2 * np.pi)) for pr in self.priors])
        log_mass = np.array([np.log(pr._mass) if pr.truncated else 0.0
                             for pr in self.priors])
        bounds = np.array(list(NOISE_LOG10_BOUNDS.values()), dtype=float)
        noise_const = np.array([np.log(hi_ - lo_) for lo_, hi_ in bounds])
        return (kind, a, b, lo, hi, trunc, const, log_mass, bounds[:, 0].copy(),
                bounds[:, 1].copy(), noise_const)

    def to_dict(self) -> dict[str, str]:
        d = {n: str(p) for n, p in zip(self.names, self.priors, strict=True)}
        d.update({k: f"log10-uniform({lo:g}, {hi:g})" for k, (lo, hi) in
                  NOISE_LOG10_BOUNDS.items()})
        return d
