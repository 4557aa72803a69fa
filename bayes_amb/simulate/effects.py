"""Hidden physics: effects that the nominal reduced model leaves out.

The names are public vocabulary; the diagnosis reports them. Each effect has physical
parameters with documented realistic defaults (magnitudes typical of industrial AMB rotors):

actuator_lag    bandwidth_hz=1000 (coil inductance + amplifier current loop, 0.5-3 kHz
                typical), bearing=both|A|B. First-order current-to-force lag.
time_delay      delay_s=5e-5 (computation + PWM: 0.5 sample at 10 kHz). Delay between the
                controller output and the force; fractional samples are exact under ZOH.
cross_coupling  kxy=2e4 N/m, location=D1|D2|A|B (seal or impeller cross-coupled stiffness,
                f_x = -kxy*y, f_y = +kxy*x).
flexible_mode   n_modes=2: bending-mode pairs kept in the truth. Always present when the
                truth is the full FE model; with a reduced truth it adds n_modes pairs.
unbalance       u_kgm=2.5e-5 kg m at disc=D1|D2 (about ISO 1940 G2.5 for this rotor at
                31500 rpm), phase_deg=0: forward synchronous forcing at the running speed.
sensor_gain     gain=0.03 (a 3 % calibration error) on channel=By.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from bayes_amb.errors import BayesAmbError
from bayes_amb.rig import CHANNELS

EFFECT_DEFAULTS: dict[str, dict[str, Any]] = {
    "actuator_lag": {"bandwidth_hz": 1000.0, "bearing": "both"},
    "time_delay": {"delay_s": 5e-5},
    "cross_coupling": {"kxy": 2.0e4, "location": "D1"},
    "flexible_mode": {"n_modes": 2},
    "unbalance": {"u_kgm": 2.5e-5, "disc": "D1", "phase_deg": 0.0},
    "sensor_gain": {"gain": 0.03, "channel": "By"},
}

_CHOICES: dict[tuple[str, str], tuple[str, ...]] = {
    ("actuator_lag", "bearing"): ("both", "A", "B"),
    ("cross_coupling", "location"): ("A", "B", "D1", "D2"),
    ("unbalance", "disc"): ("D1", "D2"),
    ("sensor_gain", "channel"): CHANNELS,
}

_RANGES: dict[tuple[str, str], tuple[float, float]] = {
    ("actuator_lag", "bandwidth_hz"): (10.0, 1e5),
    ("time_delay", "delay_s"): (0.0, 0.01),
    ("cross_coupling", "kxy"): (-1e7, 1e7),
    ("flexible_mode", "n_modes"): (0, 6),
    ("unbalance", "u_kgm"): (0.0, 1e-2),
    ("unbalance", "phase_deg"): (-360.0, 360.0),
    ("sensor_gain", "gain"): (-0.9, 10.0),
}


@dataclass(frozen=True)
class Effect:
    """One hidden effect with its parameters (defaults filled in)."""

    name: str
    params: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"effect": self.name, **self.params}


def make_effect(name: str, **params: Any) -> Effect:
    """Validate an effect name and parameters; fill defaults.

    Examples
    --------
    >>> make_effect("actuator_lag", bandwidth_hz=600).params["bandwidth_hz"]
    600.0
    """
    if name not in EFFECT_DEFAULTS:
        raise BayesAmbError(f"unknown effect {name!r}; known: {', '.join(EFFECT_DEFAULTS)}")
    out = dict(EFFECT_DEFAULTS[name])
    for k, v in params.items():
        if k not in out:
            raise BayesAmbError(f"effect {name}: unknown parameter {k!r}; known: "
                                f"{', '.join(out)}")
        if (name, k) in _CHOICES:
            if v not in _CHOICES[(name, k)]:
                raise BayesAmbError(f"effect {name}: parameter {k}: value {v!r} not one of "
                                    f"{', '.join(_CHOICES[(name, k)])}")
            out[k] = v
            continue
        try:
            fv = float(v)
        except (TypeError, ValueError):
            raise BayesAmbError(f"effect {name}: parameter {k}: expected a number, "
                                f"got {v!r}") from None
        lo, hi = _RANGES[(name, k)]
        if not lo <= fv <= hi:
            raise BayesAmbError(f"effect {name}: parameter {k}: value {fv:g} out of range: "
                                f"must be in {lo:g}..{hi:g}")
        out[k] = int(fv) if k == "n_modes" else fv
    return Effect(name, out)


def parse_effect(text: str) -> Effect:
    """'actuator_lag:bandwidth_hz=600,bearing=A' -> Effect."""
    name, _, rest = text.partition(":")
    params: dict[str, Any] = {}
    for item in filter(None, (s.strip() for s in rest.split(","))):
        k, eq, v = item.partition("=")
        if not eq:
            raise BayesAmbError(f"option --effect: {text!r}: expected key=value, got {item!r}")
        params[k.strip()] = v.strip()
    return make_effect(name.strip(), **params)


def describe_effects() -> list[str]:
    """One line per effect: its parameters with default and allowed values (for --help).

    Examples
    --------
    >>> describe_effects()[1]
    'time_delay: delay_s=5e-05 (0..0.01)'
    """
    lines = []
    for name, defaults in EFFECT_DEFAULTS.items():
        parts = []
        for k, v in defaults.items():
            if (name, k) in _CHOICES:
                allowed = "/".join(_CHOICES[(name, k)])
            else:
                lo, hi = _RANGES[(name, k)]
                allowed = f"{lo:g}..{hi:g}"
            parts.append(f"{k}={v:g} ({allowed})" if isinstance(v, float | int)
                         else f"{k}={v} ({allowed})")
        lines.append(f"{name}: {', '.join(parts)}")
    return lines
