#!/usr/bin/env python3
"""Writes studies/b747_cruise24.toml: a 24-state linear model of a Boeing 747 in cruise, both axes, with
actuators, sensor filters and Dryden turbulence, for a detection filter of 10 sensors (issue 19).

    python3 scripts/b747_deck.py > studies/b747_cruise24.toml

Published parts (public sources, their units kept):
- Longitudinal airframe: A. E. Bryson Jr., "Control of Spacecraft and Aircraft", Princeton University
  Press, 1994: 747 in level flight at 40,000 ft, 774 ft/s (Mach 0.80); states u, w (ft/s), q (crad/s),
  theta (crad), inputs elevator and throttle; climb rate hdot = -w + 7.74 theta. As the APMonitor GEKKO
  documentation reproduces it ("Linear model of a Boeing 747").
- Lateral airframe: MathWorks, Control System Toolbox example "Yaw Damper Design for a 747 Jet Aircraft"
  (simplified trim model, cruise); states beta (rad), r, p (rad/s), phi (rad), inputs rudder, aileron.
- Turbulence: the Dryden spectra of MIL-F-8785C (first-order for u, second-order for v and w), scale
  length 1,750 ft above 2,000 ft.
Choices of this script (none from the sources):
- The two axes are combined block-diagonally (the sources give them separately, and their flight
  conditions are both cruise but not stated as the same); heading psi_dot = r (level flight).
- Actuators: first-order lags, 20 rad/s for elevator, rudder and aileron, 0.5 rad/s for thrust.
- Gusts enter through the airframe's u, w and beta columns (the derivatives act on the airspeed the gust
  changes); sigma 3 ft/s for each component (light turbulence).
- Sensors: rate gyros q, r, p through first-order filters at 20 rad/s, angle-of-attack (w / V) and
  sideslip vanes at 10 rad/s; airspeed u, theta, phi, h and psi measured directly (air-data computer,
  AHRS, altimeter); white noise sigmas in `[noise]`. Airspeed is read without a lag on purpose: the
  airframe's w-q-u block without theta has an unstable speed mode (+0.0024 1/s), and an unmeasured u
  would leave it in the detection filter's closed loop.
The script checks that every state is observable from the 10 outputs and that the block of unmeasured
states is stable (the minimum-norm detection filter leaves its eigenvalues in place).
"""

import numpy as np

from plant_deck import toml_matrix, toml_strings  # the same TOML writing (this folder)

V_FT_S = 774.0
L_FT = 1750.0

STATES = [
    "u_ft_s", "w_ft_s", "q_crad_s", "theta_crad",            # Bryson, longitudinal
    "beta_rad", "r_rad_s", "p_rad_s", "phi_rad",             # MathWorks, lateral
    "h_ft", "psi_rad",                                        # kinematics
    "elevator_crad", "throttle", "rudder_rad", "aileron_rad",  # actuators
    "ug_ft_s", "wg_1", "wg_2", "vg_1", "vg_2",                # Dryden states
    "q_gyro_crad_s", "r_gyro_rad_s", "p_gyro_rad_s", "alpha_vane_rad", "beta_vane_rad",  # sensor filters
]
INPUTS = ["elevator_cmd_crad", "throttle_cmd", "rudder_cmd_rad", "aileron_cmd_rad"]
MEASURED = ["q_gyro_crad_s", "r_gyro_rad_s", "p_gyro_rad_s", "alpha_vane_rad", "beta_vane_rad",
            "u_ft_s", "theta_crad", "phi_rad", "h_ft", "psi_rad"]
SENSOR_SIGMA = [0.05, 0.0005, 0.0005, 0.002, 0.002, 0.3, 0.05, 0.001, 5.0, 0.002]
# Per-output thresholds: `fdimc summarize --target-pfa 0.01` on this deck's first 1,500 trials (300
# fault-free 60 s flights, alarms per flight), rounded to 3 digits. Turbulence the filter does not model
# sets them, not the sensor noise.
THRESHOLDS = [13.7, 0.158, 0.432, 0.0447, 0.0598, 1.6, 0.331, 0.0127, 28.6, 0.0114]


