"""Shared CLI helpers: output in text or JSON, and user-error handling."""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

from bayes_amb.errors import one_line  # noqa: F401  (re-exported for the commands)


def to_jsonable(obj: Any) -> Any:
    """Convert numpy scalars/arrays and complex numbers into JSON-friendly values."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (complex, np.complexfloating)):
        return [float(obj.real), float(obj.imag)]
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    return obj


def emit(data: dict[str, Any], text: str, as_json: bool) -> None:
    """Print machine-readable JSON or the human-readable text."""
    if as_json:                  # non-finite numbers as null, listed (io/nonfinite.py)
        from bayes_amb.io.nonfinite import result_json_text

        sys.stdout.write(result_json_text(to_jsonable(data)))
    else:
        sys.stdout.write(text.rstrip() + "\n")


def add_prior_options(p: Any) -> None:
    """--prior NAME=kind(a,b) (repeatable) and --prior-file FILE."""
    p.add_argument("--prior", action="append", default=[], metavar="NAME=kind(a,b)",
                   help="prior of one parameter: uniform(lo,hi), normal(mu,sd), "
                   "normal(mu,sd,lo,hi) (truncated) or lognormal(mu,sigma), e.g. "
                   "k_By=normal(0.3,0.2) (repeatable; wins over --prior-file; default: "
                   "uniform over the stability-safe range, k_*/c_* -0.8..0.8, kxy_* -1..1)")
    p.add_argument("--prior-file", default=None, metavar="FILE",
                   help="TOML file with a [priors] table (default none)")


def read_priors(args: Any) -> dict[str, Any]:
    """The priors of --prior-file, then --prior (which wins)."""
    from bayes_amb.inference.priors import load_prior_file, parse_prior_assignment

    priors = dict(load_prior_file(args.prior_file)) if args.prior_file else {}
    for text in args.prior:
        name, pr = parse_prior_assignment(text)
        priors[name] = pr
    return priors


def add_rig_option(p: Any) -> None:
    """--rig FILE on a command that builds its model from a recording."""
    p.add_argument("--rig", default=None, metavar="FILE",
                   help="rig file (or shipped rig name) the recording should be from; the "
                   "model is always built from the rig embedded in the recording, and a "
                   "--rig that differs from it is refused with the first differing field "
                   "(default: no check)")


def check_rig_option(args: Any, recording: Any) -> None:
    """Refuse (one line, exit 2) a --rig that is not the recording's embedded rig."""
    if getattr(args, "rig", None) is None:
        return
    from bayes_amb.errors import RigError
    from bayes_amb.rig import check_rig_matches

    if recording is None:
        raise RigError(f"option --rig: no recording to check rig file {args.rig} against")
    check_rig_matches(args.rig, recording.rig, f"recording {recording.source}")
