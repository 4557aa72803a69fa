#!/usr/bin/env bash
# Issue 28's scenario, start to finish, as README.md and docs/your_rig.md describe it:
# a ROSS rotor, a PID as a continuous MATLAB state space, a DAQ .mat in volts (made here
# from a simulation), import, identify (all eight coefficients), diagnose, answers, report.
# Usage: own_rig_scenario.sh BIN_DIR WORK_DIR   (BIN_DIR holds python and bayes-amb,
# with the [ross] extra installed), e.g. studies/own_rig_scenario.sh .venv/bin /tmp/own_rig
# About 2.5 min on 2 cores (plus ~30 s the first time, compiling the kernels); measured on
# Python 3.12 (ROSS 3.0) and 3.13 (ROSS 3.1) with the same numbers: k_By 0.2936 (true
# 0.3) nominal, 0.2977 after the diagnosis names the three bending pairs and the residual
# flexibility the 8-state model leaves out.
set -euo pipefail
BIN=$(cd "${1:?bin dir}" && pwd); W=${2:?work dir}; mkdir -p "$W"; cd "$W"
PY=$BIN/python; BA=$BIN/bayes-amb
t() { local s=$SECONDS; "$@"; echo "[$(( SECONDS - s )) s] $*" >&2; }

cat > build_rotor.py <<'EOF'
import ross as rs
steel = rs.Material(name="Steel28", rho=7810, E=211e9, G_s=81.2e9)
n_el = 24                                   # 0.6 m shaft, 25 nodes 25 mm apart
shaft = [rs.ShaftElement(L=0.6 / n_el, idl=0.0, odl=0.05, material=steel,
                         shear_effects=False) for _ in range(n_el)]
discs = [rs.DiskElement.from_geometry(n=1, material=steel, width=0.03, i_d=0.05, o_d=0.16),
         rs.DiskElement.from_geometry(n=23, material=steel, width=0.025, i_d=0.05, o_d=0.14)]
amb = dict(g0=0.5e-3, i0=2.0, ag=4e-4, nw=120, kp_pid=4000.0, kd_pid=5.0)
bearings = [rs.MagneticBearingElement(n=4, sensor_node=3, tag="A", **amb),
            rs.MagneticBearingElement(n=20, sensor_node=21, tag="B", **amb)]
rs.Rotor(shaft, discs, bearings).save("my_rotor.toml")
EOF
cat > write_pid.py <<'EOF'
import numpy as np, scipy.io
kp, ki, kd, wf = 12000.0, 2.8e5, 28.0, 2 * np.pi * 1500   # u = -C(s) y per axis
a, b = np.array([[0.0, 0.0], [0.0, -wf]]), np.array([[1.0], [wf]])
c, d = np.array([[ki, -kd * wf]]), np.array([[kp + kd * wf]])
A, B, C, D = (np.kron(np.eye(4), m) for m in (a, b, c, d))
scipy.io.savemat("K.mat", {"A": A, "B": B, "C": C, "D": D, "Ts": 0.0})
EOF
cat > to_daq.py <<'EOF'
import numpy as np, scipy.io
head = open("sim.csv").readline().strip().split(",")
rows = np.loadtxt("sim.csv", delimiter=",", skiprows=1)
col = {h: rows[:, i] for i, h in enumerate(head)}
y_off, y_sign = {"Ax": 0.12, "Ay": -0.05, "Bx": 0.03, "By": 0.08}, {"Ay": -1}
u_off = {"Ax": 0.010, "Ay": -0.004, "Bx": 0.002, "By": 0.0}
out, lines = {"time": col["t"] + 12.5}, ['[time]', 'column = "time"', '', '[recording]',
    'rig = "my_rig.toml"', 'speed_rpm = 18000.0', 'controller = "ctrl.json"', '']
for k, ax in enumerate(("Ax", "Ay", "Bx", "By"), start=1):
    s = y_sign.get(ax, 1)
    out[f"AMB_pos_{k}"] = s * 8000.0 * col[f"y_{ax}"] + y_off[ax]       # 8 V/mm probes
    out[f"I_ref_{k}"] = col[f"u_{ax}"] / 0.5 + u_off[ax]                # 0.5 A/V amplifiers
    out[f"exc_{k}"] = col[f"r2_{ax}"] / 0.5
    lines += [f'[channels.y_{ax}]', f'source = "AMB_pos_{k}"', 'unit = "V"',
              'sensitivity = 8000.0', f'offset = {y_off[ax]}', f'sign = {s}', '',
              f'[channels.u_{ax}]', f'source = "I_ref_{k}"', 'unit = "V"', 'gain = 0.5',
              'remove_offset = true', '', f'[channels.r2_{ax}]', f'source = "exc_{k}"',
              'unit = "V"', 'gain = 0.5', '']
scipy.io.savemat("run17.mat", {k: v.reshape(-1, 1) for k, v in out.items()})
open("run17.toml", "w").write("\n".join(lines))
EOF
P=k_Ax,k_Ay,k_Bx,k_By,c_Ax,c_Ay,c_Bx,c_By
t $PY build_rotor.py 2>/dev/null
t $BA rig from-ross my_rotor.toml -o my_rig.toml --speed-rpm 18000 --zeta 0.005
t $BA model --rig my_rig.toml
t $PY write_pid.py
t $BA import-controller K.mat --rig my_rig.toml --dt 1e-4 --method tustin -o ctrl.json
t $BA simulate --rig my_rig.toml --controller ctrl.json --port r2 --set k_By=0.3 \
    --set c_By=0.2 --noise-rms 2e-7 --r2-rms 0.02 --duration 2 --dt 1e-4 --seed 5 -o sim.csv
t $PY to_daq.py
t $BA import run17.mat --map run17.toml -o run17.csv
t $BA identify run17.csv --params $P --rig my_rig.toml --out runs/run17 --no-progress
t $BA diagnose run17.csv --params $P --rig my_rig.toml --out runs/run17 --no-progress
t $BA answers runs/run17 --rig my_rig.toml --out runs/run17/answers.json > answers.txt
t $BA report runs/run17 --rig my_rig.toml
