"""The nonlinearity a diagnosis modelled, for its report: the parameter per location with
its 90 % interval, and the amplitude answer (where the linearisation holds), from the
linearity check's values (nonlinear.py, linearity.py)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from bayes_amb.discrepancy.flat_tops import held_half_spans, held_mask
from bayes_amb.discrepancy.linearity import LIMIT_SD
from bayes_amb.discrepancy.nonlinear import (
    FORCE_LAW,
    LOOP,
    RIG_FORCE_LAW,
    SLEW,
    TITLES,
    bias_per_gap,
    centred,
)
from bayes_amb.rig import Rig
from bayes_amb.rig.force_law import law_current

UNITS = {"gap_m": "m", "slew_a_per_s": "A/s", "limit_a": "A"}


def nonlinearity_block(values: dict[str, Any], rig: Rig, u: NDArray, dt: float,
                       coefficients: dict[str, dict[str, Any]],
                       recorded_u: NDArray | None = None) -> dict[str, Any] | None:
    """The diagnosis' nonlinearity block from the linearity check's values (None when no
    nonlinearity was modelled): the parameter per location with its 90 % interval and the
    amplitude answer. coefficients: the reported bearing coefficients (theta summaries);
    recorded_u: the currents as recorded (a coil current's flat tops, before the offsets
    check's detrending tilts them; default u). A saturating magnet's linear range is
    read from how far modelling the law moved each coefficient (the check's
    ``coefficient_shift``, in the coefficients' order)."""
    modelled = values.get("modelled")
    if modelled is None:
        return None
    u = centred(u)
    if modelled in (FORCE_LAW, SLEW, LOOP, RIG_FORCE_LAW):
        n = values["nonlinearity"]
        block = {"name": n["name"], "title": TITLES[n["name"]], "where": n["where"],
                 "parameter": n["parameter"], "unit": UNITS[n["parameter"]],
                 "estimate": n["estimate"], "hdi90": n["interval90"], "z": n["z"],
                 **({"saturation": n["saturation"]} if n.get("saturation") else {})}
    elif modelled == "command":
        lim = values["clipping_limit_a"]
        block = {"name": "current_limit", "title": TITLES["current_limit"],
                 "where": ["all"], "parameter": "limit_a", "unit": "A",
                 "estimate": {"all": lim},
                 "hdi90": {"all": [lim * (1 - 1.645 * LIMIT_SD), lim * (1 + 1.645 * LIMIT_SD)]},
                 "z": values.get("clipping_z", 0.0)}
    else:                                           # a recorded coil current held at a limit
        return _coil_limit(np.asarray(u if recorded_u is None else recorded_u, dtype=float))
    # a modelled loop's shift carries its lag after the coefficients; none: {}
    shift = dict(zip(coefficients, values.get("coefficient_shift") or (), strict=False))
    block["linear_range"], block["derived"] = _amplitude_answer(block, rig, u, dt,
                                                                 coefficients, shift)
    return block


def _coil_limit(raw: NDArray) -> dict[str, Any]:
    """The current limit's block from a recorded coil current's flat tops (raw: the
    currents as recorded): the limit read off them (flat_tops.held_half_spans), its 90 %
    interval their channels' spread and the 1 % (LIMIT_SD) the offsets and noise before
    the limit leave, and the share of samples held there."""
    block: dict[str, Any] = {"name": "current_limit", "title": TITLES["current_limit"],
                             "where": ["all"], "parameter": "", "unit": "", "estimate": {},
                             "hdi90": {}, "z": 0.0}
    spans = held_half_spans(raw)
    if not spans:
        block["linear_range"] = ("the coil current is held at the amplifier limit on the "
                                 "flat tops of the record: keep the excitation below it")
        return block
    lim = float(np.median(spans))
    held = held_mask(raw)
    share = float(held[:, held.any(axis=0)].mean())
    block.update(
        parameter="limit_a", unit="A", estimate={"all": lim},
        hdi90={"all": [min(spans) - 1.645 * LIMIT_SD * lim,
                       max(spans) + 1.645 * LIMIT_SD * lim]},
        linear_range=(f"the amplifier delivers at most {lim:.3g} A about its centre (read "
                      "off the flat tops of the recorded coil current); this record holds it "
                      f"there on {100 * share:.2g} % of the samples: scale the excitation so "
                      "that the current stays below it"),
        derived={"limited_share": share})
    return block


def _half_width(coefficients: dict[str, dict[str, Any]], bearing: str) -> float | None:
    """The median 90 % half-width (theta) of a bearing's stiffness coefficients."""
    hw = [0.5 * (c["hdi90"][1] - c["hdi90"][0]) for n, c in coefficients.items()
          if n.startswith(f"k_{bearing}")]
    return float(np.median(hw)) if hw else None


def _saturated_answer(rig: Rig, u: NDArray, b: str, gap: float, ratio: float,
                      coefficients: dict[str, dict[str, Any]],
                      shift: dict[str, float]) -> tuple[str, dict]:
    """A saturating magnet's amplitude answer. Its static shifts at this record's currents
    (the law's defect regressed on the current at the centre: ki; its slope in x: ks) are
    small, but in the loop the softening acts on the controller's feedback as well as on
    the excitation, and a linear fit moves the bearing's coefficients by much more: how
    far modelling the law moved them (``shift``) is the answer, and as each shift grows
    with the current squared while each interval narrows as its inverse, the linear range
    is the rms current where the largest move, over its half-width, falls to one as the
    cube of the current."""
    j = "AB".index(b)
    sl = slice(2 * j, 2 * j + 2)
    ub = u[:, sl]
    rho = float(np.mean(bias_per_gap(rig)[sl]))
    i0 = rho * gap
    zero = np.zeros_like(u)
    d0 = law_current(rig, u, zero, {b: gap}, {b: ratio})[:, sl]
    d1 = law_current(rig, u, zero + 1e-4 * gap, {b: gap}, {b: ratio})[:, sl]
    ki_shift = float(np.sum(d0 * ub) / np.sum(ub * ub))
    ks_shift = float(np.mean((d1 - d0) / (1e-4 * gap))) / rho      # d in A; ks / ki = rho
    rms = float(np.sqrt(np.mean(ub ** 2)))
    moved = {n: -v for n, v in shift.items() if n[2:3] == b and n in coefficients}
    worst, ratio_hw = None, 0.0
    for n, v in moved.items():
        lo, hi = coefficients[n]["hdi90"]
        r = abs(v) / max(0.5 * (hi - lo), 1e-12)
        if r > ratio_hw:
            worst, ratio_hw = n, r
    # the move grows as the current squared and the half-width shrinks as its inverse
    i_max = rms / ratio_hw ** (1.0 / 3.0) if ratio_hw > 0 else None
    derived = {"bias_current_a": i0, "saturation_ratio": ratio, "rms_current_a": rms,
               "ki_shift_relative": ki_shift, "ks_shift_relative": ks_shift,
               "ks_shift_n_per_m": ks_shift * rig.magnets[b].ks,
               "linear_fit_offset": moved,
               "linear_rms_current_a": None if i_max is None else float(i_max)}
    line = (f"bearing {b}: bias {i0:.3g} A, the iron saturating at {ratio:.3g} times the "
            f"bias flux density; at this record's {rms:.3g} A rms its ki is {100 * ki_shift:+.2g}"
            f" % and its ks {100 * ks_shift:+.2g} % from the small-signal values")
    if worst is not None:
        v = moved[worst]
        line += (f", and a linear fit reads {worst} {abs(v):.3g} {'lower' if v < 0 else 'higher'}"
                 f" ({ratio_hw:.2g} times its 90 % half-width); the linearisation holds within "
                 f"the intervals below {i_max:.3g} A rms (an excitation scaled by "
                 f"{min(1.0, i_max / rms):.2g} or less)")
    return line, derived


def _amplitude_answer(block: dict[str, Any], rig: Rig, u: NDArray, dt: float,
                      coefficients: dict[str, dict[str, Any]],
                      shift: dict[str, float]) -> tuple[str, dict]:
    """Where the linearisation holds: the force law's stiffness shift a linear fit makes
    at this record's current, and the rms current below which it stays inside the
    stiffness intervals; the slew limit's largest step per sample; the current limit's
    share."""
    if block["name"] == FORCE_LAW:
        rhos = bias_per_gap(rig)
        parts, derived = [], {}
        saturation = block.get("saturation") or {}
        for b in block["where"]:
            if b in saturation:
                line, derived[b] = _saturated_answer(rig, u, b, block["estimate"][b],
                                                     saturation[b], coefficients, shift)
                parts.append(line)
                continue
            j = "AB".index(b)
            sl = slice(2 * j, 2 * j + 2)
            i0 = float(np.mean(rhos[sl]) * block["estimate"][b])
            rms = float(np.sqrt(np.mean(u[:, sl] ** 2)))
            shift = (rms / i0) ** 2                 # relative ks a linear fit adds
            hw = _half_width(coefficients, b)
            i_max = None if hw is None else i0 * np.sqrt(hw)
            derived[b] = {"bias_current_a": i0, "rms_current_a": rms,
                          "ks_shift_relative": shift,
                          "ks_shift_n_per_m": shift * rig.magnets[b].ks,
                          "linear_rms_current_a": None if i_max is None else float(i_max)}
            kn = shift * rig.magnets[b].ks / 1e3
            line = (f"bearing {b}: bias {i0:.3g} A; at this record's {rms:.3g} A rms a "
                    f"linear fit reads ks {100 * shift:.2g} % ({kn:.3g} kN/m) too high")
            if i_max is not None:
                line += (f"; the linearisation holds within the stiffness intervals "
                         f"(+-{100 * hw:.2g} %) below {i_max:.3g} A rms (an excitation "
                         f"scaled by {min(1.0, i_max / rms):.2g} or less)")
            parts.append(line)
        return "; ".join(parts), derived
    if block["name"] == LOOP:
        rate, bw = block["estimate"]["all"], block["estimate"]["bandwidth_hz"]
        x = float(np.exp(-2.0 * np.pi * bw * dt))
        lag = np.zeros_like(u[0])
        asked = np.empty_like(u)
        for k in range(u.shape[0]):             # the rate the uncapped loop asks
            asked[k] = 2.0 * np.pi * bw * np.abs(u[k] - lag)
            lag = x * lag + (1.0 - x) * u[k]
        share = float(np.mean(asked > rate))
        return (f"the amplifier's current loop ({bw:.4g} Hz) changes the current at "
                f"{rate:.4g} A/s at most; this record asks more on {100 * share:.2g} % of "
                "the samples: an excitation with smaller or fewer fast steps (a lower "
                "level, or a smoother signal than a random binary one) keeps it a linear "
                "lag", {"limited_share": share, "bandwidth_hz": bw})
    if block["name"] == SLEW:
        rate = block["estimate"]["all"]
        steps = np.abs(np.diff(u, axis=0))
        share = float(np.mean(steps > rate * dt))
        return (f"the amplifier follows steps of up to {rate * dt:.3g} A per sample "
                f"({rate:.4g} A/s); this record asks more on {100 * share:.2g} % of the "
                "samples: an excitation with smaller or fewer fast steps (a lower level, "
                "or a smoother signal than a random binary one) stays linear",
                {"largest_step_a": rate * dt, "limited_share": share})
    lim = block["estimate"]["all"]
    share = float(np.mean(np.abs(u) > lim))
    return (f"the amplifier delivers at most {lim:.3g} A about its centre; this record "
            f"asks more on {100 * share:.2g} % of the samples: scale the excitation so "
            "that the current stays below it", {"limited_share": share})
