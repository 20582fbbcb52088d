#!/usr/bin/env python3
"""vigp's `Gp::train` against scikit-learn's GaussianProcessRegressor on the
unseen data sets of scripts/gp_campaign_data.py.

Both sides: ConstantKernel(sf2) * RBF(ARD) + WhiteKernel(sn2), constant
prior mean with normalize_y=True (vigp: PriorMean::Constant,
normalise_outputs), 1 + 10 starts, L-BFGS-B with scipy's defaults.

--mode raw (default; "raw units"): inputs as given to both, bounds
    (1e-5, 1e5) on every hyperparameter, start 0 at sf2 = l = sn2 = 1
    (vigp: examples/gp_csv.rs --raw).
--mode std: vigp's defaults (inputs standardised inside vigp, default
    bounds l in [1e-3, 1e3], sf2 in [1e-4, 1e4], sn2 in [1e-10, 10], start
    0 at l = 1, sf2 = 1, sn2 = 0.01); scikit-learn gets the standardised
    inputs (divisor N) and the same bounds and start, as
    scripts/gp_sklearn_bench.py does.

scikit-learn's alpha (added to the diagonal of K in normalised units) is
--alpha (default 1e-10, scikit-learn's default) for training; the checks
at fixed hyperparameters use alpha = 0 so that both sides compute the
same model.

For every data set it prints: best LML of each (normalised units, as
scikit-learn reports it), the relative difference (vigp − sklearn)/|sklearn|,
each side's LML function at the other's optimum (to tell optimiser from
likelihood differences), evaluations, and at scikit-learn's optimum the
relative errors of vigp's LML, gradient (relative to its norm), mean
(relative to max(|m|, s_y)) and variance of a new observation (relative to
max(var, sf2 s_y^2 + sn2 s_y^2)); as the gradient vanishes there, the LML
and gradient are also compared at a point off the optimum (each ln
hyperparameter moved by ±0.3, clamped into the bounds).

    cargo build --release --example gp_csv
    python scripts/gp_campaign.py [--mode raw|std] [--only NAME ...] [--out results.json]
"""
import argparse
import json
import os
import subprocess
import sys
import time
import warnings

import numpy as np
import scipy.optimize
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from gp_campaign_data import datasets, write_csv  # noqa: E402

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
NFEV = []


def lbfgsb(obj_func, initial_theta, bounds):
    """scikit-learn's default "fmin_l_bfgs_b" optimizer, counting evaluations."""
    res = scipy.optimize.minimize(
        obj_func, initial_theta, method="L-BFGS-B", jac=True, bounds=bounds,
        options={"ftol": 2.220446049250313e-09, "gtol": 1e-5, "maxcor": 10},
    )
    NFEV.append(int(res.nfev))
    return res.x, res.fun


def setup(mode, d):
    if mode == "raw":
        b = (1e-5, 1e5)
        return ConstantKernel(1.0, b) * RBF([1.0] * d, b) + WhiteKernel(1.0, b)
    return ConstantKernel(1.0, (1e-4, 1e4)) * RBF([1.0] * d, (1e-3, 1e3)) + WhiteKernel(1e-2, (1e-10, 1e1))


def standardise(X, ref):
    m = ref.mean(axis=0)
    s = ref.std(axis=0)
    s = np.where(s < 10 * np.finfo(float).eps, 1.0, s)
    return (X - m) / s


def to_vigp(t, d):  # sklearn (ln sf2, ln l.., ln sn2) -> vigp (ln l.., ln sf2, ln sn2)
    return list(t[1:1 + d]) + [t[0], t[1 + d]]


def to_sk(t, d):
    return np.array([t[d]] + list(t[:d]) + [t[d + 1]])


