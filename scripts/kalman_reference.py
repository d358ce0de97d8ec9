#!/usr/bin/env python3
"""Reference steady-state Kalman gain for src/design/kalman.rs's test, independent of fdimc: the seed-000
plant of studies/seed000_robustness.toml sampled at its dt by scipy's matrix exponential, Q = 1e-4 I per
step, R = diag(sensor_sigma^2), P from scipy.linalg.solve_discrete_are, K = Ad P C' (C P C' + R)^-1.

    pip install scipy
    python3 scripts/kalman_reference.py      # prints the Rust array the test holds
"""
import os
import tomllib

import numpy as np
import scipy.linalg

root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
deck = tomllib.load(open(os.path.join(root, "studies/seed000_robustness.toml"), "rb"))
A = np.array(deck["plant"]["a"], dtype=float)
C = np.array(deck["plant"]["c"], dtype=float)
dt = deck["study"]["dt_s"]
Ad = scipy.linalg.expm(A * dt)
Q = 1e-4 * np.eye(A.shape[0])
R = np.diag(np.array(deck["noise"]["sensor_sigma"], dtype=float) ** 2)
P = scipy.linalg.solve_discrete_are(Ad.T, C.T, Q, R)
K = Ad @ P @ C.T @ np.linalg.inv(C @ P @ C.T + R)
entries = [(i, j, K[i, j]) for i in range(K.shape[0]) for j in range(K.shape[1])]
print(f"const KALMAN_REFERENCE: [(usize, usize, f64); {len(entries)}] = [")
for i, j, v in entries:
    print(f"    ({i}, {j}, {float(v)!r}),")
print("];")
