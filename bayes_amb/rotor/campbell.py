"""Natural frequencies against speed (Campbell data) and open-loop pole summaries."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bayes_amb.rig import Rig
from bayes_amb.rotor.assembly import FullModel, assemble, full_model

N_RIGID_EIGENVALUES = 8


def bending_frequencies_hz(model: FullModel, n_modes: int = 8) -> NDArray:
    """Open-loop flexible-mode frequencies |Im lambda|/2pi in Hz, ascending.

    The 8 suspended rigid-body eigenvalues (smallest |lambda|) and overdamped real modes are
    excluded; one entry per conjugate pair (backward and forward whirl are separate entries).
    Modes are taken in order of |lambda| and kept when underdamped (|Im| > |Re|): the
    high-order FE modes that C = beta*K overdamps are not vibration modes.
    """
    lam = model.poles[N_RIGID_EIGENVALUES:]
    lam = lam[(lam.imag > 0) & (lam.imag > np.abs(lam.real))]
    return np.sort(lam[:n_modes].imag / (2 * np.pi))


def unstable_poles(model: FullModel) -> NDArray:
    """Right-half-plane poles (rad/s), sorted by real part, descending."""
    lam = model.poles
    rhp = lam[lam.real > 0]
    return rhp[np.argsort(-rhp.real, kind="stable")]


@dataclass(frozen=True)
class CampbellData:
    """speeds_rpm (n_s,); freqs_hz (n_s, n_modes) flexible-mode frequencies at each speed."""

    speeds_rpm: NDArray
    freqs_hz: NDArray
    nominal_speed_rpm: float


def campbell_data(rig: Rig, speeds_rpm: NDArray | None = None, n_modes: int = 6
                  ) -> CampbellData:
    """Flexible-mode frequencies (Hz) against speed, bearings' ks in place.

    Examples
    --------
    >>> from bayes_amb.rig import load_rig
    >>> cd = campbell_data(load_rig(), np.array([0.0, 31500.0]), n_modes=2)
    >>> cd.freqs_hz.shape
    (2, 2)
    """
    speeds = np.linspace(0, 1.2 * rig.nominal_speed_rpm, 13) if speeds_rpm is None \
        else np.asarray(speeds_rpm, dtype=float)
    mats = assemble(rig)
    f = np.array([bending_frequencies_hz(full_model(rig, s, mats), n_modes) for s in speeds])
    return CampbellData(speeds_rpm=speeds, freqs_hz=f, nominal_speed_rpm=rig.nominal_speed_rpm)
