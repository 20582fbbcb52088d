#!/usr/bin/env python3
"""Unseen data sets at N = 512..2048 for checking the screened training
(`Screening::Auto`: every start first on a subset, then the distinct
optima refined on all samples) against the unscreened one and against
scikit-learn (scripts/gp_screening_check.py). None of these sets is used
by a test, a benchmark or a default of vigp.

Smooth and rough targets, d = 1..8, noise from none to dominant, inputs
of very different scales and far from 0, large output offsets, clustered
and duplicated inputs, irrelevant inputs, a pure-noise set (the white-noise
plateau must win there), a weak signal in strong noise, and velocity
residuals of a damped pendulum (the learned integrator's kind of data).

`datasets()` returns a list of (name, X, y, X_test, note), deterministic
(numpy default_rng with fixed seeds)."""
import numpy as np

from gp_campaign_data import _test_points


def _pendulum_residuals(rng, n, damping=0.3, dt=0.01):
    """(θ, ω) of a damped pendulum's trajectories, and the velocity a
    frictionless model misses after one step (the GP's target in vigp's
    learned integrator, up to units)."""
    X, y = [], []
    while len(X) < n:
        th, om = rng.uniform(-2.5, 2.5), rng.uniform(-3, 3)
        for _ in range(60):
            acc_true = -9.81 * np.sin(th) - damping * om
            acc_nom = -9.81 * np.sin(th)
            X.append([th, om])
            y.append(dt * (acc_true - acc_nom) + 1e-4 * rng.standard_normal())
            om += dt * acc_true
            th += dt * om
            if len(X) == n:
                break
    return np.array(X), np.array(y)


