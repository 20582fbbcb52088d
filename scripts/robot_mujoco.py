#!/usr/bin/env python3
"""MuJoCo reference trajectories of URDF robots for vigp-runtime/tests/robot.rs:
the Panda and the Solo-12 legs (fixed base) of tests/fixtures/robots, loaded
by MuJoCo's own URDF importer, integrated with RK4 at dt = 1e-5 s (its error,
O(dt^4), is far below the errors the test measures) for T = 0.5 s from a
moving state. No contacts, no joint limits, no friction loss, no armature;
the joint damping is the file's (MuJoCo reads <dynamics damping>).

Writes tests/fixtures/robots/mujoco_rk4.json:
{robot: {"joints": [...], "q0": [...], "v0": [...], "t": T, "q": [...], "v": [...]}}

    pip install mujoco
    python3 scripts/robot_mujoco.py
"""
import json
import os

import mujoco
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
FIX = os.path.join(HERE, "..", "tests", "fixtures", "robots")

CASES = {
    "panda": ("panda.urdf", [0.1, -0.4, 0.3, -1.8, 0.2, 1.4, 0.6],
              [0.5, -0.3, 0.2, 0.4, -0.6, 0.1, 0.3]),
    "solo12": ("solo12.urdf", [0.1 * np.sin(1.3 * i) for i in range(12)],
               [0.8 * np.cos(0.7 * i) for i in range(12)]),
}
T = 0.5
DT = 1e-5


def main():
    out = {}
    for name, (file, q0, v0) in CASES.items():
        model = mujoco.MjModel.from_xml_string(open(os.path.join(FIX, file)).read())
        model.opt.timestep = DT
        model.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
        model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
        model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_LIMIT
        model.dof_frictionloss[:] = 0.0
        model.dof_armature[:] = 0.0
        assert model.nq == model.nv == len(q0)
        data = mujoco.MjData(model)
        data.qpos[:] = q0
        data.qvel[:] = v0
        for _ in range(int(round(T / DT))):
            mujoco.mj_step(model, data)
        joints = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(model.njnt)]
        out[name] = {
            "mujoco": mujoco.__version__,
            "joints": joints,
            "damping": model.dof_damping.tolist(),
            "q0": [float(x) for x in q0],
            "v0": [float(x) for x in v0],
            "t": T,
            "dt": DT,
            "q": data.qpos.tolist(),
            "v": data.qvel.tolist(),
        }
        print(name, "q(T) =", np.round(data.qpos, 6))
    with open(os.path.join(FIX, "mujoco_rk4.json"), "w") as f:
        json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
