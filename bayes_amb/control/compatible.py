"""K-compatible coprime factors for a controller that is not observer-based (METHOD.md s. 3).

Any controller K that stabilises the nominal plant G is K(Q_K) for one stable Youla
parameter (eq. 4, K = (Vt + Q Nt)^-1 (Ut + Q Mt)); solving for Q gives

    Q_K = (Vt K - Ut)(Mt - Nt K)^-1.

The K-compatible factors keep the plant factors and move the controller factors:

    U_K = U + M Q_K,  V_K = V + N Q_K,  Ut_K = Ut + Q_K Mt,  Vt_K = Vt + Q_K Nt,

so that K = U_K V_K^-1 = Vt_K^-1 Ut_K and the double Bezout identity (eq. 3) still holds.
With an excitation r2 added at the plant input (u = K y + r2) and y = G_theta u:

    eps := Mt y - Nt u = S_K(theta) x,   x := Vt_K u - Ut_K y = Vt_K r2,
    S_K(theta) = (Mt G_theta - Nt)(Vt_K - Ut_K G_theta)^-1 = (I - S Q_K)^-1 S,

where S = S(theta) is the dual-Youla parameter of the observer-based factors. eps needs
only the recorded (y, u) and the nominal plant factors; x is known from r2 alone.

Realisation of Q_K
------------------
The formula above realised by system arithmetic carries the unstable plant poles as
hidden modes (Mt^-1 has the poles of G). Instead Q_K is realised as the map eps -> eta of
the observer fed with the output y and the input u = K y of a loop whose innovation is
eps (y = C xhat + eps), with eta = u - F xhat. Its states [xhat; x_K] have the state matrix
of the nominal loop [[A + B Dk C, B Ck], [Bk C, Ak]], Schur iff K stabilises (A, B, C).
"""

from __future__ import annotations

import control as ct
import numpy as np
from numpy.typing import NDArray

from bayes_amb.control.coprime import CoprimeFactors, ss
from bayes_amb.control.discrete import spectral_radius
from bayes_amb.errors import ControllerError


def observer_data(f: CoprimeFactors) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray]:
    """(A, B, C, F, L) of the observer-based factors of :func:`coprime_factors`.

    Read from the realisations Mt = [A+LC | L ; C | I], Nt = [A+LC | B ; C | 0] and
    M = [A+BF | B ; F | I]; raises ControllerError if the factors are not of that form.
    """
    L, C = np.asarray(f.Mt.B), np.asarray(f.Mt.C)
    A = np.asarray(f.Mt.A) - L @ C
    B, F = np.asarray(f.Nt.B), np.asarray(f.M.C)
    scale = max(1.0, float(np.abs(A).max()))
    if (np.asarray(f.M.A).shape != A.shape
            or np.abs(np.asarray(f.M.A) - (A + B @ F)).max() > 1e-9 * scale
            or np.abs(np.asarray(f.Nt.A) - np.asarray(f.Mt.A)).max() > 1e-12 * scale):
        raise ControllerError("coprime factors are not the observer-based realisations of "
                              "coprime_factors(); cannot read A, B, C, F, L from them")
    return A, B, C, F, L


def _as_matrices(K: ct.StateSpace | tuple[NDArray, ...]) -> tuple[NDArray, ...]:
    if isinstance(K, ct.StateSpace):
        return tuple(np.asarray(m, dtype=float) for m in (K.A, K.B, K.C, K.D))
    return tuple(np.asarray(m, dtype=float) for m in K)


def youla_parameter_of(f: CoprimeFactors, K_ss: ct.StateSpace | tuple[NDArray, ...],
                       check_stable: bool = True) -> ct.StateSpace:
    """Youla parameter Q_K = (Vt K - Ut)(Mt - Nt K)^-1 of a controller K (u = K y).

    Parameters
    ----------
    f : CoprimeFactors
        Observer-based factors (:func:`bayes_amb.control.coprime_factors`).
    K_ss : StateSpace or (Ak, Bk, Ck, Dk)
        Discrete controller at the sample time of ``f``, positive feedback u = K y.
    check_stable : bool
        Raise ControllerError if K does not stabilise the nominal plant (Q_K unstable).

    Returns
    -------
    StateSpace
        Q_K from eps (m) to eta (A), states [xhat; x_K] (module docstring), so that
        K = K(Q_K) (eq. 4).

    Examples
    --------
    >>> from bayes_amb.rig import load_rig
    >>> from bayes_amb.reduction import reduce_pseudo_modal
    >>> from bayes_amb.control import coprime_factors, design_observer_controller
    >>> from bayes_amb.control.pid import design_decentralised_pid
    >>> rig = load_rig()
    >>> f = coprime_factors(design_observer_controller(reduce_pseudo_modal(rig), 1e-4))
    >>> Q = youla_parameter_of(f, design_decentralised_pid(rig, 1e-4).controller_matrices())
    >>> Q.nstates, Q.ninputs, Q.noutputs
    (16, 4, 4)
    """
    A, B, C, F, L = observer_data(f)
    Ak, Bk, Ck, Dk = _as_matrices(K_ss)
    m, p = B.shape[1], C.shape[0]
    if Dk.shape != (m, p) or Bk.shape[1] != p or Ck.shape[0] != m:
        raise ControllerError(f"controller K has the wrong shape; expected {m} outputs and "
                              f"{p} inputs instead of {Dk.shape[0]} and {Dk.shape[1]}")
    A_Q = np.block([[A + B @ Dk @ C, B @ Ck], [Bk @ C, Ak]])
    if check_stable and spectral_radius(A_Q) >= 1.0:
        raise ControllerError("controller K does not stabilise the nominal plant: Q_K has "
                              f"spectral radius {spectral_radius(A_Q):.6g}; expected < 1")
    B_Q = np.vstack([B @ Dk - L, Bk])
    C_Q = np.hstack([Dk @ C - F, Ck])
    return ss(A_Q, B_Q, C_Q, Dk, f.dt)


