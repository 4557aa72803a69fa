"""Issue 30: the plan's expected log Bayes factor against the diagnosis' on one record each.

For each effect (the simulator's), ``bayes_amb.planning.detect.detectability`` predicts the
expected log Bayes factor for a 2 s, 10 kHz random-binary record with 50 nm sensor noise;
one such record (seed 5) is diagnosed with default options and the accepted explanation's
log Bayes factor (or the candidate's best, when none is accepted) is printed beside it.

    PYTHONPATH=. python studies/plan_detect.py
"""

from __future__ import annotations

from bayes_amb.control.export import export_controller, reference_controller
from bayes_amb.discrepancy import diagnose
from bayes_amb.planning import Design, Noise
from bayes_amb.planning.detect import detectability
from bayes_amb.rig import load_rig
from bayes_amb.simulate import SimulationConfig, simulate_recording
from bayes_amb.simulate.effects import parse_effect

EFFECTS = ("sensor_gain:gain=0.002,channel=By", "sensor_gain:gain=0.004,channel=By",
           "cross_coupling:kxy=4000,location=D1", "cross_coupling:kxy=20000,location=D1",
           "time_delay:delay_s=5e-6", "actuator_lag:bandwidth_hz=6000",
           "actuator_lag:bandwidth_hz=2500")


def main() -> None:
    rig = load_rig()
    ctrl = export_controller(reference_controller(rig, 1e-4), rig)
    design, noise = Design(duration=2.0), Noise(noise_rms=5e-8)
    for text in EFFECTS:
        e = parse_effect(text)
        r = detectability(rig, ctrl, design, noise, e)
        rec, _ = simulate_recording(rig, ctrl, SimulationConfig(
            truth="reduced", effects=(e,), noise_rms=5e-8, duration=2.0, seed=5))
        rep = diagnose(rec).to_dict()
        named = [(x["effect"], x["location"], round(x["score"], 1))
                 for x in rep["explanations"]]
        best = max((c.get("log_bayes_factor") or float("-inf")) for c in rep["candidates"]
                   if c["effect"] == e.name)
        print(f"{text}: predicted log BF {r['expected_log_bayes_factor']:.1f} +- "
              f"{r['scatter_of_log_bf']:.1f} (odds {r['expected_log_posterior_odds']:.1f}, "
              f"P(detected) {r['probability_detected']:.2f}); diagnose: {rep['verdict']}, "
              f"{named}, best {e.name} log BF {best:.1f}")


if __name__ == "__main__":
    main()
