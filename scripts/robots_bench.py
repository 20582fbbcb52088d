#!/usr/bin/env python3
"""MuJoCo's step on the robots of `cargo run --release --example robots`:
planar and spatial chains of N = 2 … 32 rods (m = 1, l = 0.5, the same
URDF as the example) and the Panda and UR5 of tests/fixtures/robots, loaded
from the same URDF files. Euler integrator, dt = 2 ms, no contacts, no
joint limits; median ns per step of `mujoco.rollout` over 5 runs of 2000
steps (a C loop), and the fitted slope of log time against log N from N = 8.
With `--rollouts`, only this table, each number the fastest of 7 runs
instead of the median of 5 (the `robots` example runs it so, twice, and
prints the numbers beside its own, taken the same way: on a shared
machine the fastest run is the one least disturbed by other processes). Then, for the second table of the
example, the same robots with a motor on every joint: one `mj_step` against one centred `mjd_transitionFD` (A and B
by centred differences of `mj_step`, eps = 1e-6), median ns per call over
301 calls with preallocated matrices.

    pip install mujoco
    python3 scripts/robots_bench.py                 # both tables
    python3 scripts/robots_bench.py --derivatives   # the second alone
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


def time_rollout(model, q0, steps=2000, reps=5, stat=np.median):
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
    return float(stat(times))


def with_motors(urdf_text):
    """The robot with a unit-gear motor on every hinge or slide joint."""
    spec = mujoco.MjSpec.from_string(urdf_text)
    for j in spec.joints:
        if j.type in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE):
            a = spec.add_actuator()
            a.name = "motor_" + j.name
            a.target = j.name
            a.trntype = mujoco.mjtTrn.mjTRN_JOINT
            a.gainprm[0] = 1.0
            a.biastype = mujoco.mjtBias.mjBIAS_NONE
    model = spec.compile()
    model.opt.timestep = 0.002
    model.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_LIMIT
    return model


def median_call_ns(f, calls=301):
    f()
    times = []
    for _ in range(calls):
        t = time.perf_counter_ns()
        f()
        times.append(time.perf_counter_ns() - t)
    return float(np.median(times))


def derivatives_table():
    print()
    print("MuJoCo", mujoco.__version__, "Euler, dt = 2 ms, a motor on every joint; median ns per call of 301")
    print("| mechanism | N | mj_step (µs) | centred mjd_transitionFD (µs) |")
    print("|---|---|---|---|")
    cases = [(name, open(os.path.join(FIX, f)).read()) for name, f in (
        ("Panda", "panda.urdf"), ("UR5", "ur5.urdf"),
        ("Solo-12 (fixed base)", "solo12.urdf"), ("G1 humanoid (fixed base)", "g1.urdf"))]
    cases += [(f"spatial chain (z/y), {n} rods", chain(n, True)) for n in (8, 16, 32)]
    for name, text in cases:
        model = with_motors(text)
        data = mujoco.MjData(model)
        n = model.nv
        # the example's state: q_i = 0.3 sin(1.7 i), v_i = 0.4 cos(0.9 i), u_i = 0.2 sin(1.3 i)
        i = np.arange(n)
        q, v, u = 0.3 * np.sin(1.7 * i), 0.4 * np.cos(0.9 * i), 0.2 * np.sin(1.3 * i)

        def reset():
            data.qpos[:] = q
            data.qvel[:] = v
            data.ctrl[:] = u

        def step():
            reset()
            mujoco.mj_step(model, data)

        A = np.zeros((2 * n, 2 * n))
        B = np.zeros((2 * n, model.nu))

        def fd():
            reset()
            mujoco.mjd_transitionFD(model, data, 1e-6, 1, A, B, None, None)

        print(f"| {name} | {n} | {median_call_ns(step) * 1e-3:.1f} | {median_call_ns(fd) * 1e-3:.1f} |")


def main():
    import sys
    if "--derivatives" in sys.argv[1:]:
        derivatives_table()
        return
    fastest = "--rollouts" in sys.argv[1:]
    reps, stat, how = (7, np.min, "fastest of 7") if fastest else (5, np.median, "median of 5")
    print("MuJoCo", mujoco.__version__, f"Euler, dt = 2 ms, 2000-step rollouts, {how}")
    print("| mechanism | N | ns/step |")
    print("|---|---|---|")
    for spatial in (False, True):
        fit = []
        for n in (2, 4, 8, 12, 16, 24, 32):
            model = load(chain(n, spatial))
            q0 = np.zeros(model.nq)
            q0[0], q0[1] = 1.0, -0.5
            ns = time_rollout(model, q0, reps=reps, stat=stat)
            name = "spatial chain (z/y)" if spatial else "planar chain"
            print(f"| {name} | {n} | {ns:.0f} |")
            if n >= 8:
                fit.append((np.log(n), np.log(ns)))
        x, y = np.array(fit).T
        print(f"| fitted slope, N = 8…32 | | {np.polyfit(x, y, 1)[0]:.2f} |")
    for name, f, q in (("Panda", "panda.urdf", [0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8]),
                       ("UR5", "ur5.urdf", [0.3, -1.2, 1.0, -0.5, 0.8, 0.2]),
                       ("Solo-12 (fixed base)", "solo12.urdf", None)):
        model = load(open(os.path.join(FIX, f)).read())
        q0 = np.zeros(model.nq) if q is None else np.array(q)
        print(f"| {name} | {model.nq} | {time_rollout(model, q0, reps=reps, stat=stat):.0f} |")
    if fastest:
        return
    derivatives_table()


if __name__ == "__main__":
    main()
