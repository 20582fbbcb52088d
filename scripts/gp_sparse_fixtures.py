#!/usr/bin/env python3
"""Generate tests/fixtures/gp_sparse.json: reference values of Titsias' (2009)
sparse variational GP bound (SGPR / VFE) for tests/gp/gp_sparse.rs, computed
independently of vigp with dense numpy linear algebra (N x N matrices, no
Cholesky tricks):

    F = log N(y | 0, Q + s2 I) - tr(Kff - Q) / (2 s2),   Q = Kfu Kuu^-1 Kuf

with Kuu carrying the relative jitter 1e-10 * sf2 on its diagonal (part of
vigp's model definition). Also:
  * dF/dtheta by central differences (theta = ln l_1..ln l_d, ln sf2, ln s2;
    step 1e-5, on the dense formula above);
  * the SGPR predictive mean Ksu (s2 Kuu + Kuf Kfu)^-1 Kuf y and latent
    variance Kss - Ksu Kuu^-1 Kus + Ksu (Kuu + Kuf Kfu / s2)^-1 Kus, by
    numpy.linalg.solve;
  * the exact GP log marginal likelihood (for the M = N case).

Raw units: zero prior mean, no normalisation.

Usage: python3 -m venv /tmp/venv && /tmp/venv/bin/pip install numpy
       /tmp/venv/bin/python scripts/gp_sparse_fixtures.py
"""
import json
import os

import numpy as np

JITTER = 1e-10


def kern(a, b, ls, sf2):
    d = (a[:, None, :] - b[None, :, :]) / ls
    return sf2 * np.exp(-0.5 * np.sum(d * d, axis=-1))


def bound(X, y, Z, theta):
    d = X.shape[1]
    ls, sf2, s2 = np.exp(theta[:d]), np.exp(theta[d]), np.exp(theta[d + 1])
    n = len(y)
    Kuu = kern(Z, Z, ls, sf2) + JITTER * sf2 * np.eye(len(Z))
    Kuf = kern(Z, X, ls, sf2)
    Q = Kuf.T @ np.linalg.solve(Kuu, Kuf)
    C = Q + s2 * np.eye(n)
    sign, logdet = np.linalg.slogdet(C)
    assert sign > 0
    ll = -0.5 * (n * np.log(2 * np.pi) + logdet + y @ np.linalg.solve(C, y))
    return ll - (n * sf2 - np.trace(Q)) / (2 * s2)


def exact_lml(X, y, theta):
    d = X.shape[1]
    ls, sf2, s2 = np.exp(theta[:d]), np.exp(theta[d]), np.exp(theta[d + 1])
    n = len(y)
    C = kern(X, X, ls, sf2) + s2 * np.eye(n)
    sign, logdet = np.linalg.slogdet(C)
    return -0.5 * (n * np.log(2 * np.pi) + logdet + y @ np.linalg.solve(C, y))


def predict(X, y, Z, theta, Xs):
    d = X.shape[1]
    ls, sf2, s2 = np.exp(theta[:d]), np.exp(theta[d]), np.exp(theta[d + 1])
    Kuu = kern(Z, Z, ls, sf2) + JITTER * sf2 * np.eye(len(Z))
    Kuf = kern(Z, X, ls, sf2)
    Ksu = kern(Xs, Z, ls, sf2)
    mean = Ksu @ np.linalg.solve(s2 * Kuu + Kuf @ Kuf.T, Kuf @ y)
    var = (
        sf2
        - np.sum(Ksu * np.linalg.solve(Kuu, Ksu.T).T, axis=1)
        + np.sum(Ksu * np.linalg.solve(Kuu + Kuf @ Kuf.T / s2, Ksu.T).T, axis=1)
    )
    return mean, var


def case(rng, name, n, d, m, theta, z_from_data):
    X = rng.uniform(-2.0, 2.0, size=(n, d))
    y = np.sin(2.0 * X[:, 0]) + 0.4 * X[:, -1] ** 2 + 0.05 * rng.standard_normal(n)
    if z_from_data:
        Z = X[:m].copy()
    else:
        Z = rng.uniform(-2.0, 2.0, size=(m, d))
    Xs = rng.uniform(-2.5, 2.5, size=(12, d))
    theta = np.array(theta, dtype=float)
    f = bound(X, y, Z, theta)
    h = 1e-5
    grad = []
    for k in range(len(theta)):
        tp, tm = theta.copy(), theta.copy()
        tp[k] += h
        tm[k] -= h
        grad.append((bound(X, y, Z, tp) - bound(X, y, Z, tm)) / (2 * h))
    mean, var = predict(X, y, Z, theta, Xs)
    return {
        "name": name,
        "n": n,
        "d": d,
        "m": m,
        "x": X.ravel().tolist(),
        "y": y.tolist(),
        "z": Z.ravel().tolist(),
        "x_test": Xs.ravel().tolist(),
        "log_params": theta.tolist(),
        "bound": float(f),
        "bound_gradient_fd": grad,
        "exact_lml": float(exact_lml(X, y, theta)),
        "mean": mean.tolist(),
        "variance": var.tolist(),
    }


def main():
    rng = np.random.default_rng(20261122)
    cases = [
        case(rng, "d2_n150_m20_random_z", 150, 2, 20, [-0.3, 0.2, 0.1, np.log(0.01)], False),
        case(rng, "d3_n200_m40_data_z", 200, 3, 40, [0.1, -0.2, 0.4, -0.5, np.log(0.005)], True),
        # M = N with Z = X: the bound equals the exact LML up to the jitter
        case(rng, "d2_n60_m60_full", 60, 2, 60, [0.0, 0.3, 0.0, np.log(0.02)], True),
    ]
    out = {
        "numpy": np.__version__,
        "kuu_relative_jitter": JITTER,
        "cases": cases,
    }
    path = os.path.join(os.path.dirname(__file__), "..", "tests", "fixtures", "gp_sparse.json")
    with open(path, "w") as f:
        json.dump(out, f, indent=1)
    for c in cases:
        print(c["name"], "bound", c["bound"], "exact", c["exact_lml"])


if __name__ == "__main__":
    main()
