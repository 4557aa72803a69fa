"""Import a DAQ file (.mat, TDMS, HDF5, CSV) through a channel map into a Recording.

Steps, in this order (each stated in the recording's provenance):

1. read the mapped channels and the time column (:func:`bayes_amb.io.daq.read_channels`);
   every channel must have the same length and finite values;
2. time base: the time column (s; strictly increasing, each step within 1 % of the mean
   step, the sample time is the mean step), or ``sample_rate_hz``, or a TDMS channel's
   ``wf_increment``; a time column and a sample rate must agree to 1e-4 (relative);
3. trim to ``start_s <= t - t[0] < stop_s``;
4. offsets: subtract ``offset`` (source units) or, with ``remove_offset``, the mean of the
   trimmed record;
5. scale to SI: ``sign * factor(unit)`` (see :mod:`bayes_amb.io.channel_map`);
6. decimate by ``decimate`` with :func:`scipy.signal.decimate` (order-8 Chebyshev type I
   low-pass at 0.8 of the new Nyquist frequency, applied forward and backward: zero phase),
   in stages of at most 10;
7. load the controller (a controller file, or a MATLAB .mat imported at the new sample
   time, see :mod:`bayes_amb.io.controller_import`) and build and check the
   :class:`~bayes_amb.io.recording.Recording` with the rig, speed and controller of the
   map. Its ``meta["provenance"]["import"]`` holds the sha256 of the source file, the map
   and the controller file, the parsed map and the steps.

Steps 4-6 are linear, so the imported signal is exactly (to float precision) the source's
scaled and decimated signal; ``tests/test_daq_roundtrip.py`` checks it.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import scipy.signal as sig
from numpy.typing import NDArray

from bayes_amb import __version__
from bayes_amb.errors import ControllerError, DataImportError, RecordingError, RigError
from bayes_amb.io.channel_map import ChannelMap, channel_map_from_dict, load_channel_map
from bayes_amb.io.controller_file import ControllerFile, load_controller
from bayes_amb.io.daq import file_sha256, read_channels
from bayes_amb.io.recording import Recording, make_recording
from bayes_amb.rig import CHANNELS, Rig, load_rig

__all__ = ["DECIMATION", "decimate_stages", "import_recording"]

DECIMATION = ("scipy.signal.decimate: order-8 Chebyshev type I IIR low-pass at 0.8 x the new "
              "Nyquist frequency, forward-backward (zero phase), stages of at most 10")
TIME_STEP_RTOL = 0.01   # each step of a time column within 1 % of the mean step
RATE_RTOL = 1e-4        # a time column and a sample rate must agree to this
_MIN_STAGE = 28         # scipy's filtfilt needs more samples than its pad length (27)


def decimate_stages(q: int) -> list[int]:
    """Factors of q, each at most 10, largest first (DataImportError if q has a prime > 10).

    Examples
    --------
    >>> decimate_stages(50), decimate_stages(1)
    ([10, 5], [])
    """
    out, rest = [], int(q)
    for f in range(10, 1, -1):
        while rest % f == 0:
            out.append(f)
            rest //= f
    if rest != 1:
        raise DataImportError(f"time.decimate: {q} has a prime factor above 10 ({rest}); "
                              "choose a factor that is a product of 2..10")
    return out


def _time_base(m: ChannelMap, data: dict[str, NDArray], inc: dict[str, float], where: str,
               n: int) -> tuple[float, float]:
    """(dt, t0) of the raw record."""
    tb = m.time
    if tb.column is not None:
        t = data[tb.column]
        ch = f"{where}: channel {tb.column!r} (time)"
        if n < 2:
            raise DataImportError(f"{ch}: expected at least 2 samples, got {n}")
        d = np.diff(t)
        mean = float(t[-1] - t[0]) / (n - 1)
        bad = ~(d > 0)
        if bad.any():
            i = int(np.argmax(bad)) + 1
            raise DataImportError(f"{ch}: not strictly increasing at sample {i}: t = "
                                  f"{float(t[i])!r} after {float(t[i - 1])!r}")
        bad = np.abs(d - mean) > TIME_STEP_RTOL * mean
        if bad.any():
            i = int(np.argmax(bad)) + 1
            raise DataImportError(f"{ch}: non-uniform: step {float(d[i - 1])!r} s at sample "
                                  f"{i}, mean step {mean!r} s")
        if tb.sample_rate_hz is not None and abs(mean * tb.sample_rate_hz - 1) > RATE_RTOL:
            raise DataImportError(f"{ch}: sample_rate_hz = {tb.sample_rate_hz!r} disagrees with "
                                  f"the time column (mean step {mean!r} s = "
                                  f"{1 / mean!r} Hz)")
        return mean, float(t[0])
    if tb.sample_rate_hz is not None:
        return 1.0 / tb.sample_rate_hz, 0.0
    steps = {inc[s.source] for s in m.channels.values() if s.source in inc}
    if len(steps) == 1:
        step = steps.pop()
        if np.isfinite(step) and step > 0:
            return step, 0.0
    raise DataImportError(f"{where}: time base: the file gives no single sample interval "
                          f"({sorted(steps) or 'none'}); give time.column or "
                          "time.sample_rate_hz in the map")


def _load_rig(m: ChannelMap, rig: Rig | str | None) -> Rig:
    try:
        return rig if isinstance(rig, Rig) else load_rig(rig if rig is not None else m.rig)
    except RigError as err:
        raise DataImportError(f"channel map {m.source}: field recording.rig: {err}") from None


def _load_controller(m: ChannelMap, controller: ControllerFile | str | None, rig: Rig,
                     dt: float) -> tuple[ControllerFile, str | None]:
    """The controller that ran, and the sha256 of its file (None for an object)."""
    where = f"channel map {m.source}"
    ctrl = controller if controller is not None else m.controller
    if ctrl is None:
        raise DataImportError(f"{where}: field recording.controller: missing (the controller "
                              "file of the controller that ran)")
    if isinstance(ctrl, ControllerFile):
        return ctrl, None
    try:
        if str(ctrl).lower().endswith(".mat"):
            from bayes_amb.io.controller_import import import_controller

            imp = import_controller(ctrl, rig, dt=dt, speed_rpm=m.speed_rpm,
                                    **(m.controller_options or {}))
            return imp.controller, imp.controller.design["source_sha256"]
        return load_controller(ctrl), file_sha256(ctrl)
    except (ControllerError, DataImportError) as err:
        raise DataImportError(f"{where}: field recording.controller: {err}") from None


def import_recording(source: str | os.PathLike[str], mapping: str | os.PathLike[str]
                     | ChannelMap | dict[str, Any], *, rig: Rig | str | None = None,
                     controller: ControllerFile | str | None = None) -> Recording:
    """Read a DAQ file through a channel map and return a checked, SI Recording.

    Parameters
    ----------
    source : path
        The .mat (v5 or v7.3), .tdms, .h5/.hdf5 or .csv file.
    mapping : path, ChannelMap or dict
        The channel map (TOML file, see :mod:`bayes_amb.io.channel_map`).
    rig, controller : optional
        Override the map's ``recording.rig`` / ``recording.controller`` (a Rig or rig
        file; a ControllerFile or controller file).

    Returns
    -------
    Recording
        ``meta["provenance"]["import"]`` names the source and map files with their sha256,
        the map as parsed, the offsets removed (SI) and the decimation used. Save it with
        :func:`bayes_amb.io.save_recording`.

    Raises
    ------
    DataImportError
        One line naming the file, the channel and the value (module docstring).
    """
    if isinstance(mapping, ChannelMap):
        m, map_sha = mapping, None
    elif isinstance(mapping, dict):
        m, map_sha = channel_map_from_dict(mapping), None
    else:
        m, map_sha = load_channel_map(mapping), file_sha256(mapping)
    rig_obj = _load_rig(m, rig)
    if controller is None and m.controller is None:
        raise DataImportError(f"channel map {m.source}: field recording.controller: missing "
                              "(the controller file of the controller that ran)")
    names = [s.source for s in m.channels.values()]
    if m.time.column is not None:
        names.append(m.time.column)
    src = read_channels(source, names, m.format)
    where = f"source {src.path}"
    first = next(iter(m.channels.values()))
    n = src.channels[first.source].shape[0]
    for name in names:
        got = src.channels[name].shape[0]
        if got != n:
            raise DataImportError(f"{where}: channel {name!r}: {got} samples, but channel "
                                  f"{first.source!r} ({first.target}) has {n}")
        bad = np.flatnonzero(~np.isfinite(src.channels[name]))
        if bad.size:
            raise DataImportError(f"{where}: channel {name!r}: sample {int(bad[0])} is not "
                                  f"finite ({float(src.channels[name][bad[0]])!r})")
    dt, t0 = _time_base(m, src.channels, src.increments, where, n)
    if n < 2:
        raise DataImportError(f"{where}: channel {first.source!r}: expected at least 2 "
                              f"samples, got {n}")
    i0 = 0 if m.time.start_s is None else int(np.ceil(m.time.start_s / dt - 1e-9))
    i1 = n if m.time.stop_s is None else min(n, int(np.ceil(m.time.stop_s / dt - 1e-9)))
    stages = decimate_stages(m.time.decimate)
    need = 2 if not stages else max(_MIN_STAGE, 2) * int(np.prod(stages[:-1], dtype=int))
    if i1 - i0 < need:
        raise DataImportError(f"{where}: time: {max(0, i1 - i0)} samples remain after "
                              f"trimming to "
                              f"[{m.time.start_s or 0.0!r}, {m.time.stop_s!r}) s of a "
                              f"{n * dt!r} s record; need at least {need}"
                              + (f" to decimate by {m.time.decimate}" if stages else ""))
    signals: dict[str, NDArray] = {}
    removed: dict[str, float] = {}
    for target, s in m.channels.items():
        raw = src.channels[s.source][i0:i1]
        off = float(np.mean(raw)) if s.remove_offset else s.offset
        if s.remove_offset:
            removed[target] = off * s.factor
        x = s.factor * (raw - off)
        for q in stages:
            x = sig.decimate(x, q, n=8, ftype="iir", zero_phase=True)
        signals[target] = x
    dt_out = dt * m.time.decimate
    ctrl, ctrl_sha = _load_controller(m, controller, rig_obj, dt_out)
    groups = {g: np.column_stack([signals[f"{g}_{c}"] for c in CHANNELS])
              for g in ("y", "u", *m.groups)}
    n_out = groups["y"].shape[0]
    t = t0 + i0 * dt + dt_out * np.arange(n_out)
    provenance = {"import": {
        "software": f"bayes-amb {__version__}",
        "source": str(src.path), "source_format": src.format, "source_sha256": src.sha256,
        "map": m.source, "map_sha256": map_sha, "mapping": m.raw,
        "controller": ctrl.source, "controller_sha256": ctrl_sha,
        "conversion": "value = sign * factor(unit) * (raw - offset), then decimation",
        "samples_read": n, "sample_time_read_s": dt, "trim_samples": [i0, i1],
        "decimate": m.time.decimate,
        "decimation": DECIMATION if stages else "none",
        "offsets_removed_si": removed}}
    speed = m.speed_rpm
    try:
        return make_recording(groups["y"], groups["u"], {g: groups[g] for g in m.groups},
                              dt_out, ctrl, speed_rpm=speed, rig=rig_obj, t=t, notes=m.notes,
                              provenance=provenance, source=str(src.path))
    except RecordingError as err:
        raise DataImportError(f"{where}: imported recording rejected: {err}") from None