def compatible_factors(f: CoprimeFactors, K_ss: ct.StateSpace | tuple[NDArray, ...]
                       ) -> CoprimeFactors:
    """K-compatible factors: U_K = U + M Q_K, V_K = V + N Q_K, Ut_K = Ut + Q_K Mt,
    Vt_K = Vt + Q_K Nt; M, N, Mt, Nt unchanged (the same objects).

    Examples
    --------
    >>> from bayes_amb.rig import load_rig
    >>> from bayes_amb.reduction import reduce_pseudo_modal
    >>> from bayes_amb.control import bezout_residual, coprime_factors
    >>> from bayes_amb.control import design_observer_controller
    >>> from bayes_amb.control.pid import design_decentralised_pid
    >>> rig = load_rig()
    >>> f = coprime_factors(design_observer_controller(reduce_pseudo_modal(rig), 1e-4))
    >>> fK = compatible_factors(f, design_decentralised_pid(rig, 1e-4).controller_matrices())
    >>> bezout_residual(fK) < 1e-9
    True
    """
    Q = youla_parameter_of(f, K_ss)
    return CoprimeFactors(M=f.M, N=f.N, U=f.U + f.M * Q, V=f.V + f.N * Q,
                          Mt=f.Mt, Nt=f.Nt, Ut=f.Ut + Q * f.Mt, Vt=f.Vt + Q * f.Nt, dt=f.dt)


def s_theta_compatible(S: ct.StateSpace, Q_K: ct.StateSpace) -> ct.StateSpace:
    """S_K(theta) = (I - S Q_K)^-1 S of the K-compatible factors, from S(theta) and Q_K.

    S is the dual-Youla parameter of the observer-based factors (e.g. :func:`s_theta`).
    The realisation is the loop of S with Q_K closed (eta = Q_K eps + x); it is stable
    whenever K stabilises G(theta).
    """
    return ct.feedback(S, Q_K, sign=1)


def simulate(sys: ct.StateSpace, u: NDArray) -> NDArray:
    """Response of a discrete system from rest to u of shape (n_samples, n_inputs).

    A plain loop over samples, x[k+1] = A x[k] + B u[k], y[k] = C x[k] + D u[k].
    Returns (n_samples, n_outputs).
    """
    u = np.asarray(u, dtype=float)
    A, B, C, D = (np.asarray(m, dtype=float) for m in (sys.A, sys.B, sys.C, sys.D))
    if u.ndim != 2 or u.shape[1] != B.shape[1]:
        raise ControllerError(f"input signal has the wrong shape; expected (n_samples, "
                              f"{B.shape[1]}) instead of {u.shape}")
    # states only driven by B u: propagate all samples, then map to outputs in one product
    x = np.zeros(A.shape[0])
    X = np.empty((u.shape[0], A.shape[0]))
    Bu = u @ B.T
    for k in range(u.shape[0]):
        X[k] = x
        x = A @ x + Bu[k]
    return X @ C.T + u @ D.T


def excitation_signal_x(f_K: CoprimeFactors, r2: NDArray) -> NDArray:
    """x = Vt_K r2: the noise-free dual-Youla input of a loop excited by r2 at the plant input.

    Parameters
    ----------
    f_K : CoprimeFactors
        K-compatible factors (:func:`compatible_factors`).
    r2 : ndarray, shape (n_samples, 4)
        Excitation currents added to u = K y, in A, from rest.

    Returns
    -------
    ndarray, shape (n_samples, 4)
        x in A; eps = S_K(theta) x for the recorded data.
    """
    return simulate(f_K.Vt, r2)
