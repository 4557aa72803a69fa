"""The Fisher oracle: Cramer-Rao widths of the eight bearing coefficients on a record.

What an ideal estimator could know about k_Ax..k_By, c_Ax..c_By (the truth file's 'theta'
units: k_<axis> = theta, ks_true = (1 - theta) ks; c_<axis> = c / c_ref, c in N s/m) from
a record of this generator, computed from the generator's own world only: its plant
(cases.plant_of: its state space, the case's truth, effects on as in the case), its own
sampling (loop._gamma, the ZOH with fractional delays of loop.closed_loop), the controller
as read from its file, the record's design (duration, dt, eta amplitude and channels) and
the TRUE disturbance spectrum of the case (habits and disturbances.Disturbance). Nothing of
the product's noise model is read or copied.

Model (frequency domain, closed loop, per DFT bin k, 0 < f_k < f_max):

    Y_k = T(theta, w_k) Eta_k + V_k,   T = S P K_e,   S = (I - P K_y)^-1,
    V_k ~ CN(0, N Phi_v(w_k)),   Phi_v = S Phi_m S^H + S P Phi_w P^H S^H + S P_f Phi_f P_f^H S^H

with P(z) = C (zI - Phi)^-1 (G_new z^-n + G_old z^-n-1) + D z^-n-1 the sampled plant
(current -> probe, m/A), P_f the sampled disc-force map (m/N), K_y, K_e the controller's
y -> u and eta -> u, and the diagonal per-sample spectral densities (variance = their mean
over w) Phi_m of everything on the measurement (sensor noise: white, AR(1) or pink; r1
white; r1_band), Phi_w at the amplifier input (r2 white, r2_band, r2_narrow) and Phi_f of
the process force. eta is random binary +/-a on its channels: white with variance a^2,
so E[Eta_k Eta_k^H] = N a^2 E (E the excited channels). The Fisher information is

    I_jl = sum_k 2 a^2 Re tr[E dT_j^H Phi_v^-1 dT_l]     (dT_j = dT/dtheta_j at w_k)

(the N cancels), dT_j by central finite differences in theta on the generator's plant.

Choices (stated here, as they set what 'ideal' means):
- y alone carries the information: the recorded u is the controller's output, a
  deterministic function of the recorded y and eta (the controller is known), so it adds
  nothing (this excludes a current limit recording the coil current: refused).
- Only the mean term. The disturbance spectrum also depends on theta (through S and P);
  the term tr(Phi^-1 dPhi_j Phi^-1 dPhi_l) of that dependence is left out by default: the
  ideal estimator here knows the disturbance spectrum's shape only as a nuisance, not the
  exact source spectra. ``covariance_term=True`` adds it (an estimator that knows the
  source spectra exactly): on the reference rig it narrows the widths by < 0.5 % on a
  plain control, 2 % with pink sensor noise, but up to ~20 % (c on the forced bearing)
  with a strong coloured r2, whose path through the plant then carries information.
- Deterministic lines (the habits' and the disturbance's mains lines on y, a current line,
  the 1x line of unbalance or runout) are fitted out by the ideal estimator (a sinusoid:
  amplitude and phase per channel); they occupy their bins: every bin closer than one bin
  spacing to a line frequency is dropped (one bin for a line on the grid, two otherwise).
  Offsets, drift and the amplifier offset sit at 0 Hz (a fitted constant and slope): the
  DC bin is never used, and their leakage is taken as fitted out.
- The record is long against the loop's memory (Whittle): bins independent; the burn-in
  makes the record stationary.
- The process force and the coloured parts are scaled to their target rms in the
  generator by their realised rms; the oracle uses the target rms (their expectation).
- Linear, time-invariant cases only: a nonlinear effect (current or slew limit, magnet
  law, voltage-limited amplifier) or a ks_drift is refused (ValueError).

Width = z sd, z = 1.645 (the 90 % half-width), sd = sqrt(diag(I^-1)).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray
from scipy.signal import freqz, sosfreqz

from bayes_amb.rig import Rig, load_rig
from benchmarks.foreign.cases import CaseSpec, _controller, plant_of
from benchmarks.foreign.disturbances import Disturbance, band_sos, resonator
from benchmarks.foreign.effects import NONLINEAR, Effect
from benchmarks.foreign.habits import PINK_POLES, Habits
from benchmarks.foreign.loop import Controller, _gamma
from benchmarks.foreign.plant import AXES

PARAMS = tuple(f"k_{a}" for a in AXES) + tuple(f"c_{a}" for a in AXES)
"""The eight bearing coefficients, in the truth file's order and 'theta' units."""
Z90 = 1.6448536269514722
"""The two-sided 90 % normal quantile: half-width = Z90 sd."""
_DIRECT_BELOW = 0
"""Systems with fewer states than this are evaluated by direct solves at every z; the
others through their eigen-decomposition, checked against direct solves at three z (a
defective matrix falls back to direct solves)."""


