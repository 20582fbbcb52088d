#!/usr/bin/env python3
"""MuJoCo's step on the robots of `cargo run --release --example robots`:
planar and spatial chains of N = 2 … 32 rods (m = 1, l = 0.5, the same
URDF as the example) and the Panda and UR5 of tests/fixtures/robots, loaded
from the same URDF files. Euler integrator, dt = 2 ms, no contacts, no
joint limits; median ns per step of `mujoco.rollout` over 5 runs of 2000
steps (a C loop), and the fitted slope of log time against log N from N = 8.

    pip install mujoco
    python3 scripts/robots_bench.py
"""
import os
import time

import numpy as np
import mujoco
from mujoco import rollout

HERE = os.path.dirname(os.path.abspath(__file__))
FIX = os.path.join(HERE, "..", "tests", "fixtures", "robots")


def chain(n, spatial):
    m, l = 1.0, 0.5
    i = m * l * l / 12.0
    s = '<robot name="chain"><link name="l0"/>'
    for k in range(1, n + 1):
        axis = "0 0 1" if spatial and k % 2 == 1 else "0 1 0"
        if spatial:
            com, origin = f"{l / 2} 0 0", f"{0.0 if k == 1 else l} 0 0"
        else:
            com, origin = f"0 0 {-l / 2}", f"0 0 {0.0 if k == 1 else -l}"
        s += (f'<link name="l{k}"><inertial><origin xyz="{com}"/><mass value="{m}"/>'
              f'<inertia ixx="{i}" ixy="0" ixz="0" iyy="{i}" iyz="0" izz="{i}"/></inertial></link>'
              f'<joint name="j{k}" type="continuous"><parent link="l{k - 1}"/><child link="l{k}"/>'
              f'<origin xyz="{origin}"/><axis xyz="{axis}"/></joint>')
    return s + "</robot>"


def load(urdf_text):
    model = mujoco.MjModel.from_xml_string(urdf_text)
    model.opt.timestep = 0.002
    model.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_LIMIT
    return model


def time_rollout(model, q0, steps=2000, reps=5):
    data = mujoco.MjData(model)
    state = np.zeros(mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_FULLPHYSICS))
    data.qpos[:] = q0
    mujoco.mj_getState(model, data, state, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    ctrl = np.zeros((1, steps, model.nu))
    times = []
    for _ in range(reps):
        t = time.perf_counter()
        rollout.rollout(model, data, state[None, :], ctrl)
        times.append((time.perf_counter() - t) * 1e9 / steps)
    return float(np.median(times))


def main():
    print("MuJoCo", mujoco.__version__, "Euler, dt = 2 ms, 2000-step rollouts, median of 5")
    print("| mechanism | N | ns/step |")
    print("|---|---|---|")
    for spatial in (False, True):
        fit = []
        for n in (2, 4, 8, 12, 16, 24, 32):
            model = load(chain(n, spatial))
            q0 = np.zeros(model.nq)
            q0[0], q0[1] = 1.0, -0.5
            ns = time_rollout(model, q0)
            name = "spatial chain (z/y)" if spatial else "planar chain"
            print(f"| {name} | {n} | {ns:.0f} |")
            if n >= 8:
                fit.append((np.log(n), np.log(ns)))
        x, y = np.array(fit).T
        print(f"| fitted slope, N = 8…32 | | {np.polyfit(x, y, 1)[0]:.2f} |")
    for name, f, q in (("Panda", "panda.urdf", [0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8]),
                       ("UR5", "ur5.urdf", [0.3, -1.2, 1.0, -0.5, 0.8, 0.2])):
        model = load(open(os.path.join(FIX, f)).read())
        print(f"| {name} | {model.nq} | {time_rollout(model, np.array(q)):.0f} |")


if __name__ == "__main__":
    main()