def model():
    n = len(STATES)
    i = {s: k for k, s in enumerate(STATES)}
    A = np.zeros((n, n))
    B = np.zeros((n, len(INPUTS)))
    lon = ["u_ft_s", "w_ft_s", "q_crad_s", "theta_crad"]
    A_lon = np.array([[-0.003, 0.039, 0.0, -0.322],
                      [-0.065, -0.319, 7.74, 0.0],
                      [0.020, -0.101, -0.429, 0.0],
                      [0.0, 0.0, 1.0, 0.0]])
    B_lon = np.array([[0.01, 1.0], [-0.18, -0.04], [-1.16, 0.598], [0.0, 0.0]])
    lat = ["beta_rad", "r_rad_s", "p_rad_s", "phi_rad"]
    A_lat = np.array([[-0.0558, -0.9968, 0.0802, 0.0415],
                      [0.598, -0.115, -0.0318, 0.0],
                      [-3.05, 0.388, -0.465, 0.0],
                      [0.0, 0.0805, 1.0, 0.0]])
    B_lat = np.array([[0.00729, 0.0], [-0.475, 0.00775], [0.153, 0.143], [0.0, 0.0]])
    for rows, a, b, acts in [(lon, A_lon, B_lon, ["elevator_crad", "throttle"]),
                             (lat, A_lat, B_lat, ["rudder_rad", "aileron_rad"])]:
        for r, row in enumerate(rows):
            for c, col in enumerate(rows):
                A[i[row], i[col]] = a[r, c]
            for c, act in enumerate(acts):
                A[i[row], i[act]] = b[r, c]
    A[i["h_ft"], i["w_ft_s"]] = -1.0
    A[i["h_ft"], i["theta_crad"]] = 7.74
    A[i["psi_rad"], i["r_rad_s"]] = 1.0
    for act, cmd, rate in [("elevator_crad", "elevator_cmd_crad", 20.0), ("throttle", "throttle_cmd", 0.5),
                           ("rudder_rad", "rudder_cmd_rad", 20.0), ("aileron_rad", "aileron_cmd_rad", 20.0)]:
        A[i[act], i[act]] = -rate
        B[i[act], INPUTS.index(cmd)] = rate
    # Dryden: u_g first order; w_g and v_g (1 + sqrt(3) T s) / (1 + T s)^2 as z1' = z2,
    # z2' = -z1 / T^2 - 2 z2 / T + white, gust = k (z1 + sqrt(3) T z2) / T^2 with k setting its sigma.
    T = L_FT / V_FT_S
    A[i["ug_ft_s"], i["ug_ft_s"]] = -1.0 / T
    gust_cols = {}
    for z1, z2 in [("wg_1", "wg_2"), ("vg_1", "vg_2")]:
        A[i[z1], i[z2]] = 1.0
        A[i[z2], i[z1]] = -1.0 / T**2
        A[i[z2], i[z2]] = -2.0 / T
        gust_cols[z1] = (1.0 / T**2, np.sqrt(3.0) / T)
    # Gusts through the airframe's columns: d/dt x_air += A[:, u] (-u_g) etc.; v_g as sideslip v_g / V.
    for air, (z1, z2), scale in [("w_ft_s", ("wg_1", "wg_2"), 1.0), ("beta_rad", ("vg_1", "vg_2"), 1.0 / V_FT_S)]:
        c1, c2 = gust_cols[z1]
        for row in range(n):
            a = A[row, i[air]]
            if a != 0.0 and STATES[row] in lon + lat:
                A[row, i[z1]] -= a * scale * c1
                A[row, i[z2]] -= a * scale * c2
    for row in range(n):
        a = A[row, i["u_ft_s"]]
        if a != 0.0 and STATES[row] in lon + lat:
            A[row, i["ug_ft_s"]] -= a
    for sensor, truth, rate in [("q_gyro_crad_s", "q_crad_s", 20.0), ("r_gyro_rad_s", "r_rad_s", 20.0),
                                ("p_gyro_rad_s", "p_rad_s", 20.0), ("alpha_vane_rad", "w_ft_s", 10.0),
                                ("beta_vane_rad", "beta_rad", 10.0)]:
        A[i[sensor], i[sensor]] = -rate
        # The alpha vane reads w / V (rad): the small-angle angle of attack of the perturbation.
        A[i[sensor], i[truth]] = rate / V_FT_S if sensor == "alpha_vane_rad" else rate
    C = np.zeros((len(MEASURED), n))
    for r, m in enumerate(MEASURED):
        C[r, i[m]] = 1.0
    return A, B, C, T