# ------------------------------------------------------------------ the loop's FRFs
def _plant_frf(spec: CaseSpec, rig: Rig, dt: float, z: NDArray) -> tuple[NDArray, NDArray]:
    """(P, P_f) (K, 4, 4): the sampled plant (current -> probe, m/A) and disc forces
    [D1x, D1y, D2x, D2y] -> probe (m/N) at z (K,), the ZOH with the case's fractional
    delays exactly as loop.closed_loop samples them."""
    pl = plant_of(spec, rig)
    A, B, C, F = pl.A, pl.B, pl.C, pl.F
    if pl.osc >= 0:     # the 1x oscillator is unreachable from every input: drop it
        keep = np.r_[0:pl.osc, pl.osc + 2:A.shape[0]]
        A, B, C, F = A[np.ix_(keep, keep)], B[keep], C[:, keep], F[keep]
    ratio = pl.delay_s / dt
    n_shift = int(np.floor(ratio + 1e-12))
    f = ratio - n_shift
    f = 0.0 if f < 1e-12 else f
    Phi, G_new = _gamma(A, B, (1.0 - f) * dt)
    G_old = np.zeros_like(G_new)
    if f > 0:
        E1, G1 = _gamma(A, B, f * dt)
        G_old = Phi @ G1
        Phi = Phi @ E1
    G_f = _gamma(A, F, dt)[1]
    R = _resolvent(Phi, C, np.hstack([G_new, G_old, G_f]), z)       # (K, 4, 12)
    zi = 1.0 / z
    P = (R[:, :, :4] * zi[:, None, None] ** n_shift
         + R[:, :, 4:8] * zi[:, None, None] ** (n_shift + 1))
    if pl.D is not None:
        P = P + pl.D[None] * zi[:, None, None] ** (n_shift + 1)
    return P, R[:, :, 8:]


def _resolvent(Phi: NDArray, C: NDArray, G: NDArray, z: NDArray) -> NDArray:
    """C (zI - Phi)^-1 G at every z (see _DIRECT_BELOW)."""
    n = Phi.shape[0]

    def direct(zz: NDArray) -> NDArray:
        out = np.empty((zz.size, C.shape[0], G.shape[1]), complex)
        for i in range(0, zz.size, 1024):
            M = zz[i:i + 1024, None, None] * np.eye(n) - Phi
            out[i:i + 1024] = C @ np.linalg.solve(M, np.broadcast_to(G, (M.shape[0], *G.shape)))
        return out

    if n < _DIRECT_BELOW:
        return direct(z)
    mu, V = sla.eig(Phi)
    CV, VG = C @ V, np.linalg.solve(V, G)
    out = np.empty((z.size, C.shape[0], G.shape[1]), complex)
    for i in range(0, z.size, 512):
        R = 1.0 / (z[i:i + 512, None] - mu[None, :])
        out[i:i + 512] = (CV[None] * R[:, None, :]) @ VG
    probe = np.unique(np.linspace(0, z.size - 1, 3).astype(int))
    ref = direct(z[probe])
    if np.max(np.abs(out[probe] - ref)) > 1e-8 * np.max(np.abs(ref)):
        return direct(z)
    return out


def controller_frf(ctrl: Controller, z: NDArray) -> tuple[NDArray, NDArray]:
    """(K_y, K_e) (K, 4, 4): the controller's y_m -> u (A/m) and eta -> u (A/A) at z."""
    R = _resolvent(ctrl.Ak, ctrl.Cu, np.hstack([ctrl.By, ctrl.Be]), z)
    return R[:, :, :4] + ctrl.Duy, R[:, :, 4:] + ctrl.Due


