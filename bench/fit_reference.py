#!/usr/bin/python3
"""The same 101-point fits as bench_automation's BM_Fit101, by scipy.optimize.curve_fit (MINPACK's
lmdif, numerical Jacobian, as a Python plan would fit a rocking curve): time per fit [us].
Needs Debian's python3-scipy (not a beamctl dependency; the figure is a reference only).
    /usr/bin/python3 bench/fit_reference.py"""
import time

import numpy as np
from scipy.optimize import curve_fit
from scipy.special import erf


def lorentzian(x, x0, g, a, b):
    return b + a / (1 + ((x - x0) / g) ** 2)


def gaussian(x, x0, s, a, b):
    return b + a * np.exp(-0.5 * ((x - x0) / s) ** 2)


def edge(x, x0, s, a, b):
    return b + 0.5 * a * (1 + erf((x - x0) / (np.sqrt(2) * s)))


rng = np.random.default_rng(1)
x = 0.25 + 0.1 * np.arange(101) / 100.0
for name, f, w in (("lorentzian", lorentzian, 0.01), ("gaussian", gaussian, 0.02 / 2.3548), ("edge", edge, 0.02 / 2.5631)):
    y = f(x, 0.3, w, 1.0, 0.1) + rng.normal(0, 0.02, x.size)
    p0 = (x[np.argmax(y)], 0.025, y.max() - y.min(), y.min())
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < 1.0:
        p, cov = curve_fit(f, x, y, p0=p0)
        n += 1
    dt = (time.perf_counter() - t0) / n
    print(f"scipy curve_fit {name:<10} {dt * 1e6:8.1f} us per fit  centre {p[0]:.5f} +- {np.sqrt(cov[0, 0]):.5f}")
