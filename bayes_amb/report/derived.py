"""Quantities the report derives from a run and its recording (no plotting here).

Nothing estimated is recomputed: theta is the posterior mean from summary.json. What follows
from it and the recording is evaluated here: G(theta) and S(theta) poles and zeros,
sensitivities with the full plant, the prediction S(theta) x, the residual, its spectra,
SNR and correlation tests.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray
from scipy import signal, stats

from bayes_amb.control.discrete import ss_freqresp, zoh
from bayes_amb.control.robustness import sensitivity
from bayes_amb.inference.forward import ForwardModel
from bayes_amb.inference.offline import dual_youla_eps
from bayes_amb.reduction.fidelity import state_space_frequency_response
from bayes_amb.report.collect import RunData
from bayes_amb.rig import CHANNELS
from bayes_amb.rotor import FullModel
from bayes_amb.uncertainty import lft_full

__all__ = ["Derived", "PoleZeroSet", "ResidualTests", "channel_zeros", "controller_data",
           "derive", "residual_tests", "snr_table", "time_window", "welch", "xcorr"]

Z99 = 2.5758
"""Two-sided 99 % point of the standard normal (bounds of Ljung ch. 16)."""


@dataclass(frozen=True)
class PoleZeroSet:
    """Poles and (transmission) zeros of one system: complex arrays; ``label`` its name.

    Continuous systems in rad/s, discrete systems in the z-plane.
    """

    label: str
    poles: NDArray
    zeros: NDArray


@dataclass
class Derived:
    """Everything the model, controller, data and validation sections share.

    theta (p,) the posterior mean (MAP after a MAP-only run); t (N,) s; x (N, 4) the
    excitation; eps (N, 4) m the recorded innovation; signal = S(theta) x and
    residual = eps - signal, (N, 4) m.
    """

    forward: ForwardModel
    full: FullModel
    theta: NDArray
    t: NDArray
    x: NDArray
    eps: NDArray
    signal: NDArray
    residual: NDArray

    @property
    def dt(self) -> float:
        return float(self.forward.dt)


def derive(run: RunData) -> Derived:
    """Build the forward model of the recording and evaluate S(theta_mean) x."""
    rec = run.recording
    if rec is None:
        raise ValueError("derive() needs the recording")
    fwd = ForwardModel(rec, run.names)
    theta = run.theta_point()
    if run.posterior is not None:
        eps = np.asarray(run.posterior["observed_data"]["eps"].values, dtype=float)
    else:
        eps = dual_youla_eps(fwd.parts, np.asarray(rec.y), np.asarray(rec.u))
    sig = fwd.simulate(theta)
    t = np.arange(eps.shape[0]) * rec.dt
    return Derived(fwd, fwd.reduced.full, theta, t, fwd.x, eps, sig, eps - sig)


def channel_zeros(A: NDArray, B: NDArray, C: NDArray, j: int, limit: float) -> NDArray:
    """Finite zeros of the SISO channel j -> j (input j, output j) with |z| <= limit:
    generalised eigenvalues of the Rosenbrock pencil [[A, b_j], [c_j, 0]] - s [[I, 0],
    [0, 0]]. (S(theta) has the rank of the LFT channels, often 1, so its MIMO invariant
    zeros are not defined; a channel's zeros are.)

    Examples
    --------
    >>> A = np.array([[-1.0, 0.0], [0.0, -2.0]]); B = np.array([[1.0], [1.0]])
    >>> C = np.array([[1.0, 1.0]])       # (s + 2 + s + 1) / ((s + 1)(s + 2)): zero at -1.5
    >>> channel_zeros(A, B, C, 0, 10.0).real.round(6).tolist()
    [-1.5]
    """
    n = A.shape[0]
    M = np.block([[A, B[:, j:j + 1]], [C[j:j + 1], np.zeros((1, 1))]])
    N = np.zeros_like(M)
    N[:n, :n] = np.eye(n)
    with np.errstate(all="ignore"):
        z = sla.eigvals(M, N)
    return z[np.isfinite(z) & (np.abs(z) <= limit)]


def welch(x: NDArray, dt: float) -> tuple[NDArray, NDArray]:
    """One-sided Welch PSD per column: (freq Hz, psd (n_f, 4)) in unit^2/Hz."""
    n = x.shape[0]
    nper = int(min(n, max(64, 2 ** int(np.log2(max(n // 8, 64))))))
    return signal.welch(x, fs=1.0 / dt, nperseg=nper, axis=0)


def xcorr(a: NDArray, b: NDArray, max_lag: int) -> tuple[NDArray, NDArray]:
    """Normalised cross-correlation r(k) = corr(a[t + k], b[t]), k = -max_lag..max_lag,
    per column pair; returns (lags, r (2 max_lag + 1, n_cols))."""
    a = a - a.mean(axis=0)
    b = b - b.mean(axis=0)
    n = a.shape[0]
    nfft = int(2 ** np.ceil(np.log2(2 * n)))
    r = np.fft.irfft(np.fft.rfft(a, nfft, axis=0) * np.conj(np.fft.rfft(b, nfft, axis=0)),
                     nfft, axis=0)
    den = n * a.std(axis=0) * b.std(axis=0)
    den = np.where(den > 0, den, np.inf)
    lags = np.arange(-max_lag, max_lag + 1)
    return lags, r[lags % nfft] / den


@dataclass(frozen=True)
class ResidualTests:
    """Whiteness and independence of the residual (Ljung ch. 16), per channel.

    acf (L + 1, 4) for lags 0..L with bound, the 99 % bound of white data; ccf (2 L + 1, 4)
    residual j against excitation j with bound_cross (4,) its 99 % bound under
    independence (Bartlett: var = (1 + 2 sum_m rho_eps(m) rho_x(m)) / N, so a coloured
    residual or excitation widens it). frac_auto / frac_cross (4,): fraction of lags
    outside the bounds (cross: against all four excitation channels); limit_*: the
    fraction clean data exceed with probability 1 % (binomial); z_cross (4,) the largest
    |r| / sd over all lags and excitation channels, z_limit its 99 % family-wise limit.
    """

    lags_auto: NDArray
    acf: NDArray
    bound: float
    lags_cross: NDArray
    ccf: NDArray
    bound_cross: NDArray
    frac_auto: NDArray
    frac_cross: NDArray
    limit_auto: float
    limit_cross: float
    z_cross: NDArray
    z_limit: float

    @property
    def model_error(self) -> NDArray:
        """Per residual channel: does it correlate with the excitation (bool (4,))?"""
        return (self.frac_cross > self.limit_cross) | (self.z_cross > self.z_limit)


def residual_tests(d: Derived, max_lag: int = 40) -> ResidualTests:
    """Autocorrelation of the residual and its cross-correlation with the excitation."""
    n = d.residual.shape[0]
    L = int(min(max_lag, max(5, n // 10)))
    _, acf_r = xcorr(d.residual, d.residual, L)
    _, acf_x = xcorr(d.x, d.x, L)
    rho_r, rho_x = acf_r[L + 1:], acf_x[L + 1:]                       # lags 1..L
    var = (1.0 + 2.0 * np.einsum("mj,mi->ji", rho_r, rho_x)) / n       # (res j, exc i)
    sd = np.sqrt(np.maximum(var, 0.25 / n))
    frac_cross, z_cross = np.zeros(4), np.zeros(4)
    ccf = np.zeros((2 * L + 1, 4))
    for j in range(4):
        lags, r = xcorr(np.repeat(d.residual[:, j:j + 1], 4, axis=1), d.x, L)  # (lags, i)
        z = np.abs(r) / sd[j][None, :]
        frac_cross[j] = float(np.mean(z > Z99))
        z_cross[j] = float(np.max(z))
        ccf[:, j] = r[:, j]
    bound = Z99 / np.sqrt(n)
    frac_auto = np.mean(np.abs(acf_r[L + 1:]) > bound, axis=0)
    n_c = 4 * (2 * L + 1)
    return ResidualTests(np.arange(L + 1), acf_r[L:], bound, lags, ccf,
                         Z99 * np.diagonal(sd).copy(), frac_auto, frac_cross,
                         float(stats.binom.ppf(0.99, L, 0.01) / L),
                         float(stats.binom.ppf(0.99, n_c, 0.01) / n_c), z_cross,
                         float(stats.norm.isf(0.005 / n_c)))


def snr_table(d: Derived, band_hz: float | None = None) -> list[dict[str, float]]:
    """Per channel: RMS of x, of eps, of S(theta) x and of the residual (m), the SNR in dB
    over the whole band and (``band_hz``) over 0 < f <= band_hz, the band the likelihood
    uses."""
    f = np.fft.rfftfreq(d.signal.shape[0], d.dt)
    in_band = (f > 0) & (f <= (band_hz if band_hz is not None else np.inf))
    ps = np.sum(np.abs(np.fft.rfft(d.signal, axis=0)[in_band]) ** 2, axis=0)
    pr = np.sum(np.abs(np.fft.rfft(d.residual, axis=0)[in_band]) ** 2, axis=0)
    out = []
    for j in range(4):
        s, r = float(np.std(d.signal[:, j])), float(np.std(d.residual[:, j]))
        snr = 20 * np.log10(s / r) if r > 0 and s > 0 else float("inf")
        band = 10 * np.log10(ps[j] / pr[j]) if pr[j] > 0 and ps[j] > 0 else float("inf")
        out.append({"eps_rms": float(np.sqrt(np.mean(d.eps[:, j] ** 2))), "signal_rms": s,
                    "residual_rms": r, "snr_db": snr, "snr_band_db": float(band),
                    "x_rms": float(np.sqrt(np.mean(d.x[:, j] ** 2)))})
    return out


def time_window(t: NDArray, span: float | None = None) -> tuple[float, float]:
    """A window of ``span`` s (default: 150 samples, at most 0.05 s) in the middle of the
    record, or the whole record when it is shorter."""
    if span is None:
        span = min(0.05, 150 * float(t[1] - t[0]))
    if t[-1] - t[0] <= span:
        return float(t[0]), float(t[-1])
    mid = 0.5 * (t[0] + t[-1])
    return mid - span / 2, mid + span / 2



def controller_data(run: RunData, d: Derived, n_freq: int = 300) -> dict[str, Any]:
    """Poles of G and S with the zeros of their most affected diagonal channel,
    sensitivities (nominal and identified full plant) and the plant singular values
    (nominal, identified, true when known)."""
    rec, fwd, th = run.recording, d.forward, d.theta
    pl = fwd.plant
    A_S, B_S, C_S = (np.asarray(m[0]) for m in fwd.excitation_system(th[None]))
    z = np.exp(1j * np.linspace(1e-3, np.pi, 200))
    gain = np.abs(np.diagonal(ss_freqresp(A_S, B_S, C_S, None, z), axis1=1, axis2=2))
    j = int(np.argmax(gain.max(axis=0)))
    A_th = pl.A_theta(th)
    lim = 100.0 * float(np.max(np.abs(np.linalg.eigvals(pl.A))))
    g_nom = PoleZeroSet("nominal G(0)", np.linalg.eigvals(pl.A),
                        channel_zeros(pl.A, pl.B, pl.C, j, lim))
    g_id = PoleZeroSet("identified G(θ̂)", np.linalg.eigvals(A_th),
                       channel_zeros(A_th, pl.B, pl.C, j, lim))
    s_id = PoleZeroSet("S(θ̂)", np.linalg.eigvals(A_S), channel_zeros(A_S, B_S, C_S, j, 10.0))
    c = rec.controller
    K = (c.A, c.B[:, :4], c.C[:4], c.D[:4, :4])
    Ap, Bp = zoh(d.full.A, d.full.B, rec.dt)
    sens_nom = sensitivity(Ap, Bp, d.full.C, K, rec.dt, n_freq=n_freq)
    A_full_th = lft_full(d.full, rec.rig, run.names).A_theta(th)
    Ap_th, Bp_th = zoh(A_full_th, d.full.B, rec.dt)
    sens_id = sensitivity(Ap_th, Bp_th, d.full.C, K, rec.dt, n_freq=n_freq)
    w = np.logspace(1, np.log10(5e4), 300)
    curves = [("nominal G(0)", _sv(pl.A, pl.B, pl.C, w)),
              ("identified G(θ̂)", _sv(A_th, pl.B, pl.C, w))]
    true = run.true_theta()
    if true:
        A_true = pl.A_theta(np.array([true[n] for n in run.names]))
        curves.append(("true G(θ) (simulated)", _sv(A_true, pl.B, pl.C, w)))
    return {"g": (g_nom, g_id), "s": s_id, "channel": CHANNELS[j],
            "sens": (sens_nom, sens_id), "sv": (w, curves),
            "full_states": int(d.full.n_states), "rig_name": rec.rig.name}


def _sv(A: NDArray, B: NDArray, C: NDArray, w: NDArray) -> NDArray:
    return np.linalg.svd(state_space_frequency_response(A, B, C, 1j * w), compute_uv=False)


