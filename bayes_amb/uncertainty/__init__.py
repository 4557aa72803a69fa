"""Physical parameter uncertainty as an LFT, full and reduced (eqs. 46-52)."""

from bayes_amb.uncertainty.accuracy import ReducedAccuracy, reduced_eigenvalue_error
from bayes_amb.uncertainty.lft import UncertainPlant, lft_full, lft_reduced, lower_lft
from bayes_amb.uncertainty.parameters import (
    PARAMETERS,
    ParameterSpec,
    get_spec,
    parse_param_list,
    physical_change,
)

__all__ = ["PARAMETERS", "ParameterSpec", "ReducedAccuracy", "UncertainPlant", "get_spec",
           "lft_full", "lft_reduced", "lower_lft", "parse_param_list", "physical_change",
           "reduced_eigenvalue_error"]
