"""Exceptions for user-facing errors.

Every error a user can cause (a bad file, an unknown name, a value out of range) is one of
these. The CLI turns them into a single line on stderr (:func:`one_line`) and exit status 2.
No heavy imports here: the CLI imports this before it sets the BLAS thread limits.
"""

import unicodedata


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


class ResultError(BayesAmbError):
    """A result file (diagnosis.json, summary.json, ...) is missing or malformed."""


class LFTError(BayesAmbError):
    """An LFT is ill-posed or its blocks have inconsistent dimensions."""


class StudyInterrupted(KeyboardInterrupt):
    """A study was stopped by SIGINT or SIGTERM; the finished replicates are saved.

    A KeyboardInterrupt (not a user error): ``except Exception`` in numerical code must not
    swallow it. ``signum`` is the signal, ``done`` and ``total`` count the replicates in
    ``results`` (the results file), so the caller can say how to resume.
    """

    def __init__(self, signum: int, done: int = 0, total: int = 0,
                 results: str = "") -> None:
        import signal

        self.signum, self.done, self.total, self.results = signum, done, total, results
        name = signal.Signals(signum).name
        super().__init__(f"interrupted by {name}: {done} of {total} replicates are saved in "
                         f"{results}" if results else f"interrupted by {name}")

    @property
    def exit_status(self) -> int:
        """128 + the signal number (130 for SIGINT, 143 for SIGTERM), as a shell reports."""
        return 128 + self.signum


class DataImportError(BayesAmbError):
    """A foreign DAQ file, its channel map or an imported controller is missing, malformed
    or inconsistent."""


def one_line(text: str) -> str:
    """``text`` with control characters escaped (a path or value holding a newline, a
    carriage return or a NUL must not break an error message over several lines).

    Examples
    --------
    >>> one_line("rig file a\\nb.toml: not found")
    'rig file a\\\\nb.toml: not found'
    """
    return "".join(repr(c)[1:-1] if unicodedata.category(c) in ("Cc", "Zl", "Zp") else c
                   for c in text)
