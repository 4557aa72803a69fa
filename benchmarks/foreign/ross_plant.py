"""ROSS's model of the real AMB test rig as a plant of the foreign generator.

The rotor is ROSS's ``rotor_example_amb_complex_controllers()`` (ross.bearings.magnetic
.amb_models; doi 10.14393/ufu.di.2015.186), the rig the product ships converted as
``bayes_amb/rig/data/ross_test_rig.toml``. What is ROSS's and what is ours:

- ROSS's: the bare rotor's matrices ``Rotor(shaft_elements, disk_elements)``.M(0), K(0),
  C(0) (Rayleigh damping, alpha M_e + beta K_e per element) and G() of its 52 Timoshenko
  elements and 19 discs, restricted to the lateral DOFs x, y, rot_x, rot_y of each node
  (ROSS's DOFs 0, 1, 3, 4 of 6; the axial and torsional ones are uncoupled, checked); the
  magnets' ki and ks (``MagneticBearingElement.ki``, ``.ks``, ROSS's ks < 0); the bearings'
  and sensors' nodes; each bearing's controller C(s) (``controller_transfer_function``
  num, den), ``k_amp`` and ``k_sense``.
- Ours: the state space x = [q; q'] of M q'' + (C + Omega G) q' + (K - ks P_b) q = f, the
  magnets' linearised force f = ki i + ks x applied at the bearing DOFs (ks > 0 the
  physical negative stiffness, ks = -ROSS's ks), the full FE model kept (424 states: the
  bending modes to far beyond the 5 kHz Nyquist frequency are in the world); the
  controllers realised from ROSS's num/den as a cascade of first and second order
  sections (poles and zeros from the polynomials), the coil current
  i = -s_b k_amp C(s) k_sense y (negative feedback, as ROSS's own k_eq = ks + ki k_amp
  k_sense C; k_amp and k_sense folded into the controller file, which maps m to A), s_b
  the scale that takes out the bearing constant ROSS writes twice into each gain
  (``SCALE``); discretised by Tustin (bilinear, no prewarping; ``method="zoh"`` for the
  exact zero-order hold) and written as a ``generic`` controller file.

Only ``bayes_amb.rig`` is read from the product (the rig file: sensor nodes, the disc
names, c_ref, the rig embedded in the recordings); ROSS is imported lazily, on the first
call of :func:`ross_rig`.
"""

from __future__ import annotations

import contextlib
import io
import warnings
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
import scipy.signal as sig
from numpy.typing import NDArray

from bayes_amb.rig import Rig, load_rig
from benchmarks.foreign.effects import ContinuousPlant, Effect

RIG_NAME = "ross_test_rig"
SPEED_RPM = 3000.0
SCALE = {"A": 1 / 0.0062, "B": 1 / 0.0046}
"""Each ROSS gain carries its bearing constant twice (0.0062 at A, 0.0046 at B): one out."""
AXES = ("Ax", "Ay", "Bx", "By")
LATERAL = (0, 1, 3, 4)
"""ROSS's lateral DOFs of a node (x, y, rotation about x, about y) of its 6."""


def dof(node: int, axis: str) -> int:
    """0-based index of a 1-based node's x or y DOF in the lateral DOFs (4 a node)."""
    return 4 * (node - 1) + "xy".index(axis)


