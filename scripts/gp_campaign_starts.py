#!/usr/bin/env python3
"""Start-by-start optimiser comparison on one data set of
scripts/gp_campaign_data.py: vigp's L-BFGS-B against scipy's (scikit-learn's
optimizer) from the *same* start points, on the same likelihood.

--starts vigp (default): vigp's own 1 + 10 starts (`TrainOptions::seed`
    --seed; SplitMix64 port of scripts/gp_scipy_evals.py); for each, vigp's
    final LML (examples/gp_csv.rs --restarts 0 --start θ), the projected
    gradient ∞-norm at vigp's end point, scipy's L-BFGS-B polish from that
    end point, and scipy's run from the same start (scikit-learn's LML with
    alpha = --alpha, default 0 as vigp has no alpha).
--starts sklearn: scikit-learn's 1 + 10 starts (random_state --seed), each
    run by scipy inside GaussianProcessRegressor.fit (scikit-learn's default
    alpha = 1e-10 there) and by vigp.

`--start` goes through exp/ln in gp_csv (Hyperparameters::from_log), which
can move θ by an ulp; paths that are sensitive to that are marked
"(differs from the full run)".

    cargo build --release --example gp_csv
    python scripts/gp_campaign_starts.py dup3_noisy_d2_n150 --mode raw --starts sklearn
    python scripts/gp_campaign_starts.py purenoise_d2_n100 --mode raw
"""
import argparse
import json
import math
import os
import subprocess
import sys
import warnings

import numpy as np
import scipy.optimize
from sklearn.gaussian_process import GaussianProcessRegressor

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from gp_campaign import ROOT, setup, standardise, to_sk, to_vigp  # noqa: E402
from gp_campaign_data import datasets, write_csv  # noqa: E402
from gp_scipy_evals import SplitMix64  # noqa: E402

OPTS = {"ftol": 2.220446049250313e-09, "gtol": 1e-5, "maxcor": 10}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("name")
    ap.add_argument("--mode", choices=["raw", "std"], default="raw")
    ap.add_argument("--starts", choices=["vigp", "sklearn"], default="vigp")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--alpha", type=float, default=0.0)
    ap.add_argument("--dir", default="/tmp/gpcampaign")
    ap.add_argument("--exe", default=os.path.join(ROOT, "target", "release", "examples", "gp_csv"))
    a = ap.parse_args()
    ds = {n: (X, y) for n, X, y, _, _ in datasets()}
    X, y = ds[a.name]
    d = X.shape[1]
    Xs = X if a.mode == "raw" else standardise(X, X)
    os.makedirs(a.dir, exist_ok=True)
    csv = os.path.join(a.dir, a.name + ".csv")
    write_csv(csv, X, y)
    raw = ["--raw"] if a.mode == "raw" else []
    if a.mode == "raw":
        lo, hi, s0 = [math.log(1e-5)] * (d + 2), [math.log(1e5)] * (d + 2), [0.0] * (d + 2)
    else:
        lo = [math.log(1e-3)] * d + [math.log(1e-4), math.log(1e-10)]
        hi = [math.log(1e3)] * d + [math.log(1e4), math.log(1e1)]
        s0 = [0.0] * (d + 1) + [math.log(1e-2)]
    bounds = [(lo[d], hi[d])] + list(zip(lo[:d], hi[:d])) + [(lo[d + 1], hi[d + 1])]
    gp = GaussianProcessRegressor(setup(a.mode, d), optimizer=None, normalize_y=True, alpha=a.alpha).fit(Xs, y)

    def obj(t):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            v, g = gp.log_marginal_likelihood(t, eval_gradient=True, clone_kernel=False)
        return -v, -g

    def vigp(start):
        st = ",".join(repr(float(v)) for v in start)
        out = subprocess.run([a.exe, "--csv", csv, "--restarts", "0", "--start", st] + raw,
                             capture_output=True, text=True).stdout
        return json.loads(out)

    if a.starts == "sklearn":
        runs = []

        def opt(o, t0, bounds):
            r = scipy.optimize.minimize(o, t0, method="L-BFGS-B", jac=True, bounds=bounds, options=OPTS)
            runs.append((t0.copy(), -r.fun, r.nfev))
            return r.x, r.fun

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            GaussianProcessRegressor(setup(a.mode, d), optimizer=opt, n_restarts_optimizer=10, normalize_y=True,
                                     random_state=a.seed).fit(Xs, y)
        for k, (t0, f, nfev) in enumerate(runs):
            j = vigp(to_vigp(t0, d))
            flag = "  <-- vigp lower" if j["lml"] < f - 1e-6 * abs(f) else ""
            print(f"sklearn start {k:2d} {np.round(to_vigp(t0, d), 3)}: scipy {f:.6f} ({nfev} ev)  "
                  f"vigp {j['lml']:.6f} ({j['evaluations']} ev){flag}", flush=True)
        return
    r = SplitMix64(a.seed)
    rng = SplitMix64(r.next_u64())
    starts = [s0] + [[rng.uniform(l, h) for l, h in zip(lo, hi)] for _ in range(10)]
    full = json.loads(subprocess.run([a.exe, "--csv", csv, "--seed", str(a.seed)] + raw,
                                     capture_output=True, text=True).stdout)
    b = np.array(bounds)
    for k, s in enumerate(starts):
        j = vigp(s)
        rs = scipy.optimize.minimize(obj, to_sk(s, d), method="L-BFGS-B", jac=True, bounds=bounds, options=OPTS)
        tv = to_sk(j["theta"], d)
        _, g = obj(tv)
        pg = np.abs(np.clip(tv - g, b[:, 0], b[:, 1]) - tv).max()
        pol = scipy.optimize.minimize(obj, tv, method="L-BFGS-B", jac=True, bounds=bounds, options=OPTS)
        same = abs(j["lml"] - full["start_lmls"][k]) <= 1e-9 * abs(j["lml"]) + 1e-12
        note = "" if same else f" (differs from the full run: {full['start_lmls'][k]:.6f})"
        flag = "  <-- vigp lower" if j["lml"] < -rs.fun - 1e-6 * abs(rs.fun) else ""
        print(f"vigp start {k:2d}: vigp {j['lml']:.6f} ({j['evaluations']} ev, |pg|inf {pg:.1e}, "
              f"scipy polish -> {-pol.fun:.6f})  scipy {-rs.fun:.6f} ({rs.nfev} ev){note}{flag}", flush=True)


if __name__ == "__main__":
    main()
