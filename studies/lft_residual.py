"""How far is the model identify fits from the full FE model once the bearings move?

On a rig whose model keeps bending pairs, the nominal model holds the compliance of the
modes it leaves out from the currents to the probes, at nominal bearings
(ForwardModel.static). The reduced LFT (eqs. 51-52) carries a bearing coefficient through
the kept modes only. For each coefficient set to VALUE alone, this prints the relative
error of the model's sampled plant against the full FE model's with the same coefficient
(uncertainty.lft_full), per direct channel, at a few frequencies of the model's band:
where the left-out modes' deflection at the bearing matters, the error grows with the
coefficient.

    PYTHONPATH=. python studies/lft_residual.py runs/rr57l/control_000.csv

A study of a question (docs/validation.md, "ROSS's real test rig"); the truth of the
record is not read.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

COEFFICIENTS = ("k_Ax", "k_Ay", "k_Bx", "k_By", "c_Ax", "c_Ay", "c_Bx", "c_By")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("record", type=Path, help="a recording (NAME.csv) on the rig")
    ap.add_argument("--value", type=float, default=0.2, help="theta of each coefficient")
    ap.add_argument("--hz", default="50,100,150,193", help="frequencies, Hz")
    a = ap.parse_args(argv)
    from bayes_amb.control.discrete import ss_freqresp, zoh
    from bayes_amb.inference.forward import ForwardModel
    from bayes_amb.io.recording import load_recording
    from bayes_amb.uncertainty.lft import lft_full

    rec = load_recording(a.record)
    fwd = ForwardModel(rec, COEFFICIENTS)
    fl = lft_full(fwd.reduced.full, rec.rig, COEFFICIENTS)
    hz = np.array([float(v) for v in a.hz.split(",")])
    z = np.exp(2j * np.pi * hz * fwd.dt)
    print(fwd.band.line() if fwd.band is not None else "")
    for i, name in enumerate(COEFFICIENTS):
        th = np.zeros(len(COEFFICIENTS))
        th[i] = a.value
        Ad, Bd = zoh(fl.A_theta(th), fl.B, fwd.dt)
        G_fe = ss_freqresp(Ad, Bd, fl.C, None, z)
        Ap, Bp, Cp = fwd.plants(th[None])
        G = ss_freqresp(Ap[0], Bp[0], Cp, None, z)
        e = np.diagonal(G - G_fe, axis1=1, axis2=2) / np.abs(np.diagonal(G_fe, axis1=1,
                                                                         axis2=2))
        cells = [f"{h:.0f} Hz " + " ".join(f"{ch} {v.real:+.4f}{v.imag:+.4f}j"
                                           for ch, v in zip(("Ax", "Ay", "Bx", "By"), row,
                                                            strict=True))
                 for h, row in zip(hz, e, strict=True)]
        print(f"{name} = {a.value:g}: " + " | ".join(cells), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
