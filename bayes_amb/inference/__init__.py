"""The likelihood of S(theta) and the sampler: forward model (forward.py, loop_model.py),
batched and compiled kernels (batched.py, eigen.py, kernels.py, walker_kernels.py), the
Whittle likelihood (whittle.py), priors, MAP and sampler (priors.py, estimate.py, moves.py,
sampler.py) and the identify entry point (identify.py).

No imports here: the modules are imported by their full names. The file makes the folder a
regular package, so that pytest's doctest collection imports each module once, under its
package name (as a bare top-level module, the compiled kernels' on-disk cache would be
written under another module name than the package loads it with).
"""