def datasets():
    out = []

    def add(name, X, y, note, seed):
        X = np.asarray(X, dtype=float)
        if X.ndim == 1:
            X = X[:, None]
        rng = np.random.default_rng(seed + 2000)
        out.append((name, X, np.asarray(y, dtype=float), _test_points(rng, X), note))

    for s in (101, 102):
        r = np.random.default_rng(s)
        X = r.uniform(-2, 2, (512, 4))
        y = np.sin(2.5 * X[:, 0]) * np.cos(X[:, 1]) + 0.3 * X[:, 2] ** 2 - 0.2 * X[:, 3] + 0.02 * r.standard_normal(512)
        add(f"random_d4_n512_s{s}", X, y, "random inputs, smooth, noise 0.02", s)

    r = np.random.default_rng(103)
    X = r.uniform(0, 1, 800)
    add("highfreq_d1_n800", X, np.sin(35 * X) + 0.05 * r.standard_normal(800), "high frequency", 103)

    r = np.random.default_rng(104)
    X = np.linspace(-4, 4, 1000)
    add("noisefree_d1_n1000", X, np.tanh(X) + 0.05 * X ** 2, "dense, noise-free", 104)

    r = np.random.default_rng(105)
    X = r.uniform(-1, 1, 600)
    add("steps_d1_n600", X, np.floor(4 * X) + 0.02 * r.standard_normal(600), "steps", 105)

    r = np.random.default_rng(106)
    X = np.column_stack([r.uniform(0, 1e-2, 700), r.uniform(0, 1e2, 700)])
    y = np.cos(X[:, 0] / 2e-3) * np.sin(X[:, 1] / 20.0) + 0.03 * r.standard_normal(700)
    add("scales_1e-2_1e2_d2_n700", X, y, "input scales 1e-2 and 1e2", 106)

    r = np.random.default_rng(107)
    X = -5e3 + r.uniform(-1, 1, (600, 3))
    y = np.cos(3 * (X[:, 0] + 5e3)) + (X[:, 1] + 5e3) * (X[:, 2] + 5e3) + 0.01 * r.standard_normal(600)
    add("shifted_-5e3_d3_n600", X, y, "inputs centred at -5e3", 107)

    r = np.random.default_rng(108)
    X = r.uniform(-2, 2, (900, 2))
    y = -3e3 + 500.0 * np.sin(X[:, 0] * X[:, 1]) + 5.0 * r.standard_normal(900)
    add("offset_-3e3_d2_n900", X, y, "y offset -3e3, scale 500", 108)

    r = np.random.default_rng(109)
    X = r.uniform(-1, 1, (600, 3))
    add("nearconst_d3_n600", X, 2.0 + 1e-7 * X[:, 0] + 1e-9 * r.standard_normal(600), "near-constant", 109)

    r = np.random.default_rng(110)
    X0 = r.uniform(-2, 2, (320, 2))
    X = np.vstack([X0, X0])
    y = np.sin(X[:, 0]) + np.cos(2 * X[:, 1])
    y = y + 0.05 * r.standard_normal(640)
    add("duplicated_d2_n640", X, y, "every input twice, noisy", 110)

    r = np.random.default_rng(111)
    centres = r.uniform(-3, 3, (6, 2))
    X = centres[r.integers(0, 6, 800)] + 0.08 * r.standard_normal((800, 2))
    y = np.sin(X[:, 0]) * X[:, 1] + 0.01 * r.standard_normal(800)
    add("clustered_d2_n800", X, y, "six clusters", 111)

    r = np.random.default_rng(112)
    X = r.uniform(-2, 2, (1000, 5))
    y = np.exp(-X[:, 0] ** 2) + np.sin(2 * X[:, 1]) + 0.02 * r.standard_normal(1000)
    add("irrelevant3_d5_n1000", X, y, "three irrelevant inputs", 112)

    r = np.random.default_rng(113)
    X = r.uniform(-1, 1, (768, 6))
    y = np.sin(X @ np.array([1.0, -2.0, 0.5, 0.0, 1.5, -0.7])) + 0.1 * X[:, 3] + 0.01 * r.standard_normal(768)
    add("ridge_d6_n768", X, y, "a ridge function", 113)

    r = np.random.default_rng(114)
    X = r.uniform(-1, 1, (1024, 8))
    y = np.cos(2 * X[:, 0]) + X[:, 1] * X[:, 2] + 0.3 * np.sin(4 * X[:, 7]) + 0.05 * r.standard_normal(1024)
    add("mixed_d8_n1024", X, y, "d = 8", 114)

    r = np.random.default_rng(115)
    X, y = _pendulum_residuals(r, 1024)
    add("pendulum_friction_d2_n1024", X, y, "damped-pendulum velocity residuals", 115)

    r = np.random.default_rng(116)
    X = r.uniform(-2, 2, (600, 2))
    y = np.sin(2 * X[:, 0]) + (0.05 + 0.3 * np.abs(X[:, 1])) * r.standard_t(3, 600)
    add("heavy_tails_d2_n600", X, y, "heteroscedastic t(3) noise", 116)

    r = np.random.default_rng(117)
    X = np.sort(r.uniform(0, 30, 1500))
    add("periodic_trend_d1_n1500", X, np.sin(2 * X) + 0.05 * X + 0.1 * r.standard_normal(1500), "periodic + trend", 117)

    r = np.random.default_rng(118)
    X = r.uniform(-2, 2, (700, 3))
    y = 0.05 * np.sin(X[:, 0]) + 1.0 * r.standard_normal(700)
    add("weak_signal_d3_n700", X, y, "signal 20x below the noise", 118)

    r = np.random.default_rng(119)
    X = r.uniform(-2, 2, (600, 2))
    add("pure_noise_d2_n600", X, r.standard_normal(600), "white noise only", 119)

    r = np.random.default_rng(120)
    X = r.uniform(-1, 1, (1000, 2))
    y = (X[:, 0] + X[:, 1] > 0).astype(float) + 0.01 * r.standard_normal(1000)
    add("diagonal_step_d2_n1000", X, y, "a step along a diagonal", 120)

    r = np.random.default_rng(121)
    X = r.uniform(-2, 2, (2048, 4))
    y = np.sin(3 * X[:, 0]) + np.cos(2 * X[:, 1]) + 0.5 * X[:, 2] * X[:, 3] + 0.01 * r.standard_normal(2048)
    add("random_d4_n2048", X, y, "N = 2048", 121)

    r = np.random.default_rng(122)
    X, y = _pendulum_residuals(r, 2048, damping=0.8)
    add("pendulum_friction_d2_n2048", X, y, "damped-pendulum velocity residuals, N = 2048", 122)
    return out