def run_vigp(exe, csv, mode, extra=()):
    cmd = [exe, "--csv", csv, "--restarts", "10"] + (["--raw"] if mode == "raw" else []) + list(extra)
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        return {"ok": False, "error": (p.stderr or p.stdout).strip()[-300:]}
    return json.loads(p.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--mode", choices=["raw", "std"], default="raw")
    ap.add_argument("--alpha", type=float, default=1e-10)
    ap.add_argument("--seed", type=int, default=0, help="scikit-learn random_state")
    ap.add_argument("--only", nargs="*")
    ap.add_argument("--dir", default="/tmp/gpcampaign")
    ap.add_argument("--exe", default=os.path.join(ROOT, "target", "release", "examples", "gp_csv"))
    ap.add_argument("--out")
    a = ap.parse_args()
    os.makedirs(a.dir, exist_ok=True)
    results = []
    print(f"mode {a.mode}, sklearn alpha {a.alpha:g}, random_state {a.seed}")
    hdr = f"{'dataset':28s} {'N':>5s} {'d':>2s} {'vigp LML':>16s} {'sklearn LML':>16s} {'rel diff':>10s} " \
          f"{'sk@vigp':>10s} {'vigp@sk':>10s} {'ev v/sk':>9s} | at sk optimum: lml grad mean var; off it: lml grad"
    print(hdr, flush=True)
    for name, X, y, T, note in datasets():
        if a.only and name not in a.only:
            continue
        n, d = X.shape
        csv = os.path.join(a.dir, name + ".csv")
        tcsv = os.path.join(a.dir, name + ".test.csv")
        write_csv(csv, X, y)
        write_csv(tcsv, T)
        Xs, Ts = (X, T) if a.mode == "raw" else (standardise(X, X), standardise(T, X))
        NFEV.clear()
        gp = GaussianProcessRegressor(setup(a.mode, d), optimizer=lbfgsb, n_restarts_optimizer=10,
                                      normalize_y=True, alpha=a.alpha, random_state=a.seed)
        t0 = time.perf_counter()
        sk_err = None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                gp.fit(Xs, y)
            sk_lml = float(gp.log_marginal_likelihood_value_)
            sk_theta = gp.kernel_.theta.copy()
        except Exception as e:  # noqa: BLE001
            sk_err, sk_lml, sk_theta = repr(e), float("nan"), None
        sk_secs = time.perf_counter() - t0
        sk_nfev = list(NFEV)
        v = run_vigp(a.exe, csv, a.mode)
        row = {"name": name, "n": n, "d": d, "note": note, "sklearn_lml": sk_lml, "sklearn_error": sk_err,
               "sklearn_nfev": sk_nfev, "sklearn_seconds": sk_secs,
               "sklearn_theta": None if sk_theta is None else to_vigp(sk_theta, d), "vigp": v}
        rel = sk_at_v = v_at_sk = float("nan")
        fixed = {}
        if v.get("ok") and sk_theta is not None:
            rel = (v["lml"] - sk_lml) / abs(sk_lml)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                sk_at_v = float(gp.log_marginal_likelihood(to_sk(v["theta"], d)))
            # fixed-hyperparameter agreement at sklearn's optimum (alpha = 0 on both sides)
            g0 = GaussianProcessRegressor(gp.kernel_, optimizer=None, normalize_y=True, alpha=0.0)
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    g0.fit(Xs, y)
                    lml0, grad0 = g0.log_marginal_likelihood(sk_theta, eval_gradient=True)
                    m0, s0 = g0.predict(Ts, return_std=True)
                th = ",".join(repr(float(t)) for t in to_vigp(sk_theta, d))
                fv = run_vigp(a.exe, csv, a.mode, ["--theta", th, "--test", tcsv])
                if fv.get("ok", True) and "lml" in fv:
                    v_at_sk = fv["lml"]
                    sy = float(g0._y_train_std)
                    sf2, sn2 = np.exp(sk_theta[0]), np.exp(sk_theta[-1])
                    g_ref = np.array(to_vigp(grad0, d))
                    gn = max(np.linalg.norm(g_ref), 1e-300)
                    # the gradient vanishes at the optimum: check it also at a point off it
                    th_off = sk_theta + 0.3 * (-1.0) ** np.arange(len(sk_theta))
                    b = np.array(gp.kernel_.bounds)
                    th_off = np.clip(th_off, b[:, 0], b[:, 1])
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        lml1, grad1 = g0.log_marginal_likelihood(th_off, eval_gradient=True)
                    th1 = ",".join(repr(float(t)) for t in to_vigp(th_off, d))
                    fv1 = run_vigp(a.exe, csv, a.mode, ["--theta", th1])
                    g1 = np.array(to_vigp(grad1, d))
                    fixed = {
                        "lml_off": abs(fv1["lml"] - lml1) / abs(lml1),
                        "grad_off": float(np.max(np.abs(np.array(fv1["gradient"]) - g1)) / np.linalg.norm(g1)),
                        "lml": abs(fv["lml"] - lml0) / abs(lml0),
                        "grad": float(np.max(np.abs(np.array(fv["gradient"]) - g_ref)) / gn),
                        "mean": float(np.max(np.abs(np.array(fv["mean"]) - m0) / np.maximum(np.abs(m0), sy))),
                        "var": float(np.max(np.abs(np.array(fv["var_with_noise"]) - s0 ** 2)
                                            / np.maximum(s0 ** 2, (sf2 + sn2) * sy * sy))),
                        "jitter": fv["jitter"],
                    }
                else:
                    fixed = {"error": fv.get("error")}
            except Exception as e:  # noqa: BLE001
                fixed = {"error": "sklearn: " + repr(e)}
        row.update({"rel_diff": rel, "sklearn_lml_at_vigp_theta": sk_at_v, "vigp_lml_at_sklearn_theta": v_at_sk,
                    "fixed": fixed})
        results.append(row)
        ev = f"{v.get('evaluations', '-')}/{sum(sk_nfev)}"
        fx = ("ERR " + str(fixed.get("error"))[:60]) if "error" in fixed else \
            " ".join(f"{fixed[k]:.1e}" for k in ("lml", "grad", "mean", "var", "lml_off", "grad_off")) if fixed else "-"
        if fixed.get("jitter"):
            fx += f" (vigp jitter {fixed['jitter']:.1e})"
        vl = f"{v['lml']:16.6f}" if v.get("ok") else f"{'ERROR':>16s}"
        flag = "  <-- WORSE" if rel < -1e-6 else ""
        if not v.get("ok"):
            flag = "  <-- vigp error: " + str(v.get("error"))[:120]
        print(f"{name:28s} {n:5d} {d:2d} {vl} {sk_lml:16.6f} {rel:10.2e} {sk_at_v:10.3f} {v_at_sk:10.3f} {ev:>9s} | {fx}{flag}",
              flush=True)
    if a.out:
        with open(a.out, "w") as f:
            json.dump(results, f, indent=1, default=float)


if __name__ == "__main__":
    main()