@dataclass(frozen=True)
class RossRig:
    """ROSS's test rig, as read from the live ROSS rotor (SI units).

    M, K, C, G (n_q, n_q): the bare rotor's lateral matrices (kg, N/m, N s/m, kg m^2 per
    rad/s of spin). Nodes are 1-based (ROSS's n + 1). ``ki`` (N/A) and ``ks`` (N/m, > 0)
    per bearing A, B; ``magnets`` each magnet's constants as ROSS holds them (g0, i0, ag,
    nw, alpha); ``controllers`` per bearing (num, den) of ROSS's C(s) as written (no
    scale, k_amp and k_sense apart); ``k_amp``, ``k_sense`` per bearing and axis (x, y)."""

    M: NDArray
    K: NDArray
    C: NDArray
    G: NDArray
    bearing_nodes: dict[str, int]
    sensor_nodes: dict[str, int]
    ki: dict[str, float]
    ks: dict[str, float]
    magnets: dict[str, dict[str, float]]
    controllers: dict[str, tuple[NDArray, NDArray]]
    k_amp: dict[str, tuple[float, float]]
    k_sense: dict[str, tuple[float, float]]
    disc_nodes: tuple[int, ...]

    @property
    def n_q(self) -> int:
        return self.M.shape[0]


def _two(v: Any) -> tuple[float, float]:
    a = np.atleast_1d(np.asarray(v, dtype=float)).ravel()
    return (float(a[0]), float(a[-1]))


@lru_cache(maxsize=1)
def ross_rig() -> RossRig:
    """Read ROSS's rotor (about 10 s: importing ROSS is most of it); cached."""
    with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import ross as rs
        from ross.bearings.magnetic.amb_models import rotor_example_amb_complex_controllers
        rotor = rotor_example_amb_complex_controllers()
        bare = rs.Rotor(rotor.shaft_elements, rotor.disk_elements)
        mats = [np.asarray(X, dtype=float) for X in (bare.M(0), bare.K(0), bare.C(0),
                                                     bare.G())]
    n6 = mats[0].shape[0]
    lat = [i for i in range(n6) if i % 6 in LATERAL]
    other = [i for i in range(n6) if i % 6 not in LATERAL]
    for X in mats:
        if np.abs(X[np.ix_(lat, other)]).max() > 1e-12 * np.abs(X).max():
            raise ValueError("ROSS's lateral DOFs couple to the axial/torsional ones")
    M, K, C, G = (X[np.ix_(lat, lat)] for X in mats)
    mbs = sorted((b for b in rotor.bearing_elements if hasattr(b, "ki")),
                 key=lambda b: b.n)
    if len(mbs) != 2:
        raise ValueError(f"expected 2 magnetic bearings, got {len(mbs)}")
    out: dict[str, dict] = {k: {} for k in ("nodes", "sensors", "ki", "ks", "mag", "ctrl",
                                            "amp", "sense")}
    for name, b in zip(("A", "B"), mbs, strict=True):
        out["nodes"][name] = int(b.n) + 1
        out["sensors"][name] = int(b.sensor_node) + 1
        out["ki"][name] = float(np.atleast_1d(b.ki)[0])
        out["ks"][name] = -float(np.atleast_1d(b.ks)[0])           # ROSS's ks < 0
        out["mag"][name] = {"g0": float(b.g0), "i0": _two(b.i0)[0], "ag": float(b.ag),
                            "nw": float(b.nw), "alpha": float(b.alpha)}
        out["ctrl"][name] = (np.trim_zeros(np.asarray(b.controller_transfer_function_num,
                                                      float).ravel(), "f"),
                             np.trim_zeros(np.asarray(b.controller_transfer_function_den,
                                                      float).ravel(), "f"))
        out["amp"][name], out["sense"][name] = _two(b.k_amp), _two(b.k_sense)
    discs = tuple(sorted(int(d.n) + 1 for d in rotor.disk_elements))
    return RossRig(M, K, C, G, out["nodes"], out["sensors"], out["ki"], out["ks"],
                   out["mag"], out["ctrl"], out["amp"], out["sense"], discs)


def rig() -> Rig:
    """The product's rig file of this rotor (a drawing: sensor nodes, disc names, c_ref)."""
    return load_rig(RIG_NAME)


