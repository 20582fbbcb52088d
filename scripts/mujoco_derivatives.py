#!/usr/bin/env python3
"""Time MuJoCo's finite-difference transition derivatives,
mujoco.mjd_transitionFD, on vigp's double pendulum (scripts/mujoco_models.py:
1 kg, 1 m thin rods, dt = 0.01 s), called from Python as a user would.

    pip install mujoco
    python3 scripts/mujoco_derivatives.py [--calls 2000] [--reps 21]

mjd_transitionFD(m, d, eps, flg_centered, A, B, None, None) returns
A = d x_{k+1} / d x_k (2nv x 2nv, x = (qpos, qvel) in tangent space) and,
with actuators, B = d x_{k+1} / d u_k (2nv x nu) by forward (flg_centered = 0)
or centered (1) differences of mj_step. Timed for the unactuated double
pendulum (A only) and for one with a motor on each joint (A and B: vigp's
control derivatives take inputs), for the Euler and implicitfast
integrators (MuJoCo refuses RK4 here), at the state
q = (1.0, -0.5), qdot = (0.5, 1.0), eps = 1e-6. Each repetition times
--calls consecutive calls with preallocated A and B (time.perf_counter_ns);
prints the median (and minimum) over --reps repetitions, per call, and the
load average. As a sanity check it prints the largest difference between
the forward and the centered A (O(eps) apart).
"""
import argparse
import os
import platform
import statistics
import sys
import time

import mujoco
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mujoco_models as mm  # noqa: E402

Q = np.array([1.0, -0.5])
QDOT = np.array([0.5, 1.0])
EPS = 1e-6


def time_fd(xml, centered, calls, reps):
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    d.qpos[:] = Q
    d.qvel[:] = QDOT
    mujoco.mj_forward(m, d)
    nx = 2 * m.nv + m.na
    a = np.zeros((nx, nx))
    b = np.zeros((nx, m.nu)) if m.nu else None
    mujoco.mjd_transitionFD(m, d, EPS, centered, a, b, None, None)  # warm-up
    times = []
    for _ in range(reps):
        t0 = time.perf_counter_ns()
        for _ in range(calls):
            mujoco.mjd_transitionFD(m, d, EPS, centered, a, b, None, None)
        times.append((time.perf_counter_ns() - t0) / calls)
    return statistics.median(times), min(times), a.copy()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--calls", type=int, default=2000, help="calls per repetition")
    ap.add_argument("--reps", type=int, default=21, help="repetitions")
    args = ap.parse_args()
    load = os.getloadavg()
    print(f"MuJoCo {mujoco.__version__}, numpy {np.__version__}, Python "
          f"{platform.python_version()}, {os.cpu_count()} CPUs, load average "
          f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    print(f"mjd_transitionFD on the double pendulum, dt = {mm.DT} s, eps = {EPS:g}, "
          f"median (min) of {args.reps} x {args.calls} calls, µs per call\n")
    print("| integrator | inputs | forward (µs) | centered (µs) | max abs(A_fwd - A_ctr) |")
    print("|---|---|---|---|---|")
    for integ in mm.INTEGRATORS:
        if integ == "RK4":
            continue  # "mjd_transitionFD: RK4 integrator is not supported"
        for actuated in (False, True):
            xml = mm.double_pendulum(integ, actuated=actuated)
            fwd = time_fd(xml, 0, args.calls, args.reps)
            ctr = time_fd(xml, 1, args.calls, args.reps)
            inputs = "2 motors (A, B)" if actuated else "none (A)"
            print(f"| {integ} | {inputs} | {fwd[0] / 1e3:.2f} ({fwd[1] / 1e3:.2f}) | "
                  f"{ctr[0] / 1e3:.2f} ({ctr[1] / 1e3:.2f}) | "
                  f"{np.abs(fwd[2] - ctr[2]).max():.1e} |")
    print("\n(RK4: mjd_transitionFD refuses it, 'RK4 integrator is not supported'.)")


if __name__ == "__main__":
    main()
