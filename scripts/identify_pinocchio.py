#!/usr/bin/env python3
"""The continuous-time identification route, for the side-by-side of
`cargo run --release --example identify_peers`.

A driven, damped planar double pendulum (both joints actuated) is simulated
in continuous time: Pinocchio's ABA for the accelerations, SciPy's DOP853 at
rtol = atol = 1e-12. Its samples, noise-free at dt = 20, 10 and 5 ms and
with position noise sigma = 1e-4 and 1e-3 at 10 ms (several seeds), go to a
JSON file, together with the estimates of the continuous-time route:
Savitzky-Golay velocities and accelerations (scipy.signal.savgol_filter)
into Pinocchio's `computeJointTorqueRegressor`, plus one damping column per
joint, solved by least squares (minimum norm). The estimate is written for
every window and polynomial order of a grid, so that the example can give
this route the window that suits it best.

Frames: vigp's planar link has its frame at its start, x along the link, and
theta = 0 hangs down (world -y). Here the link runs along the body x axis
and gravity points along world +x, the same mechanism turned by 90 degrees;
Pinocchio's 10 dynamic parameters of a body (m, m c, inertia about the body
origin) give vigp's planar standard parameters (m, m c_x, m c_y, I_O,zz).

    pip install pin scipy numpy
    python3 scripts/identify_pinocchio.py --out target/identify_peers.json
"""

import argparse
import json

import numpy as np
import pinocchio as pin
from scipy.integrate import solve_ivp
from scipy.signal import savgol_filter

# The declared mechanism (as in examples/identify_peers.rs) and its truth.
LENGTHS = (1.0, 0.7)
G = 9.81
TRUTH = {
    # mass, centre of mass (x, y) in the link frame, inertia about it
    "upper": (1.1, (0.55, 0.03), 1.15 * 1.0 * 1.0**2 / 12.0),
    "lower": (0.72, (0.32, -0.02), 0.85 * 0.8 * 0.7**2 / 12.0),
}
DAMPING = (0.25, 0.05)
Q0 = (0.5, 0.2)
T_END = 15.0


def inputs(t):
    """Torques on the shoulder and the elbow (smooth, persistently exciting)."""
    return np.array(
        [
            3.0 * np.sin(1.3 * t) + 1.0 + 1.5 * np.sin(3.7 * t),
            2.0 * np.cos(2.1 * t + 0.4) + 1.0 * np.sin(5.3 * t),
        ]
    )


def model(truth=True):
    m = pin.Model()
    m.gravity.linear = np.array([G, 0.0, 0.0])
    parent = 0
    placement = pin.SE3.Identity()
    for i, (name, length) in enumerate(zip(("upper", "lower"), LENGTHS)):
        j = m.addJoint(parent, pin.JointModelRZ(), placement, name)
        mass, (cx, cy), ic = TRUTH[name]
        inertia = np.diag([1e-3, 1e-3, ic]) if truth else np.diag([1e-3, 1e-3, 1.0 / 12.0])
        m.appendBodyToJoint(j, pin.Inertia(mass, np.array([cx, cy, 0.0]), inertia), pin.SE3.Identity())
        parent = j
        placement = pin.SE3(np.eye(3), np.array([length, 0.0, 0.0]))
    return m


def standard():
    """The truth in vigp's layout: per link (m, m c_x, m c_y, I_O), then damping per joint."""
    pi = []
    for name in ("upper", "lower"):
        mass, (cx, cy), ic = TRUTH[name]
        pi += [mass, mass * cx, mass * cy, ic + mass * (cx * cx + cy * cy)]
    return pi + list(DAMPING)


def simulate(dt):
    m = model()
    d = m.createData()
    c = np.array(DAMPING)

    def f(t, y):
        q, v = y[:2], y[2:]
        a = pin.aba(m, d, q, v, inputs(t) - c * v)
        return np.concatenate([v, a])

    n = int(round(T_END / dt)) + 1
    ts = dt * np.arange(n)
    sol = solve_ivp(f, (0.0, ts[-1]), np.array([*Q0, 0.0, 0.0]), method="DOP853",
                    t_eval=ts, rtol=1e-12, atol=1e-12)
    assert sol.success, sol.message
    return ts, sol.y[:2].T


def pinocchio_estimate(q, ts, dt, window, order):
    """Savitzky-Golay derivatives, the torque regressor, least squares."""
    m = model(truth=False)  # the regressor does not depend on inertias
    d = m.createData()
    qs = savgol_filter(q, window, order, deriv=0, axis=0)
    vs = savgol_filter(q, window, order, deriv=1, delta=dt, axis=0)
    As = savgol_filter(q, window, order, deriv=2, delta=dt, axis=0)
    rows, rhs = [], []
    h = window // 2
    for k in range(h, len(ts) - h):
        y = pin.computeJointTorqueRegressor(m, d, qs[k], vs[k], As[k])
        # Pinocchio's body parameters (m, mc_x, mc_y, mc_z, I_xx, I_xy,
        # I_yy, I_xz, I_yz, I_zz): the planar ones are 0, 1, 2, 9
        cols = [y[:, 10 * b + c] for b in range(2) for c in (0, 1, 2, 9)]
        block = np.column_stack(cols + [np.array([vs[k][0], 0.0]), np.array([0.0, vs[k][1]])])
        rows.append(block)
        rhs.append(inputs(ts[k]))
    a = np.vstack(rows)
    b = np.concatenate(rhs)
    return np.linalg.lstsq(a, b, rcond=None)[0].tolist()


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", required=True)
    p.add_argument("--seeds", type=int, default=10)
    args = p.parse_args()
    rng = np.random.default_rng(2026)
    out = {"truth": standard(), "clean": [], "noisy": []}

    def log(ts, q, dt):
        # vigp's row k input is held over [t_k, t_k + dt]: its midpoint value
        mid = [inputs(t + 0.5 * dt).tolist() for t in ts]
        return {"dt": dt, "positions": q.tolist(), "inputs": mid}

    for dt in (0.02, 0.01, 0.005):
        ts, q = simulate(dt)
        out["clean"].append(log(ts, q, dt))
    dt = 0.01
    ts, q = simulate(dt)
    windows = list(range(5, 82, 4))
    for sigma in (1e-4, 1e-3):
        for seed in range(args.seeds):
            noisy = q + sigma * rng.standard_normal(q.shape)
            entry = log(ts, noisy, dt)
            entry["sigma"] = sigma
            entry["seed"] = seed
            entry["pinocchio"] = [
                {"window": w, "order": o, "estimate": pinocchio_estimate(noisy, ts, dt, w, o)}
                for w in windows
                for o in (2, 3, 4)
                if o < w
            ]
            out["noisy"].append(entry)
            print(f"sigma {sigma:g} seed {seed}: {len(entry['pinocchio'])} Savitzky-Golay settings")
    with open(args.out, "w") as f:
        json.dump(out, f)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
