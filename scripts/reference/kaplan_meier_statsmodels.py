#!/usr/bin/env python3
"""Checks scripts/findings.py's Kaplan-Meier curve (the seed-004 recovery table) against statsmodels'
`SurvfuncRight`, which shares no code with it: the survival probability, its Greenwood standard error and
the median on a fixed censored sample. Needs numpy and statsmodels (`pip install numpy statsmodels`).
Run: python3 scripts/reference/kaplan_meier_statsmodels.py (exit 1 on a difference).
"""
import math
import pathlib
import random
import sys

import numpy as np
from statsmodels.duration.survfunc import SurvfuncRight

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent))
from findings import kaplan_meier, survival_at  # noqa: E402

rng = random.Random(5)
events_at = [round(rng.expovariate(0.3), 2) for _ in range(200)]  # ties on a 0.01 grid, as the delays
censored_at = [round(rng.uniform(2, 15), 2) for _ in range(200)]
events = [t <= c for t, c in zip(events_at, censored_at)]
times = [min(t, c) for t, c in zip(events_at, censored_at)]
curve = kaplan_meier(times, events)
reference = SurvfuncRight(np.array(times), np.array(events, dtype=float))
worst = 0.0
for t in [0.5, 1.0, 2.0, 5.0, 10.0]:
    s, _, _ = survival_at(curve, t)
    i = np.searchsorted(reference.surv_times, t, side="right") - 1
    greenwood = next(g for u, _, g in reversed(curve) if u <= t)
    worst = max(worst, abs(s - reference.surv_prob[i]), abs(s * math.sqrt(greenwood) - reference.surv_prob_se[i]))
median = next(t for t, s, _ in curve if s <= 0.5)
print(f"largest difference in S(t) and its standard error: {worst:.1e}; median {median} against {reference.quantile(0.5)}")
sys.exit(0 if worst < 1e-12 and median == reference.quantile(0.5) else 1)
