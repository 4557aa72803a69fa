"""Pseudo-modal reduction of the FE model (eqs. 18-45) and its fidelity data (Fig. 5)."""

from bayes_amb.reduction.pseudo_modal import N_RIGID, ReducedModel, reduce_pseudo_modal

__all__ = ["N_RIGID", "ReducedModel", "reduce_pseudo_modal"]
