#!/usr/bin/env python3
"""Reference numbers for `analytic_false_alarm_bounds_bracket_the_brute_force` (tests/cli.rs): the
per-trial false-alarm probability of studies/seed000_rare_false_alarms.toml's two detectors, in NumPy
and SciPy (which share no code with fdimc). From the deck (tomllib): the continuous plant, dt, the
sensor sigmas and the thresholds; from `fdimc design DECK --json`: only the detection filter's discrete
gain Kd (its closed-loop eigenvalues are checked here against exp(lambda dt)). The filter started on the
truth: e(k+1) = (Ad - Kd C) e(k) - Kd v(k), residual r(k) = C e(k) + v(k), v ~ N(0, diag(sigma^2)),
Ad = expm(A dt) (the controller and the excitation cancel in e). An alarm: |r_j(k)| > T_j at any of
the trial's samples. Printed: the union (Bonferroni) bound and Sidak's bound (both upper bounds; Sidak's
inequality holds for any centred Gaussian), and a plain NumPy simulation of the same process at looser
thresholds where it can be checked by counting. Run:
  cargo run --release -- design studies/seed000_rare_false_alarms.toml --json > /tmp/design.json
  python3 scripts/reference/rare_false_alarm_numpy.py /tmp/design.json
"""
import json
import sys
import tomllib

import numpy as np
from scipy.linalg import expm
from scipy.stats import norm

deck_path = "studies/seed000_rare_false_alarms.toml"
deck = tomllib.load(open(deck_path, "rb"))
design = json.load(open(sys.argv[1]))
A, C = np.array(deck["plant"]["a"]), np.array(deck["plant"]["c"])
dt = deck["study"]["dt_s"]
samples = int(round(deck["study"]["duration_s"] / dt))
sigma = np.array(deck["noise"]["sensor_sigma"])
Ad = expm(A * dt)
R = np.diag(sigma**2)


def law(Kd):
    """Each sample's residual standard deviations, from the covariance recursion written out here."""
    Phi = Ad - Kd @ C
    P = np.zeros_like(Ad)
    sd = np.empty((samples, C.shape[0]))
    for k in range(samples):
        sd[k] = np.sqrt(np.diag(C @ P @ C.T + R))
        P = Phi @ P @ Phi.T + Kd @ R @ Kd.T
    return sd


def bounds(sd, T):
    p = 2 * norm.sf(T / sd)
    return p.sum(), -np.expm1(np.log1p(-p).sum())


def simulate(Kd, T, trials, seed):
    """Plain trials of the same process, vectorised over trials: the count of trials that alarm."""
    rng = np.random.default_rng(seed)
    Phi = Ad - Kd @ C
    e = np.zeros((trials, Ad.shape[0]))
    alarmed = np.zeros(trials, bool)
    for _ in range(samples):
        v = rng.standard_normal((trials, C.shape[0])) * sigma
        r = e @ C.T + v
        alarmed |= (np.abs(r) > T).any(axis=1)
        e = e @ Phi.T - v @ Kd.T
    return alarmed.sum()


for i, det in enumerate(deck["detector"]):
    Kd = np.array(design["detectors"][i]["discrete"]["K"])
    got = np.sort(np.linalg.eigvals(Ad - Kd @ C).real)
    want = np.sort(np.exp(np.array(det["eigenvalues_per_s"]) * dt))
    assert np.allclose(got, want, rtol=1e-9), (got, want)
    T = np.array(det["thresholds"])
    sd = law(Kd)
    union, sidak = bounds(sd, T)
    print(f"{det['name']}: union bound {union:.7e}, Sidak {sidak:.7e}")
    # Where counting can check the law: thresholds x 0.75, 40,000 plain trials.
    loose = 0.75 * T
    u, s = bounds(sd, loose)
    n = 40_000
    k = simulate(Kd, loose, n, 7 + i)
    se = np.sqrt(s * (1 - s) / n)
    print(f"  at thresholds x 0.75: Sidak {s:.5f}, union {u:.5f}; simulated {k}/{n} = {k / n:.5f} (+-{2 * se:.5f})")
