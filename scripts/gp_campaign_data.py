#!/usr/bin/env python3
"""Unseen data sets for the vigp-vs-scikit-learn GP campaign
(scripts/gp_campaign.py): N 20..1000, d 1..8, smooth and rough targets,
inputs of very different scales per dimension and far from 0, outputs with
large offset and scale, near-constant outputs, noise-free and noisy,
duplicated rows, clustered inputs, an irrelevant input dimension.

`datasets()` returns a list of (name, X, y, X_test, note), deterministic
(numpy default_rng with fixed seeds). Run as a script to write them as CSV
(inputs then output, one sample per line) into a directory:

    python scripts/gp_campaign_data.py /tmp/gpcampaign
"""
import os
import sys

import numpy as np


def _test_points(rng, X, k=5):
    """k test points: inside the data's box, plus one just outside."""
    lo, hi = X.min(axis=0), X.max(axis=0)
    span = np.where(hi > lo, hi - lo, 1.0)
    T = lo + span * rng.uniform(0.0, 1.0, size=(k - 1, X.shape[1]))
    out = hi + 0.1 * span
    return np.vstack([T, out[None, :]])


def datasets():
    out = []

    def add(name, X, y, note, seed):
        X = np.asarray(X, dtype=float)
        if X.ndim == 1:
            X = X[:, None]
        rng = np.random.default_rng(seed + 1000)
        out.append((name, X, np.asarray(y, dtype=float), _test_points(rng, X), note))

    r = np.random.default_rng(1)
    X = r.uniform(-3, 3, 20)
    add("smooth_d1_n20", X, np.sin(X) + 0.05 * r.standard_normal(20), "tiny, noisy", 1)

    r = np.random.default_rng(2)
    X = r.uniform(0, 1, 60)
    add("noisefree_d1_n60", X, np.sin(6 * X), "noise-free smooth", 2)

    r = np.random.default_rng(3)
    X = r.uniform(-1, 1, 200)
    y = np.abs(X) + 0.3 * np.sign(np.sin(9 * X)) + 0.01 * r.standard_normal(200)
    add("rough_d1_n200", X, y, "kink + steps", 3)

    r = np.random.default_rng(4)
    X = r.uniform(0, 1, 500)
    add("highfreq_d1_n500", X, np.sin(40 * X) + 0.02 * r.standard_normal(500), "high frequency", 4)

    r = np.random.default_rng(5)
    X = np.linspace(0, 10, 1000)
    add("noisefree_d1_n1000", X, np.sin(X) + 0.1 * X, "dense, noise-free (ill-conditioned)", 5)

    r = np.random.default_rng(6)
    X = r.uniform(-2, 2, (100, 2))
    add("smooth_d2_n100", X, np.sin(2 * X[:, 0]) * np.cos(X[:, 1]) + 0.05 * r.standard_normal(100), "", 6)

    r = np.random.default_rng(7)
    X = np.column_stack([r.uniform(0, 1e-3, 150), r.uniform(0, 1e3, 150)])
    y = np.sin(X[:, 0] / 1.5e-4) + np.cos(X[:, 1] / 150.0) + 0.02 * r.standard_normal(150)
    add("scales_1e-3_1e3_d2_n150", X, y, "input scales 1e-3 and 1e3", 7)

    r = np.random.default_rng(8)
    X = 1e4 + r.uniform(-1, 1, (120, 3))
    y = np.sin(2 * (X[:, 0] - 1e4)) + (X[:, 1] - 1e4) ** 2 + 0.01 * r.standard_normal(120)
    add("shifted_1e4_d3_n120", X, y, "inputs centred at 1e4", 8)

    r = np.random.default_rng(9)
    X = r.uniform(-2, 2, (200, 2))
    y = 1e4 + 1e4 * (np.sin(X[:, 0]) + 0.5 * X[:, 1]) + 10.0 * r.standard_normal(200)
    add("offset_scale_1e4_d2_n200", X, y, "y offset and scale 1e4", 9)

    r = np.random.default_rng(10)
    X = r.uniform(-2, 2, (80, 2))
    y = 5.0 + 1e-9 * np.sin(X[:, 0] + X[:, 1])
    add("nearconst_1e-9_d2_n80", X, y, "y = 5 + 1e-9 f(x), noise-free", 10)

    r = np.random.default_rng(11)
    X = r.uniform(-2, 2, (80, 2))
    y = 3e3 + 1e-6 * r.standard_normal(80)
    add("nearconst_noise_d2_n80", X, y, "y = 3e3 + 1e-6 white noise", 11)

    r = np.random.default_rng(12)
    X0 = r.uniform(-2, 2, (50, 2))
    X = np.repeat(X0, 3, axis=0)
    y = np.sin(X[:, 0]) + X[:, 1] ** 2 + 0.1 * r.standard_normal(150)
    add("dup3_noisy_d2_n150", X, y, "each row 3 times, noisy", 12)

    r = np.random.default_rng(13)
    X0 = r.uniform(-2, 2, (40, 2))
    X = np.vstack([X0, X0[:20]])
    y = np.sin(X[:, 0]) * np.cos(X[:, 1])
    add("dup_noisefree_d2_n60", X, y, "20 duplicated rows, same y, noise-free", 13)

    r = np.random.default_rng(14)
    C = np.array([[-5.0, -5.0], [0.0, 3.0], [4.0, -1.0]])
    X = np.vstack([c + 1e-3 * r.standard_normal((40, 2)) for c in C])
    y = np.sin(X[:, 0]) + np.cos(X[:, 1]) + 1e-3 * r.standard_normal(120)
    add("clusters3_tight_d2_n120", X, y, "3 clusters of std 1e-3", 14)

    r = np.random.default_rng(15)
    X = r.uniform(-2, 2, (150, 3))
    y = np.sin(2 * X[:, 0]) + 0.5 * X[:, 1] ** 2 + 0.05 * r.standard_normal(150)
    add("irrelevant_d3_n150", X, y, "x3 irrelevant: l3 -> upper bound", 15)

    r = np.random.default_rng(16)
    X = r.uniform(-1, 1, (300, 8))
    y = np.sin(2 * X[:, 0]) + np.cos(3 * X[:, 1]) + X[:, 2] * X[:, 3] + 0.3 * X[:, 4] + 0.01 * r.standard_normal(300)
    add("smooth_d8_n300", X, y, "3 dims irrelevant", 16)

    r = np.random.default_rng(17)
    X = r.uniform(-2, 2, (1000, 5))
    y = np.sin(X[:, 0]) * np.cos(X[:, 1]) + 0.2 * X[:, 2] ** 2 - 0.1 * X[:, 3] * X[:, 4] + 0.01 * r.standard_normal(1000)
    add("smooth_d5_n1000", X, y, "largest N", 17)

    r = np.random.default_rng(18)
    X = r.uniform(-1, 1, (400, 6))
    y = np.abs(X[:, 0]) + (X[:, 1] > 0.2) + np.abs(X[:, 2] * X[:, 3]) + 0.05 * r.standard_normal(400)
    add("rough_d6_n400", X, y, "kinks and a step", 18)

    r = np.random.default_rng(19)
    X = r.uniform(-2, 2, (100, 2))
    add("purenoise_d2_n100", X, r.standard_normal(100), "y is white noise", 19)

    r = np.random.default_rng(20)
    X = r.uniform(-3, 3, 80)
    add("linear_d1_n80", X, 2.0 * X + 1.0 + 0.1 * r.standard_normal(80), "linear: l -> large", 20)

    r = np.random.default_rng(21)
    g = np.arange(15.0)
    X = np.array([[a, b] for a in g for b in g])
    y = np.sin(X[:, 0] / 3.0) + np.cos(X[:, 1] / 4.0) + 0.01 * r.standard_normal(len(X))
    add("intgrid_d2_n225", X, y, "integer grid 15x15", 21)

    r = np.random.default_rng(22)
    X = np.column_stack([
        1e5 + r.uniform(0, 1e-3, 250),
        r.uniform(-1, 1, 250),
        -3e4 + r.uniform(0, 1e3, 250),
        r.uniform(0, 1, 250),
    ])
    y = 1e3 * (np.sin((X[:, 0] - 1e5) / 2e-4) + X[:, 1] ** 2 + np.cos((X[:, 2] + 3e4) / 200.0)) + 5.0 * r.standard_normal(250)
    add("mixed_scales_shift_d4_n250", X, y, "scales 1e-3/1/1e3/1, shifts 1e5/-3e4, y x1e3, x4 irrelevant", 22)

    r = np.random.default_rng(23)
    X = r.uniform(-1, 1, (20, 8))
    add("tiny_d8_n20", X, X[:, 0] + np.sin(X[:, 1]) + 0.01 * r.standard_normal(20), "N = 20, d = 8", 23)

    r = np.random.default_rng(24)
    X = r.uniform(-2, 2, 120)
    y = np.where(X > 0.3, 1.0, 0.0) + 0.01 * r.standard_normal(120)
    add("step_d1_n120", X, y, "discontinuous", 24)

    r = np.random.default_rng(25)
    X = np.column_stack([r.uniform(0, 1e3, 200), r.uniform(0, 1e-3, 200), r.uniform(0, 1, 200)])
    y = 1e4 * np.sin(X[:, 0] / 100.0) + 1e4 * np.cos(X[:, 1] / 3e-4)
    add("scales_noisefree_d3_n200", X, y, "scales 1e3/1e-3/1, noise-free, x3 irrelevant, y scale 1e4", 25)
    return out


def write_csv(path, X, y=None):
    A = X if y is None else np.column_stack([X, y])
    np.savetxt(path, A, delimiter=",", fmt="%.17g")


def main():
    outdir = sys.argv[1] if len(sys.argv) > 1 else "/tmp/gpcampaign"
    os.makedirs(outdir, exist_ok=True)
    for name, X, y, T, _ in datasets():
        write_csv(os.path.join(outdir, name + ".csv"), X, y)
        write_csv(os.path.join(outdir, name + ".test.csv"), T)
        print(name, X.shape)


if __name__ == "__main__":
    main()