def check_against_rig(rr: RossRig, r: Rig, rtol: float = 1e-9) -> None:
    """ROSS's magnets and nodes agree with the rig file's (ValueError naming the first that
    does not)."""
    for b in ("A", "B"):
        for what, mine, theirs in (("ki", rr.ki[b], r.magnets[b].ki),
                                   ("ks", rr.ks[b], r.magnets[b].ks)):
            if abs(mine - theirs) > rtol * abs(theirs):
                raise ValueError(f"bearing {b}: ROSS's {what} {mine!r} != rig's {theirs!r}")
        if (rr.bearing_nodes[b], rr.sensor_nodes[b]) != (r.bearing_nodes[b],
                                                         r.sensor_nodes[b]):
            raise ValueError(f"bearing {b}: nodes differ from the rig file's")


# ------------------------------------------------------------------------ the plant
def rotor_matrices(rr: RossRig, speed_rpm: float, k_theta: dict[str, float] | None = None,
                   c_nsm: dict[str, float] | None = None) -> tuple[NDArray, NDArray]:
    """(A, Minv): the rotor's state matrix (2 n_q) with the magnets' negative stiffness,
    ks_true = (1 - k_theta) ks of each axis' own bearing, and c_nsm (N s/m) added viscous
    damping per axis at the bearing node; Minv for the force maps."""
    K, C = rr.K.copy(), rr.C.copy()
    for ax in AXES:
        j = dof(rr.bearing_nodes[ax[0]], ax[1])
        K[j, j] -= (1.0 - (k_theta or {}).get(ax, 0.0)) * rr.ks[ax[0]]
        C[j, j] += (c_nsm or {}).get(ax, 0.0)
    n, om = rr.n_q, float(speed_rpm) * np.pi / 30.0
    Minv = np.linalg.inv(rr.M)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ K, -Minv @ (C + om * rr.G)]])
    return A, Minv


def open_loop_poles(rr: RossRig, speed_rpm: float = SPEED_RPM) -> NDArray:
    """Eigenvalues (1/s) of the bare rotor with the magnets' negative stiffness."""
    return np.linalg.eigvals(rotor_matrices(rr, speed_rpm)[0])


def _where(where: str) -> list[int]:
    return [0, 1, 2, 3] if where == "all" else [i for i, a in enumerate(AXES)
                                                 if a[0] == where or a == where]


