"""Binomial intervals of coverage fractions (studies, SBC, benchmarks)."""

from __future__ import annotations

from scipy import stats


def binomial_interval(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Clopper-Pearson interval of a proportion k/n."""
    if n == 0:
        return (float("nan"), float("nan"))
    a = 1 - level
    lo = stats.beta.ppf(a / 2, k, n - k + 1) if k > 0 else 0.0
    hi = stats.beta.ppf(1 - a / 2, k + 1, n - k) if k < n else 1.0
    return float(lo), float(hi)


def binomial_band(n: int, p: float, level: float = 0.99) -> tuple[float, float]:
    """Central band of the observed coverage fraction for n datasets at nominal p."""
    a = 1 - level
    return (float(stats.binom.ppf(a / 2, n, p) / n), float(stats.binom.isf(a / 2, n, p) / n))
