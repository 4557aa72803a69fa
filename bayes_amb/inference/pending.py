"""identify's adequacy test, run beside identify's own fit.

The adequacy test (discrepancy/adequacy.assess_fit) reads only the recording, the names,
the priors and the seed: nothing of identify's fit. It runs in a second thread from the
start of identify, while identify finds its MAP and samples; the likelihood kernels are
compiled without the GIL, so on two cores the two share the machine. Whether identify
samples at all depends on the verdict (a model that is not adequate is not sampled), so
the sampler is started on speculation and stopped at its next check once the verdict
says the model is doubted. Both computations are the same as run one after the other,
and so are their results: only the wall time changes.
"""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

from bayes_amb.discrepancy.adequacy import assess_fit
from bayes_amb.inference.doubted import within_band
from bayes_amb.inference.priors import Prior
from bayes_amb.io.recording import Recording


class Doubted(Exception):
    """Raised inside the sampler's progress check when the adequacy test has doubted the
    model: the speculative sample is dropped."""


def _assessed(recording: Recording, names: tuple[str, ...],
              priors: dict[str, Prior] | None, seed: int, f_max_hz: float
              ) -> tuple[Any, Any]:
    verdict, nominal = assess_fit(recording, names, priors, seed=seed)
    return within_band(verdict, nominal, f_max_hz), nominal


class PendingAdequacy:
    """The adequacy verdict for identify's band (doubted.within_band), being computed."""

    def __init__(self, recording: Recording, names: tuple[str, ...],
                 priors: dict[str, Prior] | None, seed: int, f_max_hz: float):
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="bayes-amb-adequacy")
        self._future: Future = self._pool.submit(_assessed, recording, names, priors, seed,
                                                 f_max_hz)
        self._pool.shutdown(wait=False)

    def doubted(self) -> bool:
        """True once the verdict is in and doubts the model (it carries a model error), or
        the test failed (its error is raised by result()); False while it runs."""
        if not self._future.done():
            return False
        if self._future.exception() is not None:
            return True
        return self._future.result()[1].model_error is not None

    def result(self) -> tuple[Any, Any]:
        """(verdict, nominal fit), waiting for them."""
        return self._future.result()
