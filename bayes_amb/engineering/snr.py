"""Response-to-excitation SNR per channel: how much of the recorded displacement the
excitation drives, against everything else (noise, disturbances, unmodelled response).

    y_x = T_yx(theta) x       (the identified closed loop driven by the recorded excitation)
    SNR_j = 10 log10( mean(y_x,j^2) / mean((y_j - y_x,j)^2) )   dB

T_yx is the full plant with the identified parameters, sampled at dt and closed with the
recorded controller; x enters where it was injected (the controller's Youla port, or added
to the current at the plant input). This is the SNR a test engineer plans an excitation
with; it is not the ratio of S(theta) x to the residual of eps (which measures how much
theta changes eps).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from bayes_amb.control.discrete import zoh
from bayes_amb.engineering.loop import plant_matrices
from bayes_amb.io.recording import Recording

__all__ = ["excitation_response", "response_snr_db"]


def excitation_response(recording: Recording, theta: dict[str, float],
                        model: str = "full") -> NDArray:
    """y_x (N, 4) in m: the displacement the recorded excitation drives through the
    identified closed loop, from rest."""
    port = next(iter(recording.excitation))
    x = np.asarray(recording.excitation[port], dtype=float)
    A, B, C = plant_matrices(recording.rig, recording.speed_rpm, theta, model)
    Ad, Bd = zoh(A, B, recording.dt)
    c = recording.controller
    Ak, Bk, Ck, Dk = (np.asarray(m) for m in (c.A, c.B, c.C, c.D))
    n, nk = Ad.shape[0], Ak.shape[0]
    if port == "eta":               # at the controller's excitation port
        Bx_p, Bx_k = Bd @ Dk[:4, 4:], Bk[:, 4:]
    else:                           # r2: added to the plant-input current; r1 at the sensor
        Bx_p, Bx_k = (Bd, np.zeros((nk, 4))) if port == "r2" else \
            (Bd @ Dk[:4, :4], Bk[:, :4])
    Acl = np.block([[Ad + Bd @ Dk[:4, :4] @ C, Bd @ Ck[:4]], [Bk[:, :4] @ C, Ak]])
    Bcl = np.vstack([Bx_p, Bx_k])
    Ccl = np.hstack([C, np.zeros((4, nk))])
    s = np.zeros(n + nk)
    out = np.empty((x.shape[0], 4))
    for k in range(x.shape[0]):
        out[k] = Ccl @ s
        s = Acl @ s + Bcl @ x[k]
    if port == "r1":
        out += x
    return out


def response_snr_db(recording: Recording, theta: dict[str, float], model: str = "full"
                    ) -> NDArray:
    """Response-to-excitation SNR per channel (dB), shape (4,) (module docstring)."""
    yx = excitation_response(recording, theta, model)
    rest = np.asarray(recording.y) - yx
    with np.errstate(divide="ignore"):
        return 10 * np.log10(np.mean(yx**2, axis=0) / np.mean(rest**2, axis=0))
