#!/usr/bin/env python3
"""Reference numbers for `the_fit_and_its_shape_interval_match_scipy` (src/engine/stats/tail.rs): the
generalised Pareto maximum-likelihood fit and the 95 % profile interval of its shape, by SciPy (which
shares no code with fdimc). Needs numpy and scipy (`pip install numpy scipy`); printed numbers are
pasted into the test. Run: python3 scripts/reference/gpd_scipy.py
"""
import warnings

warnings.filterwarnings("ignore", category=RuntimeWarning)
import numpy as np
from scipy.stats import genpareto
from scipy.optimize import minimize_scalar, brentq
phi = (np.sqrt(5) - 1) / 2
def sample(k, xi, sigma):
    u = np.array([((i + 1) * phi) % 1.0 for i in range(k)])
    return sigma / xi * ((1 - u) ** (-xi) - 1)
for (xi0, s0) in [(0.2, 1.5), (-0.2, 1.5)]:
    y = sample(300, xi0, s0)
    c, loc, scale = genpareto.fit(y, floc=0)
    # refine with a direct optimisation
    nll = lambda p: -genpareto.logpdf(y, p[1], loc=0, scale=np.exp(p[0])).sum()
    from scipy.optimize import minimize
    r = minimize(nll, [np.log(scale), c], method='Nelder-Mead', options={'xatol':1e-12,'fatol':1e-12,'maxiter':20000})
    ls, cc = r.x
    best = -r.fun
    def prof(xi):
        f = lambda lsig: -genpareto.logpdf(y, xi, loc=0, scale=np.exp(lsig)).sum()
        m = minimize_scalar(f, bounds=(ls - 8, ls + 8), method='bounded', options={'xatol':1e-12})
        return -m.fun
    dev = lambda xi: 2 * (best - prof(xi)) - 3.841458820694124
    lo = brentq(dev, cc - 1.0, cc, xtol=1e-12)
    hi = brentq(dev, cc, cc + 1.5, xtol=1e-12)
    print(f"xi0={xi0}: scipy fit c={c:.10f} scale={scale:.10f}; NM c={cc:.10f} scale={np.exp(ls):.10f} loglik={best:.8f}; xi 95% profile [{lo:.8f}, {hi:.8f}]")
