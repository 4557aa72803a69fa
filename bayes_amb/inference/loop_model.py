"""The closed loop seen by the identification: plant G(theta), the recorded controller K and
the offline dual-Youla filter, as one discrete state-space system.

Signals (METHOD.md sections 3-4). The offline filter computes, from recorded y and u,

    eps = Mt y - Nt u        (nominal coprime factors: x_o+ = (A+LC) x_o + L y - B u,
                              eps = C x_o + y)

and the loop is driven by the known excitation e and the unknown noise sources:
n (sensor noise, in recorded y), r1 (added to y at the controller input only) and r2
(added to the plant input current, not recorded). The port of e is one of
``eta`` (the controller's Youla port), ``r2`` (added to the recorded plant current) or
``r1`` (added to y at the controller input).

States z = [x_p; x_k; x_o], inputs [e; n; r1; r2] (4 each), output eps (4). The map
e -> eps is S(theta) for the observer-based controller (x = eta) and S_K(theta) Vt_K for any
other stabilising K (x = Vt_K r2); n, r1, r2 -> eps are the noise filters of eq. 14.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

PORTS = ("eta", "r2", "r1")


@dataclass(frozen=True)
class LoopParts:
    """theta-independent parts: controller (Ak, Bk, Ck, Dk) with inputs [y; eta] and
    outputs [u; eps]; nominal discrete (A, B, C) and the factor observer gain L."""

    Ak: NDArray
    Bk: NDArray
    Ck: NDArray
    Dk: NDArray
    A: NDArray
    B: NDArray
    C: NDArray
    L: NDArray
    port: str


def loop_matrices(parts: LoopParts, Ap: NDArray, Bp: NDArray, Cp: NDArray
                  ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """(A_cl, B_cl, C_cl, D_cl) for a stack of plants Ap (nb, np, np), Bp (nb, np, 4).

    B_cl has 16 columns: [e, n, r1, r2]; D_cl (4, 16).
    """
    p = parts
    nb, n_p, _ = Ap.shape
    nk, no = p.Ak.shape[0], p.A.shape[0]
    m = 4
    Cu = p.Ck[:m]
    Duy, Due = p.Dk[:m, :m], p.Dk[:m, m:]
    Bky, Bke = p.Bk[:, :m], p.Bk[:, m:]
    eye, zero = np.eye(m), np.zeros((m, m))
    P1 = eye if p.port == "r1" else zero
    Pe = eye if p.port == "eta" else zero
    P2 = eye if p.port == "r2" else zero
    Ge = Duy @ P1 + Due @ Pe + P2
    nz = n_p + nk + no
    A_cl = np.zeros((nb, nz, nz))
    sp, sk, so = slice(0, n_p), slice(n_p, n_p + nk), slice(n_p + nk, nz)
    A_cl[:, sp, sp] = Ap + Bp @ Duy @ Cp
    A_cl[:, sp, sk] = Bp @ Cu
    A_cl[:, sk, sp] = Bky @ Cp
    A_cl[:, sk, sk] = p.Ak
    A_cl[:, so, sp] = (p.L - p.B @ Duy) @ Cp
    A_cl[:, so, sk] = -p.B @ Cu
    A_cl[:, so, so] = p.A + p.L @ p.C
    B_cl = np.zeros((nb, nz, 4 * m))
    se, sn, s1, s2 = (slice(i * m, (i + 1) * m) for i in range(4))
    B_cl[:, sp, se] = Bp @ Ge
    B_cl[:, sk, se] = Bky @ P1 + Bke @ Pe
    B_cl[:, so, se] = -p.B @ Ge
    B_cl[:, sp, sn] = Bp @ Duy
    B_cl[:, sk, sn] = Bky
    B_cl[:, so, sn] = p.L - p.B @ Duy
    B_cl[:, sp, s1] = Bp @ Duy
    B_cl[:, sk, s1] = Bky
    B_cl[:, so, s1] = -p.B @ Duy
    B_cl[:, sp, s2] = Bp
    C_cl = np.concatenate([np.broadcast_to(Cp, (nb, m, n_p)), np.zeros((nb, m, nk)),
                           np.broadcast_to(p.C, (nb, m, no))], axis=2)
    D_cl = np.zeros((m, 4 * m))
    D_cl[:, sn] = eye
    return A_cl, B_cl, C_cl, D_cl


def error_form_matrices(A: NDArray, B: NDArray, C: NDArray, F: NDArray, L: NDArray,
                        Ap: NDArray, Bp: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """S(theta) of the observer-based loop in error coordinates, for a stack of plants.

    Same as bayes_amb.control.youla.s_theta_exact (exactly zero at the nominal plant), with
    A_S (nb, 2n, 2n), B_S (nb, 2n, 4), C_S (4, 2n).
    """
    nb, n, _ = Ap.shape
    dA, dB = Ap - A, Bp - B
    A_S = np.empty((nb, 2 * n, 2 * n))
    A_S[:, :n, :n] = A + L @ C - dB @ F
    A_S[:, :n, n:] = dA + dB @ F
    A_S[:, n:, :n] = -Bp @ F
    A_S[:, n:, n:] = Ap + Bp @ F
    B_S = np.concatenate([dB, Bp], axis=1)
    C_S = np.hstack([C, np.zeros_like(C)])
    return A_S, B_S, C_S


@njit(cache=True, nogil=True)
def _error_form(A, B, F, LC, Ap, Bp, A_S, B_S):  # pragma: no cover - compiled
    nb, n, _ = Ap.shape
    m = B.shape[1]
    dB = np.empty((n, m))
    for b in range(nb):
        for i in range(n):
            for c in range(m):
                dB[i, c] = Bp[b, i, c] - B[i, c]
                B_S[b, i, c] = dB[i, c]
                B_S[b, n + i, c] = Bp[b, i, c]
            for j in range(n):
                s = 0.0                     # dB F and Bp F
                t = 0.0
                for c in range(m):
                    s += dB[i, c] * F[c, j]
                    t += Bp[b, i, c] * F[c, j]
                A_S[b, i, j] = A[i, j] + LC[i, j] - s
                A_S[b, i, n + j] = (Ap[b, i, j] - A[i, j]) + s
                A_S[b, n + i, j] = -t
                A_S[b, n + i, n + j] = Ap[b, i, j] + t


def error_form_compiled(A: NDArray, B: NDArray, C: NDArray, F: NDArray, L: NDArray,
                        Ap: NDArray, Bp: NDArray, LC: NDArray | None = None
                        ) -> tuple[NDArray, NDArray, NDArray]:
    """:func:`error_form_matrices` in one compiled pass over the batch (the same blocks;
    LC = L @ C may be passed precomputed)."""
    nb, n, _ = Ap.shape
    A_S = np.empty((nb, 2 * n, 2 * n))
    B_S = np.empty((nb, 2 * n, B.shape[1]))
    LC = L @ C if LC is None else LC
    def own(a: NDArray) -> NDArray:         # one compiled signature (eigen.modal_batch)
        return np.require(a, np.float64, ("C", "W"))
    _error_form(own(A), own(B), own(F), own(LC), own(Ap), own(Bp), A_S, B_S)
    return A_S, B_S, np.hstack([C, np.zeros_like(C)])
