"""Sensitivity and calibration studies: declarative (TOML), parallel, resumable, Dask-ready."""

from bayes_amb.studies.replicate import replicate_seeds, run_replicate
from bayes_amb.studies.runner import read_rows, run_study
from bayes_amb.studies.spec import StudyError, StudySpec, load_study, study_from_dict
from bayes_amb.studies.summary import cell_summary, conclusions, finalise, sbc_statistics

__all__ = ["StudyError", "StudySpec", "cell_summary", "conclusions", "finalise",
           "load_study", "read_rows", "replicate_seeds", "run_replicate", "run_study",
           "sbc_statistics", "study_from_dict"]
