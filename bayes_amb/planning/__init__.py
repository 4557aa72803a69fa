"""Test design: the posterior a record of a given design will give, before it is run
(issue 30). ``plan(rig, controller, Design(...), Noise(...))`` -> :class:`Plan`."""

from bayes_amb.planning.fisher import Information, fisher_information
from bayes_amb.planning.plan import Design, Noise, Plan, plan

__all__ = ["Design", "Information", "Noise", "Plan", "fisher_information", "plan"]
