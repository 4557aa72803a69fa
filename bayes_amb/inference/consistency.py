"""Do several records agree on the parameters they are said to share? (issue 29)

A joint posterior of shared coefficients (joint.py) is only right when the records
measure the same numbers. They do not when a coefficient depends on speed (a damping
that changes with running speed), on amplitude (a loop that is not linear: a current limit
makes the effective force constant smaller at the larger level) or on time (a bearing
that changed between a record and the next). Then the joint interval, narrower than
each record's, is narrow and wrong.

Each record's own posterior of a shared parameter, mean m_r and sd s_r (its reported one,
with any model error integrated out), is tested for equality, as in the meta-analysis of
independent estimates (Cochran's Q):

    Q = sum_r w_r (m_r - m_bar)^2,  w_r = 1 / s_r^2,  m_bar = sum w_r m_r / sum w_r,

chi-square with R - 1 degrees of freedom when they agree. A parameter whose Holm-adjusted
p falls below ALPHA disagrees. Its joint interval is then replaced by the random-effects
one (DerSimonian and Laird 1986): the records' spread beyond their own precision,

    tau^2 = max(0, (Q - (R - 1)) / (sum w - sum w^2 / sum w)),

is added to each record's variance before they are combined, so the interval says how
well the mean over these records is known and widens by as much as the records disagree.
The adequacy line names the parameters and says what to do: estimate them per record
(``--per-record``), and check the linearity when the records differ in amplitude.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import stats

ALPHA = 0.01
"""Family-wise level of the disagreement test over the shared parameters (Holm)."""


def _holm(p: list[float]) -> list[float]:
    """Holm-adjusted p-values, in the input order."""
    order = np.argsort(p)
    adj = np.empty(len(p))
    run = 0.0
    for rank, i in enumerate(order):
        run = max(run, min(1.0, (len(p) - rank) * p[i]))
        adj[i] = run
    return adj.tolist()


def agreement(means: dict[str, list[float]], sds: dict[str, list[float]]
              ) -> dict[str, Any]:
    """Cochran's Q per shared parameter over the records (module doc). ``means`` and
    ``sds``: per parameter, one value per record (a record without a finite positive sd is
    left out of that parameter's test). Returns per parameter Q, p, p_adjusted, tau (the
    spread beyond the records' own precision), the random-effects mean and sd, and
    ``disagree`` (the parameters with p_adjusted < ALPHA)."""
    rows: dict[str, dict[str, Any]] = {}
    for n, m in means.items():
        m_arr, s_arr = np.asarray(m, float), np.asarray(sds[n], float)
        ok = np.isfinite(m_arr) & np.isfinite(s_arr) & (s_arr > 0)
        m_arr, s_arr = m_arr[ok], s_arr[ok]
        if m_arr.size < 2:
            continue
        w = 1.0 / s_arr ** 2
        m_bar = float(np.sum(w * m_arr) / np.sum(w))
        q = float(np.sum(w * (m_arr - m_bar) ** 2))
        dof = m_arr.size - 1
        tau2 = max(0.0, (q - dof) / (np.sum(w) - np.sum(w ** 2) / np.sum(w)))
        w_re = 1.0 / (s_arr ** 2 + tau2)
        rows[n] = {"Q": q, "dof": dof, "p": float(stats.chi2.sf(q, dof)),
                   "tau": float(np.sqrt(tau2)),
                   "random_effects_mean": float(np.sum(w_re * m_arr) / np.sum(w_re)),
                   "random_effects_sd": float(1.0 / np.sqrt(np.sum(w_re))),
                   "record_means": m_arr.tolist(), "record_sds": s_arr.tolist()}
    names = list(rows)
    for n, pa in zip(names, _holm([rows[n]["p"] for n in names]), strict=True):
        rows[n]["p_adjusted"] = pa
    disagree = [n for n in names if rows[n]["p_adjusted"] < ALPHA]
    return {"test": "Cochran's Q per shared parameter, Holm-adjusted", "alpha": ALPHA,
            "parameters": rows, "disagree": disagree, "line": _line(rows, disagree)}


def _line(rows: dict[str, dict[str, Any]], disagree: list[str]) -> str:
    if not rows:
        return "records' agreement not tested (fewer than two records inform a parameter)"
    if not disagree:
        worst = min(rows, key=lambda n: rows[n]["p_adjusted"])
        return (f"the records agree on every shared parameter (smallest adjusted p "
                f"{rows[worst]['p_adjusted']:.2g}, {worst})")
    parts = [f"{n} (p {rows[n]['p_adjusted']:.1g}; per record "
             + ", ".join(f"{v:+.3g}" for v in rows[n]["record_means"]) + ")"
             for n in disagree]
    return ("the records disagree on " + "; ".join(parts) + ": these differ between the "
            "records (speed, amplitude or time) or the loop is not linear. Their joint "
            "intervals are the random-effects ones, widened by the spread; estimate them "
            "per record (--per-record " + ",".join(disagree) + ") and, where the records "
            "differ in amplitude, read the linearity checks.")
