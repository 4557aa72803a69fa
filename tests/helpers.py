"""Small helpers shared by the test modules."""

from __future__ import annotations

import numpy as np
import scipy.signal as sig

from bayes_amb.cli.main import main


def run_cli(argv: list[str], capsys) -> tuple[int, str, str]:
    """Exit status, stdout and stderr of main(argv); argparse errors raise SystemExit."""
    try:
        code = main(argv)
    except SystemExit as exc:                          # argparse usage errors
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def rel_freq(a: np.ndarray, b: np.ndarray) -> float:
    """max over z of ||a(z) - b(z)||_F / ||b(z)||_F."""
    return float(np.max(np.linalg.norm(a - b, axis=(1, 2)) / np.linalg.norm(b, axis=(1, 2))))


def rel_signal(a: np.ndarray, b: np.ndarray) -> float:
    """Largest per-channel max|a - b| / max|b| (channels carry different units)."""
    return float(np.max(np.max(np.abs(a - b), axis=0) / np.max(np.abs(b), axis=0)))


def dlsim(sys, u: np.ndarray) -> np.ndarray:
    """scipy.signal.dlsim of a discrete system from rest; u (n, m) -> y (n, p)."""
    _, y, _ = sig.dlsim((np.asarray(sys.A), np.asarray(sys.B), np.asarray(sys.C),
                         np.asarray(sys.D), sys.dt), u)
    return y


K_THETA = {"Ax": 0.2, "Ay": -0.1, "Bx": 0.25, "By": -0.3}
C_NSM = {"Ax": 100.0, "Ay": 0.0, "Bx": 250.0, "By": 50.0}
"""Every bearing coefficient off nominal (ks reduction per axis, added damping in N s/m):
the foreign generator's settings in the identity tests."""
