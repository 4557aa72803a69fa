"""Compare a result file with its golden copy, each number on its own scale.

A golden file is written on one machine and read on others. Rounding differs between CPUs
(BLAS kernels, FMA, the order of a sum), and an optimiser's end point moves with it by far
less than the posterior's width. So a number is compared on the scale on which it means
something, not at a fixed 1e-4 of itself:

- **A posterior summary** (a table with ``mean`` and ``sd``, or ``mean``, ``q05`` and
  ``q95``): its location numbers (map, mean; the same in physical units) within
  ``SD_FRACTION`` of its own sd, and its sd within ``SD_FRACTION`` relative (both
  ``MODEL_ERROR_FRACTION`` for the model-error posterior of a doubted model; the location
  within ``LEARNED_FRACTION`` where the fit is under a learned noise spectrum). Its 90 %
  interval's ends within their Monte Carlo error: an HDI found in draws is the narrowest of
  many windows of nearly the same width, and rounding picks another one (``DRAWS``
  draws, or the chain's effective sample size; ``HDI_MC``, a cube-root rate). In a
  sampled run (``monte_carlo``) the location and sd too within z Monte Carlo standard
  errors, when those are wider.
- **A noise intensity** (log-uniform priors nine decades wide) on a log10 scale: its MAP
  within ``DECADES``, its posterior summary as above in log10.
- **A covariance** within ``SD_FRACTION`` of sqrt(c_ii c_jj); **a correlation** within
  ``SD_FRACTION`` (or its Monte Carlo error).
- **A p-value** on the decision scale: both below ``P_DECISIVE`` is the same answer,
  otherwise log10 within ``P_LOG10``.
- **A log-likelihood, Bayes factor or score** (nats) within ``NATS`` absolute.
- **A learned noise spectrum's gain** (dB at a knot) within ``GAIN_DB`` absolute.
- **A measurement of rounding** (the controller check's difference of 1e-14 of u): both
  below ``ROUNDING`` is the same, and the p-value computed on it is not compared.
- **Words** exactly, with the numbers in them masked: every number a sentence prints is
  compared where the file holds it as a number.
- **Candidates** as a set keyed by effect, location and round: two candidates that the data
  cannot tell apart (a sensor lag and an actuator lag, METHOD.md section 8) tie, and their
  order follows rounding.
- **Everything else** (verdicts, names, flags, lengths, keys) exactly, and other numbers to
  ``RTOL`` relative.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

IGNORED = frozenset({"wall_s", "map_wall_s", "package_version", "recording", "source",
                     "seconds", "sampling_wall_s"})
"""Timings, versions and paths: not results."""

SD_FRACTION = 0.01
"""Deterministic estimates agree within a hundredth of the posterior sd."""
MODEL_ERROR_FRACTION = 0.05
"""The same for the reported intervals of a model the adequacy test doubts (location, and
sd relative): the model-error posterior is formed at the whole-band fit's MAP under a noise
spectrum learned by a smoothing fit, whose end point moves with rounding (about 0.1 dB,
GAIN_DB; its L-BFGS-B stops at 500 iterations, 0.2 nats short, on a flat objective). The
location moved by 0.01-0.017 sd between two builds that differ in the order of a sum
(probe_angle_01's c_Ay); actuator_gain_00's k_Ax sd by 1.4 % with numpy 2.4 / scipy 1.17
and by 2 % when the eq. 15 start's rounding changed."""
LEARNED_FRACTION = 0.05
"""The location (MAP, mean) of a fit under a learned noise spectrum (``noise.spectrum``
adopted), in sd. The spectrum's smoothing fit stops at its iteration cap on a flat
objective (GAIN_DB), and the MAP under it follows its end point: over five OpenBLAS
kernels (the machine's own, and OPENBLAS_CORETYPE Haswell, SandyBridge, Zen and Nehalem)
the 15 golden cases' locations moved by at most 0.0175 sd, all on probe_angle_01 (c_Ay
0.3980 against 0.3991, sd 0.068; Haswell and Zen), whose spectrum's gains moved by up to
0.16 dB; every other location by at most 0.007 sd. Its sd stays at SD_FRACTION (at most
0.4 % moved)."""
Z_MC = 4.0
"""Sampled estimates agree within this many Monte Carlo standard errors."""
HDI_MC = 1.1
"""A 90 % HDI end's Monte Carlo sd in units of sd / N^(1/3), N draws (or the chain's ESS).
The HDI is the narrowest window of the sorted draws: near it the window's width is flat in
its position, so its end converges at the cube-root rate of the shorth (Kim & Pollard
1990), not at a quantile's square root. Measured on normal draws (2000 sets each):
1.05-1.1 x N^(-1/3), i.e. 0.066 sd at 4000 draws, twice a 5 % quantile's 0.034 sd
(2.1 / sqrt(N)). Rounding that changes the covariance's shape a little picks another of
the near-tied windows: probe_angle_01's k_By HDI moved 0.2 sd with numpy 2.4 / scipy 1.17
against 2.5 / 1.18, its mean 0.0002 sd."""
HDI_Z = 3.3
"""Interval ends agree within HDI_Z standard deviations of the difference of two such
ends (sqrt 2 x HDI_MC x N^(-1/3) x sd): 0.32 sd at 4000 draws, 0.65 sd at an ESS of 500.
The location and sd, compared far tighter, are what catch a changed posterior."""
DRAWS = 4000
"""Draws behind a summary that is not sampled (discrepancy.fitstats.draws)."""
DECADES = 0.01
P_DECISIVE = 1e-8
P_LOG10 = 0.05
NATS = 0.05
GAIN_DB = 0.4
"""A knot's gain of a learned noise spectrum (dB). It is read from at least 4 bins, each
band's power with a relative sd of 1/sqrt(bins) (4.3 dB / sqrt(bins): 0.25 dB at 300
bins); the smoothing fit's end point moves with rounding along a source the record barely
informs (r1 on the goldens: 4.98 against 5.10 dB when the fit's band algebra was compiled;
over five OpenBLAS kernels, LEARNED_FRACTION, at most 0.20 dB: probe_angle_01's r1 at By's
first knot, -8.28 against -8.48 dB, under Nehalem's)."""
ROUNDING = 1e-9
RTOL = 1e-2
ROUNDING_KEYS = frozenset({"relative_difference", "excitation_share"})
NATS_KEYS = frozenset({"score", "screen_gain", "linear_gain", "log_bayes_factor",
                       "log_posterior_odds", "log_likelihood_gain", "statistic",
                       "log_evidence", "elpd"})
LOCATION_KEYS = ("map", "mean", "hdi90", "q05", "q95", "median")
SAMPLER_DIAGNOSTICS = frozenset({"ess_bulk", "ess_tail", "tau"})
MC_SECTIONS = ("sampler", "noise.check.sd_ratio")
"""Sections of a sampled run's file computed from the chain, compared to the Monte Carlo
relative error z / sqrt(ESS)."""
CEILED_COUNTS = frozenset({"burn", "thin"})
"""The sampler's counts taken as the ceiling of a multiple of tau (sampler._burn_thin): a
Monte Carlo estimate rounded up, so one step more or less is its rounding (burn 8 against
9 where 2 tau is 8.6 on one CPU and 8.0x on another)."""
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


@dataclass(frozen=True)
class Context:
    """What the comparison knows about the file: whether it holds a sampled posterior, and
    the chain's effective sample size (the smallest over the parameters)."""

    monte_carlo: bool = False
    ess: float = math.inf
    model_error: bool = False
    learned: bool = False
    """The fit is under a learned noise spectrum (LEARNED_FRACTION)."""
    map_sd: tuple[tuple[str, float], ...] = ()
    """Each parameter's reported sd (its own model's where a model error widened the
    reported one): the scale of the ``map`` block's estimates."""


def context_of(golden: dict[str, Any]) -> Context:
    """The file's context: a sampled run is one with a ``sampler`` section; a summary whose
    intervals are the model-error posterior of the adequacy's fit has
    ``parameters_model_only`` beside a verdict that is not adequate."""
    doubted = ("parameters_model_only" in golden
               and golden.get("adequacy", {}).get("adequate") is False)
    own = golden.get("parameters_model_only") or golden.get("parameters") or {}
    map_sd = tuple((n, abs(float(v["sd"]))) for n, v in own.items()
                   if isinstance(v, dict) and _is_number(v.get("sd")) and v["sd"])
    spectrum = (golden.get("noise") or {}).get("spectrum")
    learned = isinstance(spectrum, dict) and spectrum.get("adopted") is True
    if "sampler" not in golden:
        return Context(model_error=doubted, learned=learned, map_sd=map_sd)
    ess = [float(v["ess_bulk"]) for v in golden.get("parameters", {}).values()
           if isinstance(v, dict) and isinstance(v.get("ess_bulk"), (int, float))]
    return Context(True, max(min(ess, default=100.0), 1.0), doubted, learned, map_sd)


def differences(got: Any, golden: Any, ctx: Context | None = None) -> list[str]:
    """Where ``got`` and its ``golden`` copy differ beyond each quantity's own scale
    (module docstring); an empty list when they agree."""
    ctx = context_of(golden) if ctx is None else ctx
    return _diff(got, golden, "", ctx)


def _is_number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _close(a: float, b: float, tol: float) -> bool:
    if (isinstance(a, float) and math.isnan(a)) and (isinstance(b, float) and math.isnan(b)):
        return True
    if a == b:
        return True
    return bool(abs(a - b) <= tol)


def _numbers(a: Any, b: Any, where: str, tol: float) -> list[str]:
    """Numbers, or lists of numbers (an interval), within tol."""
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{where}: length {len(a)} != {len(b)}"]
        return [d for i, (x, y) in enumerate(zip(a, b, strict=True))
                for d in _numbers(x, y, f"{where}[{i}]", tol)]
    if _is_number(a) and _is_number(b):
        return [] if _close(a, b, tol) else [f"{where}: {a!r} != {b!r} (tolerance {tol:.3g})"]
    return [] if a == b else [f"{where}: {a!r} != {b!r}"]


def _summary_scale(block: dict[str, Any]) -> float | None:
    """The posterior sd of a summary block, or None when the block is not one."""
    if not isinstance(block.get("mean"), (int, float)):
        return None
    if _is_number(block.get("sd")):
        return abs(float(block["sd"]))
    for lo_key, hi_key, interval in (("q05", "q95", None), (None, None, "hdi90")):
        lo, hi = ((block.get(lo_key), block.get(hi_key)) if interval is None
                  else (block.get(interval) or [None, None])[:2] + [None] * 0)
        if _is_number(lo) and _is_number(hi):
            return abs(hi - lo) / 3.29         # a normal's 90 % interval is 3.29 sd wide
    return None


def _physical_factor(block: dict[str, Any]) -> float:
    """Physical units per theta unit of a summary block (1 when it has none)."""
    if _is_number(block.get("physical_sd")) and block.get("sd"):
        return abs(block["physical_sd"] / block["sd"])
    ph, th = block.get("physical_hdi90"), block.get("hdi90")
    if (isinstance(ph, list) and isinstance(th, list) and len(ph) == 2 and len(th) == 2
            and all(_is_number(v) for v in (*ph, *th)) and th[1] != th[0]):
        return abs((ph[1] - ph[0]) / (th[1] - th[0]))
    if _is_number(block.get("physical_mean")) and block.get("mean"):
        return abs(block["physical_mean"] / block["mean"])
    return 1.0


def _location_fraction(ctx: Context) -> float:
    """A location's tolerance in sd: LEARNED_FRACTION under a learned spectrum."""
    return LEARNED_FRACTION if ctx.learned else SD_FRACTION


def _summary(got: dict, gold: dict, where: str, sd: float, ctx: Context) -> list[str]:
    """A posterior summary block, on the scale of its own sd."""
    ess = float(gold.get("ess_bulk") or ctx.ess) if ctx.monte_carlo else math.inf
    mc = Z_MC / math.sqrt(ess) if math.isfinite(ess) else 0.0
    fraction = MODEL_ERROR_FRACTION if ctx.model_error and where.startswith(
        ".parameters.") else SD_FRACTION
    loc = max(fraction, _location_fraction(ctx), mc) * sd
    ends = max(loc, HDI_Z * math.sqrt(2) * HDI_MC * min(ess, DRAWS) ** (-1 / 3) * sd)
    factor = _physical_factor(gold)
    out = []
    if got.keys() != gold.keys():
        out.append(f"{where}: keys {sorted(got.keys() ^ gold.keys())} in one only")
    for k in got.keys() & gold.keys():
        a, b, w = got[k], gold[k], f"{where}.{k}"
        base = k.removeprefix("physical_")
        scale = factor if k.startswith("physical_") else 1.0
        if base in ("hdi90", "q05", "q95"):
            out += _numbers(a, b, w, ends * scale)
        elif base in LOCATION_KEYS:
            out += _numbers(a, b, w, loc * scale)
        elif base == "sd":
            rel = max(fraction, mc / math.sqrt(2))
            out += _numbers(a, b, w, rel * abs(b) if _is_number(b) else 0.0)
        elif k in SAMPLER_DIAGNOSTICS and ctx.monte_carlo:
            out += _numbers(a, b, w, abs(b) if _is_number(b) else 0.0)  # within 2x
        elif k == "r_hat" and ctx.monte_carlo:
            out += _numbers(a, b, w, 0.1)
        else:
            out += _diff(a, b, w, ctx)
    return out


def _log10_block(block: dict[str, Any]) -> dict[str, Any]:
    """A noise posterior block (mean, q05, q95 of a positive intensity) in log10."""
    return {k: (math.log10(v) if k in ("mean", "q05", "q95", "median") and _is_number(v)
                and v > 0 else v) for k, v in block.items()}


def _is_p(key: str, parent: str) -> bool:
    return (key in ("p", "p_value", "p_adjusted", "p_adjusted_min")
            or parent.endswith("_p") or parent in ("family_min_p_adjusted",
                                                   "posterior_predictive_p"))


def _p_values(a: float, b: float, where: str) -> list[str]:
    if a == b or (a <= P_DECISIVE and b <= P_DECISIVE):
        return []
    if a <= 0 or b <= 0 or abs(math.log10(a) - math.log10(b)) > P_LOG10:
        return [f"{where}: p {a!r} != {b!r} (log10 tolerance {P_LOG10})"]
    return []


def _text(a: str, b: str, where: str) -> list[str]:
    if a == b or _NUMBER.sub("#", a) == _NUMBER.sub("#", b):
        return []
    return [f"{where}: {a!r} != {b!r}"]


def _matrix(a: Any, b: Any, where: str, tol_ij) -> list[str]:
    if not (isinstance(a, list) and isinstance(b, list) and len(a) == len(b)
            and all(isinstance(r, list) and isinstance(s, list) and len(r) == len(s)
                    for r, s in zip(a, b, strict=True))):
        return [f"{where}: shapes differ"]
    return [f"{where}[{i}][{j}]: {x!r} != {y!r}"
            for i, (r, s) in enumerate(zip(a, b, strict=True))
            for j, (x, y) in enumerate(zip(r, s, strict=True))
            if not _close(x, y, tol_ij(i, j))]


def _keyed(items: list) -> dict[str, Any] | None:
    """Candidates keyed by effect, location and round (None when a key repeats)."""
    keys = [f"{c.get('effect')}@{c.get('location')}#{c.get('round')}" for c in items]
    return dict(zip(keys, items, strict=True)) if len(set(keys)) == len(keys) else None


def _diff(a: Any, b: Any, where: str, ctx: Context) -> list[str]:
    key = where.rsplit(".", 1)[-1]
    if isinstance(a, dict) and isinstance(b, dict):
        if ".noise.posterior." in where + ".":
            a, b = _log10_block(a), _log10_block(b)
        sd = _summary_scale(b)
        if sd is not None:
            return _summary(a, b, where, sd, ctx)
        out = []
        if a.keys() != b.keys():
            out.append(f"{where}: keys {sorted(a.keys() ^ b.keys())} in one only")
        rounding = all(_is_number(a.get(k)) and _is_number(b.get(k))
                       and abs(a[k]) < ROUNDING and abs(b[k]) < ROUNDING
                       for k in ROUNDING_KEYS & b.keys()) and bool(ROUNDING_KEYS & b.keys())
        for k in a.keys() & b.keys():
            if k in IGNORED or (rounding and _is_p(k, key)):
                continue
            out += _diff(a[k], b[k], f"{where}.{k}", ctx)
        return out
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{where}: length {len(a)} != {len(b)}"]
        if key == "candidates" and a and all(isinstance(c, dict) for c in (*a, *b)):
            ka, kb = _keyed(a), _keyed(b)
            if ka is not None and kb is not None:
                if ka.keys() != kb.keys():
                    return [f"{where}: candidates {sorted(ka.keys() ^ kb.keys())} "
                            "in one only"]
                return [d for k in kb for d in _diff(ka[k], kb[k], f"{where}[{k}]", ctx)]
        if where.endswith("laplace_cov.theta"):
            return _matrix(a, b, where, lambda i, j: SD_FRACTION * math.sqrt(
                abs(b[i][i] * b[j][j])))
        if where.endswith("correlation.matrix"):
            tol = max(SD_FRACTION, Z_MC / math.sqrt(ctx.ess) if ctx.monte_carlo else 0.0)
            return _matrix(a, b, where, lambda i, j: tol)
        if key == "gain_by_band":                  # [f_lo, f_hi, gain in nats] per band
            return [d for i, (x, y) in enumerate(zip(a, b, strict=True))
                    for d in (_numbers(x[:2], y[:2], f"{where}[{i}]", RTOL * abs(y[0]))
                              + _numbers(x[2:], y[2:], f"{where}[{i}].gain", NATS))]
        return [d for i, (x, y) in enumerate(zip(a, b, strict=True))
                for d in _diff(x, y, f"{where}[{i}]", ctx)]
    if isinstance(a, str) and isinstance(b, str):
        return _text(a, b, where)
    if _is_number(a) and _is_number(b):
        parent = where.rsplit(".", 2)[-2] if where.count(".") >= 2 else ""
        if _is_p(key, parent):
            return _p_values(float(a), float(b), where)
        if key in ROUNDING_KEYS and abs(a) < ROUNDING and abs(b) < ROUNDING:
            return []
        if ".noise.map." in where and key == "value" and a > 0 and b > 0:
            return _numbers(math.log10(a), math.log10(b), where + " (log10)", DECADES)
        if key in NATS_KEYS:
            return _numbers(a, b, where, NATS + RTOL * abs(b))
        if ".noise.spectrum.gain_db." in where:
            return _numbers(a, b, where, GAIN_DB)
        sd = dict(ctx.map_sd).get(key) if where == f".map.{key}" else None
        if sd is not None:                     # the MAP, on its parameter's sd scale
            return _numbers(a, b, where, _location_fraction(ctx) * sd)
        rtol = RTOL
        if ctx.monte_carlo and any(where.startswith("." + s) for s in MC_SECTIONS):
            rtol = max(RTOL, Z_MC / math.sqrt(ctx.ess))
            if key in CEILED_COUNTS:
                return _numbers(a, b, where, rtol * abs(b) + 1)
        return _numbers(a, b, where, rtol * abs(b))
    return [] if a == b else [f"{where}: {a!r} != {b!r}"]
