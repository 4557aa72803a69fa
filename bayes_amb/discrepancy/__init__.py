"""Model discrepancy: locate where the nominal model fails, name the physics that was left
out, model it, and show the fit improve.

    from bayes_amb.discrepancy import diagnose
    d = diagnose(load_recording("realistic.csv"), "k_By,c_By")
    d.explanations                    # the named effects with their physical parameters
    d.save("runs/diag")               # diagnosis.json, residuals.nc, models/*.nc
"""

from bayes_amb.discrepancy.diagnose import DiagnoseOptions, Diagnosis, diagnose
from bayes_amb.discrepancy.library import (
    REGISTRY,
    VOCABULARY,
    Actuator2nd,
    ActuatorGain,
    ActuatorLag,
    Candidate,
    CrossCoupling,
    FlexibleMode,
    Runout,
    SensorDelay,
    SensorGain,
    SensorLag,
    TimeDelay,
    Unbalance,
    all_candidates,
    library_table,
    node_scan,
)
from bayes_amb.discrepancy.locate import LocateOptions, Location, locate

__all__ = ["REGISTRY", "VOCABULARY", "Actuator2nd", "ActuatorGain", "ActuatorLag", "Candidate",
           "CrossCoupling", "DiagnoseOptions", "Diagnosis", "FlexibleMode", "LocateOptions",
           "Location", "Runout", "SensorDelay", "SensorGain", "SensorLag", "TimeDelay",
           "Unbalance", "all_candidates", "diagnose", "library_table", "locate", "node_scan"]
