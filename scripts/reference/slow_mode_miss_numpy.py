#!/usr/bin/env python3
"""Reference numbers for `src/exact/slow_mode.rs` and the test that uses it,
`the_miss_before_the_hazard_of_a_slow_mode_residual_meets_its_exact_law` (tests/cli.rs): the probability
that a residual with a slow mode stays within +-c through the window after a bias fault's onset.

The residual is r(k) = e(k) + v(k) (+ b from the onset), v white N(0, 1), and e an AR(1) state error
e(k+1) = phi e(k) + w(k), w ~ N(0, q), from e(0) = 0 (a gain-0 filter on a one-state plant with
process noise: tests/data/white_residual.toml with a = -1 /s, eigenvalue -1 /s). Given e's path the
alarms are independent, so P(miss) = E[prod over the window of g(e(k))], g(e) = Phi(c - b - e) -
Phi(-c - b - e): e's density at the onset is N(0, P(k0)), carried through the window on a grid by the
Gaussian kernel (trapezoid rule, SciPy's norm; no code shared with fdimc or with the Rust support).
Faults of random size: the miss averaged over b uniform on [lo, hi] (Simpson's rule, 41 points).
Printed: the miss at b = 2 on grids of 801 and 3201 points, the white approximation (each sample's
marginal alone: what the memory changes), the uniform average over [1, 3], the average over onsets
uniform on [0.5, 1.5] s, and the one-sample closed
form the grid must meet. Then the fault-free residual at threshold 6 from e(0) = 0: the probability of
an alarm in a 2 s trial (200 samples) and in a 20 s flight (2,000), and the extremal index, -ln P(no
alarm in the flight) over ten trials' (for
`the_extremal_index_intervals_cover_a_slow_mode_residuals_exact_index_over_seeds`). Last, at threshold 8,
a trial and an hour flown through (360,000 samples): once a sample's hazard settles (changes by under
1e-11 of itself: the kernel's leading eigenvalue) the samples left each take it; the hour's trials'
conversion and the index (for `the_tail_fits_per_hour_row_meets_an_hour_flown_through_on_a_slow_mode`). Run:
  python3 scripts/reference/slow_mode_miss_numpy.py
"""
import numpy as np
from scipy.integrate import simpson
from scipy.stats import norm

PHI, Q, K0, WINDOW, C = np.exp(-0.01), 0.141067**2, 100, 20, 4.0


def onset_variance(k0=K0):
    return Q * (1 - PHI ** (2 * k0)) / (1 - PHI**2)


def miss(b, window=WINDOW, n=801, k0=K0):
    spread = 9 * np.sqrt(Q / (1 - PHI**2))
    x = np.linspace(-spread, spread, n)
    dx = x[1] - x[0]
    f = norm.pdf(x, 0, np.sqrt(onset_variance(k0)))
    g = norm.cdf(C - b - x) - norm.cdf(-C - b - x)
    kernel = norm.pdf(x[None, :], PHI * x[:, None], np.sqrt(Q)) * dx
    for j in range(window):
        h = f * g
        if j == window - 1:
            return h.sum() * dx
        f = h @ kernel


def white(b):
    p = 1.0
    for k in range(K0, K0 + WINDOW):
        s = np.sqrt(1 + Q * (1 - PHI ** (2 * k)) / (1 - PHI**2))
        p *= norm.cdf((C - b) / s) - norm.cdf((-C - b) / s)
    return p


print(f"b = 2: {miss(2.0):.12f} (801 points), {miss(2.0, n=3201):.12f} (3201 points)")
print(f"b = 2, each sample alone: {white(2.0):.10f}")
sizes = np.linspace(1.0, 3.0, 41)
print(f"b uniform on [1, 3]: {simpson([miss(b) for b in sizes], x=sizes) / 2.0:.12f}")
# A random onset u uniform on [0.5, 1.5] s: faulty from sample m + 1 (u = 0.01 (m + f)), 19 samples within
# 0.195 s of it where f < 0.5, 20 where f >= 0.5; on 401 points, as the test computes it.
onsets = [miss(2.0, window=w, n=401, k0=m + 1) for m in range(50, 150) for w in (19, 20)]
print(f"b = 2, the onset uniform on [0.5, 1.5] s: {np.mean(onsets):.10f}")
s = np.sqrt(1 + onset_variance())
print(f"one sample, b = 2: {miss(2.0, window=1):.12f} on the grid, {norm.cdf((C - 2) / s) - norm.cdf((-C - 2) / s):.12f} closed")


def fault_free_log_no_alarm(c, samples, n=801):
    spread = 9 * np.sqrt(Q / (1 - PHI**2))
    x = np.linspace(-spread, spread, n)
    dx = x[1] - x[0]
    # The alarm from the two tails: 1 - (Phi(c - e) - Phi(-c - e)) loses the tail's digits (1e-9 a sample),
    # and the hazards are summed as log1p(-h): the log of a survival near 1 would lose a hazard of 1e-17.
    a = norm.sf(c - x) + norm.sf(c + x)
    kernel = norm.pdf(x[None, :], PHI * x[:, None], np.sqrt(Q)) * dx
    # e(0) = 0: the first sample alarms with |v| > c alone; e(1) ~ N(0, q).
    f = norm.pdf(x, 0, np.sqrt(Q))
    log_s, before = np.log1p(-2 * norm.sf(c)), np.nan
    for k in range(1, samples):
        h = (f * a).sum() / f.sum()
        log_s += np.log1p(-h)
        if k == samples - 1:
            return log_s
        if abs(h / before - 1) < 1e-11:
            return log_s + np.log1p(-h) * (samples - 1 - k)
        before = h
        f = (f * (1 - a)) @ kernel


def fault_free_alarm(c, samples, n=801):
    return -np.expm1(fault_free_log_no_alarm(c, samples, n))


segment, flight = fault_free_alarm(6.0, 200), fault_free_alarm(6.0, 2000)
print(f"threshold 6: a trial {segment:.12e}, a flight {flight:.12e}, index {np.log1p(-flight) / (10 * np.log1p(-segment)):.10f}")
print(f"  on 1601 points: {fault_free_alarm(6.0, 200, 1601):.12e}, {fault_free_alarm(6.0, 2000, 1601):.12e}")

trial, hour = fault_free_log_no_alarm(8.0, 200), fault_free_log_no_alarm(8.0, 360_000)
print(
    f"threshold 8: a trial {-np.expm1(trial):.12e}, an hour flown through {-np.expm1(hour):.12e}, the conversion "
    f"{-np.expm1(1800 * trial):.12e}, index {hour / (1800 * trial):.10f}"
)
print(f"  on 1601 points: {-np.expm1(fault_free_log_no_alarm(8.0, 200, 1601)):.12e}, {-np.expm1(fault_free_log_no_alarm(8.0, 360_000, 1601)):.12e}")
