"""Closed-loop stability on the full plant and robustness in industry terms (ISO 14839-3)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bayes_amb.control.discrete import spectral_radius, ss_freqresp, zoh
from bayes_amb.rig import CHANNELS

ISO_ZONES = (("A", 3.0), ("B", 4.0), ("C", 5.0))
"""ISO 14839-3 zone limits on the peak sensitivity magnitude (A < 3 = 9.5 dB, ...; D above)."""


def iso14839_zone(peak_abs: float) -> str:
    """ISO 14839-3 zone of a peak sensitivity magnitude (absolute, not dB).

    Examples
    --------
    >>> iso14839_zone(2.0), iso14839_zone(3.5), iso14839_zone(6.0)
    ('A', 'B', 'D')
    """
    for zone, limit in ISO_ZONES:
        if peak_abs < limit:
            return zone
    return "D"


def closed_loop_matrix(Ap: NDArray, Bp: NDArray, Cp: NDArray, Ak: NDArray, Bk: NDArray,
                       Ck: NDArray, Dk: NDArray | None = None) -> NDArray:
    """State matrix of the discrete loop plant (Ap, Bp, Cp) with u = K y, K = (Ak, Bk, Ck, Dk)."""
    Dk = np.zeros((Ck.shape[0], Bk.shape[1])) if Dk is None else Dk
    return np.block([[Ap + Bp @ Dk @ Cp, Bp @ Ck], [Bk @ Cp, Ak]])


@dataclass(frozen=True)
class SensitivityData:
    """Output sensitivity (I - G K)^-1 diagonal per axis over frequency.

    freq_hz (n_w,); magnitude (n_w, 4) absolute; peak_db (4,) per channel Ax..By.
    """

    freq_hz: NDArray
    magnitude: NDArray
    peak_db: dict[str, float]
    zone: str


def sensitivity(Ap: NDArray, Bp: NDArray, Cp: NDArray, K: tuple[NDArray, ...], dt: float,
                n_freq: int = 600) -> SensitivityData:
    """Per-axis sensitivity of the discrete loop, evaluated up to the Nyquist frequency.

    Each axis' value is the diagonal element of (I - G K)^-1 with the other loops closed, as
    a sensitivity measured on a rig by injecting on one axis (ISO 14839-3).
    """
    w, z = sensitivity_grid(dt, n_freq)
    return sensitivity_from_response(w, ss_freqresp(Ap, Bp, Cp, None, z), ss_freqresp(*K, z))


def sensitivity_grid(dt: float, n_freq: int = 600) -> tuple[NDArray, NDArray]:
    """The sensitivity's frequency grid: w (rad/s, 1 Hz to Nyquist, log) and z = e^{j w dt}."""
    w = np.logspace(np.log10(2 * np.pi * 1.0), np.log10(np.pi / dt), n_freq)
    return w, np.exp(1j * w * dt)


def sensitivity_from_response(w: NDArray, G: NDArray, Kz: NDArray) -> SensitivityData:
    """Per-axis sensitivity from the plant and controller responses G, Kz (nf, 4, 4) on the
    grid w: the diagonal of (I - G K)^-1, its peaks and the ISO 14839-3 zone."""
    S = np.linalg.inv(np.eye(G.shape[1])[None] - G @ Kz)
    mag = np.abs(np.diagonal(S, axis1=1, axis2=2))
    peaks = mag.max(axis=0)
    return SensitivityData(freq_hz=w / (2 * np.pi), magnitude=mag,
                           peak_db={ch: float(20 * np.log10(p))
                                    for ch, p in zip(CHANNELS, peaks, strict=True)},
                           zone=iso14839_zone(float(peaks.max())))


def full_plant_discrete(A_f: NDArray, B_f: NDArray, dt: float) -> tuple[NDArray, NDArray]:
    """ZOH discretisation of a full (continuous) plant."""
    return zoh(A_f, B_f, dt)


def loop_spectral_radius(Ap: NDArray, Bp: NDArray, Cp: NDArray, K: tuple[NDArray, ...]) -> float:
    """Largest |eigenvalue| of the discrete closed loop; stable iff < 1."""
    return spectral_radius(closed_loop_matrix(Ap, Bp, Cp, *K))


def unstable_where(Ap: NDArray, Bp: NDArray, Cp: NDArray, K: tuple[NDArray, ...],
                   A_cont: NDArray, dt: float) -> str:
    """Where a discrete loop is unstable, in words: the frequency of its least stable pole
    and, when the continuous plant ``A_cont`` has a lightly damped mode near it, that mode
    (the usual cause: a bending mode the controller's phase destabilises). A pole below the
    plant's unstable rigid-body poles means the controller does not hold the rotor up."""
    z = np.linalg.eigvals(closed_loop_matrix(Ap, Bp, Cp, *K))
    worst = z[np.argmax(np.abs(z))]
    f = abs(np.angle(worst)) / (2 * np.pi * dt)
    text = f"least stable closed-loop pole at {f:.0f} Hz (|z| = {abs(worst):.6g})"
    lam = np.linalg.eigvals(A_cont)
    low = lam[np.argsort(np.abs(lam))][:8]                # the suspended rigid body
    rigid = low[low.real > 1e-3 * np.abs(low)]
    if rigid.size and f <= np.abs(rigid).max() / (2 * np.pi):
        return text + (", at the magnets' unstable rigid-body poles (up to "
                       f"{np.abs(rigid).max() / (2 * np.pi):.0f} Hz): the controller does not "
                       "hold the rotor up, its stiffness ki C(0) being short of the magnets' "
                       "negative stiffness ks, or its phase wrong there")
    lam = lam[(lam.imag > 0) & (np.abs(lam) > 0)]
    if f > 0 and lam.size:
        fo = np.abs(lam.imag) / (2 * np.pi)
        k = int(np.argmin(np.abs(fo - f)))
        zeta = -lam[k].real / abs(lam[k])
        if abs(fo[k] - f) < 0.1 * f and zeta < 0.05:
            text += (f", next to the open-loop mode at {fo[k]:.0f} Hz (damping ratio "
                     f"{zeta:.2g}): a bending mode the controller destabilises; it needs "
                     "roll-off or a notch there (the rig's damping is its first_mode_zeta)")
    return text
