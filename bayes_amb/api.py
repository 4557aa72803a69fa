"""The top-level ``identify`` and ``diagnose`` (``from bayes_amb import identify``): one
recording, or a list of them.

    res = identify(rec, "k_By,c_By")                 # one record (inference/identify.py)
    res = identify([r1, r2, r3], "k_By,c_By")        # one joint posterior (inference/joint.py)
    d = diagnose([r1, r2, r3])                       # across records (discrepancy/records.py)

They sit above the modules they call, so that neither the single-record modules nor the
several-record ones import each other both ways.
"""

from __future__ import annotations

from bayes_amb.discrepancy.diagnose import DiagnoseOptions
from bayes_amb.discrepancy.diagnose import diagnose as diagnose_one
from bayes_amb.discrepancy.records import diagnose_records
from bayes_amb.errors import BayesAmbError
from bayes_amb.inference.identify import IdentifyOptions
from bayes_amb.inference.identify import identify as identify_one
from bayes_amb.inference.joint import identify_joint
from bayes_amb.inference.priors import Prior
from bayes_amb.io.recording import Recording
from bayes_amb.results.diagnosis import Diagnosis
from bayes_amb.results.identification import Identification
from bayes_amb.results.records import RecordsDiagnosis

__all__ = ["diagnose", "identify"]


def identify(recording: Recording | list[Recording],
             params: str | tuple[str, ...] | list[str],
             priors: dict[str, Prior] | None = None,
             options: IdentifyOptions | None = None,
             per_record: tuple[str, ...] | list[str] = ()) -> Identification:
    """The posterior of ``params`` from one recording (inference.identify.identify), or
    from a list of them jointly (inference.joint.identify_joint; ``per_record`` the
    parameters estimated per record)."""
    if isinstance(recording, (list, tuple)):
        return identify_joint(list(recording), params, priors, options, per_record)
    if per_record:
        raise BayesAmbError("option --per-record: needs several recordings")
    return identify_one(recording, params, priors, options)


def diagnose(recording: Recording | list[Recording],
             params: str | tuple[str, ...] | list[str] | None = None,
             priors: dict[str, Prior] | None = None,
             options: DiagnoseOptions | None = None) -> Diagnosis | RecordsDiagnosis:
    """The diagnosis of one recording (discrepancy.diagnose.diagnose), or of a list of
    them, each diagnosed and the effects tested across them (diagnose_records)."""
    if isinstance(recording, (list, tuple)):
        return diagnose_records(list(recording), params, priors, options)
    return diagnose_one(recording, params, priors, options)
