"""The S(theta) forward model of a recording, fast and exact, vectorised over theta.

For a batch of parameter vectors the exactly sampled plant ZOH(A + B_w Theta C_z) is formed
with a batched matrix exponential, the loop is diagonalised, and the forward prediction
eps_pred = S(theta) x is evaluated on the DFT grid of the record *including the exact
finite-record transient*, so that its DFT equals the DFT of the time-domain simulation from
rest (no circular-convolution error). For x(z) and a stable system (A, B, C):

    DFT(y)_k = C (z_k I - A)^-1 B X_k - C (z_k I - A)^-1 z_k x_N,    z_k = e^{2 pi j k / N}

with x_N the state after the last sample (computed from the last few hundred samples).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bayes_amb.control.design import design_observer_controller
from bayes_amb.control.discrete import zoh
from bayes_amb.errors import RecordingError
from bayes_amb.inference import kernels
from bayes_amb.inference.batched import zoh_batched, zoh_compiled
from bayes_amb.inference.eigen import final_state, modal_batch
from bayes_amb.inference.loop_model import (
    LoopParts,
    error_form_compiled,
    error_form_matrices,
    loop_matrices,
)
from bayes_amb.inference.model_band import choose_model, feedback_part, validity_hz
from bayes_amb.inference.triangular import (
    FixedBlock,
    exact_pairs,
    fixed_block,
    modal_triangular,
    takes,
)
from bayes_amb.io.recording import Recording
from bayes_amb.reduction import reduce_pseudo_modal
from bayes_amb.reduction.pseudo_modal import residual_static
from bayes_amb.rotor import full_model
from bayes_amb.uncertainty import UncertainPlant, lft_reduced, parse_param_list

_TRANSIENT_TOL = 1e-13

DEFAULT_ENGINE = kernels.Engine()
"""The compiled engine, for callers outside a model (a model carries its own)."""


def state_transform(A: NDArray, B: NDArray, C: NDArray, Ad: NDArray, Bd: NDArray,
                    Cd: NDArray, tol: float = 1e-7) -> NDArray | None:
    """T with (A, B, C) = (T Ad T^-1, T Bd, Cd T^-1), i.e. x = T x_d, or None if there is
    none (to ``tol``, relative, in each of the three equations).

    A controller file carries its own copy of the nominal reduced model. Its state basis is
    the reduction's, which is unique only up to a rotation inside a (nearly) repeated
    eigenspace: a file exported with other BLAS threads, or on another machine, may hold the
    same model in a rotated basis. T is found from the linear equations T Ad = A T,
    T Bd = B, C T = Cd by least squares, each block scaled to unit norm.

    >>> import numpy as np
    >>> Ad, Bd, Cd = np.diag([0.9, 0.8]), np.eye(2)[:, :1], np.ones((1, 2))
    >>> T = np.array([[1.0, 2.0], [0.5, 3.0]])
    >>> Ti = np.linalg.inv(T)
    >>> np.allclose(state_transform(T @ Ad @ Ti, T @ Bd, Cd @ Ti, Ad, Bd, Cd), T)
    True
    """
    n = Ad.shape[0]
    if A.shape != Ad.shape or B.shape != Bd.shape or C.shape != Cd.shape:
        return None
    eye = np.eye(n)
    sa, sb, sc = (1.0 / max(np.linalg.norm(M), 1e-300) for M in (Ad, Bd, Cd))
    # vec(T X) = (X^T kron I) vec(T), vec(X T) = (I kron X) vec(T) (column-major vec)
    M = np.vstack([sa * (np.kron(Ad.T, eye) - np.kron(eye, A)),
                   sb * np.kron(Bd.T, eye),
                   sc * np.kron(eye, C)])
    rhs = np.concatenate([np.zeros(n * n), sb * B.ravel(order="F"), sc * Cd.ravel(order="F")])
    t, *_ = np.linalg.lstsq(M, rhs, rcond=None)
    T = t.reshape(n, n, order="F")
    if not np.all(np.isfinite(T)) or np.linalg.cond(T) > 1e8:
        return None
    ok = (np.linalg.norm(T @ Ad - A @ T) <= tol * np.linalg.norm(A) * np.linalg.norm(T)
          and np.linalg.norm(T @ Bd - B) <= tol * np.linalg.norm(B)
          and np.linalg.norm(C @ T - Cd) <= tol * np.linalg.norm(Cd))
    return T if ok else None


@dataclass
class ModalBatch:
    """Diagonalised stack of discrete systems: lam (nb, ns), Bm (nb, ns, m), Cm (nb, p, ns)."""

    lam: NDArray
    Bm: NDArray
    Cm: NDArray
    stable: NDArray


def diagonalise(A: NDArray, B: NDArray, C: NDArray, x: NDArray | None = None,
                engine: kernels.Engine = DEFAULT_ENGINE, fixed: FixedBlock | None = None
                ) -> tuple[ModalBatch, NDArray | None]:
    """Eigen-decompose a stack of systems; unstable or non-finite members are flagged.

    With an input record x, also returns the modal state after its last sample (nb, ns).
    The default path is compiled (bayes_amb.inference.eigen; members it cannot take go to
    ``np.linalg.eig``); with the engine "lapack" or "numpy" every member goes to
    ``np.linalg.eig`` and the modal state to :func:`final_modal_state`. ``fixed``: the
    loop's fixed observer block, where A has it (triangular.py): the compiled path then
    decomposes only the rest of the loop.
    """
    finite = np.all(np.isfinite(A), axis=(1, 2))
    if engine.compiled_modal:
        if fixed is not None and takes(A, fixed):
            lam, Bm, Cm, ok = modal_triangular(A, B, C, fixed)
        else:
            lam, Bm, Cm, ok = modal_batch(A, B, C)
        redo = np.flatnonzero(finite & ~ok)
        if redo.size:
            Bb = np.broadcast_to(B, (A.shape[0], *B.shape[-2:]))
            Cb = np.broadcast_to(C, (A.shape[0], *C.shape[-2:]))
            mb, _ = _diagonalise_lapack(A[redo], Bb[redo], Cb[redo], None)
            lam[redo], Bm[redo], Cm[redo] = _real_symmetric(mb.lam, mb.Bm, mb.Cm)
        stable = finite & (np.max(np.abs(lam), axis=1) < 1.0 - 1e-12)
        mb = ModalBatch(lam=lam, Bm=Bm, Cm=Cm, stable=stable)
        if x is None:
            return mb, None
        lam_s = np.where(stable[:, None], lam, 0.0)
        return mb, final_state(lam_s, Bm, x, _TRANSIENT_TOL)
    return _diagonalise_lapack(A, B, C, x)


def state_after(lam: NDArray, Bm: NDArray, x: NDArray,
                engine: kernels.Engine = DEFAULT_ENGINE) -> NDArray:
    """Modal state after the record x from rest, (nb, ns): the compiled
    :func:`bayes_amb.inference.eigen.final_state` (each eigenvalue's own number of terms),
    or :func:`final_modal_state` with the engine "lapack" or "numpy"."""
    if engine.compiled_modal:
        return final_state(lam, Bm, x, _TRANSIENT_TOL)
    return final_modal_state(lam, Bm, x)


def observer_block(parts: LoopParts) -> FixedBlock | None:
    """The fixed trailing block A + L C of loop_matrices' loop, diagonalised
    (triangular.py), or None where it is not usable."""
    return fixed_block(parts.A + parts.L @ parts.C)


def _real_symmetric(lam: NDArray, Bm: NDArray, Cm: NDArray
                    ) -> tuple[NDArray, NDArray, NDArray]:
    """LAPACK's modal form of real systems with the symmetry exact, as the compiled one has
    it (triangular.exact_pairs, on copies)."""
    return lam, *exact_pairs(lam, Bm.copy(), Cm.copy())


def _diagonalise_lapack(A: NDArray, B: NDArray, C: NDArray, x: NDArray | None
                        ) -> tuple[ModalBatch, NDArray | None]:
    finite = np.all(np.isfinite(A), axis=(1, 2))
    A = np.where(finite[:, None, None], A, 0.0)
    lam, V = np.linalg.eig(A)
    stable = finite & (np.max(np.abs(lam), axis=1) < 1.0 - 1e-12)
    Bm = np.linalg.solve(V, B.astype(complex))
    Cm = np.broadcast_to(C, (A.shape[0], *C.shape[-2:])) @ V
    mb = ModalBatch(lam=lam, Bm=Bm, Cm=Cm, stable=stable)
    if x is None:
        return mb, None
    lam_s = np.where(stable[:, None], lam, 0.0)
    return mb, final_modal_state(lam_s, Bm, x)


class ForwardModel:
    """S(theta) forward model of one recording for a set of named parameters.

    The nominal model is the rig's reduced model at the recording's speed, sampled exactly
    at its dt: its rigid-body modes, and the bending pairs inside the loop's control band
    (model_band.choose_model; the paper's 8 states where the band holds none, or
    ``n_bending`` pairs when given); theta enters through the reduced LFT (eqs. 51-52).

    Where the model keeps bending pairs, the modes it leaves out still bend the shaft
    below their frequencies, and it holds their compliance too, on every path of the LFT
    (uncertainty.lft.with_left_out; ``static``, their FE static compliance from the
    currents to the probes at nominal bearings, reduction.pseudo_modal.residual_static):
    one lumped mode per actuator channel (8 states) that follows their rise below the
    lowest of them and falls above it as they do, driven by the currents and by the
    bearing coefficients' forces, and seen by the probes and by the coefficients. On
    ROSS's test rig the left-out modes (pair 2 at 386/413 Hz and up) add 10 % to the
    model's compliance at bearing A at the band's top; without it identify's in-band fit
    put k_Ax and k_Ay about 3 sd low in nine records of ten, and with it on the currents'
    path only, the dampings at A about 0.4-1 sd low. A path through one sample of delay
    (the form of a mode far above the sampling rate) fits the band too, but its instant
    step response, which the left-out modes (heavily damped, 386-1144 Hz) do not have,
    failed the slew-limit screen on 17 of 30 linear records (docs/validation.md). The
    paper's 8-state model has no such path: there the left-out modes lie far above the
    band.
    """

    def __init__(self, recording: Recording, params: str | tuple[str, ...],
                 n_bending: int | None = None):
        self.params = parse_param_list(params)
        self.recording = recording
        self.engine = kernels.engine_from_env()     # the likelihood path, chosen once
        rig, dt = recording.rig, recording.dt
        groups = list(recording.excitation)
        if len(groups) != 1:
            raise RecordingError(f"recording {recording.source}: field excitation: exactly one "
                                 f"excitation group is supported, got {groups}")
        self.port = groups[0]
        self.x = np.asarray(recording.excitation[self.port], dtype=float)
        ctrl = recording.controller
        full = full_model(rig, recording.speed_rpm)
        if n_bending is None:
            self.reduced, self.band = choose_model(full, feedback_part(ctrl.A, ctrl.B, ctrl.C,
                                                                       ctrl.D), dt)
        else:
            self.reduced = reduce_pseudo_modal(full, n_bending=n_bending)
            self.band = None
        pairs = tuple(range(1, self.reduced.n_bending + 1))
        self.plant: UncertainPlant = lft_reduced(self.reduced, rig, self.params, keeps=pairs)
        self.dt = dt
        self.static = residual_static(full, pairs) if pairs else None
        Ad, Bd = zoh(self.reduced.A, self.reduced.B, dt)
        self.nominal = (Ad, Bd, self.reduced.C)
        self.fast = False
        # the file's observer is this model's (to a change of basis): the error form
        # below, and ExtendedForwardModel's observer form, may use it
        self.observer_ok = False
        if ctrl.kind == "observer":
            # the file's own nominal model and gains: J = [A+BF+LC, [-L, B]; [F; -C], D]
            L = -ctrl.B[:, :4]
            F = ctrl.C[:4]
            B = ctrl.B[:, 4:]
            C = -ctrl.C[4:]
            A = ctrl.A - B @ F - L @ C
            self.parts = LoopParts(ctrl.A, ctrl.B, ctrl.C, ctrl.D, A, B, C, L, self.port)
            T = state_transform(A, B, C, Ad, Bd, self.reduced.C)
            if T is not None and self.port == "eta":
                self.observer_ok = True
                self.fast = self.static is None     # the error form has no left-out modes
                self.F, self.L = F, L                  # in the file's state basis
                # the same observer in this model's basis (x_file = T x): F T, T^-1 L
                self._F, self._L = F @ T, np.linalg.solve(T, L)
                # theta-independent parts of the compiled error form (contiguous float64)
                self._error_parts = tuple(np.ascontiguousarray(a, dtype=float)
                                          for a in (Ad, Bd, self.reduced.C, self._F, self._L))
                self._LC = np.ascontiguousarray(self._L @ self.reduced.C, dtype=float)
        else:
            L = design_observer_controller(self.reduced, dt).L
            self.parts = LoopParts(ctrl.A, ctrl.B, ctrl.C, ctrl.D, Ad, Bd, self.reduced.C, L,
                                   self.port)
        # the offline filter's observer block of the general loop, decomposed once
        self.fixed = None if self.fast else observer_block(self.parts)

    def validity_band_hz(self) -> float:
        """Half the frequency (|lambda|/2pi) of the lowest mode the reduction left out."""
        return validity_hz(self.reduced.full, self.reduced.n_states)

    # ------------------------------------------------------------------ plants
    def plants(self, theta: NDArray) -> tuple[NDArray, NDArray, NDArray]:
        """Exactly sampled plants for a batch theta (nb, p): Ap (nb, n, n), Bp (nb, n, 4)
        and Cp (4, n); n = 8 + 4 bending pairs (+ 8 states of the left-out modes)."""
        th = np.atleast_2d(np.asarray(theta, dtype=float))
        pl = self.plant
        diag = np.repeat(th, pl.blocks, axis=1)                      # (nb, r)
        if self.engine.compiled_modal:
            Ap, Bp = zoh_compiled(pl.A[None] + (pl.B_w * diag[:, None, :]) @ pl.C_z, pl.B,
                                  self.dt)
        else:
            A = pl.A[None] + np.einsum("ir,br,rj->bij", pl.B_w, diag, pl.C_z)
            Ap, Bp = zoh_batched(A, pl.B, self.dt)
        return Ap, Bp, pl.C

    def excitation_system(self, theta: NDArray) -> tuple[NDArray, NDArray, NDArray]:
        """(A, B, C) of the map x -> eps for a batch of theta."""
        Ap, Bp, Cp = self.plants(theta)
        if self.fast:
            if self.engine.compiled_modal:
                A_S, B_S, C_S = error_form_compiled(*self._error_parts, Ap, Bp, self._LC)
            else:
                Ad, Bd, C = self.nominal
                A_S, B_S, C_S = error_form_matrices(Ad, Bd, C, self._F, self._L, Ap, Bp)
            return A_S, B_S, np.broadcast_to(C_S, (Ap.shape[0], *C_S.shape))
        A_cl, B_cl, C_cl, _ = loop_matrices(self.parts, Ap, Bp, Cp)
        return A_cl, B_cl[:, :, :4], C_cl

    def noise_system(self, theta: NDArray) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        """(A, B, C, D) of [n, r1, r2] -> eps at one theta (the noise filters, eq. 14)."""
        A_cl, B_cl, C_cl, D_cl = loop_matrices(self.parts, *self.plants(np.atleast_2d(theta)))
        return A_cl[0], B_cl[0][:, 4:], C_cl[0], D_cl[:, 4:]

    def modal(self, theta: NDArray, x: NDArray | None = None
              ) -> tuple[ModalBatch, NDArray | None]:
        """Modal form of x -> eps for a batch, and the modal state after the record x
        (default: the recording's excitation)."""
        return diagonalise(*self.excitation_system(theta), self.x if x is None else x,
                           self.engine, self.fixed)

    # ------------------------------------------------------------- predictions
    def simulate(self, theta: NDArray) -> NDArray:
        """Time-domain eps_pred = S(theta) x for one theta, shape (N, 4) (reference path)."""
        A, B, C = (m[0] for m in self.excitation_system(np.atleast_2d(theta)))
        xs = np.zeros(A.shape[0])
        out = np.empty((self.x.shape[0], C.shape[0]))
        for k, xk in enumerate(self.x):
            out[k] = C @ xs
            xs = A @ xs + B @ xk
        return out


def final_modal_state(lam: NDArray, Bm: NDArray, x: NDArray, chunk: int = 32) -> NDArray:
    """Modal state after the last sample, xi_N = sum_m lam^m Bm x_{N-1-m}, (nb, ns).

    Only the last n_tail samples matter (max|lam|^n_tail below 1e-13). Per input channel c
    this is Bm times the polynomial p_c(lam) = sum_m x_{N-1-m,c} lam^m, evaluated at every
    eigenvalue of the batch at once: in chunks of L coefficients, p = sum_q lam^(qL) q_q(lam)
    with all chunk polynomials q_q from one matrix product against the powers lam^0..L-1,
    then Horner across the chunks.
    """
    rho = float(np.max(np.abs(lam), initial=0.5))
    rho = min(max(rho, 1e-3), 1 - 1e-9)
    n_tail = int(min(x.shape[0], np.ceil(np.log(_TRANSIENT_TOL) / np.log(rho)) + 1))
    n_chunks = -(-n_tail // chunk)
    m_in = x.shape[1]
    tail = np.zeros((n_chunks * chunk, m_in))
    m = min(n_chunks * chunk, x.shape[0])
    tail[:m] = x[::-1][:m]                                          # x_{N-1-m}, m = 0..
    T = tail.reshape(n_chunks, chunk, m_in).transpose(0, 2, 1).reshape(-1, chunk)
    pts = lam.ravel()
    powers = pts[None, :] ** np.arange(chunk)[:, None]              # (L, nb * ns)
    Q = (T @ powers).reshape(n_chunks, m_in, pts.size)              # chunk polynomials
    step = pts**chunk
    acc = Q[-1]
    for q in range(n_chunks - 2, -1, -1):                           # Horner across chunks
        acc = acc * step + Q[q]
    p = acc.reshape(m_in, *lam.shape)                               # (m, nb, ns)
    return np.einsum("bsc,cbs->bs", Bm, p)


def dft_response(mb: ModalBatch, X: NDArray, z: NDArray, xi_N: NDArray) -> NDArray:
    """DFT of the response from rest: (nb, nf, p) at points z (nf,) for input DFT X (nf, m).

    Evaluated walker by walker on 2-D arrays that stay in cache; 1/(z - lam) is formed in
    real arithmetic (cheaper than numpy's complex division).
    """
    nb = mb.lam.shape[0]
    out = np.empty((nb, z.size, mb.Cm.shape[1]), dtype=complex)
    zc = z[:, None]
    zr, zi = z.real[:, None], z.imag[:, None]
    for b in range(nb):
        U = X @ mb.Bm[b].T                                          # (nf, ns)
        U -= zc * xi_N[b]
        dr = zr - mb.lam[b].real
        di = zi - mb.lam[b].imag
        inv = (dr - 1j * di) / (dr * dr + di * di)
        U *= inv
        out[b] = U @ mb.Cm[b].T
    return out
