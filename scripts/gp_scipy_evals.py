#!/usr/bin/env python3
"""LML + gradient evaluations per start: scipy's L-BFGS-B on scikit-learn's
log marginal likelihood, from the **same start points** as vigp's
`Gp::train` (SplitMix64 restarts of vigp-gp/src/train.rs, ported
below), on the data of benches/gp.rs, with the same bounds and stopping
rules (ftol 2.220446049250313e-9, pgtol 1e-5, memory 10).

Compare with `cargo run --release --example gp_train -- --n N --restarts R
--runs 1`, which prints vigp's evaluations per start and final LMLs
(`--d` and `--seed` likewise match gp_train's flags).

    python scripts/gp_scipy_evals.py --n 512 --restarts 10
    python scripts/gp_scipy_evals.py --n 512 --d 6 --seed 1 --restarts 10
"""
import argparse
import math
import warnings

import numpy as np
import scipy.optimize
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

from gp_sklearn_bench import bench_data

M64 = (1 << 64) - 1


class SplitMix64:
    def __init__(self, seed):
        self.s = seed & M64

    def next_u64(self):
        self.s = (self.s + 0x9E3779B97F4A7C15) & M64
        z = self.s
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & M64
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & M64
        return z ^ (z >> 31)

    def uniform(self, lo, hi):
        return lo + (hi - lo) * ((self.next_u64() >> 11) * (1.0 / (1 << 53)))


def vigp_starts(seed, output, d, restarts):
    """Start 0 (l = 1, sf2 = 1, sn2 = 0.01) and the restarts, in vigp's order
    (ln l_1..ln l_d, ln sf2, ln sn2)."""
    lo = [math.log(1e-3)] * d + [math.log(1e-4), math.log(1e-10)]
    hi = [math.log(1e3)] * d + [math.log(1e4), math.log(1e1)]
    r = SplitMix64(seed ^ ((output * 0xD1B54A32D192ED03) & M64))
    rng = SplitMix64(r.next_u64())
    starts = [[0.0] * d + [0.0, math.log(1e-2)]]
    for _ in range(restarts):
        starts.append([rng.uniform(l, h) for l, h in zip(lo, hi)])
    return starts, list(zip(lo, hi))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=512)
    ap.add_argument("--d", type=int, default=4)
    ap.add_argument("--restarts", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0, help="TrainOptions::seed (gp_train --seed)")
    a = ap.parse_args()
    X, y = bench_data(a.n, a.d)
    std = X.std(axis=0)
    Xn = (X - X.mean(axis=0)) / np.where(std < 10 * np.finfo(float).eps, 1.0, std)
    k = ConstantKernel(1.0, (1e-4, 1e4)) * RBF([1.0] * a.d, (1e-3, 1e3)) + WhiteKernel(1e-2, (1e-10, 1e1))
    gp = GaussianProcessRegressor(k, optimizer=None, normalize_y=True).fit(Xn, y)
    d = a.d

    def to_sk(t):  # vigp (ln l.., ln sf2, ln sn2) -> sklearn (ln sf2, ln l.., ln sn2)
        return np.array([t[d]] + list(t[:d]) + [t[d + 1]])

    def obj(ts):
        v, g = gp.log_marginal_likelihood(ts, eval_gradient=True, clone_kernel=False)
        return -v, -g

    starts, bounds = vigp_starts(a.seed, 0, d, a.restarts)
    sk_bounds = [bounds[d]] + bounds[:d] + [bounds[d + 1]]
    nfevs, lmls = [], []
    for t0 in starts:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = scipy.optimize.minimize(
                obj,
                to_sk(t0),
                method="L-BFGS-B",
                jac=True,
                bounds=sk_bounds,
                options={"ftol": 2.220446049250313e-09, "gtol": 1e-5, "maxcor": 10},
            )
        nfevs.append(int(res.nfev))
        lmls.append(-float(res.fun))
        print(f"start {len(nfevs) - 1}: {res.nfev} evaluations, {res.nit} iterations, LML {-res.fun:.6f} ({res.message})", flush=True)
    print(f"scipy L-BFGS-B: {sum(nfevs)} evaluations, per start {nfevs}; best LML {max(lmls):.6f} (start {int(np.argmax(lmls))})")


if __name__ == "__main__":
    main()
