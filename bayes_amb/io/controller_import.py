"""Import the controller as shipped: MATLAB state space or per-axis transfer functions.

A .mat file (v5 or v7.3) holds either

- a state space ``A``, ``B``, ``C``, ``D`` (4 inputs: displacements Ax, Ay, Bx, By in m;
  4 outputs: coil currents in A) and a sample time ``Ts`` in s, or
- per-axis transfer functions ``num_Ax``, ``den_Ax``, ..., ``num_By``, ``den_By``
  (coefficients in descending powers of s or z; the controller is decentralised,
  diagonal) and ``Ts``.

``Ts = 0`` means continuous time. It is discretised at the recording's sample time ``dt``
with the stated method: ``"tustin"`` (bilinear, s = 2/dt (z-1)/(z+1); with
``prewarp_hz = f`` the substitution s = w/tan(w dt/2) (z-1)/(z+1), w = 2 pi f, matches
the response exactly at f) or ``"zoh"`` (exact zero-order hold of the controller's input).
A discrete controller (``Ts > 0``) must have ``Ts = dt``; it is not resampled.

Sign: ``feedback = "negative"`` (MATLAB's ``feedback(G, C)`` default, the usual
documentation: u = -C(s) y) or ``"positive"`` (u = K y, this package's convention).

The result is a ``kind = "generic"`` controller file (u = K y + r2, no innovation), used
by identification through the K-compatible coprime factors (METHOD.md section 3). The
import checks that K stabilises the rig's full FE plant (ZOH at dt, closed-loop spectral
radius < 1) and reports the peak sensitivities and the ISO 14839-3 zone.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.signal as sig
from numpy.typing import NDArray

from bayes_amb.errors import DataImportError
from bayes_amb.io.controller_file import (
    CONTROLLER_INPUTS,
    CONTROLLER_OUTPUTS,
    ControllerFile,
    short_repr,
)
from bayes_amb.io.daq import file_sha256
from bayes_amb.rig import CHANNELS, Rig, load_rig

__all__ = ["DISCRETISATION_METHODS", "ControllerImport", "checked_controller",
           "diagonal_state_space", "import_controller", "read_controller_mat"]

DISCRETISATION_METHODS = ("tustin", "zoh")
TS_RTOL = 1e-9


@dataclass(frozen=True, eq=False)
class ControllerImport:
    """An imported controller and its check on the rig.

    Attributes
    ----------
    controller : ControllerFile
        ``kind = "generic"``, discrete at ``dt``; ``design`` records the source, its sha256,
        the form, the sign convention and the discretisation.
    form : str
        ``"state space"`` or ``"transfer functions"``.
    discretisation : str
        How a continuous controller was discretised, or ``"none (discrete, Ts = dt)"``.
    spectral_radius : float
        Largest |eigenvalue| of the discrete closed loop with the full FE plant (< 1: stable).
    sensitivity_peak_db : dict
        Peak of each axis' sensitivity, dB.
    zone : str
        ISO 14839-3 zone (A-D) of the largest peak.
    speed_rpm : float
        Speed of the plant used for the check.
    """

    controller: ControllerFile
    form: str
    discretisation: str
    spectral_radius: float
    sensitivity_peak_db: dict[str, float]
    zone: str
    speed_rpm: float


def _mat_variables(p: Path) -> dict[str, NDArray]:
    """Top-level numeric variables of a .mat file as 2-D arrays in MATLAB orientation."""
    import h5py
    import scipy.io

    where = f"controller {p}"
    if not p.is_file():
        raise DataImportError(f"{where}: field <file>: not found")
    try:
        if h5py.is_hdf5(p):
            with h5py.File(p, "r") as f:
                return {k: np.atleast_2d(np.asarray(v[()])).T for k, v in f.items()
                        if isinstance(v, h5py.Dataset)}
        data = scipy.io.loadmat(p)
    except Exception as exc:  # third-party parsers raise many types on corrupt files
        raise DataImportError(f"{where}: field <file>: not a readable .mat file "
                              f"({type(exc).__name__}: {short_repr(str(exc), 100)})") from None
    return {k: v for k, v in data.items() if not k.startswith("__")}


def _real(vars_: dict[str, NDArray], name: str, where: str) -> NDArray:
    if name not in vars_:
        raise DataImportError(f"{where}: variable {name}: missing (have: "
                              f"{', '.join(sorted(vars_)) or 'nothing'})")
    a = np.asarray(vars_[name])
    if a.dtype.kind not in "biuf" or a.ndim > 2:
        raise DataImportError(f"{where}: variable {name}: expected a real matrix, got "
                              f"dtype {a.dtype} shape {a.shape}")
    a = np.atleast_2d(a.astype(float))
    if not np.all(np.isfinite(a)):
        raise DataImportError(f"{where}: variable {name}: contains NaN or inf")
    return a


def read_controller_mat(path: str | os.PathLike[str]
                        ) -> tuple[tuple[NDArray, NDArray, NDArray, NDArray], float, str]:
    """((A, B, C, D), Ts, form) of a MATLAB controller file (module docstring).

    Raises DataImportError naming the file and the variable.
    """
    p = Path(path)
    where = f"controller {p}"
    v = _mat_variables(p)
    ts = _real(v, "Ts", where)
    if ts.size != 1 or ts.flat[0] < 0:
        raise DataImportError(f"{where}: variable Ts: expected a scalar >= 0 (0: continuous),"
                              f" got {short_repr(ts.ravel().tolist())}")
    k = len(CHANNELS)
    if "A" in v or "D" in v:
        D = _real(v, "D", where)
        if D.shape != (k, k):
            raise DataImportError(f"{where}: variable D: expected shape ({k}, {k}) (currents "
                                  f"Ax..By from displacements Ax..By), got {D.shape}")
        if "A" in v and v["A"].size:
            A = _real(v, "A", where)
            n = A.shape[0]
            if A.shape != (n, n):
                raise DataImportError(f"{where}: variable A: expected a square matrix, got "
                                      f"{A.shape}")
            B, C = _real(v, "B", where), _real(v, "C", where)
        else:
            n, A, B, C = 0, np.zeros((0, 0)), np.zeros((0, k)), np.zeros((k, 0))
        for name, m, shape in (("B", B, (n, k)), ("C", C, (k, n))):
            if m.shape != shape and not (n == 0 and m.size == 0):
                raise DataImportError(f"{where}: variable {name}: expected shape {shape}, got "
                                      f"{m.shape}")
        return (A, B.reshape(n, k), C.reshape(k, n), D), float(ts.flat[0]), "state space"
    tfs = {ch: (_real(v, f"num_{ch}", where).ravel(), _real(v, f"den_{ch}", where).ravel())
           for ch in CHANNELS}
    return diagonal_state_space(tfs, where, "variable "), float(ts.flat[0]), \
        "transfer functions"


def balanced_realisation(A: NDArray, B: NDArray, C: NDArray, D: NDArray
                         ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """The same transfer function in a well-scaled realisation: a diagonal similarity that
    balances A's rows and columns (scipy.linalg.matrix_balance, no permutation), then one
    scale that gives B and C the same size. tf2ss's companion form of a high-order
    controller (a lead-lag and notch chain with poles at 10^3-10^4 rad/s) has entries from
    1e-5 to 1e25 and an eigenvector condition of 1e18; every later computation with it (the
    discretisation, the loop's noise filters) loses what that costs."""
    n = A.shape[0]
    if n == 0:
        return A, B, C, D
    _, (scale, _) = sla.matrix_balance(A, permute=False, separate=True)
    A = A * scale[None, :] / scale[:, None]
    B, C = B / scale[:, None], C * scale[None, :]
    b, c = np.linalg.norm(B), np.linalg.norm(C)
    if b > 0 and c > 0:
        a = np.sqrt(c / b)
        B, C = B * a, C / a
    return A, B, C, D


def diagonal_state_space(tfs: dict[str, tuple[NDArray, NDArray]], where: str,
                         field: str = "") -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """(A, B, C, D) of a decentralised controller: one SISO transfer function (num, den;
    descending powers) per channel Ax, Ay, Bx, By, from that channel's displacement to its
    current. Raises DataImportError naming the channel of an improper or empty one."""
    blocks = []
    for ch in CHANNELS:
        num, den = (np.asarray(c, dtype=float).ravel() for c in tfs[ch])
        den = np.trim_zeros(den, "f")
        if den.size == 0:
            raise DataImportError(f"{where}: {field}den_{ch}: all zero")
        if np.trim_zeros(num, "f").size > den.size:
            raise DataImportError(f"{where}: {field}num_{ch}: improper transfer function "
                                  f"(numerator degree {np.trim_zeros(num, 'f').size - 1} > "
                                  f"denominator degree {den.size - 1})")
        with warnings.catch_warnings():            # tf2ss's BadCoefficients on leading 0s
            warnings.simplefilter("ignore")
            blocks.append(balanced_realisation(*sig.tf2ss(num, den)))
    k = len(CHANNELS)
    A = sla.block_diag(*(b[0] for b in blocks))
    B = sla.block_diag(*(b[1] for b in blocks))
    C = sla.block_diag(*(b[2] for b in blocks))
    D = np.diag([float(np.asarray(b[3]).ravel()[0]) for b in blocks])
    n = A.shape[0]
    return A.reshape(n, n), B.reshape(n, k), C.reshape(k, n), D


def _discretise(K: tuple[NDArray, ...], dt: float, method: str, prewarp_hz: float | None,
                where: str) -> tuple[tuple[NDArray, ...], str]:
    from bayes_amb.control.discrete import zoh

    A, B, C, D = K
    if method == "zoh":
        if prewarp_hz is not None:
            raise DataImportError(f"{where}: option prewarp_hz: only with method 'tustin'")
        Ad, Bd = zoh(A, B, dt) if A.size else (A, B)
        return (Ad, Bd, C, D), f"zoh (exact zero-order hold) at dt = {dt!r} s"
    if method != "tustin":
        raise DataImportError(f"{where}: option method: expected one of "
                              f"{list(DISCRETISATION_METHODS)}, got {short_repr(method)}")
    T, text = dt, f"tustin (bilinear, no prewarping) at dt = {dt!r} s"
    if prewarp_hz is not None:
        w = 2 * np.pi * prewarp_hz
        if not (np.isfinite(w) and 0 < prewarp_hz < 0.5 / dt):
            raise DataImportError(f"{where}: option prewarp_hz: expected 0 < f < Nyquist "
                                  f"{0.5 / dt:g} Hz, got {prewarp_hz!r}")
        T = 2 * np.tan(w * dt / 2) / w
        text = f"tustin (bilinear) prewarped at {prewarp_hz:g} Hz, dt = {dt!r} s"
    if not A.size:
        return (A, B, C, D), text
    with warnings.catch_warnings():       # no raw LinAlgWarning reaches the user: the
        warnings.simplefilter("ignore")   # stability check below judges the result
        Ad, Bd, Cd, Dd, _ = sig.cont2discrete((A, B, C, D), T, method="bilinear")
    return tuple(np.asarray(m) for m in (Ad, Bd, Cd, Dd)), text


def _modal_sensitivity(Ap: NDArray, Bp: NDArray, Cp: NDArray, K: tuple[NDArray, ...],
                       dt: float, n_freq: int = 600) -> Any:
    """Per-axis sensitivity as :func:`bayes_amb.control.robustness.sensitivity` computes it
    (same grid), with G(z) = C V diag(1/(z - lambda)) V^-1 B from one eigendecomposition
    instead of one solve per frequency (about 100 times faster on the reference rig's
    320-state plant; relative difference of G about 3e-10 there)."""
    from bayes_amb.control.discrete import ss_freqresp
    from bayes_amb.control.robustness import sensitivity_from_response, sensitivity_grid

    lam, V = np.linalg.eig(Ap)
    CV, WB = Cp @ V, np.linalg.solve(V, Bp)
    w, z = sensitivity_grid(dt, n_freq)
    G = np.einsum("pn,zn,nm->zpm", CV, 1.0 / (z[:, None] - lam[None]), WB)
    return sensitivity_from_response(w, G, ss_freqresp(*K, z))


def import_controller(source: str | os.PathLike[str], rig: Rig | str | None = None, *,
                      dt: float | None = None, method: str = "tustin",
                      prewarp_hz: float | None = None, feedback: str = "negative",
                      speed_rpm: float | None = None) -> ControllerImport:
    """Import a MATLAB-style controller, discretise it, check it on the rig's full plant.

    Parameters
    ----------
    source : path
        .mat file (v5 or v7.3) with A, B, C, D, Ts or num_*/den_*, Ts (module docstring).
    rig : Rig or rig file, optional
        The rig it runs on (default: the reference rig).
    dt : float, optional
        Sample time in s; required for a continuous controller (Ts = 0), else Ts is used
        and must equal dt if both are given.
    method : {"tustin", "zoh"}
        Discretisation of a continuous controller.
    prewarp_hz : float, optional
        Tustin prewarping frequency, Hz.
    feedback : {"negative", "positive"}
        u = -K_file y (MATLAB convention) or u = +K_file y.
    speed_rpm : float, optional
        Speed of the plant for the stability check (default: the rig's nominal speed).

    Returns
    -------
    ControllerImport
        The controller file and its stability margin and ISO 14839-3 zone.

    Raises
    ------
    DataImportError
        A missing or malformed variable, a Ts that disagrees with dt, or a controller that
        does not stabilise the rig (the spectral radius is named).
    """
    p = Path(source)
    where = f"controller {p}"
    if feedback not in ("negative", "positive"):
        raise DataImportError(f"{where}: option feedback: expected 'negative' or 'positive', "
                              f"got {short_repr(feedback)}")
    K, ts, form = read_controller_mat(p)
    return checked_controller(K, ts, form, where, rig, dt=dt, method=method,
                              prewarp_hz=prewarp_hz, feedback=feedback, speed_rpm=speed_rpm,
                              source={"imported_from": str(p),
                                      "source_sha256": file_sha256(p)},
                              source_name=str(p))


def checked_controller(K: tuple[NDArray, NDArray, NDArray, NDArray], ts: float, form: str,
                       where: str, rig: Rig | str | None = None, *, dt: float | None = None,
                       method: str = "tustin", prewarp_hz: float | None = None,
                       feedback: str = "negative", speed_rpm: float | None = None,
                       source: dict[str, Any] | None = None, source_name: str = "",
                       hint: str = "") -> ControllerImport:
    """A controller (A, B, C, D) from displacements Ax..By (m) to currents (A), sample time
    ``ts`` (0: continuous), discretised at ``dt`` and checked on the rig's full FE plant, as
    a generic controller file (the shared end of every import: :func:`import_controller`,
    bayes_amb.io.ross_controller). ``hint`` is added to the refusal of an unstable loop."""
    from bayes_amb.control.robustness import (
        full_plant_discrete,
        loop_spectral_radius,
        unstable_where,
    )
    from bayes_amb.rotor import full_model

    if ts == 0:
        if dt is None or not (np.isfinite(dt) and dt > 0):
            raise DataImportError(f"{where}: variable Ts: 0 (continuous) needs a sample time "
                                  f"dt > 0 to discretise at, got {dt!r}")
        K, how = _discretise(K, float(dt), method, prewarp_hz, where)
    else:
        if dt is not None and abs(ts - dt) > TS_RTOL * dt:
            raise DataImportError(f"{where}: variable Ts: {ts!r} s but the sample time is "
                                  f"{dt!r} s (a discrete controller is not resampled)")
        dt, how = ts, f"none (discrete, Ts = {ts!r} s)"
    A, B, C, D = K
    if feedback == "negative":
        C, D = -C, -D
    rig_obj = rig if isinstance(rig, Rig) else load_rig(rig)
    fm = full_model(rig_obj, speed_rpm)
    Ap, Bp = full_plant_discrete(fm.A, fm.B, float(dt))
    rho = loop_spectral_radius(Ap, Bp, fm.C, (A, B, C, D))
    if not rho < 1.0:
        raise DataImportError(f"{where}: does not stabilise rig '{rig_obj.name}' at "
                              f"{fm.speed_rpm:g} rpm: closed-loop spectral radius {rho:.6g} "
                              f"(>= 1) on the {fm.A.shape[0]}-state plant, with feedback = "
                              f"'{feedback}' and {how}; "
                              + unstable_where(Ap, Bp, fm.C, (A, B, C, D), fm.A, float(dt))
                              + hint)
    sens = _modal_sensitivity(Ap, Bp, fm.C, (A, B, C, D), float(dt))
    n, k = A.shape[0], len(CHANNELS)
    Bk = np.hstack([B, np.zeros((n, k))])
    Ck = np.vstack([C, np.zeros((k, n))])
    Dk = np.block([[D, np.eye(k)], [np.zeros((k, k)), np.zeros((k, k))]])
    design: dict[str, Any] = {
        "kind": "generic", **(source or {}),
        "form": form, "feedback": feedback, "discretisation": how,
        "check": {"speed_rpm": fm.speed_rpm, "spectral_radius_full": rho,
                  "sensitivity_peak_db": sens.peak_db, "iso14839_zone": sens.zone}}
    ctrl = ControllerFile(dt=float(dt), A=A, B=Bk, C=Ck, D=Dk, inputs=CONTROLLER_INPUTS,
                          outputs=CONTROLLER_OUTPUTS, design=design,
                          rig="reference" if rig_obj.source == "reference" else rig_obj.to_dict(),
                          kind="generic", source=source_name)
    return ControllerImport(controller=ctrl, form=form, discretisation=how,
                            spectral_radius=rho, sensitivity_peak_db=sens.peak_db,
                            zone=sens.zone, speed_rpm=fm.speed_rpm)
