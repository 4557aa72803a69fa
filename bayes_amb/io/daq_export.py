"""Write a recording the way a rig's DAQ would: foreign formats, volts, engineer's names.

The inverse of :func:`bayes_amb.io.daq_import.import_recording`, used by the round-trip
tests and ``bayes-amb demo --import-formats``: each mapped channel is written as
``raw = offset + value / (sign * factor(unit))`` under its ``source`` name, in .mat v5
(:func:`scipy.io.savemat`), .mat v7.3 (HDF5 with MATLAB's 512-byte header, arrays
transposed as MATLAB stores them), TDMS (npTDMS, with ``wf_increment``), HDF5 or CSV.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bayes_amb.io.atomic import atomic_path
from bayes_amb.io.channel_map import ChannelMap, channel_map_from_dict
from bayes_amb.io.recording import Recording
from bayes_amb.rig import CHANNELS

__all__ = ["ENGINEER_NAMES", "export_daq", "realistic_channel_map", "source_name", "write_mat"]

ENGINEER_NAMES = {"y": [f"AMB{b}_{a}_pos" for b in (1, 2) for a in ("X", "Y")],
                  "u": [f"I_ref_{k}" for k in range(1, 5)],
                  "eta": [f"exc_youla_{k}" for k in range(1, 5)],
                  "r2": [f"exc_current_{k}" for k in range(1, 5)],
                  "r1": [f"exc_sensor_{k}" for k in range(1, 5)]}
"""Channel names a rig engineer might use, per group, in CHANNELS order (Ax, Ay, Bx, By)."""


def source_name(fmt: str, name: str) -> str:
    """How a channel called ``name`` is addressed in each format (TDMS group/channel, ...)."""
    return {"tdms": f"AMB/{name}", "hdf5": f"/daq/{name}"}.get(fmt, name)


def realistic_channel_map(fmt: str, groups: tuple[str, ...] | list[str], *, controller: str,
                          speed_rpm: float, rig: str = "reference",
                          time_column: bool = True, dt: float | None = None
                          ) -> dict[str, Any]:
    """A channel map as a rig would need it: volts, sensitivities, offsets, one sign flipped.

    Displacements: 8 V/mm probes (sensitivity 8000 V/m) with offsets of 0.12, -0.05, 0.03,
    0.08 V; the Ay probe is mounted the other way (sign -1). Currents: amplifier set-points
    in V with a transconductance of 0.5 A/V and offsets of 10-40 mV. Excitation in mA
    (``eta``/``r2``) or um (``r1``). Time in a column ``time`` (or ``sample_rate_hz = 1/dt``
    when ``time_column`` is False).
    """
    chans: dict[str, dict[str, Any]] = {}
    y_off, u_off = (0.12, -0.05, 0.03, 0.08), (0.01, -0.02, 0.04, -0.03)
    for k, c in enumerate(CHANNELS):
        chans[f"y_{c}"] = {"source": source_name(fmt, ENGINEER_NAMES["y"][k]), "unit": "V",
                           "sensitivity": 8000.0, "sign": -1 if c == "Ay" else 1,
                           "offset": y_off[k]}
    for k, c in enumerate(CHANNELS):
        chans[f"u_{c}"] = {"source": source_name(fmt, ENGINEER_NAMES["u"][k]), "unit": "V",
                           "gain": 0.5, "offset": u_off[k]}
    for g in groups:
        for k, c in enumerate(CHANNELS):
            chans[f"{g}_{c}"] = {"source": source_name(fmt, ENGINEER_NAMES[g][k]),
                                 "unit": "um" if g == "r1" else "mA"}
    if time_column:
        tt: dict[str, Any] = {"column": source_name(fmt, "time")}
    else:
        if dt is None:
            raise ValueError("realistic_channel_map: give dt when time_column is False")
        tt = {"sample_rate_hz": 1.0 / dt}
    return {"source": {"format": fmt}, "time": tt,
            "recording": {"rig": rig, "speed_rpm": float(speed_rpm), "controller": controller,
                          "notes": f"exported to {fmt} by bayes_amb.io.daq_export"},
            "channels": chans}


def _mat73_header() -> bytes:
    text = (f"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: "
            f"{time.strftime('%a %b %d %H:%M:%S %Y', time.gmtime(0))} HDF5 schema 1.00 .")
    return text.encode("ascii").ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02" + b"IM"


def write_mat(path: str | os.PathLike[str], variables: dict[str, NDArray | float],
              v73: bool = False) -> None:
    """Write variables to a .mat file, v5 (scipy) or v7.3 (HDF5, MATLAB layout), atomically.

    Vectors become n x 1 columns, scalars 1 x 1. In v7.3 every array is stored transposed
    (MATLAB is column-major), with its ``MATLAB_class`` attribute.
    """
    import h5py
    import scipy.io

    arrays = {}
    for k, v in variables.items():
        a = np.asarray(v, dtype=float)
        arrays[k] = a.reshape(-1, 1) if a.ndim <= 1 else a
    with atomic_path(path) as tmp:
        if not v73:
            scipy.io.savemat(tmp, arrays, format="5", oned_as="column", appendmat=False)
            return
        with h5py.File(tmp, "w", userblock_size=512) as f:
            for k, a in arrays.items():
                ds = f.create_dataset(k, data=a.T)
                ds.attrs["MATLAB_class"] = np.bytes_("double")
        with open(tmp, "r+b") as f:
            f.write(_mat73_header())


def export_daq(recording: Recording, path: str | os.PathLike[str],
               mapping: ChannelMap | dict[str, Any], fmt: str | None = None) -> Path:
    """Write ``recording`` as a DAQ file through ``mapping`` (the inverse of the import).

    Parameters
    ----------
    recording : Recording
        SI signals to write.
    path : path
        Output file (.mat, .tdms, .h5 or .csv), written atomically.
    mapping : ChannelMap or dict
        The channel map the file is to be read with; its time column (if any) receives
        ``recording.t``. Channels with ``remove_offset`` are written without an offset.
    fmt : str, optional
        ``mat``, ``mat73``, ``tdms``, ``hdf5`` or ``csv`` (default: the map's format).

    Returns
    -------
    Path
        The file written.
    """
    m = mapping if isinstance(mapping, ChannelMap) else channel_map_from_dict(mapping)
    kind = fmt or m.format
    sig = {"y": recording.y, "u": recording.u, **recording.excitation}
    cols: dict[str, NDArray] = {}
    for target, s in m.channels.items():
        g, c = target.rsplit("_", 1)
        cols[s.source] = s.offset + np.asarray(sig[g][:, CHANNELS.index(c)]) / s.factor
    if m.time.column is not None:
        cols[m.time.column] = np.asarray(recording.t)
    p = Path(path)
    if kind in ("mat", "mat73"):
        write_mat(p, cols, v73=kind == "mat73")
    elif kind == "hdf5":
        import h5py

        with atomic_path(p) as tmp, h5py.File(tmp, "w") as f:
            for name, v in cols.items():
                f.create_dataset(name, data=v)
    elif kind == "tdms":
        from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

        objs: list[Any] = [RootObject({"title": "bayes_amb export"})]
        for group in dict.fromkeys(name.split("/")[0] for name in cols):
            objs.append(GroupObject(group))
        for name, v in cols.items():
            group, chan = name.split("/", 1)
            objs.append(ChannelObject(group, chan, v, properties={
                "wf_increment": float(recording.dt), "wf_start_offset": 0.0}))
        with atomic_path(p) as tmp, TdmsWriter(str(tmp)) as w:
            w.write_segment(objs)
    elif kind == "csv":
        names = list(cols)
        data = np.column_stack([cols[n] for n in names])
        lines = [",".join(names), *(",".join(map(repr, row)) for row in data.tolist()), ""]
        with atomic_path(p) as tmp:
            tmp.write_text("\n".join(lines), encoding="ascii")
    else:
        raise ValueError(f"export_daq: unknown format {kind!r}")
    return p
