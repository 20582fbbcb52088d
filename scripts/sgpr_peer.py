#!/usr/bin/env python3
"""GPflow's SGPR on vigp's sparse benchmark problem (docs/gp.md, "Sparse GP at
N = 10⁵"), for a side-by-side time at the same data, inducing points and
starting point.

The problem vigp solves (`cargo run --release --example gp_train -- --n 100000
--sparse 256 --restarts 0 --runs 1`, `TrainOptions::default()` with
`Method::Sparse(SparseOptions::kmeans(256))`):

* data: `bench_data` of examples/gp_train.rs (ported below, identical to
  scripts/gp_sklearn_bench.py): Weyl-sequence inputs in [−2, 2]^d, target
  sin 3x₁ + cos 2x₂ + ½x₃x₄ + 0.01·(Weyl − ½);
* inputs standardised per dimension, x_n = (x − mean)/std (divisor N);
* constant prior mean (the target mean) and output scaling: the GP models
  r_n = (y − ȳ)/s_y with s_y the root mean square of y − ȳ, i.e.
  scikit-learn's `normalize_y=True`;
* kernel σ_f²·exp(−½ Σ_j (x_j − x'_j)²/ℓ_j²) (SE-ARD) plus Gaussian noise
  σ², one output;
* Titsias' (2009) collapsed bound F (GPflow's SGPR form), K_uu + ε·σ_f²·I
  with ε = 1e-10 (×10 only if the Cholesky fails);
* M = 256 inducing points: k-means++ seeding (seed 0, no Lloyd
  iterations, i.e. M training inputs), **held fixed** during training;
* start ℓ = 1, σ_f² = 1, σ² = 0.01 (normalised units), no restarts;
  bounds ℓ ∈ [1e-3, 1e3], σ_f² ∈ [1e-4, 1e4], σ² ∈ [1e-10, 10];
* optimiser: vigp's projected L-BFGS (memory 10, Moré–Thuente line
  search with scipy's constants) on θ = ln(ℓ, σ_f², σ²); stop when
  ‖P(θ − g) − θ‖∞ ≤ 1e-5 or the relative decrease of −F in one iteration is
  ≤ 2.22e-9 (scipy's L-BFGS-B defaults), at most 500 iterations;
* the printed "best LML" is F in normalised units (the bound for r_n on
  x_n, not per sample); in original units it is F − N·ln s_y.

This script reproduces that problem in GPflow: the inducing points,
standardisation and target mean/scale are read from the JSON that
`gp_train --dump-inducing PATH` writes (so both sides use the same Z to the
last bit; the script also checks its own numpy standardisation against
them), and `gpflow.models.SGPR` with `SquaredExponential(1, [1]*d)`,
`Gaussian(variance=0.01, variance_lower_bound=1e-10)`, zero mean function on
r_n, float64, trained with `gpflow.optimizers.Scipy()` (scipy L-BFGS-B,
`compile=True`, i.e. a `tf.function` graph) with ftol = 2.22e-9,
gtol = 1e-5, maxcor = 10, maxiter = 500. Differences that remain:

* GPflow optimises softplus-transformed parameters (its default), vigp log
  parameters, so the paths differ; `--bijector exp` uses exp (= vigp's
  log space) instead;
* GPflow's K_uu jitter is absolute (`gpflow.config` default_jitter, set to
  1e-10 here = vigp's 1e-10·σ_f² at the start σ_f² = 1). That changes the
  problem: with a fixed absolute jitter, raising σ_f² lowers the relative
  jitter, and at N = 10⁵ GPflow then climbs to σ_f² ≈ 2200 and a "bound"
  of 454 623 that exists only through the near-singular K_uu (the same
  point with the jitter 1e-10·σ_f² gives 434 905, below vigp's 445 848).
  `--jitter relative` subclasses SGPR with vigp's rule 1e-10·σ_f² (the
  rest of GPflow's `_common_calculation` unchanged): the same problem;
* GPflow has no upper bounds and no lower bounds on ℓ, σ_f² (vigp's do not
  bind at the optimum: the script prints the fitted values);
* GPflow computes yᵀΣ⁻¹y and tr(K − Q) as differences of large terms
  (σ⁻²yᵀy − ‖c‖², Σk/σ² − tr AAᵀ), vigp in the cancellation-free form.

`--check` (use at small N, e.g. a dump of `gp_train -- --n 2000`) instead
evaluates GPflow's bound at vigp's first start (ℓ = 1, σ_f² = 1, σ² = 0.01,
well conditioned) and at the hyperparameters, jitter and Z that vigp
trained to, and compares them with vigp's bounds, in normalised units (data r_n, x_n) and in original
units (data y, x with a constant mean function ȳ, ℓ·s_x, σ_f²·s_y², σ²·s_y²,
jitter·s_y², Z in original units; expected F − N·ln s_y). This is the
independent check of the unit conversion. At the trained point
(σ_f²/σ² ≈ 6·10⁷, cond K_uu ≈ 10¹⁰) every float64 evaluation carries
rounding ≈ 1e-8 relative, so agreement there is only to that level.

Usage (see docs/gp.md), each command under `flock /tmp/vigp-bench.lock`:
    cargo run --release --example gp_train -- --n 100000 --sparse 256 \\
        --restarts 0 --runs 1 --dump-inducing /tmp/z100k.json
    python scripts/sgpr_peer.py --inducing /tmp/z100k.json --threads 2 --jitter relative
    python scripts/sgpr_peer.py --inducing /tmp/z100k.json --threads 1 --jitter relative
    python scripts/sgpr_peer.py --inducing /tmp/z100k.json --threads 2   # GPflow's absolute jitter
    cargo run --release --example gp_train -- --n 2000 --sparse 256 \
        --restarts 0 --runs 1 --dump-inducing /tmp/z2k.json
    python scripts/sgpr_peer.py --inducing /tmp/z2k.json --check
    # Z trained on both sides (vigp: fixed-Z starts, then the joint refinement)
    cargo run --release --example gp_train -- --n 10000 --sparse 64 \
        --restarts 0 --runs 1 --dump-inducing /tmp/z10k.json
    cargo run --release --example gp_train -- --n 10000 --sparse 64 \
        --restarts 0 --runs 1 --optimise-inducing
    python scripts/sgpr_peer.py --inducing /tmp/z10k.json --threads 2 --jitter relative --train-z
`--threads` sets TensorFlow's intra- and inter-op thread pools (must be set
before TensorFlow starts, hence one process per setting). `--train-z` adds a
run with Z trainable (GPflow's default), capped at `--z-maxiter` iterations
(not run at N = 10⁵: 1024 more parameters at ≈ 6 s per evaluation).
Prints the versions, load average before and after, each run's wall time
(time.perf_counter, including the tf.function tracing) and process CPU time,
the final bound in normalised units, the L-BFGS-B function evaluations
(nfev) and iterations, the fitted hyperparameters (full precision; `--save`
writes them as JSON) and the bound at the fitted point with the jitter
1e-10·σ_f², from GPflow and from the cancellation-free numpy form.
"""
import argparse
import json
import math
import os
import resource
import time