def loop_frf(spec: CaseSpec, rig: Rig, K: tuple[NDArray, NDArray], z: NDArray
             ) -> dict[str, NDArray]:
    """The closed loop's maps into the recorded y at z (K, 4, 4 each): 'T' eta -> y,
    'S' measurement additions (m) -> y, 'SP' amplifier-input additions (A) -> y, 'SPf'
    disc forces (N) -> y. K: the controller's (K_y, K_e) at the same z."""
    P, Pf = _plant_frf(spec, rig, spec.dt, z)
    Ky, Ke = K
    S = np.linalg.inv(np.eye(4) - P @ Ky)
    SP = S @ P
    return {"T": SP @ Ke, "S": S, "SP": SP, "SPf": S @ Pf}


# -------------------------------------------------------- the disturbance spectrum
def _unit_power(h2: NDArray, full: NDArray) -> NDArray:
    """|H|^2 at the bins over its mean over the circle (per-sample PSD of unit variance)."""
    return h2 / np.mean(full)


_GRID = np.linspace(0.0, np.pi, 1 << 18, endpoint=False)


def band_psd(band: tuple[float, float], dt: float, w: NDArray) -> NDArray:
    """Per-sample PSD (unit variance) of white noise through disturbances.band_sos."""
    sos = band_sos(band, dt)
    return _unit_power(np.abs(sosfreqz(sos, worN=w)[1]) ** 2,
                       np.abs(sosfreqz(sos, worN=_GRID)[1]) ** 2)


def resonator_psd(f0_hz: float, q: float, dt: float, w: NDArray) -> NDArray:
    """Per-sample PSD (unit variance) of white noise through disturbances.resonator."""
    b, a = resonator(f0_hz, q, dt)
    return _unit_power(np.abs(freqz(b, a, worN=w)[1]) ** 2,
                       np.abs(freqz(b, a, worN=_GRID)[1]) ** 2)


def ar1_psd(a: float, w: NDArray) -> NDArray:
    """Per-sample PSD (unit variance) of habits.ar1_noise with pole a."""
    return (1.0 - a * a) / np.abs(1.0 - a * np.exp(-1j * w)) ** 2


def source_psd(spec: CaseSpec, w: NDArray) -> dict[str, NDArray]:
    """The diagonal per-sample PSDs (K, 4) of the case's random sources: 'm' on the
    measurement (m^2), 'w' at the amplifier input (A^2), 'f' of the disc forces (N^2)."""
    h, d, dt = spec.habits, spec.disturbance, spec.dt
    K = w.size
    if h.noise_kind == "pink":
        noise = np.mean([ar1_psd(a, w) for a in PINK_POLES], axis=0)
    elif h.noise_kind == "ar1":
        noise = ar1_psd(h.noise_ar, w)
    else:
        raise ValueError(f"noise_kind {h.noise_kind!r}")
    m = np.outer(h.noise_rms_m**2 * noise + h.r1_rms_m**2, np.ones(4))
    u = np.full((K, 4), h.r2_rms_a**2)
    f = np.zeros((K, 4))
    if h.force_rms_n > 0 and h.force_at:
        cols = [2 * ("D1", "D2").index(s) + i for s in h.force_at for i in (0, 1)]
        f[:, cols] = h.force_rms_n**2 * band_psd(h.force_band_hz, dt, w)[:, None]
    if d is not None:
        if any(d.r2_band_rms_a):
            u += np.outer(band_psd(d.r2_band_hz, dt, w), np.square(d.r2_band_rms_a))
        if any(d.r2_narrow_rms_a):
            u += np.outer(resonator_psd(d.r2_narrow_hz, d.r2_narrow_q, dt, w),
                          np.square(d.r2_narrow_rms_a))
        if any(d.r1_band_rms_m):
            m += np.outer(band_psd(d.r1_band_hz, dt, w), np.square(d.r1_band_rms_m))
    return {"m": m, "w": u, "f": f}


def disturbance_psd(maps: dict[str, NDArray], src: dict[str, NDArray]) -> NDArray:
    """Phi_v (K, 4, 4): the per-sample spectral density of the disturbance part of y."""
    out = np.zeros(maps["S"].shape, complex)
    for H, s in ((maps["S"], src["m"]), (maps["SP"], src["w"]), (maps["SPf"], src["f"])):
        out += (H * s[:, None, :]) @ np.conj(np.swapaxes(H, 1, 2))
    return out


