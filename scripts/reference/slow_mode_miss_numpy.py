#!/usr/bin/env python3
"""Reference numbers for `tests/support/exact_slow_mode.rs` and the test that uses it,
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
marginal alone: what the memory changes), the uniform average over [1, 3], and the one-sample closed
form the grid must meet. Then the fault-free residual at threshold 6 from e(0) = 0: the probability of
an alarm in a 2 s trial (200 samples) and in a 20 s flight (2,000), and the extremal index, -ln P(no
alarm in the flight) over ten trials' (for
`the_extremal_index_intervals_cover_a_slow_mode_residuals_exact_index_over_seeds`). Run:
  python3 scripts/reference/slow_mode_miss_numpy.py
"""
import numpy as np
from scipy.integrate import simpson
from scipy.stats import norm

PHI, Q, K0, WINDOW, C = np.exp(-0.01), 0.141067**2, 100, 20, 4.0


def onset_variance(k0=K0):
    return Q * (1 - PHI ** (2 * k0)) / (1 - PHI**2)


def miss(b, window=WINDOW, n=801):
    spread = 9 * np.sqrt(Q / (1 - PHI**2))
    x = np.linspace(-spread, spread, n)
    dx = x[1] - x[0]
    f = norm.pdf(x, 0, np.sqrt(onset_variance()))
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
s = np.sqrt(1 + onset_variance())
print(f"one sample, b = 2: {miss(2.0, window=1):.12f} on the grid, {norm.cdf((C - 2) / s) - norm.cdf((-C - 2) / s):.12f} closed")


def fault_free_alarm(c, samples, n=801):
    spread = 9 * np.sqrt(Q / (1 - PHI**2))
    x = np.linspace(-spread, spread, n)
    dx = x[1] - x[0]
    # From the two tails: Phi(c - e) - Phi(-c - e) loses the tail's digits (the alarms are 1e-9 a sample).
    g = 1 - (norm.sf(c - x) + norm.sf(c + x))
    kernel = norm.pdf(x[None, :], PHI * x[:, None], np.sqrt(Q)) * dx
    # e(0) = 0: the first sample alarms with |v| > c alone; e(1) ~ N(0, q).
    f = (1 - 2 * norm.sf(c)) * norm.pdf(x, 0, np.sqrt(Q))
    for k in range(1, samples):
        h = f * g
        if k == samples - 1:
            return 1 - h.sum() * dx
        f = h @ kernel


segment, flight = fault_free_alarm(6.0, 200), fault_free_alarm(6.0, 2000)
print(f"threshold 6: a trial {segment:.12e}, a flight {flight:.12e}, index {np.log1p(-flight) / (10 * np.log1p(-segment)):.10f}")
print(f"  on 1601 points: {fault_free_alarm(6.0, 200, 1601):.12e}, {fault_free_alarm(6.0, 2000, 1601):.12e}")
