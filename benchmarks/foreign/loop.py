"""The sampled loop: the controller file as a rig runs it, around the continuous plant.

Controller (read from its JSON file, nothing else of the package):

    xk[k+1] = Ak xk[k] + Bk [y_m[k]; eta[k]],   [u[k]; eps[k]] = Ck xk[k] + Dk [y_m[k]; eta[k]]

with y_m the measured displacements (m) and eta the Youla-port excitation (A). The
amplifiers get w[k] = u[k] + r2[k] + offset (A) and hold it for one sample (ZOH).

Exact sampling with delays. With a total delay tau = tau_a + tau_s = (n + f) dt
(actuator side tau_a, sensor side tau_s, integer n, 0 <= f < 1), let z[k] = x(t_k - tau_s)
be the state at the instant the k-th sample is taken. Over [t_k - tau_s, t_{k+1} - tau_s)
the applied current is w[k-n-1] for the first f dt and w[k-n] for the rest, so exactly

    z[k+1] = e^{A dt} z[k] + e^{A (1-f) dt} Gam(f dt) w[k-n-1] + Gam((1-f) dt) w[k-n],
    Gam(s) = int_0^s e^{A r} dr B,      y_m[k] = C z[k] + D w[k-n-1] + m[k]

(m: noise, offsets, drift, lines, r1; added by the sampler; D a static feedthrough, of the
current in force just before the sampling instant, w[k-n-1]). With tau = 0 this is the plain
ZOH. Plant, controller and a delay line of w form one discrete LTI system, built once and
run by a plain recursion.

The same system broken open at the amplifier input (w = Cw X + Dw e enters through Bw)
runs an amplifier current limit, clip(w), sample by sample; a plant that varies slowly in
time runs as a staircase of such systems (:func:`run_segments`); disc forces (N) enter
through ``Bf``, held over each sample like the current.

The magnets' force law (``magnet_force_law``, ``iron_saturation``) runs the same way: its
remainder beyond ki i + ks x is computed per sample from the state at the sampling instant
(the current in force just after it, the air gap at the bearing node) and enters through
``Bn``, held over the sample. An amplifier with dynamics within the sample
(``slew_limit``, ``amp_voltage_limit``; no delays) stores the current it delivered at the
end of the sample in the delay line's first slot; over the sample the plant receives that
end value held (through ``Bw``) plus the waveform's deficit as the exact means over
AMP_SUBSTEPS sub-intervals, each through e^{A (dt - (j + 1) h)} Gam(h) (``Gsub``).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray

from benchmarks.foreign.effects import AMP_SUBSTEPS, Amplifier, ContinuousPlant, MagnetLaw

_Y = ("y_Ax", "y_Ay", "y_Bx", "y_By")
_ETA = ("eta_Ax", "eta_Ay", "eta_Bx", "eta_By")
_U = ("u_Ax", "u_Ay", "u_Bx", "u_By")
_EPS = ("eps_Ax", "eps_Ay", "eps_Bx", "eps_By")


@dataclass(frozen=True)
class Controller:
    """A discrete controller from a controller file: Ak (nk, nk), By (nk, 4) on y_m,
    Be (nk, 4) on eta, Cu/Ce (4, nk) to u/eps, D blocks (4, 4); ``raw`` the file's dict."""

    dt: float
    Ak: NDArray
    By: NDArray
    Be: NDArray
    Cu: NDArray
    Ce: NDArray
    Duy: NDArray
    Due: NDArray
    Dey: NDArray
    Dee: NDArray
    raw: dict[str, Any]


def read_controller(source: str | os.PathLike[str] | dict[str, Any]) -> Controller:
    """Read a ``bayes-amb-controller/1`` JSON file (or its dict); signals ordered by name."""
    raw = source if isinstance(source, dict) else json.loads(open(source).read())
    if raw.get("format") != "bayes-amb-controller/1":
        raise ValueError(f"controller: format {raw.get('format')!r} is not bayes-amb-controller/1")
    ins, outs = list(raw["inputs"]), list(raw["outputs"])
    iy = [ins.index(s) for s in _Y]
    ie = [ins.index(s) for s in _ETA]
    ou = [outs.index(s) for s in _U]
    oe = [outs.index(s) for s in _EPS]
    A = np.array(raw["A"], dtype=float).reshape(len(raw["A"]), -1)
    nk = A.shape[0]
    B = np.array(raw["B"], dtype=float).reshape(nk, len(ins))
    C = np.array(raw["C"], dtype=float).reshape(len(outs), nk)
    D = np.array(raw["D"], dtype=float).reshape(len(outs), len(ins))
    return Controller(dt=float(raw["dt"]), Ak=A, By=B[:, iy], Be=B[:, ie], Cu=C[ou], Ce=C[oe],
                      Duy=D[np.ix_(ou, iy)], Due=D[np.ix_(ou, ie)], Dey=D[np.ix_(oe, iy)],
                      Dee=D[np.ix_(oe, ie)], raw=raw)


