"""The colour of a rig's noise, measured on a recording (``plan --noise-from``).

identify's likelihood models the noise as three white sources through the closed loop
(whittle.py). A real rig's sensor noise is often coloured (1/f, an AR(1) drift, a hum), and
then the spread of identify's estimates is not its reported sd: the estimator is still
consistent, but its variance is the sandwich F^-1 B F^-1 of the white model's curvature F
and the score's variance B under the true spectrum (fisher.py).

The true spectrum is measured where the rig's noise shows: the residual of identify's MAP
on an earlier recording. Per likelihood band b its mean periodogram P_b (4 x 4) is taken
relative to the white model's spectrum N Phi_b = L_b L_b^H at the fitted intensities,

    C_b = L_b^-1 P_b L_b^-H        (the identity where the noise is as white as modelled),

a colour that does not depend on the record's length, scale or prewhitening. A plan for
another design carries it over by frequency: Phi_true(f) = L(f) C(f) L(f)^H with the plan's
own white spectrum L L^H. As identify's noise check does (noise_check.segment_colour),
C_b is averaged over segments of at least 32 bins, so each entry has a relative error of
about 1/sqrt(32) or less (per band alone it would be 1/sqrt(n_b), and the likelihood's
lowest bands hold one bin each). On foreign records this made no measurable difference:
a plan from one 2 s record of a strongly coloured case put the sds 0.77-1.20x identify's
mean over 100 records of that case either way, against 0.89-1.09x for the white plan and
its white sd. The spread is identify's own: its sandwich sd varies 8-16 % between records
of one case (the fitted white intensities, sigma_r1 above all, differ between them), and
not with the segment length (32 to 256 bins).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bayes_amb.inference.noise_check import band_colour, segment_colour, white_spectrum
from bayes_amb.inference.spectrum import interp_matrices
from bayes_amb.inference.whittle import WhittleLikelihood


@dataclass(frozen=True)
class NoiseColour:
    """The measured colour C_b (n_bands, 4, 4) at the band frequencies ``f_hz``, from
    ``source`` (module docstring)."""

    f_hz: NDArray
    C: NDArray
    source: str = ""

    def at(self, f: NDArray) -> NDArray:
        """C at the frequencies f (Hz): linear interpolation of each entry (a convex
        combination of positive definite matrices, so positive definite), the end bands'
        colour held beyond the measured range."""
        return interp_matrices(f, self.f_hz, self.C)

    def summary(self) -> dict[str, Any]:
        """What a plan's JSON says of it: source, bands, and the mean colour per channel
        (diag C: 1 where the noise is as white as modelled) in the lowest and highest
        third of the band."""
        d = np.real(np.einsum("bii->bi", self.C))
        third = max(1, d.shape[0] // 3)
        return {"from": self.source, "n_bands": int(d.shape[0]),
                "f_hz": [float(self.f_hz[0]), float(self.f_hz[-1])],
                "low_third": [float(v) for v in d[:third].mean(axis=0)],
                "high_third": [float(v) for v in d[-third:].mean(axis=0)]}


def measure_colour(like: WhittleLikelihood, theta: NDArray, log10_sigma: NDArray,
                   source: str = "") -> NoiseColour:
    """The colour of the residual of ``like`` at (theta, log10_sigma): identify's MAP on
    the recording whose noise is measured."""
    C, _ = band_colour(like, theta, log10_sigma)
    C, _ = segment_colour(like.counts, C)
    return NoiseColour(f_hz=np.asarray(like.band_freq_hz, dtype=float), C=C, source=source)


def spectrum_colour(like: WhittleLikelihood, phi: NDArray, log10_sigma: NDArray,
                    source: str = "") -> NoiseColour:
    """The colour of a noise spectrum phi (n_bands, 4, 4; N Phi_b, as identify learned it,
    inference/spectrum.py) against the white sources of ``like`` at log10_sigma:
    L^-1 phi L^-H per band, averaged over the segments as measure_colour does."""
    Li = np.linalg.inv(np.linalg.cholesky(white_spectrum(like, log10_sigma)))
    C = Li @ phi @ np.conj(np.swapaxes(Li, -1, -2))
    C, _ = segment_colour(like.counts, 0.5 * (C + np.conj(np.swapaxes(C, -1, -2))))
    return NoiseColour(f_hz=np.asarray(like.band_freq_hz, dtype=float), C=C, source=source)


def coloured_spectrum(like: WhittleLikelihood, log10_sigma: NDArray,
                      colour: NoiseColour) -> NDArray:
    """The true N Phi_b of a likelihood's bands: its white spectrum at log10_sigma
    coloured by ``colour`` (module docstring)."""
    L = np.linalg.cholesky(white_spectrum(like, log10_sigma))
    return L @ colour.at(like.band_freq_hz) @ np.conj(np.swapaxes(L, -1, -2))
