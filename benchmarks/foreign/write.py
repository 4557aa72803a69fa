"""A small writer of the documented recording format (README, "Recording format").

NAME.csv: header ``t, y_Ax..y_By, u_Ax..u_By, eta_Ax..eta_By``, one row per sample, every
number with full precision (``repr``). NAME.json: the sidecar (format, dt, speed_rpm, rig,
controller in controller-file form, excitation, units, notes, provenance). The truth goes to
a separate NAME.truth.json that the tool never reads.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

_CH = ("Ax", "Ay", "Bx", "By")


def write_recording(stem: str | os.PathLike[str], dt: float, y: NDArray, u: NDArray,
                    eta: NDArray, speed_rpm: float, controller: dict[str, Any],
                    notes: str = "", truth: dict[str, Any] | None = None
                    ) -> dict[str, Path]:
    """Write stem.csv, stem.json (and stem.truth.json); returns their paths by key."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    n = y.shape[0]
    t = np.arange(n) * float(dt)
    header = ["t", *(f"{g}_{c}" for g in ("y", "u", "eta") for c in _CH)]
    data = np.column_stack([t, y, u, eta])
    text = "\n".join([",".join(header), *(",".join(map(repr, r)) for r in data.tolist())])
    paths = {"csv": Path(f"{stem}.csv"), "json": Path(f"{stem}.json")}
    paths["csv"].write_text(text + "\n", encoding="ascii")
    side = {"format": "bayes-amb-recording/1", "dt": float(dt), "speed_rpm": float(speed_rpm),
            "rig": "reference", "controller": controller,
            "excitation": {"columns": ["eta"], "injected_at": {"eta": "youla_port"}},
            "units": {"t": "s", "y": "m", "u": "A", "eta": "A"}, "notes": notes,
            "provenance": {"generator": "benchmarks.foreign (independent of bayes_amb.simulate)"}}
    paths["json"].write_text(json.dumps(side, indent=1), encoding="utf-8")
    if truth is not None:
        paths["truth"] = Path(f"{stem}.truth.json")
        paths["truth"].write_text(json.dumps(truth, indent=1, default=_plain), encoding="utf-8")
    return paths


def _plain(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
