"""bayes_amb: Bayesian closed-loop identification of rotors on active magnetic bearings.

The package follows the data flow of Lauridsen et al. (the paper in ../shared/seed):
rig -> rotor (FE model, eq. 17) -> reduction (eqs. 18-45) -> uncertainty (LFT, eqs. 46-52)
-> control (coprime factors, Youla, S(theta), eqs. 1-14) -> simulate -> inference -> reports.
"""

__version__ = "0.1.0"