def build(rr: RossRig, speed_rpm: float, k_theta: dict[str, float], c_nsm: dict[str, float],
          effects: tuple[Effect, ...] = ()) -> ContinuousPlant:
    """The continuous plant x' = A x + B w, y = C x (w the four commanded currents, A; y
    the probes' displacements, m), with the eight bearing coefficients and the effects:

    - ``actuator_lag`` (``bandwidth_hz``, ``where`` A/B/all): i' = wb (w - i) per channel;
    - ``unbalance`` (``planes``: [{``node``, ``u_kgm``, ``phase_rad``}]): the force
      u Omega^2 [cos, sin](Omega t + phase) at the node, from an undamped oscillator
      [cos Omega t, sin Omega t] (2 states; x0 starts it at angle 0);
    - ``probe_angle`` (``bearing``, ``angle_deg``): that bearing's probe pair turned by the
      angle against the actuator axes, [p_x, p_y] = R(a) [q_x, q_y].
    """
    known = {"actuator_lag", "unbalance", "probe_angle"}
    for e in effects:
        if e.name not in known:
            raise ValueError(f"effect {e.name!r} is not played on the ROSS rig "
                             f"(known: {sorted(known)})")
    Ar, Minv = rotor_matrices(rr, speed_rpm, k_theta, c_nsm)
    nr, nq = Ar.shape[0], rr.n_q
    lag = np.zeros(4)
    for e in effects:
        if e.name == "actuator_lag":
            lag[_where(e.params["where"])] = 2 * np.pi * float(e.params["bandwidth_hz"])
    lagged = [ch for ch in range(4) if lag[ch] > 0]
    planes = [p for e in effects if e.name == "unbalance" for p in e.params["planes"]]
    n = nr + len(lagged) + (2 if planes else 0)
    A, B, C, x0 = np.zeros((n, n)), np.zeros((n, 4)), np.zeros((4, n)), np.zeros(n)
    A[:nr, :nr] = Ar

    def force_col(node: int, axis: str) -> NDArray:       # x' per N at a DOF
        col = np.zeros(n)
        col[nq:nr] = Minv[:, dof(node, axis)]
        return col

    for ch, ax in enumerate(AXES):
        f = rr.ki[ax[0]] * force_col(rr.bearing_nodes[ax[0]], ax[1])
        if ch in lagged:
            s = nr + lagged.index(ch)
            A[s, s], B[s, ch] = -lag[ch], lag[ch]
            A[:, s] += f
        else:
            B[:, ch] = f
        C[ch, dof(rr.sensor_nodes[ax[0]], ax[1])] = 1.0
    om = float(speed_rpm) * np.pi / 30.0
    osc = -1
    if planes:
        osc = n - 2
        A[osc:, osc:] = [[0.0, -om], [om, 0.0]]
        x0[osc] = 1.0
        for p in planes:
            fx, fy = force_col(int(p["node"]), "x"), force_col(int(p["node"]), "y")
            u, ph = float(p["u_kgm"]) * om * om, float(p["phase_rad"])
            A[:, osc:] += u * (np.outer(fx, [np.cos(ph), -np.sin(ph)])
                               + np.outer(fy, [np.sin(ph), np.cos(ph)]))
    for e in effects:
        if e.name == "probe_angle":
            ix, iy = _where(e.params["bearing"])
            a = np.radians(float(e.params["angle_deg"]))
            C[[ix, iy]] = np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]]) @ C[[ix, iy]]
    return ContinuousPlant(A=A, B=B, C=C, x0=x0, delay_s=0.0, n_rotor=nr, omega=om, osc=osc)


# ------------------------------------------------------------------- the controllers
def _factors(roots: NDArray) -> list[NDArray]:
    """Real monic factors of a root set: [1, -r] per real root, [1, -2 Re, |r|^2] per pair."""
    out, used = [], np.zeros(roots.size, bool)
    for i, r in enumerate(roots):
        if used[i]:
            continue
        used[i] = True
        if abs(r.imag) <= 1e-9 * max(abs(r), 1.0):
            out.append(np.array([1.0, -r.real]))
        else:
            j = int(np.argmin(np.abs(roots - np.conj(r)) + used * 1e300))
            used[j] = True
            out.append(np.array([1.0, -2 * r.real, abs(r) ** 2]))
    return sorted(out, key=lambda f: abs(f[-1]) ** (1 / (len(f) - 1)))


def cascade(num: NDArray, den: NDArray) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """A well-scaled (A, B, C, D) of the proper SISO num/den (descending powers): a cascade
    of first and second order sections, each pole factor with the zero factor of nearest
    corner frequency (of its own order where one is left), the gain at the end."""
    num = np.trim_zeros(np.asarray(num, float), "f")
    den = np.trim_zeros(np.asarray(den, float), "f")
    if num.size > den.size:
        raise ValueError("improper transfer function")
    gain = num[0] / den[0]
    zf, pf = _factors(np.roots(num)), _factors(np.roots(den))
    secs = []
    for p in pf:
        k = next((i for i, z in enumerate(zf) if len(z) == len(p)), None)
        if k is None and len(p) == 3 and sum(len(z) == 2 for z in zf) >= 2:
            i1 = next(i for i, z in enumerate(zf) if len(z) == 2)
            z1 = zf.pop(i1)
            i2 = next(i for i, z in enumerate(zf) if len(z) == 2)
            z = np.polymul(z1, zf.pop(i2))
        elif k is not None:
            z = zf.pop(k)
        else:
            z = next((zf.pop(i) for i, z in enumerate(zf) if len(z) < len(p)), np.array([1.0]))
        secs.append(sig.tf2ss(z, p))
    if zf:
        raise ValueError("zeros left over: give a transfer function of another form")
    A = np.zeros((0, 0))
    B, C, D = np.zeros((0, 1)), np.zeros((1, 0)), np.array([[1.0]])
    for a, b, c, d in secs:            # series: this section after the cascade so far
        na, m = A.shape[0], a.shape[0]
        A = np.block([[A, np.zeros((na, m))], [b @ C, a]])
        B = np.vstack([B, b @ D])
        C = np.hstack([d @ C, c])
        D = d @ D
    return A, B, gain * C, gain * D