def _gamma(A: NDArray, B: NDArray, s: float) -> tuple[NDArray, NDArray]:
    """(e^{A s}, int_0^s e^{A r} dr B) from one matrix exponential."""
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = A * s
    M[:n, n:] = B * s
    E = sla.expm(M)
    return E[:n, :n], E[:n, n:]


@dataclass(frozen=True)
class ClosedLoop:
    """X[k+1] = Acl X[k] + Bcl e[k] with e = [eta (4); w_add (4); m (4)] (A, A, m);
    y_m = Cy X + Dy e, u = Cu X + Du e, eps = Ce X + De e.
    X = [z (np); xk (nk); delay line w[k-1..k-n-1] (4 (n+1))].

    The same loop broken open at the amplifier input, for a nonlinear amplifier:
    w = Cw X + Dw e is the total commanded current (controller output, r2, offset; A) and
    X[k+1] = Aop X[k] + Bop e[k] + Bw a(w[k]), a the amplifier map (a(w) = w gives
    Acl = Aop + Bw Cw, Bcl = Bop + Bw Dw). ``Bf`` (nx, 4): the sampled disc forces
    [D1x, D1y, D2x, D2y] (N, held over one sample of z) into X.

    Nonlinear magnets and amplifiers (see the module doc): ``Bn`` (nx, 4) bearing-node
    forces (N, held over one sample) into X; ``Cxb`` (4, nx) the air gap at the bearing
    nodes (m) and ``Ccur`` (4, nx) + ``cur_dir`` * (applied current) the current in force
    (A) at the sampling instant; ``start_slot`` the first X index of the delay-line slot
    holding the current applied just after the sampling instant (-1: this sample's own
    a(w[k])); ``Gsub`` (nx, 4 m) the sub-interval input matrices [G_0 .. G_{m-1}];
    ``line0`` the first X index of the delay line; ``magnets``, ``amp`` and ``dt`` as
    the plant has them."""

    Acl: NDArray
    Bcl: NDArray
    Cy: NDArray
    Dy: NDArray
    Cu: NDArray
    Du: NDArray
    Ce: NDArray
    De: NDArray
    n_plant: int
    n_ctrl: int
    Aop: NDArray | None = None
    Bop: NDArray | None = None
    Bw: NDArray | None = None
    Cw: NDArray | None = None
    Dw: NDArray | None = None
    Bf: NDArray | None = None
    Bn: NDArray | None = None
    Cxb: NDArray | None = None
    Ccur: NDArray | None = None
    cur_dir: NDArray | None = None
    start_slot: int = -1
    Gsub: NDArray | None = None
    line0: int = 0
    magnets: tuple[MagnetLaw, ...] = ()
    amp: Amplifier | None = None
    dt: float = 0.0

    def initial_state(self, plant_x0: NDArray) -> NDArray:
        X = np.zeros(self.Acl.shape[0])
        X[: self.n_plant] = plant_x0
        return X