def line_frequencies(spec: CaseSpec) -> list[float]:
    """The case's deterministic lines (Hz): habit and disturbance mains lines, a current
    line, the 1x line of unbalance or runout."""
    lines = [float(f) for f in spec.habits.mains_m]
    if spec.disturbance is not None:
        lines += [float(f) for f in spec.disturbance.lines_hz()]
    if any(e.name in ("unbalance", "runout") for e in spec.effects):
        lines.append(spec.speed_rpm_true / 60.0)
    return sorted(set(lines))


# ------------------------------------------------------------------- information
@dataclass(frozen=True)
class FisherBins:
    """The per-bin Fisher information of a record: ``freqs`` (K,) Hz of bins 1 .. <N/2,
    ``info`` (K, 8, 8) in theta units (zero in the bins lines occupy), ``masked`` (K,)
    bool, ``lines_hz`` the lines, ``params`` PARAMS, ``seconds`` the time it took."""

    freqs: NDArray
    info: NDArray
    masked: NDArray
    lines_hz: tuple[float, ...]
    params: tuple[str, ...]
    covariance_term: bool
    seconds: float

    def widths(self, f_max_hz: float | None = None, f_min_hz: float = 0.0,
               z: float = Z90) -> dict[str, Any]:
        """The Cramer-Rao widths from the bins with f_min_hz < f < f_max_hz (None: the
        Nyquist frequency): {'half_width', 'sd'} per parameter, 'cov' (8 x 8 list),
        'params', 'z', 'level', 'f_min_hz', 'f_max_hz', 'n_bins' (used), 'masked_hz'
        (line bins dropped inside the band), 'lines_hz', 'covariance_term', 'seconds'."""
        top = np.inf if f_max_hz is None else f_max_hz
        band = (self.freqs > f_min_hz) & (self.freqs < top)
        used = band & ~self.masked
        info = self.info[used].sum(axis=0)
        cov = np.linalg.inv(info)
        sd = np.sqrt(np.diag(cov))
        return {"params": list(self.params),
                "half_width": {p: float(z * s) for p, s in zip(self.params, sd, strict=True)},
                "sd": {p: float(s) for p, s in zip(self.params, sd, strict=True)},
                "cov": cov.tolist(), "z": z, "level": 0.90 if z == Z90 else None,
                "f_min_hz": f_min_hz,
                "f_max_hz": float(self.freqs[band][-1]) if f_max_hz is None else f_max_hz,
                "n_bins": int(used.sum()), "masked_hz": self.freqs[band & self.masked].tolist(),
                "lines_hz": list(self.lines_hz), "covariance_term": self.covariance_term,
                "seconds": self.seconds}


def _shifted(spec: CaseSpec, j: int, h: float, c_ref: float) -> CaseSpec:
    a = AXES[j % 4]
    if j < 4:
        return replace(spec, k_theta={**spec.k_theta, a: spec.k_theta[a] + h})
    return replace(spec, c_nsm={**spec.c_nsm, a: spec.c_nsm[a] + h * c_ref})


def check_linear(spec: CaseSpec) -> None:
    """Refuse what the oracle does not model (ValueError)."""
    bad = [e.name for e in spec.effects if e.name in NONLINEAR or e.name == "ks_drift"]
    if bad:
        raise ValueError(f"the Fisher oracle needs a linear time-invariant loop; {bad}")