def controller_ct(rr: RossRig, scale: dict[str, float] | None = None
                  ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """The continuous 4 x 4 decentralised controller y (m) -> u (A), negative feedback:
    channel Ax, Ay of bearing A get -s_A k_amp C_A(s) k_sense, B likewise."""
    scale = SCALE if scale is None else scale
    blocks = []
    for ch, ax in enumerate(AXES):
        b = ax[0]
        A, Bc, Cc, D = cascade(*rr.controllers[b])
        g = -float(scale.get(b, 1.0)) * rr.k_amp[b][ch % 2] * rr.k_sense[b][ch % 2]
        blocks.append((A, Bc, g * Cc, g * D))
    from scipy.linalg import block_diag
    return (block_diag(*(b[0] for b in blocks)), block_diag(*(b[1] for b in blocks)),
            block_diag(*(b[2] for b in blocks)), np.diag([b[3][0, 0] for b in blocks]))


def discretise(K: tuple[NDArray, ...], dt: float, method: str = "tustin"
               ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Tustin (bilinear, no prewarping) or 'zoh' (exact zero-order hold)."""
    if method not in ("tustin", "zoh"):
        raise ValueError(f"method must be 'tustin' or 'zoh', got {method!r}")
    out = sig.cont2discrete(K, dt, method="bilinear" if method == "tustin" else "zoh")
    return tuple(np.asarray(m, float) for m in out[:4])


def controller_file(rr: RossRig, r: Rig, dt: float = 1e-4, method: str = "tustin",
                    scale: dict[str, float] | None = None) -> dict[str, Any]:
    """The controllers as a ``bayes-amb-controller/1`` file (dict) of kind ``generic``:
    inputs [y_*, eta_*], outputs [u_*, eps_*]; as a generic controller has them, eta adds to
    u (D block I; an r2 excitation goes to the amplifier beside it, not through the port)
    and eps is zero."""
    Ad, Bd, Cd, Dd = discretise(controller_ct(rr, scale), dt, method)
    nk = Ad.shape[0]
    B = np.hstack([Bd, np.zeros((nk, 4))])
    C = np.vstack([Cd, np.zeros((4, nk))])
    D = np.zeros((8, 8))
    D[:4, :4], D[:4, 4:] = Dd, np.eye(4)
    scale = SCALE if scale is None else scale
    text = ("tustin (bilinear, no prewarping)" if method == "tustin"
            else "zoh (exact zero-order hold)") + f" at dt = {dt!r} s"
    return {"format": "bayes-amb-controller/1", "kind": "generic", "dt": float(dt),
            "inputs": [f"y_{a}" for a in AXES] + [f"eta_{a}" for a in AXES],
            "outputs": [f"u_{a}" for a in AXES] + [f"eps_{a}" for a in AXES],
            "A": Ad.tolist(), "B": B.tolist(), "C": C.tolist(), "D": D.tolist(),
            "rig": r.to_dict(),
            "design": {"kind": "generic", "form": "ROSS bearing controllers (foreign "
                       "generator's own realisation)", "feedback": "negative",
                       "discretisation": text, "ross_scale": dict(scale),
                       "imported_from": "ross.bearings.magnetic.amb_models."
                                        "rotor_example_amb_complex_controllers"}}
