"""`bayes-amb model`: the FE model and its reduction, summarised."""

from __future__ import annotations

import argparse

from bayes_amb.cli.common import emit
from bayes_amb.cli.options import real
from bayes_amb.reduction import reduce_pseudo_modal
from bayes_amb.reduction.fidelity import singular_value_data
from bayes_amb.rig import Rig, check_speed_rpm, load_rig
from bayes_amb.rotor import bending_frequencies_hz, full_model, unstable_poles


def damping_text(rig: Rig, beta: float) -> str:
    """The shaft's damping in words: 'C = beta*K_shaft, beta = 1.234e-06 s' (uniform), or
    the element table's Rayleigh damping."""
    if rig.modal_zeta:
        rest = "" if rig.shaft.uniform else "; plus each element's alpha M_e + beta K_e"
        return (f"C = modal: zeta {rig.modal_zeta:g} on every free-free bending mode of the "
                f"shaft and discs{rest}")
    if rig.shaft.uniform:
        return f"C = beta*K_shaft, beta = {beta:.3e} s"
    pairs = sorted({(e.alpha, e.beta) for e in rig.shaft.elements})
    each = ", ".join(f"alpha {a:g} 1/s, beta {b:g} s" for a, b in pairs[:3])
    more = f" (+{len(pairs) - 3} more)" if len(pairs) > 3 else ""
    extra = f"; plus beta*K_shaft, beta = {beta:.3e} s" if beta else ""
    return f"C = sum of alpha M_e + beta K_e per element: {each}{more}{extra}"


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("model", help="build the FE rotor model and its reduction; summarise",
                       description="Build the full FE model (eq. 17) of a rig at a speed, "
                       "reduce it (eqs. 18-45) and print poles, bending frequencies and the "
                       "reduction error.")
    p.add_argument("--rig", default=None, metavar="FILE",
                   help="rig TOML file (default: the reference rig)")
    p.add_argument("--speed-rpm", type=real(), default=None, metavar="RPM",
                   help="rotor speed, rpm, 0..2 x the rig's nominal speed (default: nominal, "
                   "31500 on the reference rig)")
    p.add_argument("--json", action="store_true", help="print JSON (default: text)")
    p.set_defaults(func=run)


def model_summary(rig_path: str | None = None, speed_rpm: float | None = None) -> dict:
    """The data behind `bayes-amb model` (Python API)."""
    rig = load_rig(rig_path)
    speed = check_speed_rpm(rig, speed_rpm)
    fm = full_model(rig, speed)
    red = reduce_pseudo_modal(fm)
    sv = singular_value_data(red)
    return {
        "rig": rig.name,
        "n_nodes": rig.n_nodes,
        "n_states": fm.n_states,
        "n_inputs": fm.B.shape[1],
        "n_outputs": fm.C.shape[0],
        "speed_rpm": speed,
        "unstable_poles": [[float(p.real), float(p.imag)] for p in unstable_poles(fm)],
        "bending_hz": [float(f) for f in bending_frequencies_hz(fm, 8)],
        "reduced_states": red.n_states,
        "reduced_poles": [[float(p.real), float(p.imag)] for p in red.poles],
        "reduction_error_db": sv.max_gap_db(),
        "first_bending_rad_s": sv.first_bending_rad_s,
        "beta_s": fm.matrices.beta,
        "damping": damping_text(rig, fm.matrices.beta),
        "supports": [s.to_dict() for s in rig.supports],
    }


def format_summary(d: dict) -> str:
    lines = [
        f"Rig '{d['rig']}' at {d['speed_rpm']:.0f} rpm",
        f"  full FE model : {d['n_nodes']} nodes, {d['n_states']} states, "
        f"{d['n_inputs']} inputs (currents Ax Ay Bx By, A), {d['n_outputs']} outputs "
        "(displacements, m)",
        f"  open loop     : {len(d['unstable_poles'])} poles in the right half-plane "
        "(the AMB negative stiffness makes the rotor unstable):",
    ]
    for re, im in d["unstable_poles"]:
        lines.append(f"                  {re:9.2f} {'+' if im >= 0 else '-'} {abs(im):8.2f}j rad/s")
    bh = d["bending_hz"]
    lines.append("  bending modes : " + ", ".join(f"{f:.0f}" for f in bh[:6]) + " Hz "
                 "(backward/forward whirl pairs)")
    lines.append(f"  reduced model : {d['reduced_states']} states (suspended rigid-body modes); "
                 f"largest singular-value gap below half the first bending frequency "
                 f"({d['first_bending_rad_s'] / 2:.0f} rad/s): {d['reduction_error_db']:.3f} dB")
    poles = ", ".join(f"{re:.1f}{'+' if im >= 0 else '-'}{abs(im):.1f}j"
                      for re, im in d["reduced_poles"])
    lines.append(f"  reduced poles : {poles} rad/s")
    lines.append(f"  damping       : {d['damping']}")
    for s in d.get("supports", []):
        coef = ", ".join(f"{k} {v:.4g}" for k, v in s.items() if k not in ("name", "node"))
        lines.append(f"  support       : {s['name']} at node {s['node']} (fixed, not "
                     f"identified; N/m, N s/m, kg): {coef}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    d = model_summary(args.rig, args.speed_rpm)
    emit(d, format_summary(d), args.json)
    return 0