def fisher_information(spec: CaseSpec, *, controller: Controller | str | None = None,
                       rig: Rig | None = None, step: float = 1e-3,
                       covariance_term: bool = False) -> FisherBins:
    """The per-bin Fisher information of the case's record (see the module doc).
    ``step``: the central finite-difference step in theta units (k: -, c: c / c_ref)."""
    t0 = time.perf_counter()
    check_linear(spec)
    rig = rig or load_rig()
    ctrl = _controller(spec, controller)
    if abs(ctrl.dt - spec.dt) > 1e-12 * spec.dt:
        raise ValueError(f"controller dt {ctrl.dt} differs from the case dt {spec.dt}")
    N = round(spec.duration_s / spec.dt)
    k = np.arange(1, (N + 1) // 2)            # 0 < f_k < Nyquist
    w = 2 * np.pi * k / N
    z = np.exp(1j * w)
    freqs = k / (N * spec.dt)
    K = controller_frf(ctrl, z)
    src = source_psd(spec, w)
    maps = loop_frf(spec, rig, K, z)
    Phi = disturbance_psd(maps, src)
    dT, dPhi = [], []
    for j in range(len(PARAMS)):
        up, dn = (loop_frf(_shifted(spec, j, s * step, rig.c_ref), rig, K, z) for s in (1, -1))
        dT.append((up["T"] - dn["T"]) / (2 * step))
        if covariance_term:
            dPhi.append((disturbance_psd(up, src) - disturbance_psd(dn, src)) / (2 * step))
    exc = [i for i, a in enumerate(AXES) if a in spec.habits.eta_channels]
    a2 = spec.habits.eta_amplitude_a ** 2
    L = np.linalg.cholesky(Phi)
    G = np.linalg.solve(L, np.concatenate([d[:, :, exc] for d in dT], axis=2))
    G = G.reshape(G.shape[0], 4, len(PARAMS), len(exc))
    info = 2 * a2 * np.real(np.einsum("krjc,krlc->kjl", np.conj(G), G))
    if covariance_term:
        Q = np.stack([np.linalg.solve(Phi, d) for d in dPhi], axis=1)     # (K, 8, 4, 4)
        info += np.real(np.einsum("kjab,klba->kjl", Q, Q))
    lines = line_frequencies(spec)
    df = 1.0 / (N * spec.dt)
    masked = np.zeros(freqs.size, bool)
    for f in lines:
        masked |= np.abs(freqs - f) < df * (1 - 1e-9)
    info[masked] = 0.0
    return FisherBins(freqs, info, masked, tuple(lines), PARAMS, covariance_term,
                      time.perf_counter() - t0)


def fisher_widths(spec: CaseSpec, f_max_hz: float | None = None, *, f_min_hz: float = 0.0,
                  controller: Controller | str | None = None, rig: Rig | None = None,
                  step: float = 1e-3, covariance_term: bool = False) -> dict[str, Any]:
    """The Cramer-Rao 90 % half-widths (1.645 sd) of the eight bearing coefficients (truth
    'theta' units) on the case's record, from the bins f_min_hz < f < f_max_hz (None: up
    to the Nyquist frequency). See :meth:`FisherBins.widths` for the keys; several bands
    from one computation: ``fisher_information(spec).widths(f)``."""
    return fisher_information(spec, controller=controller, rig=rig, step=step,
                              covariance_term=covariance_term).widths(f_max_hz, f_min_hz)


def spec_from_truth(truth: dict[str, Any], controller_file: str | None = None) -> CaseSpec:
    """The CaseSpec a written record was simulated from, read back from its truth file's
    dict (NAME.truth.json): the oracle of a record already written,
    ``fisher_widths(spec_from_truth(json.load(f)), controller=...)``."""
    h = dict(truth["habits"])
    h["mains_m"] = {float(k): float(v) for k, v in h["mains_m"].items()}
    habits = Habits(**{k: tuple(v) if isinstance(v, list) else v for k, v in h.items()})
    dist = None
    if truth.get("disturbance"):
        d = {k: v for k, v in truth["disturbance"].items() if k not in ("held_out", "draws")}
        d["mains_m"] = {float(k): tuple(v) for k, v in d["mains_m"].items()}
        dist = Disturbance(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})
    return CaseSpec(kind=truth["kind"], truth=truth["truth"], n_bending=truth["n_bending"],
                    static_correction=truth["static_correction"],
                    speed_rpm=truth["speed_rpm"], speed_rpm_true=truth["speed_rpm_true"],
                    k_theta={a: truth["theta"][f"k_{a}"] for a in AXES},
                    c_nsm={a: truth["bearings"][a]["c_ns_per_m"] for a in AXES},
                    effects=tuple(Effect(e["name"], e["params"]) for e in truth["effects"]),
                    habits=habits, dt=truth["dt"], duration_s=truth["duration_s"],
                    controller_file=controller_file, disturbance=dist)