def closed_loop(plant: ContinuousPlant, ctrl: Controller) -> ClosedLoop:
    """Build the discrete closed loop of a plant and a controller (at the controller's dt)."""
    dt = ctrl.dt
    np_, nk = plant.A.shape[0], ctrl.Ak.shape[0]
    ratio = plant.delay_s / dt
    n_shift = int(np.floor(ratio + 1e-12))
    f = ratio - n_shift
    if f < 1e-12:
        f = 0.0
    Phi, Gnew = _gamma(plant.A, plant.B, (1.0 - f) * dt)
    if f > 0:
        E1, G1 = _gamma(plant.A, plant.B, f * dt)
        Gold = Phi @ G1
        Phi = Phi @ E1
    else:
        Gold = np.zeros_like(Gnew)
    nl = 4 * (n_shift + 1)
    nx = np_ + nk + nl
    iz, ik = slice(0, np_), slice(np_, np_ + nk)
    line = [slice(np_ + nk + 4 * i, np_ + nk + 4 * (i + 1)) for i in range(n_shift + 1)]
    C = plant.C
    # y_m = C z + m ;  w = Cu xk + Duy y_m + Due eta + w_add
    Cy = np.zeros((4, nx))
    Cy[:, iz] = C
    if plant.D is not None:      # the current in force just before the sampling instant
        Cy[:, line[n_shift]] += plant.D
    Dy = np.zeros((4, 12))
    Dy[:, 8:] = np.eye(4)
    Cw = ctrl.Duy @ Cy
    Cw[:, ik] += ctrl.Cu
    Dw = ctrl.Duy @ Dy
    Dw[:, :4] += ctrl.Due
    Dw[:, 4:8] += np.eye(4)

    def assemble(Cw: NDArray, Dw: NDArray) -> tuple[NDArray, NDArray]:
        """Acl, Bcl with the amplifier input w = Cw X + Dw e (zeros: the loop broken open)."""
        A = np.zeros((nx, nx))
        Bm = np.zeros((nx, 12))
        A[iz, iz] = Phi
        # w[k-n] and w[k-n-1] in terms of X and e
        for coef, lag in ((Gnew, n_shift), (Gold, n_shift + 1)):
            if lag == 0:
                A[iz, :] += coef @ Cw
                Bm[iz, :] += coef @ Dw
            else:
                A[iz, line[lag - 1]] += coef
        A[ik, :] += ctrl.By @ Cy
        A[ik, ik] += ctrl.Ak
        Bm[ik, :] += ctrl.By @ Dy
        Bm[ik, :4] += ctrl.Be
        A[line[0], :] = Cw
        Bm[line[0], :] = Dw
        for i in range(1, n_shift + 1):
            A[line[i], line[i - 1]] = np.eye(4)
        return A, Bm

    A, Bm = assemble(Cw, Dw)
    Aop, Bop = assemble(np.zeros_like(Cw), np.zeros_like(Dw))
    Bw = np.zeros((nx, 4))
    Bw[line[0]] = np.eye(4)
    if n_shift == 0:
        Bw[iz] += Gnew
    Bf = np.zeros((nx, 4))
    if plant.F is not None:
        Bf[iz] = _gamma(plant.A, plant.F, dt)[1]
    nonlin: dict[str, Any] = {}
    if plant.magnets:
        Bn = np.zeros((nx, 4))
        Bn[iz] = _gamma(plant.A, plant.Fb, dt)[1]
        Cxb, Ccur = np.zeros((4, nx)), np.zeros((4, nx))
        Cxb[:, iz], Ccur[:, iz] = plant.xb_row, plant.cur_row
        # the current applied just after the sampling instant: w[k-n-1] if the switch
        # falls inside the sample, else w[k-n] (this sample's own for n = 0)
        slot = (line[n_shift].start if f > 0 else
                line[n_shift - 1].start if n_shift > 0 else -1)
        nonlin.update(Bn=Bn, Cxb=Cxb, Ccur=Ccur, cur_dir=np.array(plant.cur_dir, float),
                      start_slot=slot, magnets=plant.magnets)
    if plant.amp is not None:
        if n_shift or f:
            raise ValueError(f"{plant.amp.effect} is not played with a delay")
        m = AMP_SUBSTEPS
        Eh, Gh = _gamma(plant.A, plant.B, dt / m)
        G = [Gh]
        for _ in range(m - 1):
            G.insert(0, Eh @ G[0])                     # G_j = e^{A (dt - (j+1) h)} Gam(h)
        Gsub = np.zeros((nx, 4 * m))
        Gsub[iz] = np.hstack(G)
        nonlin.update(Gsub=Gsub, amp=plant.amp, start_slot=line[0].start)
    if nonlin:
        nonlin.update(line0=line[0].start, dt=dt)
    Cu = ctrl.Duy @ Cy
    Cu[:, ik] += ctrl.Cu
    Du = ctrl.Duy @ Dy
    Du[:, :4] += ctrl.Due
    Ce = ctrl.Dey @ Cy
    Ce[:, ik] += ctrl.Ce
    De = ctrl.Dey @ Dy
    De[:, :4] += ctrl.Dee
    return ClosedLoop(A, Bm, Cy, Dy, Cu, Du, Ce, De, np_, nk, Aop, Bop, Bw, Cw, Dw, Bf,
                      **nonlin)