def process_sigma_per_step(T, dt_s):
    """White noise into the Dryden filters for 3 ft/s per component, per step of dt_s."""
    sigma = 3.0
    n = len(STATES)
    s = np.zeros(n)
    i = {k: j for j, k in enumerate(STATES)}
    # First order: u_g' = -u_g / T + sigma sqrt(2 / T) white -> per step sigma sqrt(2 dt / T).
    s[i["ug_ft_s"]] = sigma * np.sqrt(2.0 * dt_s / T)
    # Second order: the gust's variance is k^2 q T / 4 ... for z2' = .. + sqrt(q) white, gust = (z1 + sqrt3 T z2)/T^2:
    # its stationary variance, computed from the Lyapunov equation, sets the noise for sigma.
    a = np.array([[0.0, 1.0], [-1.0 / T**2, -2.0 / T]])
    c = np.array([1.0 / T**2, np.sqrt(3.0) / T])
    # Solve a P + P a^T + e2 e2^T = 0 for unit noise intensity.
    from scipy.linalg import solve_continuous_lyapunov
    P = solve_continuous_lyapunov(a, -np.array([[0.0, 0.0], [0.0, 1.0]]))
    unit_var = c @ P @ c
    for z2 in ["wg_2", "vg_2"]:
        s[i[z2]] = sigma / np.sqrt(unit_var) * np.sqrt(dt_s)
    return s


def main():
    A, B, C, T = model()
    n = A.shape[0]
    dt_s = 0.01
    # Checks: observable (rank of the PBH matrix at every eigenvalue), unmeasured block stable.
    for lam in np.linalg.eigvals(A):
        M = np.vstack([A - lam * np.eye(n), C])
        s = np.linalg.svd(M, compute_uv=False)
        assert s[-1] > 1e-9 * s[0], f"mode {lam} is not observable"
    unmeasured = [k for k in range(n) if not C[:, k].any()]
    ev = np.linalg.eigvals(A[np.ix_(unmeasured, unmeasured)])
    assert ev.real.max() < 0, f"unmeasured block not stable: {sorted(ev.real)[-3:]}"
    q = process_sigma_per_step(T, dt_s)

    m = C.shape[0]
    print(f"""# Boeing 747 in cruise, both axes, 24 states: written by scripts/b747_deck.py (sources and every
# choice in its docstring). Airframe: Bryson (1994) longitudinal at 40,000 ft, Mach 0.8, and the
# MathWorks yaw-damper example's lateral model; actuators, sensor filters (rate gyros, pitot, vane) and
# MIL-F-8785C Dryden turbulence (3 ft/s) are this deck's choices. A detection filter on the 10 sensors
# (fault directions: the measured states, r = 10 < n = 24); thresholds calibrated at Pfa 0.01 per flight
# on 300 fault-free flights of this deck (`fdimc summarize --target-pfa 0.01`): a choice.

[study]
name = "b747_cruise24"
seed = 747
duration_s = 60.0
dt_s = {dt_s}

[plant]
states = {toml_strings(STATES)}
inputs = {toml_strings(INPUTS)}
outputs = {toml_strings(MEASURED)}
a = {toml_matrix(A)}
b = {toml_matrix(B)}
c = {toml_matrix(C)}

# Doublets on elevator and aileron (choice): excite both axes.
[[excitation]]
input = "elevator_cmd_crad"
shape = "square"
amplitude = 10.0
period_s = 20.0

[[excitation]]
input = "aileron_cmd_rad"
shape = "square"
amplitude = 0.02
period_s = 14.0

[noise]
sensor_sigma = {SENSOR_SIGMA}
# Turbulence: white noise into the Dryden filters (u_g, w_g, v_g at 3 ft/s); nothing elsewhere.
process_sigma_per_step = [{", ".join(f"{x:.6g}" for x in q)}]

[[detector]]
name = "df"
kind = "detection_filter"
eigenvalues_per_s = [{", ".join(f"{-(k + 1):.1f}" for k in range(m))}]
fault_directions = {toml_matrix(C, "{:.0f}")}
thresholds = {THRESHOLDS}

[monte_carlo]
trials = 4000
fault_free_fraction = 0.2
sampler = "lhs"
onset_s = {{ range = [10.0, 50.0] }}
outputs = {toml_strings(MEASURED)}

[[monte_carlo.fault]]
kind = "bias"
size_sigma = {{ range = [2.0, 20.0], bins = 3 }}""")


if __name__ == "__main__":
    main()
