#!/usr/bin/env python3
"""The exact miss before the hazard of the CI deck's filters (issue 82, item 1), for
`splitting_in_time_gives_the_miss_before_the_hazard` (src/methods/detection_filter/rare_event.rs) and
`rare_event_miss_before_hazard_is_checked_and_reaches_the_safety_summary` (tests/cli.rs).

studies/ci_seed000.toml is a model-exact linear loop without process noise: the filter's state error
obeys e(k+1) = Phi e(k) - Kd (v(k) + f(k)), Phi = Ad - Kd C, from e(0) = 0, and its residual is
r(k) = C e(k) + v(k) + f(k), v white N(0, diag(sensor_sigma^2)) and f the sensor fault (the loop's inputs
cancel in e). A bias b on output j from the onset sample k0 adds a deterministic mean; the noise part is
a centred Gaussian whose covariance over the window follows from P(k0) (the recursion from e(0) = 0)
and Cov(r(k + h), r(k)) = C Phi^(h-1) (Phi P(k) C' - Kd R) (h >= 1). The fault is missed before its
hazard when every |r_j(k)| <= T_j over the window's samples (the samples at t >= onset within the time
to hazard: 30 for 0.3 s, 25 for 0.25 s, whatever the onset's fraction of a sample), a rectangle
probability of dimension window x 6, computed by Genz's method (SciPy's multivariate_normal.cdf).
Alarms before the onset do not count (a detection is an alarm at or after it).

Everything is from the deck: the gain is methods.md 000's Kd = (Ad F - F Lambda_d)(C F)^+ with F = I,
computed here (`fdimc design --json`'s is only compared with it, to 1e-9). The bias faults fall on alpha or q in equal
shares, their onsets uniform on [2, 6] s: the miss is the mean over the two outputs; the onset moves it
by under 1e-5 (printed at 2, 4 and 6 s). Run (about 6 minutes):
    FDIMC=target/release/fdimc python3 scripts/reference/miss_gaussian_scipy.py
"""
import json
import os
import subprocess
import tomllib

import numpy as np
from scipy.linalg import expm
from scipy.stats import multivariate_normal

DECK = "studies/ci_seed000.toml"
deck = tomllib.load(open(DECK, "rb"))
design = json.loads(
    subprocess.run([os.environ.get("FDIMC", "fdimc"), "design", DECK, "--json"], capture_output=True, check=True).stdout
)
A, C = np.array(deck["plant"]["a"]), np.array(deck["plant"]["c"])
dt = deck["study"]["dt_s"]
Ad = expm(A * dt)
sigma = np.array(deck["noise"]["sensor_sigma"])
R = np.diag(sigma**2)
n, p = A.shape[0], C.shape[0]


def miss(detector, size_sigma, samples, k0, j):
    # The gain from methods.md 000 (F = I): Kd = (Ad F - F Lambda_d)(C F)^+, computed here; design's is
    # only compared with it.
    wanted = np.exp(np.array(deck["detector"][detector]["eigenvalues_per_s"]) * dt)
    K = (Ad - np.diag(wanted)) @ np.linalg.pinv(C)
    assert np.allclose(K, np.array(design["detectors"][detector]["discrete"]["K"]), rtol=1e-9, atol=1e-12)
    Phi = Ad - K @ C
    assert np.allclose(np.sort(np.linalg.eigvals(Phi).real), np.sort(wanted), atol=1e-9)
    T = np.array(deck["detector"][detector]["thresholds"])
    drive = K @ R @ K.T
    P = np.zeros((n, n))
    for _ in range(k0):
        P = Phi @ P @ Phi.T + drive
    cov = np.zeros((samples * p, samples * p))
    for a in range(samples):
        cov[a * p:(a + 1) * p, a * p:(a + 1) * p] = C @ P @ C.T + R
        M = Phi @ P @ C.T - K @ R
        for h in range(1, samples - a):
            block = C @ M
            cov[(a + h) * p:(a + h + 1) * p, a * p:(a + 1) * p] = block
            cov[a * p:(a + 1) * p, (a + h) * p:(a + h + 1) * p] = block.T
            M = Phi @ M
        P = Phi @ P @ Phi.T + drive
    bias = np.zeros(p)
    bias[j] = size_sigma * sigma[j]
    mean, e = np.zeros(samples * p), np.zeros(n)
    for a in range(samples):
        mean[a * p:(a + 1) * p] = C @ e + bias
        e = Phi @ e - K @ bias
    upper = np.tile(T, samples)
    law = multivariate_normal(mean=mean, cov=cov, maxpts=2_000_000 * len(mean), abseps=1e-6, releps=0)
    return law.cdf(upper, lower_limit=-upper)


outputs = [deck["plant"]["outputs"].index(o) for o in deck["monte_carlo"]["outputs"]]
for detector, size_sigma, samples in [(0, 3.0, 30), (1, 6.0, 25)]:
    name = deck["detector"][detector]["name"]
    by_output = []
    for j in outputs:
        at = [miss(detector, size_sigma, samples, k0, j) for k0 in (200, 400, 600)]
        print(f"{name}, {size_sigma} sigma on {deck['plant']['outputs'][j]}, {samples} samples: onsets 2, 4, 6 s: {at}")
        by_output.append(at[1])
    print(f"{name}, {size_sigma} sigma, {samples} samples: the miss {np.mean(by_output):.7g}")