import numpy as np

# run as `python scripts/...`: scripts/ is on the import path
from bench_data import bench_data, load


def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def numpy_bound(X, r, Z, ls, sf2, s2, jitter):
    """Titsias' bound in float64 numpy/scipy, summed without GPflow's
    cancellations: yᵀΣ⁻¹y = (‖r − Aᵀv₁‖² + ‖v₁‖²)/σ² (v₁ = B⁻¹Ar) and
    tr(K − Q) = Σ_n (σ_f² − σ²‖a_n‖²); also returns GPflow's rounding scale
    ε·(Σk/σ² + rᵀr/σ²), the size of the terms its form subtracts."""
    import scipy.linalg as sl

    def k(P, Q):
        D = ((P[:, None, :] - Q[None, :, :]) / ls) ** 2
        return sf2 * np.exp(-0.5 * D.sum(-1))

    n, m = len(r), len(Z)
    L = np.linalg.cholesky(k(Z, Z) + jitter * np.eye(m))
    A = sl.solve_triangular(L, k(Z, X), lower=True) / math.sqrt(s2)
    B = np.eye(m) + A @ A.T
    LB = np.linalg.cholesky(B)
    v1 = sl.cho_solve((LB, True), A @ r)
    fit = (math.fsum((r - A.T @ v1) ** 2) + math.fsum(v1**2)) / s2
    trace = math.fsum(sf2 - s2 * (A**2).sum(0)) / s2
    f = -0.5 * n * math.log(2 * math.pi) - np.log(np.diag(LB)).sum() - 0.5 * n * math.log(s2) - 0.5 * fit - 0.5 * trace
    return f, np.finfo(float).eps * (n * sf2 + float(r @ r)) / s2


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--inducing", required=True, help="JSON of gp_train --dump-inducing")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--check", action="store_true")
    ap.add_argument("--bijector", choices=["softplus", "exp"], default="softplus")
    ap.add_argument("--train-z", action="store_true")
    ap.add_argument("--z-maxiter", type=int, default=500)
    ap.add_argument(
        "--jitter",
        choices=["absolute", "relative"],
        default="absolute",
        help="K_uu jitter: GPflow's absolute 1e-10, or vigp's rule 1e-10·σ_f² (subclass of SGPR)",
    )
    ap.add_argument("--save", help="write the fitted hyperparameters (full precision) as JSON")
    a = ap.parse_args()

    dump = json.load(open(a.inducing))
    n, d, m = dump["n"], dump["d"], dump["m"]
    X, y = bench_data(n, d)
    shift, scale = np.array(dump["input_shift"]), np.array(dump["input_scale"])
    ybar, sy = dump["target_mean"], dump["output_scale"]
    # Our own standardisation must agree with vigp's to rounding.
    print(
        f"numpy vs vigp standardisation: shift {np.max(np.abs(X.mean(0) - shift)):.1e}, "
        f"scale {np.max(np.abs(X.std(0) / scale - 1)):.1e}, target mean {abs(y.mean() - ybar):.1e}, "
        f"s_y {abs(np.sqrt(np.mean((y - ybar) ** 2)) / sy - 1):.1e}"
    )
    Xn = (X - shift) / scale
    rn = ((y - ybar) / sy)[:, None]
    Zn = np.array(dump["inducing_normalised"])
    Zo = np.array(dump["inducing_original"])
    assert Zn.shape == (m, d)

    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")  # TensorFlow's start-up chatter
    os.environ.setdefault("CUDA_VISIBLE_DEVICES", "")  # CPU only, no cuInit probe
    import tensorflow as tf

    tf.config.threading.set_intra_op_parallelism_threads(a.threads)
    tf.config.threading.set_inter_op_parallelism_threads(a.threads)
    import gpflow

    gpflow.config.set_default_float(np.float64)
    if a.bijector == "exp":
        gpflow.config.set_default_positive_bijector("exp")
    print(
        f"GPflow {gpflow.__version__}, TensorFlow {tf.__version__}, numpy {np.__version__}, "
        f"scipy {__import__('scipy').__version__}; TF threads intra {a.threads} inter {a.threads}; "
        f"N = {n}, d = {d}, M = {m}"
    )

    class RelativeJitterSGPR(gpflow.models.SGPR):
        """GPflow's SGPR with vigp's K_uu jitter 1e-10·σ_f² instead of an
        absolute one (the rest of `_common_calculation` as in GPflow 2.11)."""

        def _common_calculation(self):
            from gpflow.covariances import Kuf, Kuu
            from gpflow.utilities import add_noise_cov

            x, _ = self.data
            sigma_sq = tf.squeeze(self.likelihood.variance_at(x), axis=-1)
            sigma = tf.sqrt(sigma_sq)
            kuf = Kuf(self.inducing_variable, self.kernel, x)
            kuu = Kuu(self.inducing_variable, self.kernel, jitter=1e-10 * self.kernel.variance)
            L = tf.linalg.cholesky(kuu)
            A = tf.linalg.triangular_solve(L, kuf / sigma, lower=True)
            AAT = tf.linalg.matmul(A, A, transpose_b=True)
            B = add_noise_cov(AAT, tf.cast(1.0, AAT.dtype))
            LB = tf.linalg.cholesky(B)
            return self.CommonTensors(sigma_sq, sigma, A, B, LB, AAT, L)

    def sgpr(Xd, Yd, Z, ls, sf2, s2, mean=None, relative=False):
        k = gpflow.kernels.SquaredExponential(variance=sf2, lengthscales=list(ls))
        lik = gpflow.likelihoods.Gaussian(variance=s2, variance_lower_bound=1e-10)
        cls = RelativeJitterSGPR if relative else gpflow.models.SGPR
        return cls(
            (Xd, Yd), k, gpflow.inducing_variables.InducingPoints(Z), likelihood=lik, mean_function=mean
        )

    if a.check:
        ls = np.array(dump["length_scales"])
        sf2, s2, jit = dump["signal_variance"], dump["noise_variance"], dump["kuu_jitter"]
        want = dump["bound_normalised"]
        mean = gpflow.functions.Constant(np.array([ybar]))
        gpflow.config.set_default_jitter(jit)
        f_norm = float(sgpr(Xn, rn, Zn, ls, sf2, s2).elbo())
        gpflow.config.set_default_jitter(jit * sy * sy)
        f_orig = float(sgpr(X, y[:, None], Zo, ls * scale, sf2 * sy * sy, s2 * sy * sy, mean).elbo())
        want_orig = want - n * math.log(sy)
        # The first start ℓ = 1, σ_f² = 1, σ² = 0.01, jitter 1e-10: well conditioned.
        gpflow.config.set_default_jitter(1e-10)
        s0 = dump["bound_at_start_normalised"]
        g0 = float(sgpr(Xn, rn, Zn, [1.0] * d, 1.0, 1e-2).elbo())
        gpflow.config.set_default_jitter(1e-10 * sy * sy)
        g0o = float(sgpr(X, y[:, None], Zo, scale, sy * sy, 1e-2 * sy * sy, mean).elbo())
        n0, _ = numpy_bound(Xn, rn[:, 0], Zn, np.ones(d), 1.0, 1e-2, 1e-10)
        s0o = s0 - n * math.log(sy)
        print("at the first start (l = 1, sf2 = 1, s2 = 0.01, jitter 1e-10):")
        print(f"  normalised units: vigp {s0:.12f}  GPflow {g0:.12f}  rel. diff {abs(g0 - s0) / max(abs(s0), 1):.2e}")
        print(f"  original units:   vigp − N ln s_y {s0o:.12f}  GPflow {g0o:.12f}  rel. diff {abs(g0o - s0o) / max(abs(s0o), 1):.2e}")
        print(f"  numpy: {n0:.12f}  rel. diff to vigp {abs(n0 - s0) / max(abs(s0), 1):.2e}")
        print("at vigp's trained point:")
        np_norm, noise = numpy_bound(Xn, rn[:, 0], Zn, ls, sf2, s2, jit)
        np_orig, noise_o = numpy_bound(X, y - ybar, Zo, ls * scale, sf2 * sy * sy, s2 * sy * sy, jit * sy * sy)
        print(f"hyperparameters (normalised): l = {ls.tolist()}, sf2 = {sf2!r}, s2 = {s2!r}, jitter {jit!r}")
        print(f"normalised units: vigp {want:.12f}  GPflow {f_norm:.12f}  rel. diff {abs(f_norm - want) / max(abs(want), 1):.2e}")
        print(
            f"original units:   vigp − N ln s_y {want_orig:.12f}  GPflow {f_orig:.12f}  "
            f"rel. diff {abs(f_orig - want_orig) / abs(want_orig):.2e}"
        )
        print(
            f"numpy (cancellation-free sums): normalised {np_norm:.12f} (rel. diff to vigp "
            f"{abs(np_norm - want) / abs(want):.2e}), original {np_orig:.12f} (rel. diff to vigp − N ln s_y "
            f"{abs(np_orig - want_orig) / abs(want_orig):.2e})"
        )
        print(
            f"GPflow's rounding scale ε·(Σk + rᵀr)/σ²: {noise:.1e} normalised, {noise_o:.1e} original "
            f"(GPflow − numpy: {f_norm - np_norm:.1e}, {f_orig - np_orig:.1e})"
        )
        return

    opts = dict(ftol=2.220446049250313e-09, gtol=1e-5, maxcor=10, maxiter=500)
    gpflow.config.set_default_jitter(1e-10)
    print("load average before:", load(), flush=True)
    configs = [("Z fixed", False, opts)] * a.runs
    if a.train_z:
        configs.append(("Z trainable", True, dict(opts, maxiter=a.z_maxiter)))
    for label, train_z, o in configs:
        model = sgpr(Xn, rn, Zn.copy(), [1.0] * d, 1.0, 1e-2, relative=a.jitter == "relative")
        gpflow.set_trainable(model.inducing_variable, train_z)
        l0, t0, c0 = load(), time.perf_counter(), cpu()
        res = gpflow.optimizers.Scipy().minimize(
            model.training_loss, model.trainable_variables, method="L-BFGS-B", options=o
        )
        t, c = time.perf_counter() - t0, cpu() - c0
        f = float(model.elbo())
        ls = model.kernel.lengthscales.numpy()
        print(
            f"{label} ({a.bijector}, {a.jitter} jitter): {t:.3f} s wall (CPU {c:.1f} s = {c / t:.2f} cores), "
            f"bound {f:.6f} (normalised units), {res.nfev} evaluations in {res.nit} iterations "
            f"({1e3 * t / res.nfev:.0f} ms each), success {res.success}: {res.message}; load {l0} → {load()}",
            flush=True,
        )
        ls, sf2, s2 = ls.tolist(), float(model.kernel.variance.numpy()), float(model.likelihood.variance.numpy())
        print(f"  l = {ls}, sf2 = {sf2!r}, s2 = {s2!r}")
        # The same point with vigp's jitter rule (1e-10·σ_f², not GPflow's
        # absolute 1e-10) and in the cancellation-free numpy form: is the
        # bound GPflow reports a rounding artefact of a near-singular K_uu?
        gpflow.config.set_default_jitter(1e-10 * sf2)
        f_j = float(model.elbo())
        gpflow.config.set_default_jitter(1e-10)
        if not train_z:
            f_np, _ = numpy_bound(Xn, rn[:, 0], Zn, np.array(ls), sf2, s2, 1e-10 * sf2)
            f_np0, _ = numpy_bound(Xn, rn[:, 0], Zn, np.array(ls), sf2, s2, 1e-10)
            print(
                f"  bound at this point: GPflow, jitter 1e-10·sf2 {f_j:.6f}; numpy, jitter 1e-10·sf2 "
                f"{f_np:.6f}, jitter 1e-10 {f_np0:.6f}",
                flush=True,
            )
        if a.save:
            json.dump(dict(length_scales=ls, signal_variance=sf2, noise_variance=s2, bound=f, label=label), open(a.save, "w"))
    print("load average after:", load())


if __name__ == "__main__":
    main()
