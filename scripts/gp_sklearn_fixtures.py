#!/usr/bin/env python3
"""Generate tests/fixtures/gp_sklearn.json: reference values from scikit-learn's
GaussianProcessRegressor for tests/gp/gp_sklearn.rs.

Kernel: ConstantKernel(sf2) * RBF(length_scale=[...]) + WhiteKernel(sn2), i.e.
the ARD squared-exponential kernel with signal and noise variance of vigp.
sklearn orders theta as (ln sf2, ln l_1..ln l_d, ln sn2); the fixture stores
vigp's order (ln l_1..ln l_d, ln sf2, ln sn2).

Usage: python3 -m venv /tmp/venv && /tmp/venv/bin/pip install scikit-learn
       /tmp/venv/bin/python scripts/gp_sklearn_fixtures.py
"""
import json
import os

import numpy as np
import sklearn
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel


def kernel(sf2, ls, sn2, bounds=(1e-5, 1e5)):
    return ConstantKernel(sf2, constant_value_bounds=bounds) * RBF(
        length_scale=ls, length_scale_bounds=bounds
    ) + WhiteKernel(sn2, noise_level_bounds=bounds)


def reorder(theta, d):
    # sklearn (ln sf2, ln l.., ln sn2) -> vigp (ln l.., ln sf2, ln sn2)
    return list(theta[1 : 1 + d]) + [theta[0], theta[1 + d]]


def fixed_case(rng, name, n, d, sf2, ls, sn2, normalize_y):
    X = rng.uniform(-2.0, 2.0, size=(n, d))
    y = np.sin(2.0 * X[:, 0]) + 0.5 * X[:, 1] ** 2 + 3.0 + 0.05 * rng.standard_normal(n)
    Xs = rng.uniform(-2.5, 2.5, size=(15, d))
    gp = GaussianProcessRegressor(kernel(sf2, ls, sn2), optimizer=None, normalize_y=normalize_y)
    gp.fit(X, y)
    lml, grad = gp.log_marginal_likelihood(gp.kernel_.theta, eval_gradient=True)
    mean, std = gp.predict(Xs, return_std=True)
    return {
        "name": name,
        "n": n,
        "d": d,
        "normalize_y": normalize_y,
        "x": X.ravel().tolist(),
        "y": y.tolist(),
        "x_test": Xs.ravel().tolist(),
        "signal_variance": sf2,
        "length_scales": list(ls),
        "noise_variance": sn2,
        "lml": float(lml),
        "lml_gradient": reorder(grad, d),
        "mean": mean.tolist(),
        # sklearn's variance of a new observation: includes the noise level
        # (times y_std^2 when normalize_y).
        "var_with_noise": (std**2).tolist(),
        "y_std": float(gp._y_train_std) if normalize_y else 1.0,
    }


def trained_case(rng, name, n, d, restarts, bound):
    X = rng.uniform(-2.0, 2.0, size=(n, d))
    y = np.sin(2.0 * X[:, 0]) * np.cos(X[:, 1]) + 0.3 * X[:, 0] + 0.02 * rng.standard_normal(n)
    k = kernel(1.0, [1.0] * d, 1.0, bounds=(1.0 / bound, bound))
    gp = GaussianProcessRegressor(k, n_restarts_optimizer=restarts, normalize_y=True, random_state=0)
    gp.fit(X, y)
    return {
        "name": name,
        "n": n,
        "d": d,
        "x": X.ravel().tolist(),
        "y": y.tolist(),
        "restarts": restarts,
        "bound_lower": 1.0 / bound,
        "bound_upper": bound,
        "lml": float(gp.log_marginal_likelihood_value_),
        "theta": reorder(gp.kernel_.theta, d),
    }


def main():
    rng = np.random.default_rng(20240603)
    fixed = [
        fixed_case(rng, "raw_d3", 40, 3, 1.7, [0.8, 1.3, 2.5], 0.01, False),
        fixed_case(rng, "normalize_y_d2", 30, 2, 0.9, [0.6, 1.1], 0.003, True),
        fixed_case(rng, "raw_d4_small_noise", 50, 4, 2.0, [1.0, 0.7, 3.0, 5.0], 1e-4, False),
    ]
    trained = [
        trained_case(rng, "trained_d2", 60, 2, 5, 1e5),
        trained_case(rng, "trained_d4", 80, 4, 5, 1e5),
    ]
    out = {
        "generator": "scripts/gp_sklearn_fixtures.py",
        "sklearn_version": sklearn.__version__,
        "numpy_version": np.__version__,
        "fixed": fixed,
        "trained": trained,
    }
    path = os.path.join(os.path.dirname(__file__), "..", "tests", "fixtures", "gp_sklearn.json")
    with open(path, "w") as f:
        json.dump(out, f, indent=1)
        f.write("\n")
    for t in trained:
        print(t["name"], "sklearn best lml", t["lml"])


if __name__ == "__main__":
    main()
