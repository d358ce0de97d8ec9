#!/usr/bin/env python3
"""Reference numbers for `the_miss_before_the_hazard_of_a_cusum_meets_brook_and_evans_chain`
(tests/cli.rs): the probability that Page's CUSUM on |r|, g(k) = max(0, g(k-1) + |r(k)| - d) from
g = 0, stays at or below its threshold h through a window, with r white N(0, 1) for the `before`
samples ahead of the onset and N(b, 1) in the window's `window` samples. Brook and Evans' (1972)
Markov chain in NumPy (no code shared with fdimc or with src/exact/cusum.rs): g's range
[0, h + top] in bins of width w, each bin at its midpoint, an atom at 0; the increment's law
P(|Z + b| - d <= x) = Phi(x + d - b) - Phi(-(x + d) - b) exactly (math.erfc). The bins' error falls as
w^2 (printed for w = 0.04 to 0.005); the last line is Richardson's extrapolation. Run:
  python3 scripts/reference/cusum_miss_numpy.py
"""
from math import erfc, sqrt

import numpy as np

phi = np.vectorize(lambda x: 0.5 * erfc(-x / sqrt(2.0)))


def increment_cdf(x, d, b):
    y = x + d
    return np.where(y < 0.0, 0.0, phi(y - b) - phi(-y - b))


def miss(d, h, b, before, window, w, top):
    n, nh = int(round((h + top) / w)), int(round(h / w))
    mid, edges = (np.arange(n) + 0.5) * w, np.arange(n + 1) * w

    def step(bias):
        m = np.zeros((n + 1, n + 1))
        m[0, 0] = increment_cdf(0.0, d, bias)
        m[0, 1:] = increment_cdf(edges[1:], d, bias) - increment_cdf(edges[:-1], d, bias)
        m[1:, 0] = increment_cdf(-mid, d, bias)
        m[1:, 1:] = increment_cdf(edges[None, 1:] - mid[:, None], d, bias) - increment_cdf(
            edges[None, :-1] - mid[:, None], d, bias
        )
        return m

    p = np.zeros(n + 1)
    p[0] = 1.0
    fault_free, faulty = step(0.0), step(b)
    for _ in range(before):
        p = p @ fault_free
    for _ in range(window):
        p = p @ faulty
        p[1 + nh :] = 0.0
    return p.sum()


for d, h, b, top in [(1.0, 4.0, 1.0, 8.0), (1.0, 25.0, 3.0, 6.0)]:
    values = [(w, miss(d, h, b, 100, 20, w, top)) for w in (0.04, 0.02, 0.01, 0.005)]
    for w, p in values:
        print(f"d {d} h {h} b {b} w {w}: {p:.10g}")
    print(f"  extrapolated: {(4 * values[-1][1] - values[-2][1]) / 3:.10g}")
