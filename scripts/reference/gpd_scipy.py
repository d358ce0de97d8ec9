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

# The 95 % profile interval of a tail probability P(X > u + d) = zeta * S_GPD(d), the same samples as
# the excesses of the 300 largest of n = 3000 values (so zeta's estimate is 0.1): the joint
# log-likelihood k ln zeta + (n - k) ln(1 - zeta) + GPD log-likelihood, profiled at each p over
# (zeta, xi) with the scale that puts zeta * S(d) at p, by Nelder-Mead from several starts; the
# deviance's 3.841459 crossings by brentq on ln p. Pasted into `the_tail_probability_interval_matches_scipy`.
from scipy.optimize import minimize
n, k = 3000, 300
def joint(y, zeta, sigma, xi):
    if not (0 < zeta < 1) or not (sigma > 0):
        return -np.inf
    z = 1 + xi * y / sigma
    if np.any(z <= 0):
        return -np.inf
    g = genpareto.logpdf(y, xi, loc=0, scale=sigma).sum()
    return k * np.log(zeta) + (n - k) * np.log1p(-zeta) + g
def scale_through(d, q, xi):
    return -d / np.log(q) if abs(xi) < 1e-12 else xi * d / np.expm1(-xi * np.log(q))
for (xi0, s0, d) in [(0.2, 1.5, 20.0), (-0.2, 1.5, 5.0)]:
    y = sample(300, xi0, s0)
    r = minimize(lambda p: -genpareto.logpdf(y, p[1], loc=0, scale=np.exp(p[0])).sum(), [0.4, xi0],
                 method='Nelder-Mead', options={'xatol': 1e-12, 'fatol': 1e-12, 'maxiter': 20000})
    sig, xi = np.exp(r.x[0]), r.x[1]
    best = joint(y, k / n, sig, xi)
    p_hat = k / n * genpareto.sf(d, xi, loc=0, scale=sig)
    def prof(ln_p):
        p = np.exp(ln_p)
        f = lambda v: -joint(y, np.exp(v[0]), scale_through(d, p / np.exp(v[0]), v[1]), v[1]) \
            if p < np.exp(v[0]) else np.inf
        starts = [[np.log(k / n), xi], [np.log(k / n), xi + 0.2], [np.log(k / n), xi - 0.2]]
        return max(-minimize(f, s, method='Nelder-Mead',
                             options={'xatol': 1e-11, 'fatol': 1e-11, 'maxiter': 40000}).fun for s in starts)
    dev = lambda ln_p: 2 * (best - prof(ln_p)) - 3.841458820694124
    lo = np.exp(brentq(dev, np.log(p_hat) - 6, np.log(p_hat), xtol=1e-10))
    hi = np.exp(brentq(dev, np.log(p_hat), min(np.log(p_hat) + 6, np.log(0.0999)), xtol=1e-10))
    print(f"xi0={xi0}: P(X > u + {d}) = {p_hat:.8e}, 95% profile interval [{lo:.8e}, {hi:.8e}]")
