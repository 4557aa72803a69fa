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


def diagnosis_json() -> dict:
    """A small diagnosis.json with every required key: an actuator lag named."""
    coef = {"map": 0.1, "mean": 0.1, "sd": 0.01, "hdi90": [0.08, 0.12], "unit": "N/m",
            "physical_mean": -1e4, "physical_hdi90": [-1.2e4, -0.8e4]}
    fit = {"nrmse": {"Ax": 0.9}, "whiteness_p": {"Ax": 0.2}}
    return {
        "format": "bayes-amb-diagnosis/1", "package_version": "0.1.0",
        "recording": "missing.csv", "parameters_estimated": ["k_By"], "checks": [],
        "record_window": {"start_s": 0.0, "at_rest": True}, "verdict": "explained",
        "mismatch": {"detected": True, "channels": ["Ax"], "bands_hz": [[100.0, 200.0]],
                     "time_s": None, "evidence": {"strength": "strong"}, "findings": [],
                     "noise_findings": [], "lines": []},
        "explanations": [{"effect": "actuator_lag", "location": "both", "score": 3.2,
                          "params": {"bandwidth_hz": {"mean": 2500.0, "map": 2500.0,
                                                      "hdi90": [2400, 2600], "unit": "Hz"}},
                          "description": "actuator lag, bandwidth 2500 Hz", "sampled": {},
                          "title": "actuator lag", "side": "actuator",
                          "log_posterior_odds": 1.0, "kind": "physics",
                          "equivalence_class": ["actuator_lag@both"],
                          "confidence": "confident", "evidence": "log Bayes factor 3.2"}],
        "unexplained": {"present": False, "channels": [], "bands_hz": [], "findings": []},
        "candidates": [],
        "fit": {"before": fit, "after": fit, "log_likelihood_gain": 5.0},
        "parameters_before": {"k_By": coef}, "parameters_after": {"k_By": coef},
        "criterion": "accept above log posterior odds 3", "inference": "MAP", "seed": 0,
        "summary": "actuator lag <b>suspected</b>"}
