#!/usr/bin/env python3
"""Screened GP training (vigp's default `Screening::Auto` from N = 512)
against unscreened training (`--screen off`, scikit-learn's procedure in
vigp) and against scikit-learn itself, on the unseen data sets of
scripts/gp_screening_data.py (N = 512..2048).

All three: ConstantKernel * RBF(ARD) + WhiteKernel, constant prior mean
with normalize_y=True, 1 + 10 starts, L-BFGS-B with scipy's stopping
rules; `--mode std` (default) or `--mode raw` as in scripts/gp_campaign.py.
scikit-learn's 11 starts are its own random points (random_state
`--seed`), vigp's are its seeded ones: the check is whether each side
reaches the best optimum, not the same path.

For every set it prints the three best LMLs (normalised units), the
relative differences screened − unscreened and screened − scikit-learn
(flagged when below −1e-6), wall times, vigp's evaluations on all samples
(and on the subset), and which starts were refined.

    cargo build --release --example gp_csv
    python scripts/gp_screening_check.py [--mode std|raw] [--only NAME ...] [--no-sklearn] [--out results.json]
"""
import argparse
import json
import os
import sys
import time
import warnings

from sklearn.gaussian_process import GaussianProcessRegressor

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from gp_campaign import NFEV, ROOT, lbfgsb, run_vigp, setup, standardise  # noqa: E402
from gp_campaign_data import write_csv  # noqa: E402
from gp_screening_data import datasets  # noqa: E402
from bench_data import load  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--mode", choices=["raw", "std"], default="std")
    ap.add_argument("--alpha", type=float, default=1e-10)
    ap.add_argument("--seed", type=int, default=0, help="scikit-learn random_state")
    ap.add_argument("--only", nargs="*")
    ap.add_argument("--no-sklearn", action="store_true")
    ap.add_argument("--dir", default="/tmp/gpscreening")
    ap.add_argument("--exe", default=os.path.join(ROOT, "target", "release", "examples", "gp_csv"))
    ap.add_argument("--out")
    a = ap.parse_args()
    os.makedirs(a.dir, exist_ok=True)
    print(f"mode {a.mode}, sklearn alpha {a.alpha:g}, random_state {a.seed}, load {load()}")
    print(f"{'dataset':28s} {'N':>5s} {'d':>2s} {'screened':>14s} {'unscreened':>14s} {'sklearn':>14s} "
          f"{'scr-unscr':>9s} {'scr-sk':>9s} {'t scr':>6s} {'t off':>6s} {'t sk':>7s}  evals scr(+subset)/off/sk; refined",
          flush=True)
    rows = []
    worse = 0
    for name, X, y, _, note in datasets():
        if a.only and name not in a.only:
            continue
        n, d = X.shape
        csv = os.path.join(a.dir, name + ".csv")
        write_csv(csv, X, y)
        scr = run_vigp(a.exe, csv, a.mode)
        off = run_vigp(a.exe, csv, a.mode, ["--screen", "off"])
        sk_lml, sk_secs, sk_nfev = float("nan"), float("nan"), []
        if not a.no_sklearn:
            Xs = X if a.mode == "raw" else standardise(X, X)
            NFEV.clear()
            gp = GaussianProcessRegressor(setup(a.mode, d), optimizer=lbfgsb, n_restarts_optimizer=10,
                                          normalize_y=True, alpha=a.alpha, random_state=a.seed)
            t0 = time.perf_counter()
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    gp.fit(Xs, y)
                sk_lml = float(gp.log_marginal_likelihood_value_)
            except Exception as e:  # noqa: BLE001
                print(f"  sklearn failed: {e!r}")
            sk_secs = time.perf_counter() - t0
            sk_nfev = list(NFEV)
        row = {"name": name, "n": n, "d": d, "note": note, "screened": scr, "unscreened": off,
               "sklearn_lml": sk_lml, "sklearn_seconds": sk_secs, "sklearn_nfev": sk_nfev}
        rows.append(row)
        if not (scr.get("ok") and off.get("ok")):
            print(f"{name:28s} {n:5d} {d:2d}  ERROR screened {scr.get('error')} / unscreened {off.get('error')}")
            worse += 1
            continue
        ref = max(off["lml"], sk_lml) if sk_lml == sk_lml else off["lml"]
        r_off = (scr["lml"] - off["lml"]) / abs(off["lml"])
        r_sk = (scr["lml"] - sk_lml) / abs(sk_lml) if sk_lml == sk_lml else float("nan")
        bad = (scr["lml"] - ref) / abs(ref) < -1e-6
        worse += bad
        s = scr.get("screening") or {}
        ev = f"{scr['evaluations']}(+{s.get('evaluations', 0)})/{off['evaluations']}/{sum(sk_nfev)}"
        extra = f"; refined {s.get('refined')}" + (" FELL BACK" if s.get("fell_back") else "") if s else "; not screened"
        print(f"{name:28s} {n:5d} {d:2d} {scr['lml']:14.6f} {off['lml']:14.6f} {sk_lml:14.6f} "
              f"{r_off:9.1e} {r_sk:9.1e} {scr['seconds']:6.2f} {off['seconds']:6.2f} {sk_secs:7.1f}  {ev}{extra}"
              + ("  <-- WORSE" if bad else ""), flush=True)
    print(f"{worse} of {len(rows)} sets: screened more than 1e-6 (relative) below the better of unscreened and sklearn; "
          f"load {load()}")
    if a.out:
        with open(a.out, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
