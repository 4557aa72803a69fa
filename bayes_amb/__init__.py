"""bayes_amb: Bayesian closed-loop identification of rotors on active magnetic bearings.

The package follows the data flow of Lauridsen et al. (the paper in ../shared/seed):
rig -> rotor (FE model, eq. 17) -> reduction (eqs. 18-45) -> uncertainty (LFT, eqs. 46-52)
-> control (coprime factors, Youla, S(theta), eqs. 1-14) -> simulate -> inference -> reports.
"""

__version__ = "0.1.0"

# The top-level API, imported on first use (PEP 562): ``import bayes_amb`` stays light, so
# that the CLI can limit the BLAS threads before numpy is loaded (bayes_amb.threads).
_API = {
    "load_rig": "bayes_amb.rig",
    "load_recording": "bayes_amb.io.recording",
    "load_controller": "bayes_amb.io.controller_file",
    "SimulationConfig": "bayes_amb.simulate",
    "simulate_recording": "bayes_amb.simulate",
    "identify": "bayes_amb.api",
    "identify_joint": "bayes_amb.inference.joint",
    "compare_runs": "bayes_amb.inference.compare",
    "IdentifyOptions": "bayes_amb.inference.identify",
    "diagnose": "bayes_amb.api",
    "DiagnoseOptions": "bayes_amb.discrepancy.diagnose",
    "diagnose_records": "bayes_amb.discrepancy.records",
    "plan": "bayes_amb.planning",
    "Diagnosis": "bayes_amb.results",
    "Identification": "bayes_amb.results",
    "EngineeringAnswers": "bayes_amb.results",
    "Design": "bayes_amb.planning",
    "Noise": "bayes_amb.planning",
}

__all__ = ["__version__", *_API]


def __getattr__(name: str):
    if name in _API:
        import importlib

        return getattr(importlib.import_module(_API[name]), name)
    raise AttributeError(f"module 'bayes_amb' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
