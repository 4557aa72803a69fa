"""The magnets' force law from records at several excitation levels.

One record at one level cannot tell the force law from a stiffness change (nonlinear.py):
a linear fit reads each bearing's stiffness as ks (1 + <(i/i0)^2>), so its theta (the
relative reduction of ks) as

    theta_hat_rj = theta_j - beta m_rb + e_rj,     m_rb = <u_b^2>_r / rho_b^2,

with beta = 1 / g0^2 (i0 = rho g0, rho = ks / ki of bearing b), <u_b^2>_r the mean square
of record r's current on bearing b's two axes (about its median), and e_rj the record's
own error (its posterior sd). Records at different levels have different m_rb, so beta
and the small-signal theta_j are a weighted least squares over the records and the
bearing stiffnesses: beta shared, one theta_j per coefficient. The force law is named when
beta's z passes the one-sided threshold; its gap is beta^(-1/2), and the bias follows. When
not named, beta's upper bound is a lower bound on the bias: "the magnets' bias is above X A
(95 %)", which says up to which current the stiffnesses read are the small-signal ones.

It needs the records' levels to differ: when the spread of m across the records is below
the stiffnesses' own sd, the records cannot tell either, and the block says so. The
damping coefficients do not move with the level (the law has no velocity term).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import stats

from bayes_amb.discrepancy.nonlinear import FORCE_LAW, TITLES, bias_per_gap
from bayes_amb.io.recording import Recording
from bayes_amb.results.diagnosis import Diagnosis

ALPHA = 1e-3
"""One-sided level of the force law's test across the records."""


def level_of(recording: Recording) -> np.ndarray:
    """<u_b^2> / rho_b^2 per bearing (A, B): the record's level in units of beta (m^2)."""
    u = np.asarray(recording.u, dtype=float)
    u = u - u.mean(axis=0)             # (a median sits on one level of a binary signal)
    rho = bias_per_gap(recording.rig)
    return np.array([np.mean(u[:, 2 * j:2 * j + 2] ** 2) / np.mean(rho[2 * j:2 * j + 2]) ** 2
                     for j in range(2)])


def force_law_levels(recordings: list[Recording], diags: list[Diagnosis]
                     ) -> dict[str, Any] | None:
    """The force law across the records' levels (module docstring), one beta per bearing
    (each magnet pair its own bias), or None when it does not apply: a record failed a
    data check or modelled a nonlinearity already (the rig file's bias, a limit), or no
    record reports a bearing stiffness."""
    if any(d.checks_failed or d.nonlinearity is not None for d in diags):
        return None
    names = sorted({n for d in diags for n in d.parameters_after if n.startswith("k_")})
    bearings = sorted({n[2] for n in names})
    if not names:
        return None
    m = [level_of(r) for r in recordings]
    scale = max(float(np.max(v)) for v in m) or 1.0     # beta's columns at unit size
    m = [v / scale for v in m]
    nb = len(bearings)
    rows, y, w = [], [], []
    for r, d in enumerate(diags):
        for j, n in enumerate(names):
            c = d.parameters_after.get(n)
            if c is None or not c.sd > 0:
                continue
            row = np.zeros(len(names) + nb)
            row[j] = 1.0
            row[len(names) + bearings.index(n[2])] = -m[r]["AB".index(n[2])]
            rows.append(row)
            y.append(c.mean)
            w.append(1.0 / c.sd ** 2)
    X, y, w = np.array(rows), np.array(y), np.array(w)
    F = X.T @ (X * w[:, None])
    levels = [float(np.sqrt(np.mean(np.asarray(r.u, dtype=float) ** 2))) for r in recordings]
    base = {"name": FORCE_LAW, "title": TITLES[FORCE_LAW], "records": len(recordings),
            "rms_current_a": levels}
    spread = min(float(np.ptp([v["AB".index(b)] for v in m])) for b in bearings)
    if spread < 1e-3 or np.linalg.cond(F) > 1e12:
        return {**base, "named": False,
                "line": "the records' levels do not differ enough to tell the magnets' force "
                        "law from a stiffness change (record at two excitation levels, e.g. "
                        "a third and full)"}
    cov = np.linalg.inv(F)
    est = cov @ (X.T @ (w * y))
    resid = y - X @ est
    chi2 = float(np.sum(w * resid ** 2))
    dof = max(len(y) - len(est), 1)
    z_crit = float(stats.norm.isf(ALPHA / nb))
    rho = bias_per_gap(recordings[0].rig)
    per, named_where, bounds = {}, [], {}
    for k, b in enumerate(bearings):
        i = len(names) + k
        beta, sd = float(est[i]) / scale, float(np.sqrt(cov[i, i])) / scale
        r_b = float(np.mean(rho[2 * "AB".index(b):2 * "AB".index(b) + 2]))
        hi = beta + 1.645 * sd
        row = {"beta_per_m2": beta, "beta_sd": sd, "z": beta / sd}
        if beta / sd > z_crit:
            lo = max(beta - 1.645 * sd, 0.0)
            gap = beta ** -0.5
            gap_hi = lo ** -0.5 if lo > 0 else float("inf")
            row.update(gap_m=gap, gap_hdi90=[hi ** -0.5, gap_hi], bias_current_a=r_b * gap,
                       bias_hdi90=[r_b * hi ** -0.5, r_b * gap_hi])
            named_where.append(b)
        else:
            bounds[b] = r_b * hi ** -0.5 if hi > 0 else float("inf")
            row["bias_lower_bound_a"] = bounds[b]
        per[b] = row
    out = {**base, "named": bool(named_where), "where": named_where, "bearings": per,
           "z": max(v["z"] for v in per.values()), "z_crit": z_crit, "chi2": chi2,
           "dof": dof, "consistency_p": float(stats.chi2.sf(chi2, dof))}
    if named_where:
        out["small_signal"] = {n: {"mean": float(est[j]), "sd": float(np.sqrt(cov[j, j])),
                                   "hdi90": [float(est[j] - 1.645 * np.sqrt(cov[j, j])),
                                             float(est[j] + 1.645 * np.sqrt(cov[j, j]))]}
                               for j, n in enumerate(names)}
    parts = []
    for b, v in per.items():
        if b in named_where:
            lo, hi = v["bias_hdi90"]
            parts.append(f"bearing {b}: the stiffnesses read rise with the current as "
                         f"ks (1 + <(i/i0)^2>), bias {v['bias_current_a']:.3g} A (90 % "
                         f"{lo:.3g} .. {hi:.3g} A; gap {1e3 * v['gap_m']:.3g} mm), z "
                         f"{v['z']:.1f}")
        else:
            parts.append(f"bearing {b}: no force law (z {v['z']:.1f}); its bias is above "
                         f"{bounds[b]:.3g} A (95 %), so at {max(levels):.3g} A rms its "
                         "stiffnesses read are the small-signal ones within "
                         f"{100 * (max(levels) / bounds[b]) ** 2:.2g} %")
    out["line"] = ("the magnets' force law across the records' levels: " + "; ".join(parts)
                   + ("; the small-signal stiffnesses are in small_signal" if named_where
                      else ""))
    out.update({k: v for k, v in per[named_where[0]].items()} if named_where else {})
    return out
