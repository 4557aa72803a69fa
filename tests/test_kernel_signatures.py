"""Each compiled kernel runs under one signature, whatever arrays its caller passes.

numba compiles a kernel once per argument type, and a read-only view (np.broadcast_to where
nothing needs broadcasting) or a non-contiguous slice is another type than a C-contiguous
writable array. The warm-up (bayes_amb/warmup.py) compiles one; any other is compiled at
the user's first use: eigen.modal_batch took 7.6 s inside the first diagnosis of ROSS's test
rig, whose closed loops came in as a whole batch (read-only after broadcast_to). The
wrappers now hand every kernel C-contiguous writable arrays. (A kernel called from another
compiled one, as fused.py calls several, takes that caller's types: one more signature,
compiled with the caller by the warm-up.)
"""

from __future__ import annotations

import numpy as np

from bayes_amb.discrepancy import nonlinear
from bayes_amb.inference import batched, eigen, priors


def _variants(shape: tuple[int, ...], rng: np.random.Generator) -> list[np.ndarray]:
    """The same values as a writable array, a read-only broadcast view and a strided
    slice."""
    x = rng.standard_normal(shape)
    wide = np.concatenate([x, x], axis=-1)[..., ::2]
    return [x, np.broadcast_to(x, shape), wide]


def test_modal_batch_and_zoh_compile_one_signature():
    rng = np.random.default_rng(0)
    A = 0.3 * rng.standard_normal((2, 5, 5))
    for B in _variants((2, 5, 2), rng):
        for C in _variants((2, 3, 5), rng):
            batched.zoh_compiled(np.broadcast_to(A, A.shape), B, 1e-3)
            eigen.modal_batch(A, B, C)
    assert len(eigen._modal_batch.signatures) == 1
    assert len(batched._zoh.signatures) == 1


def test_slew_defect_and_the_log_prior_compile_one_signature():
    rng = np.random.default_rng(1)
    for u in _variants((50, 4), rng):
        nonlinear.slew_defect(u, 100.0, 1e-4)
    assert len(nonlinear._ramp_defect.signatures) == 1
    ps = priors.PriorSet.build(("k_By", "c_By"))
    x = rng.uniform(-0.1, 0.1, (3, 7))
    ls = np.tile([-7.0, -9.0, -3.0], (3, 1))
    for theta in (x[:, :2].copy(), x[:, :2], np.broadcast_to(x[0, :2], (3, 2))):
        ps.log_prior(theta, np.broadcast_to(ls[0], (3, 3)))
        ps.log_prior(theta, ls)
    if priors._log_prior.signatures:            # compiled where the prior set has a table
        assert len(priors._log_prior.signatures) == 1
