#!/usr/bin/python3
# scripts/bench_scipy_ggx.py SAMPLES.f64 KD KS ALPHA F0
#
# The SciPy side of `make bench`'s GGX fit (tests/bench.c): reads the samples
# refl-bench wrote (float64 rows n.l n.v n.h v.h R, little-endian), fits the
# GGX model of model/brdf/brdf.c (R = [kd/pi + ks D G2 F/(4 n.l n.v)] n.l, GGX D,
# height-correlated Smith G2, Schlick F) from the same start with
# scipy.optimize.least_squares (trust region reflective, analytic Jacobian,
# the models' bounds), and prints the fit time and the result.
import sys
import time

import numpy as np
from scipy.optimize import least_squares

d = np.fromfile(sys.argv[1], dtype="<f8").reshape(-1, 5)
nl, nv, nh, vh, R = (d[:, k] for k in range(5))
x0 = np.array([float(v) for v in sys.argv[2:6]])


def parts(p):
    kd, ks, a, F0 = p
    a2 = a * a
    q = nh * nh * (a2 - 1) + 1
    D = a2 / (np.pi * q * q)
    dD = 2 * a * (q - 2 * a2 * nh * nh) / (np.pi * q ** 3)
    tl = np.maximum(0, (1 - nl * nl) / (nl * nl))
    tv = np.maximum(0, (1 - nv * nv) / (nv * nv))
    sl, sv = np.sqrt(1 + a2 * tl), np.sqrt(1 + a2 * tv)
    G = 1 / (1 + (sl - 1) / 2 + (sv - 1) / 2)
    dG = -G * G * (tl / (4 * sl) + tv / (4 * sv)) * 2 * a
    G = np.where(vh > 0, G, 0)
    dG = np.where(vh > 0, dG, 0)
    f5 = (1 - vh) ** 5
    F = F0 + (1 - F0) * f5
    dF = 1 - f5
    s = 1 / (4 * nv)
    return kd, ks, D, dD, G, dG, F, dF, s


def resid(p):
    kd, ks, D, dD, G, dG, F, dF, s = parts(p)
    return kd / np.pi * nl + ks * D * G * F * s - R


def jac(p):
    kd, ks, D, dD, G, dG, F, dF, s = parts(p)
    J = np.empty((len(R), 4))
    J[:, 0] = nl / np.pi
    J[:, 1] = D * G * F * s
    J[:, 2] = ks * (dD * G + D * dG) * F * s
    J[:, 3] = ks * D * G * dF * s
    return J


t0 = time.perf_counter()
r = least_squares(resid, x0, jac=jac, bounds=([0, 0, 0.001, 0], [1, 1, 1, 1]), method="trf",
                  xtol=1e-10, ftol=1e-10, gtol=1e-12)
t = time.perf_counter() - t0
print(f"scipy_time_s {t:.4f}")
print("scipy_params " + " ".join(f"{v:.12g}" for v in r.x))
print(f"scipy_nfev {r.nfev}")
