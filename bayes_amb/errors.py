"""Exceptions for user-facing errors.

Every error a user can cause (a bad file, an unknown name, a value out of range) is one of
these. The CLI turns them into a single line on stderr and exit status 2.
"""


class BayesAmbError(ValueError):
    """Base class of all user-facing errors of bayes_amb."""


class RigError(BayesAmbError):
    """A rig file is missing, malformed or non-physical."""


class ParameterError(BayesAmbError):
    """An unknown uncertainty-parameter name or a value outside its allowed range."""


class ReductionError(BayesAmbError):
    """The requested modes cannot be separated from the rest of the spectrum."""


class ControllerError(BayesAmbError):
    """A controller file is malformed or does not fit the rig."""


class RecordingError(BayesAmbError):
    """A recording (CSV plus JSON sidecar) is missing, malformed or inconsistent."""


class LFTError(BayesAmbError):
    """An LFT is ill-posed or its blocks have inconsistent dimensions."""


class DataImportError(BayesAmbError):
    """A foreign DAQ file, its channel map or an imported controller is missing, malformed
    or inconsistent."""
