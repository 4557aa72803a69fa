"""The identified plant closed with the controller that ran: closed-loop modes and
sensitivities in a rotordynamics engineer's terms.

The plant is the full FE model (eq. 17) with the identified parameters put in physically
(:func:`bayes_amb.uncertainty.physical_change`), or the 8-state reduced LFT model
(``model="reduced"``). It is sampled exactly (ZOH) at the controller's dt and closed with the
recorded controller (its y -> u part, excitation ports at zero), u = K y (positive
feedback, :func:`bayes_amb.control.robustness.closed_loop_matrix`).

Continuous equivalent of a discrete closed-loop eigenvalue z: lambda = ln(z)/dt, on the
branch whose frequency is nearest to the open-loop mode that dominates the eigenvector (a
bending mode above the Nyquist frequency is aliased by the principal logarithm; this puts it
back where it is). Then

    f = Im(lambda)/(2 pi) Hz,   zeta = -Re(lambda)/|lambda|,
    log dec = 2 pi zeta / sqrt(1 - zeta^2) = -2 pi Re(lambda)/Im(lambda).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bayes_amb.control.discrete import zoh
from bayes_amb.control.robustness import closed_loop_matrix
from bayes_amb.errors import BayesAmbError
from bayes_amb.io.controller_file import ControllerFile
from bayes_amb.reduction import reduce_pseudo_modal
from bayes_amb.rig import Rig
from bayes_amb.rotor import assemble, state_matrices
from bayes_amb.rotor.assembly import RotorMatrices
from bayes_amb.uncertainty import get_spec, lft_reduced, physical_change

__all__ = ["API617_LOGDEC", "MODEL_KINDS", "MODE_LABELS", "LoopModes", "closed_loop_modes",
           "log_decrement", "plant_matrices"]

MODEL_KINDS = ("full", "reduced")
ZETA_MODE = 0.9
"""Closed-loop eigenvalues with a damping ratio at or above this are not counted as modes."""
N_RIGID_PAIRS = 4
"""Underdamped closed-loop modes reported for the suspended rigid body (lowest first)."""
RIGID_SHARE = 0.5
"""A closed-loop mode is a rigid-body mode when more than this share of its kinetic energy
is rigid-body motion (:func:`closed_loop_modes`)."""
API617_LOGDEC = 0.1
"""API 617-style stability criterion: every closed-loop mode with log dec > 0.1."""

MODE_LABELS = ("rigid 1", "rigid 2", "rigid 3", "rigid 4", "bending 1 (lower)",
               "bending 1 (upper)")
"""Labels of the reported closed-loop modes, in the order of :attr:`LoopModes.lam`."""


def log_decrement(lam: NDArray) -> NDArray:
    """Logarithmic decrement of continuous eigenvalues: -2 pi Re(lambda)/|Im(lambda)|.

    Equal to 2 pi zeta / sqrt(1 - zeta^2) with zeta = -Re/|lambda|; inf for a real
    (overdamped) eigenvalue in the left half-plane.

    Examples
    --------
    >>> float(log_decrement(np.array([-1.0 + 10.0j]))[0].round(6))
    0.628319
    """
    lam = np.asarray(lam, dtype=complex)
    with np.errstate(divide="ignore", invalid="ignore"):
        return -2 * np.pi * lam.real / np.abs(lam.imag)


_CACHE: dict[tuple, tuple[Rig, object]] = {}
_CACHE_LOCK = threading.RLock()     # the points of quantities.py run in a pool of threads;
                                    # reentrant: one entry's make() may need another's


def _cached(rig: Rig, key: tuple, make):
    """Per-rig memo (rigs are not hashable; the rig object is kept with its entry)."""
    k = (id(rig), *key)
    with _CACHE_LOCK:
        hit = _CACHE.get(k)
        if hit is None or hit[0] is not rig:
            if len(_CACHE) > 64:
                _CACHE.clear()
            hit = _CACHE[k] = (rig, make())
        return hit[1]


def _matrices(rig: Rig) -> RotorMatrices:
    return _cached(rig, ("mats",), lambda: assemble(rig))


def plant_matrices(rig: Rig, speed_rpm: float, theta: dict[str, float],
                   model: str = "full") -> tuple[NDArray, NDArray, NDArray]:
    """Continuous (A, B, C) of the plant with the parameters ``theta`` (name -> value).

    ``full``: the rig's full-order FE model with the physical changes dK, dC of each parameter;
    ``reduced``: the 8-state pseudo-modal reduction with the reduced LFT (eqs. 51-52).
    """
    if model not in MODEL_KINDS:
        raise BayesAmbError(f"option model: expected one of {list(MODEL_KINDS)}, got {model!r}")
    mats = _matrices(rig)
    if model == "reduced":
        red = _reduced(rig, float(speed_rpm))
        if not theta:
            return red.A, red.B, red.C
        up = lft_reduced(red, rig, tuple(theta))
        return up.A_theta([theta[n] for n in up.names]), red.B, red.C
    dK = np.zeros((mats.n_q, mats.n_q))
    dC = np.zeros_like(dK)
    for name, th in theta.items():
        k, c = physical_change(get_spec(name), rig, float(th), mats.n_q)
        dK += k
        dC += c
    return state_matrices(mats, speed_rpm, dK, dC)


def _reduced(rig: Rig, speed_rpm: float):
    from bayes_amb.rotor import full_model

    return _cached(rig, ("reduced", speed_rpm), lambda: reduce_pseudo_modal(
        full_model(rig, speed_rpm, _matrices(rig))))


@dataclass(frozen=True)
class _Basis:
    """Open-loop modes of the nominal plant at one speed: lam (n,), W = V^-1 with the
    columns of V scaled to unit displacement norm, the index sets of the rigid-body and
    first-bending modes, and V_rigid (n, 8) the rigid-body columns of V."""

    lam: NDArray
    W: NDArray
    rigid: NDArray
    bending: NDArray
    V_rigid: NDArray


def _basis(rig: Rig, speed_rpm: float, model: str) -> _Basis:
    return _cached(rig, ("basis", speed_rpm, model), lambda: _make_basis(rig, speed_rpm, model))


def _make_basis(rig: Rig, speed_rpm: float, model: str) -> _Basis:
    A, _B, _C = plant_matrices(rig, speed_rpm, {}, model)
    lam, V = np.linalg.eig(A)
    order = np.lexsort((lam.imag, np.abs(lam)))
    lam, V = lam[order], V[:, order]
    n_pos = A.shape[0] // 2 if model == "full" else A.shape[0]
    scale = np.linalg.norm(V[:n_pos], axis=0) if model == "full" else np.linalg.norm(V, axis=0)
    V = V / np.where(scale > 0, scale, 1.0)
    rigid = np.arange(min(8, lam.size))
    rest = np.arange(8, lam.size)
    under = rest[np.abs(lam[rest].imag) > np.abs(lam[rest].real)]
    bending = under[:4]                      # backward and forward whirl, with conjugates
    return _Basis(lam=lam, W=np.linalg.inv(V), rigid=rigid, bending=bending,
                  V_rigid=V[:, rigid])


def _rigid_kinetic_share(basis: _Basis, x: NDArray, mass: NDArray | None) -> NDArray:
    """Share of each plant eigenvector's kinetic energy in its rigid-body part.

    x (n, m): plant parts of closed-loop eigenvectors, [q; q'] (full model). The rigid-body
    part is V_rigid W_rigid x; with v and v_r the velocity rows of x and of that part,
    T_r = v_r^H M v_r and T_f = (v - v_r)^H M (v - v_r), and the share is T_r / (T_r + T_f).
    In the reduced model every state is rigid-body (share 1).
    """
    if mass is None or basis.rigid.size == basis.lam.size:
        return np.ones(x.shape[1])
    n_q = x.shape[0] // 2
    v = x[n_q:]
    v_r = basis.V_rigid[n_q:] @ (basis.W[basis.rigid] @ x)
    v_f = v - v_r
    t_r = np.einsum("in,in->n", v_r.conj(), mass @ v_r).real
    t_f = np.einsum("in,in->n", v_f.conj(), mass @ v_f).real
    total = t_r + t_f
    return t_r / np.where(total > 0, total, 1.0)


@dataclass(frozen=True)
class LoopModes:
    """Closed-loop modes of one plant at one speed.

    lam (6,) continuous-equivalent eigenvalues in rad/s (Im > 0), in the order of
    MODE_LABELS, nan where the mode is not underdamped; eig (n,) every discrete
    closed-loop eigenvalue; V (n, n) its right eigenvectors (W = V^-1 on demand); B_d
    (n, 4) the closed loop's input matrix of an output disturbance d (y = G u + d), C_y
    (4, n) its output y, so that S(z) = I + C_y V diag(1/(z - eig)) W B_d (output sensitivity); B_u
    (n, 4) the plant-input current.
    """

    lam: NDArray
    eig: NDArray
    V: NDArray
    B_d: NDArray
    C_y: NDArray
    B_u: NDArray
    dt: float

    @property
    def W(self) -> NDArray:
        """V^-1 (computed on first use)."""
        w = self.__dict__.get("_W")
        if w is None:
            w = np.linalg.inv(self.V)
            object.__setattr__(self, "_W", w)
        return w

    def sensitivity_diag(self, freq_hz: NDArray) -> NDArray:
        """|diag (I - G K)^-1| per axis at ``freq_hz`` (Hz), shape (n_f, 4)."""
        z = np.exp(2j * np.pi * np.asarray(freq_hz) * self.dt)
        left = self.C_y @ self.V                           # (4, n)
        right = self.W @ self.B_d                          # (n, 4)
        prod = left * right.T                              # (4, n): diagonal terms
        S = 1.0 + (1.0 / (z[:, None] - self.eig[None])) @ prod.T
        return np.abs(S)

    def input_response(self, freq_hz: NDArray) -> NDArray:
        """Closed-loop y per plant-input current (m/A), C_y (zI - A_cl)^-1 B_u, (n_f, 4, 4)."""
        z = np.exp(2j * np.pi * np.asarray(freq_hz) * self.dt)
        left = self.C_y @ self.V
        right = self.W @ self.B_u
        return np.einsum("in,fn,nj->fij", left, 1.0 / (z[:, None] - self.eig[None]), right)


def closed_loop_modes(rig: Rig, controller: ControllerFile, speed_rpm: float,
                      theta: dict[str, float], model: str = "full") -> LoopModes:
    """Closed-loop modes of the plant with ``theta`` under ``controller`` at ``speed_rpm``.

    Rigid-body modes: the underdamped (zeta < 0.9) closed-loop eigenvalues in which the
    rotor moves mostly as a rigid body: more than half (RIGID_SHARE) of the kinetic energy
    of the eigenvector's plant part is in its component along the nominal plant's 8
    suspended rigid-body modes. Lowest frequency first, the first four kept. First bending:
    the two closed-loop eigenvalues with most modal displacement energy in the first
    bending pair (backward and forward whirl), by frequency.

    Kinetic energy, not displacement, because a bending mode can alias into the rigid-body
    band. Sampled at dt, a bending vibration at f_b appears at its alias |f_b - k/dt|; the
    controller answers with a staircase current at that frequency and moves the rotor as a
    rigid body there. This forced rigid motion is large in displacement and small in
    velocity. On the reference rig at 1 ms, the second bending pair's forward whirl (3094.6
    Hz at 31500 rpm) becomes a closed-loop mode at 94.5 Hz (zeta 0.23). Of that mode,
    76 % of the modal displacement energy but 0.3 % of the kinetic energy is in the
    rigid-body modes. Counted by displacement, it qualified above about 30000 rpm (its
    alias rises with speed), took the label rigid 1 as the lowest, and the labels jumped by
    up to 40 Hz between speeds 125-250 rpm apart. By kinetic energy, over 0.8-1.05 x 31500 rpm
    (nominal plant and k_By = 0.5), the four rigid-body modes score > 0.99 and every other
    underdamped mode below them < 0.01. At 31500 rpm they are the regulator poles the
    controller placed, eig(A + B F) of its design model, moved by 0.2-2 % by the bending
    modes the design left out (test_rigid_modes_are_the_regulator_poles). Where an alias
    falls onto a rigid-body mode, the two mix, and their shares lie near 0.5 (measured
    0.48-0.82: near standstill, rigid 4 with the second bending pair's backward whirl; at
    57000-58100 rpm, the 140 Hz pair with a 7.1 kHz mode). There a label can change branch.

    Rigid-body modes are numbered by frequency, not tracked by mode shape. On the reference
    rig at 31500 rpm and 1 ms, rigid 2 and 3 are a nearly degenerate, heavily damped pair
    (nominal: 140.28 and 140.57 Hz in the full plant, orthogonal shapes). A bearing change
    mixes the shapes: at k_By = 0.3, c_By = 0.2 the modal assurance criterion is 0.96
    between rigid 3 and 4 (147.8 and 153.5 Hz in the full plant, 146.7 and 152.0 in the
    reduced one; they veer near an exceptional point at (0.27, 0.16)) and 0.42 between
    rigid 2 and 3 (0.49 reduced). A label matched to the nominal shapes is ill-defined
    there and jumps between draws. The frequency
    order, by contrast, is what eigenvalue continuation gives over the posterior
    (tests/test_engineering.py::test_rigid_modes_keep_their_frequency_order).
    """
    dt = controller.dt
    A, B, C = plant_matrices(rig, speed_rpm, theta, model)
    Ad, Bd = zoh(A, B, dt)
    Ak, Bk, Ck, Dk = (np.asarray(controller.A), np.asarray(controller.B[:, :4]),
                      np.asarray(controller.C[:4]), np.asarray(controller.D[:4, :4]))
    Acl = closed_loop_matrix(Ad, Bd, C, Ak, Bk, Ck, Dk)
    eig, V = np.linalg.eig(Acl)
    n = Ad.shape[0]
    basis = _basis(rig, float(speed_rpm), model)
    eta = basis.W @ V[:n]                                   # open-loop modal content
    energy = np.abs(eta) ** 2
    total = energy.sum(axis=0)
    frac_b = energy[basis.bending].sum(axis=0) / np.where(total > 0, total, 1.0)
    kin_r = _rigid_kinetic_share(basis, V[:n], _matrices(rig).M if model == "full" else None)
    # continuous equivalent on the branch of the dominating open-loop mode
    dom = np.argmax(energy, axis=0)
    ref = np.abs(basis.lam[dom].imag) * np.sign(eig.imag)
    principal = np.log(eig.astype(complex))
    m = np.round((ref * dt - principal.imag) / (2 * np.pi))
    m = np.where((total > 0) & (np.abs(eig.imag) > 1e-12 * np.abs(eig)), m, 0.0)
    lam_c = (principal + 2j * np.pi * m) / dt
    zeta = -lam_c.real / np.where(np.abs(lam_c) > 0, np.abs(lam_c), 1.0)
    under = (lam_c.imag > 0) & (zeta < ZETA_MODE)
    out = np.full(len(MODE_LABELS), np.nan + 0j)
    rig_idx = np.flatnonzero(under & (kin_r > RIGID_SHARE))
    rig_idx = rig_idx[np.argsort(lam_c[rig_idx].imag)]
    rig_idx = rig_idx[:N_RIGID_PAIRS]
    out[:rig_idx.size] = lam_c[rig_idx]
    if basis.bending.size:
        cand = np.flatnonzero(under)
        top = cand[np.argsort(-frac_b[cand])][:2]
        top = top[np.argsort(lam_c[top].imag)]
        out[N_RIGID_PAIRS:N_RIGID_PAIRS + top.size] = lam_c[top]
    nk = Ak.shape[0]
    B_d = np.vstack([Bd @ Dk, Bk])
    C_y = np.hstack([C, np.zeros((C.shape[0], nk))])
    B_u = np.vstack([Bd, np.zeros((nk, Bd.shape[1]))])
    return LoopModes(lam=out, eig=eig, V=V, B_d=B_d, C_y=C_y, B_u=B_u, dt=dt)
