#!/usr/bin/env python3
"""Time scikit-learn GP training on the data and settings of benches/gp.rs
(train/N512_d4_10restarts): N = 512, d = 4, normalize_y, 10 restarts,
ConstantKernel(1)*RBF([1]*4) + WhiteKernel(1e-2) with vigp's default bounds
(l in [1e-3, 1e3], sf2 in [1e-4, 1e4], sn2 in [1e-10, 10]).

vigp standardises inputs before applying these bounds; here the inputs are
standardised the same way so both optimise the same problem.

Stopping rules: scikit-learn's default optimizer is scipy's L-BFGS-B with
its defaults, ftol = 2.220446049250313e-09 (factr 1e7) and gtol (pgtol) 1e-5,
maxcor 10; vigp's TrainOptions defaults are the same numbers. The optimizer
below is that default made explicit, only to count function evaluations.

Prints, for each BLAS thread count in --threads (set with threadpoolctl,
back to back in one process), each run's time (time.perf_counter), best LML,
the L-BFGS-B evaluations of every start, and the median; then the BLAS in
use and the load average before and after.

One command per comparison (see docs/gp.md):
    python scripts/gp_sklearn_bench.py --n 512 --restarts 10 --runs 3 --threads 1 2
    python scripts/gp_sklearn_bench.py --n 2048 --restarts 10 --runs 1 --threads 1 2
Unset OPENBLAS_CORETYPE and OPENBLAS_L2_SIZE for this command if the machine
sets them (they slow a current numpy); the script prints the BLAS kernel.
"""
import argparse
import statistics
import time
import warnings

import numpy as np
import scipy.optimize
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

# run as `python scripts/...`: scripts/ is on the import path
from bench_data import bench_data, load


NFEV = []


def lbfgsb(obj_func, initial_theta, bounds):
    """scikit-learn's default "fmin_l_bfgs_b" optimizer, counting evaluations."""
    res = scipy.optimize.minimize(
        obj_func,
        initial_theta,
        method="L-BFGS-B",
        jac=True,
        bounds=bounds,
        options={"ftol": 2.220446049250313e-09, "gtol": 1e-5, "maxcor": 10},
    )
    NFEV.append(int(res.nfev))
    return res.x, res.fun


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--n", type=int, default=512)
    ap.add_argument("--d", type=int, default=4)
    ap.add_argument("--restarts", type=int, default=10)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    a = ap.parse_args()
    from threadpoolctl import threadpool_info, threadpool_limits

    X, y = bench_data(a.n, a.d)
    std = X.std(axis=0)
    Xn = (X - X.mean(axis=0)) / np.where(std < 10 * np.finfo(float).eps, 1.0, std)
    print(f"scikit-learn GaussianProcessRegressor.fit: N = {a.n}, d = {a.d}, 1 + {a.restarts} starts")
    print("load average before:", load(), flush=True)
    for threads in a.threads:
        times, lmls = [], []
        with threadpool_limits(limits=threads, user_api="blas"):
            for r in range(a.runs):
                k = ConstantKernel(1.0, (1e-4, 1e4)) * RBF([1.0] * a.d, (1e-3, 1e3)) + WhiteKernel(
                    1e-2, (1e-10, 1e1)
                )
                gp = GaussianProcessRegressor(
                    k, optimizer=lbfgsb, n_restarts_optimizer=a.restarts, normalize_y=True, random_state=r
                )
                NFEV.clear()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    t0 = time.perf_counter()
                    gp.fit(Xn, y)
                    times.append(time.perf_counter() - t0)
                lmls.append(gp.log_marginal_likelihood_value_)
                print(
                    f"{threads} BLAS thread(s), run {r}: {times[-1]:.3f} s, best LML {lmls[-1]:.6f}, "
                    f"{sum(NFEV)} evaluations ({1e3 * times[-1] / sum(NFEV):.1f} ms each), per start {NFEV}",
                    flush=True,
                )
            for p in threadpool_info():
                print("  blas:", p.get("internal_api"), p.get("version"), p.get("architecture"), "threads", p.get("num_threads"))
        print(f"{threads} BLAS thread(s): median {statistics.median(times):.3f} s over {a.runs} runs; best LML {max(lmls):.6f}")
    print("load average after:", load())


if __name__ == "__main__":
    main()
