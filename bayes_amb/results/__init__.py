"""Typed, versioned result objects: what ``diagnose`` and ``identify`` return, what their
run folders hold (``save`` / ``load`` round-trip), what the report, the CLI and the plots
read. Each JSON file of a run folder is one of these serialised (results/blocks.py).

    from bayes_amb.results import Diagnosis, Identification
    d = Diagnosis.load("runs/diag")            # diagnosis.json (+ residuals.nc, models/)
    res = Identification.load("runs/paper")    # summary.json (+ posterior.nc)
"""

from bayes_amb.results.blocks import Block
from bayes_amb.results.diagnosis import (
    Adequacy,
    Balancing,
    CandidateScore,
    Check,
    Coefficient,
    Diagnosis,
    EffectFit,
    Estimate,
    Explanation,
    Mismatch,
    Unexplained,
)
from bayes_amb.results.engineering import Answer, EngineeringAnswers
from bayes_amb.results.identification import Identification, Noise, Posterior, RecordFit
from bayes_amb.results.records import AcrossRow, RecordsDiagnosis
from bayes_amb.results.study import Study

__all__ = ["AcrossRow", "Adequacy", "Answer", "Balancing", "Block", "CandidateScore", "Check",
           "Coefficient", "Diagnosis", "EffectFit", "EngineeringAnswers", "Estimate",
           "Explanation", "Identification", "Mismatch", "Noise", "Posterior", "RecordFit",
           "RecordsDiagnosis", "Study", "Unexplained"]