def run(cl: ClosedLoop, e: NDArray, X0: NDArray, force: NDArray | None = None
        ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Run the loop over inputs e (N, 12) from state X0; returns y_m, u, eps (N, 4) and the
    final state. Outputs at step k use X[k] (the state before the update). ``force``
    (N, 4), N: disc forces [D1x, D1y, D2x, D2y] (an unrecorded disturbance)."""
    r = run_segments([(0, cl)], e, X0, force=force)
    return r.y, r.u, r.eps, r.X


@dataclass(frozen=True)
class LoopRun:
    """A run of the loop: y_m, u (the controller's command), eps, w (the total commanded
    current, A), coil (the current the amplifier delivers: w, or clip(w) with a current
    limit, held over the sample; with an amplifier with dynamics, its value at the end of
    the sample; A), all (N, 4); X the final state. With a magnet law: i_mag (the current in
    force, A), x_mag (the air gap at the bearing node, m), n_mag (the force beyond the
    linearisation, N), each (N, 4) at the sampling instants (zero on channels without a
    law). With an amplifier with dynamics: limited (N, 4) bool (its rate limit reached)
    and ramp (N, 4) (the fraction of the sample at the rate cap), see
    effects.Amplifier.waveform."""

    y: NDArray
    u: NDArray
    eps: NDArray
    w: NDArray
    coil: NDArray
    X: NDArray
    i_mag: NDArray | None = None
    x_mag: NDArray | None = None
    n_mag: NDArray | None = None
    limited: NDArray | None = None
    ramp: NDArray | None = None


def run_segments(segments: list[tuple[int, ClosedLoop]], e: NDArray, X0: NDArray,
                 force: NDArray | None = None, i_max_a: float = np.inf) -> LoopRun:
    """Run the loop over inputs e (N, 12) from X0, as a rig runs it.

    ``segments``: (first sample, loop) pairs, first samples increasing from 0: a plant that
    changes with time (slowly, piecewise constant) runs each loop from its first sample on.
    ``i_max_a``: the amplifiers deliver clip(w, -i_max_a, i_max_a) (A) instead of w, a
    sample-level nonlinearity run with the open-loop form of :class:`ClosedLoop`; so do the
    loops' magnet laws and amplifier dynamics (see the module doc). With none of them the
    linear recursion X[k+1] = Acl X[k] + Bcl e[k] runs."""
    N = e.shape[0]
    if segments[0][0] != 0:
        raise ValueError(f"the first segment must start at sample 0, not {segments[0][0]}")
    Xs = np.empty((N, X0.size))
    X = X0.copy()
    bounds = [s for s, _ in segments[1:]] + [N]
    clipped = np.isfinite(i_max_a)
    magnets = any(cl.magnets for _, cl in segments)
    dynamic = any(cl.amp is not None for _, cl in segments)
    coil = np.empty((N, 4)) if dynamic else None
    mag = np.zeros((3, N, 4)) if magnets else None
    limited = np.zeros((N, 4), bool) if dynamic else None
    ramp = np.zeros((N, 4)) if dynamic else None
    for (k0, cl), k1 in zip(segments, bounds, strict=True):
        if k1 <= k0:
            continue
        if not (clipped or magnets or dynamic):
            drive = e[k0:k1] @ cl.Bcl.T
            if force is not None:
                drive = drive + force[k0:k1] @ cl.Bf.T
            A = cl.Acl
            for k in range(k0, k1):
                Xs[k] = X
                X = A @ X + drive[k - k0]
            continue
        drive = e[k0:k1] @ cl.Bop.T
        if force is not None:
            drive = drive + force[k0:k1] @ cl.Bf.T
        wd = e[k0:k1] @ cl.Dw.T
        A, Bw, Cw = cl.Aop, cl.Bw, cl.Cw
        amp, laws, slot = cl.amp, cl.magnets, cl.start_slot
        m = 0 if cl.Gsub is None else cl.Gsub.shape[1] // 4
        for k in range(k0, k1):
            Xs[k] = X
            w = Cw @ X + wd[k - k0]
            a = np.clip(w, -i_max_a, i_max_a) if clipped else w
            Xn = A @ X + drive[k - k0]
            if amp is not None:
                end, means, limited[k], ramp[k] = amp.waveform(X[slot:slot + 4], a,
                                                               cl.dt, m)
                Xn += Bw @ end + cl.Gsub @ (means - end).ravel()
                coil[k] = end
            else:
                Xn += Bw @ a
            if laws:
                applied = a if slot < 0 else X[slot:slot + 4]
                cur = cl.Ccur @ X + cl.cur_dir * applied
                gap = cl.Cxb @ X
                rem = np.zeros(4)
                for law in laws:
                    c = list(law.channels)
                    rem[c] = law.remainder(cur[c], gap[c])
                mag[0, k], mag[1, k], mag[2, k] = cur, gap, rem
                Xn += cl.Bn @ rem
            X = Xn
    cl = segments[0][1]     # output maps do not change with the plant's time variation
    y = Xs @ cl.Cy.T + e @ cl.Dy.T
    u = Xs @ cl.Cu.T + e @ cl.Du.T
    eps = Xs @ cl.Ce.T + e @ cl.De.T
    w = Xs @ cl.Cw.T + e @ cl.Dw.T
    if coil is None:
        coil = np.clip(w, -i_max_a, i_max_a) if clipped else w
    if magnets:
        on = np.zeros(4, bool)
        for _, c in segments:
            for law in c.magnets:
                on[list(law.channels)] = True
        mag[:2, :, ~on] = 0.0
    return LoopRun(y, u, eps, w, coil, X, *(mag if magnets else (None, None, None)),
                   limited, ramp)
