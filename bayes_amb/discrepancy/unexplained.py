"""What the best model still does not explain: where, and a nonparametric estimate of it.

After the greedy search, the location tests are run again on the residual of the chosen
model. Excitation-coherent structure (coherence F-test, cross-correlation with the
excitation) and lines at 1x that remain are *unexplained*: physics outside the library, or
a form of it the library does not have. A wrong name is worse than none, so the diagnosis
then reports that part as unexplained and marks any effect it did add as tentative.

Floor and whiteness findings alone are not counted: they say the noise is not as modelled
(coloured sensor noise, a band-limited disturbance), which the noise-marginalised
likelihood already tolerates and which is no rotor physics.

The nonparametric estimate is the output-multiplicative error of each channel per band,

    R_c(w_k) ~= Delta_c(b) Y_c(w_k),   k in band b,

with R the residual DFT and Y = S(theta_hat) x the model's prediction on the same bins:
Delta_c(b) = sum conj(Y) R / sum |Y|^2 (least squares), with standard error
sqrt(s^2 / sum |Y|^2), s^2 the mean squared misfit in the band. |Delta| is the relative size
of the missing dynamics, its phase where it sits in the loop; 90 % intervals are
+-1.645 standard errors (complex normal, per component).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bayes_amb.discrepancy.fitting import FittedModel
from bayes_amb.discrepancy.locate import Location, locate_bands
from bayes_amb.rig import CHANNELS

STRUCTURED = ("coherence", "crosscorr", "line")
"""Location findings that count as structure a physics model should explain."""


def structured_findings(loc: Location) -> list[dict[str, Any]]:
    """The findings of a location that are excitation-coherent or 1x lines."""
    return [f for f in loc.findings if f["test"] in STRUCTURED]


def multiplicative_error(fm: FittedModel, n_bands: int = 24, min_bins: int = 16
                         ) -> dict[str, Any]:
    """Output-multiplicative error Delta_c per band and channel (see module docstring)."""
    like = fm.like
    like.set_noise_reference(fm.params)
    R = like.residual_dft(fm.params[None])[0][0]                      # (nf, 4)
    Y, _ = like.prediction_dft(fm.params[None])
    Y = Y[0]
    bands = locate_bands(like.k, like.n, like.forward.dt, n_bands, min_bins)
    freq = like.k / (like.n * like.forward.dt)
    rows = []
    for idx in bands:
        Yb, Rb = Y[idx], R[idx]
        yy = np.sum(np.abs(Yb) ** 2, axis=0)
        delta = np.sum(np.conj(Yb) * Rb, axis=0) / np.maximum(yy, 1e-300)
        s2 = np.mean(np.abs(Rb - delta * Yb) ** 2, axis=0)
        se = np.sqrt(s2 / np.maximum(yy, 1e-300))
        rows.append((float(freq[idx[0]]), float(freq[idx[-1]]), delta, se))
    out: dict[str, Any] = {"band_hz": [[a, b] for a, b, _, _ in rows], "channels": {}}
    for c, ch in enumerate(CHANNELS):
        mag = np.array([abs(d[c]) for _, _, d, _ in rows])
        se = np.array([s[c] for _, _, _, s in rows])
        out["channels"][ch] = {
            "magnitude": [float(v) for v in mag],
            "phase_deg": [float(np.degrees(np.angle(d[c]))) for _, _, d, _ in rows],
            "ci90": [[float(max(m - 1.645 * s, 0.0)), float(m + 1.645 * s)]
                     for m, s in zip(mag, se, strict=True)],
            "significant": [bool(m > 1.645 * np.sqrt(2) * s)
                            for m, s in zip(mag, se, strict=True)]}
    return out


def unexplained_block(final_loc: Location, fm: FittedModel) -> dict[str, Any]:
    """The ``unexplained`` block of diagnosis.json: present (bool), the channels and bands
    of the structure the chosen model leaves, and the multiplicative-error estimate."""
    found = structured_findings(final_loc)
    if not found:
        return {"present": False, "channels": [], "bands_hz": [], "findings": []}
    chans = sorted({c for f in found for c in f.get("channels", [])}, key=CHANNELS.index)
    spans = sorted({tuple(f["band_hz"]) for f in found if "band_hz" in f})
    return {"present": True, "channels": chans, "bands_hz": [list(s) for s in spans],
            "findings": found,
            "estimate": multiplicative_error(fm),
            "meaning": ("structure coherent with the excitation (or a 1x line) that no model "
                        "in the library explains; 'estimate' is the frequency response of an "
                        "output-multiplicative error per channel, Delta = R / (S x), with 90 % "
                        "intervals")}
