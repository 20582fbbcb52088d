#!/usr/bin/env python3
"""MuJoCo reference for the spatial examples (vigp::systems::spatial).

Writes the same four models as MJCF (link frames, anchors, axes, masses and
inertias as in src/systems/spatial.rs), and

1. fixtures (default): simulates each from a fixed initial state with RK4 at
   dt = 1e-4 s for 2 s and writes tests/fixtures/spatial_mujoco.json: per
   model the reference-pose centres of mass (qpos0), the initial state of
   every link (centre of mass, orientation, centre-of-mass velocity in world
   coordinates, angular velocity in the link frame) and the centres of mass
   and orientations every 0.05 s. tests/step/spatial_mujoco.rs integrates the
   same initial states with vigp and compares.

2. `bench`: the cost per step of mujoco.rollout at dt = 0.01 s (Euler, the
   default, and RK4), median of 7 runs of 20 000 steps, single thread, and
   the energy error of 10^5 steps of each (first and last tenth), to set
   against `cargo run --release --example spatial`.

    pip install mujoco numpy scipy
    python3 scripts/spatial_mujoco.py            # fixtures
    python3 scripts/spatial_mujoco.py bench      # timing table

MuJoCo conventions used: a body's frame is the link frame (origin at the
link's `start`); its quat is the link's reference orientation relative to
the parent's; hinge axes are in the child frame (ours are in the parent
frame: a_child = Q^T a_parent); ball quaternions are in the child frame.
The slider-crank's loop is an equality `connect` between two sites, made
as stiff as the time step allows (solref = 2*dt); MuJoCo's equality
constraints are soft, so the loop closes only approximately there.
"""

import json
import os
import sys
import time

import mujoco
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
G = "0 0 -9.81"
DOWN = "0.7071067811865476 0 0.7071067811865476 0"  # link x axis along -z


def inertial(mass, diag, com):
    return (
        f'<inertial pos="{com[0]} {com[1]} {com[2]}" mass="{mass}" '
        f'diaginertia="{diag[0]} {diag[1]} {diag[2]}"/>'
    )


def mjcf(body, extra="", dt=1e-4, integrator="RK4"):
    return f"""
<mujoco>
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{dt}" integrator="{integrator}" gravity="{G}">
    <flag contact="disable" energy="enable"/>
  </option>
  <worldbody>{body}</worldbody>
  {extra}
</mujoco>"""


def spherical_pendulum(**kw):
    body = f"""
    <body name="rod" pos="0 0 0">
      <joint name="ball" type="ball" pos="0 0 0" damping="0"/>
      {inertial(1.0, [0.0002, 0.0834333, 0.0834333], [0.5, 0, 0])}
    </body>"""
    return mjcf(body, **kw)


def furuta(**kw):
    # pendulum frame: x along -z (rotation by +pi/2 about y); the pivot axis
    # (1, 0, 0) in the arm frame is (0, 0, 1) in the pendulum frame
    body = f"""
    <body name="arm" pos="0 0 0">
      <joint name="base" type="hinge" axis="0 0 1" pos="0 0 0" damping="0"/>
      {inertial(0.3, [0.000015, 0.0015700, 0.0015700], [0.125, 0, 0])}
      <body name="pendulum" pos="0.25 0 0" quat="{DOWN}">
        <joint name="pivot" type="hinge" axis="0 0 1" pos="0 0 0" damping="0"/>
        {inertial(0.1, [0.000005, 0.0013358, 0.0013358], [0.2, 0, 0])}
      </body>
    </body>"""
    return mjcf(body, **kw)


def double_pendulum_3d(damping=(0.0, 0.0), **kw):
    # both frames hang down (x along -z); the shoulder axis (0, 1, 0) world is
    # (0, 1, 0) in the upper frame; the elbow axis (0, 0.6, 0.8) is given in
    # the upper frame and the lower frame equals it (relative rotation I)
    body = f"""
    <body name="upper" pos="0 0 0" quat="{DOWN}">
      <joint name="shoulder" type="hinge" axis="0 1 0" pos="0 0 0" damping="{damping[0]}"/>
      {inertial(1.0, [0.0002, 0.0834333, 0.0834333], [0.5, 0, 0])}
      <body name="lower" pos="1 0 0">
        <joint name="elbow" type="hinge" axis="0 0.6 0.8" pos="0 0 0" damping="{damping[1]}"/>
        {inertial(1.0, [0.0002, 0.0834333, 0.0834333], [0.5, 0, 0])}
      </body>
    </body>"""
    return mjcf(body, **kw)


def slider_crank(dt=1e-4, damping=(0.0, 0.0, 0.0), **kw):
    body = f"""
    <body name="crank" pos="0 0 0">
      <joint name="crankshaft" type="hinge" axis="0 1 0" pos="0 0 0" damping="{damping[0]}"/>
      {inertial(0.5, [0.0001, 0.0017167, 0.0017167], [0.1, 0, 0])}
      <body name="rod" pos="0.2 0 0">
        <joint name="crankpin" type="ball" pos="0 0 0" damping="{damping[1]}"/>
        {inertial(0.4, [0.00008, 0.012040, 0.012040], [0.3, 0, 0])}
        <site name="rod_end" pos="0.6 0 0"/>
      </body>
    </body>
    <body name="slider" pos="0.75 0.15 0">
      <joint name="rail" type="slide" axis="1 0 0" pos="0 0 0" damping="{damping[2]}"/>
      {inertial(0.6, [0.0005, 0.0008, 0.0008], [0, 0, 0])}
      <site name="slider_com" pos="0 0 0"/>
    </body>"""
    extra = f"""
  <equality>
    <connect site1="rod_end" site2="slider_com" solref="{2 * dt} 1" solimp="0.9999 0.9999 0.001 0.5 2"/>
  </equality>"""
    return mjcf(body, extra=extra, dt=dt, **kw)


def quat_mul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def closed_slider_crank_state(model):
    """qpos, qvel of the slider-crank with the loop closed: crank angle 0,
    crank rate 6 rad/s, the rod's ball and the slider solved so that the
    rod end meets the slider (least squares), velocities projected onto the
    loop's velocity constraint with the crank rate held."""
    from scipy.optimize import least_squares

    data = mujoco.MjData(model)
    rod_end = model.site("rod_end").id
    slider = model.site("slider_com").id

    def qpos_of(p):
        q = np.zeros(model.nq)
        q[0] = 0.0
        u = np.array([1.0, p[0], p[1], p[2]])
        q[1:5] = u / np.linalg.norm(u)
        q[5] = p[3]
        return q

    def gap(p):
        data.qpos[:] = qpos_of(p)
        mujoco.mj_kinematics(model, data)
        return data.site_xpos[rod_end] - data.site_xpos[slider]

    sol = least_squares(gap, [0.0, 0.0, 0.12, 0.03], xtol=1e-15, ftol=1e-15, gtol=1e-15)
    data.qpos[:] = qpos_of(sol.x)
    mujoco.mj_forward(model, data)
    # velocity constraint J qvel = 0 of the connect (site Jacobians)
    jp1 = np.zeros((3, model.nv))
    jp2 = np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, data, jp1, None, rod_end)
    mujoco.mj_jacSite(model, data, jp2, None, slider)
    jac = jp1 - jp2
    qvel = np.zeros(model.nv)
    qvel[0] = 6.0
    qvel[2] = 0.3  # some spin of the rod about its body y axis
    # minimum-norm change of the other velocities that satisfies J qvel = 0
    free = list(range(1, model.nv))
    a = jac[:, free]
    dq = -np.linalg.lstsq(a, jac @ qvel, rcond=None)[0]
    qvel[free] += dq
    return data.qpos.copy(), qvel


MODELS = {
    "spherical_pendulum": (spherical_pendulum, None),
    "furuta": (furuta, None),
    "double_pendulum_3d": (double_pendulum_3d, None),
    "spatial_slider_crank": (slider_crank, None),
}

# Damped variants (fixtures only): joint damping on the tree joints, in
# N·m·s/rad (hinge, ball: on each angular velocity component) and N·s/m
# (slide). The slider-crank's loop joint is a MuJoCo equality, which has
# no damping.
DAMPED = {
    "double_pendulum_3d_damped": (
        lambda **kw: double_pendulum_3d(damping=(0.3, 0.15), **kw),
        "double_pendulum_3d",
    ),
    "spatial_slider_crank_damped": (
        lambda **kw: slider_crank(damping=(0.02, 0.01, 0.5), **kw),
        "spatial_slider_crank",
    ),
}


def initial_state(name, model):
    if name == "spherical_pendulum":
        u = np.array([0.8, 0.1, 0.55, 0.2])
        return u / np.linalg.norm(u), np.array([0.3, 1.0, 2.0])
    if name == "furuta":
        return np.array([0.0, 2.5]), np.array([3.0, 0.0])
    if name == "double_pendulum_3d":
        return np.array([1.0, -0.8]), np.array([0.5, 1.0])
    return closed_slider_crank_state(model)


def link_state(model, data):
    """Per body (not the world): CoM (world), frame quaternion, CoM
    velocity (world), angular velocity (body frame)."""
    out = []
    res = np.zeros(6)
    for b in range(1, model.nbody):
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, b, res, 0)
        v_com = res[3:].copy()
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_XBODY, b, res, 1)
        w_body = res[:3].copy()
        out.append(
            {
                "name": model.body(b).name,
                "com": data.xipos[b].tolist(),
                "quat": data.xquat[b].tolist(),
                "v_com": v_com.tolist(),
                "w_body": w_body.tolist(),
            }
        )
    return out


def fixtures():
    dt, t_end, every = 1e-4, 2.0, 500
    result = {"mujoco": mujoco.__version__, "dt": dt, "integrator": "RK4", "models": {}}
    cases = [(n, b, n) for n, (b, _) in MODELS.items()]
    cases += [(n, b, base) for n, (b, base) in DAMPED.items()]
    for name, build, base in cases:
        model = mujoco.MjModel.from_xml_string(build(dt=dt))
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        reference = [data.xipos[b].tolist() for b in range(1, model.nbody)]
        qpos, qvel = initial_state(base, model)
        data.qpos[:] = qpos
        data.qvel[:] = qvel
        mujoco.mj_forward(model, data)
        start = link_state(model, data)
        samples = []
        steps = int(round(t_end / dt))
        gap = 0.0
        for k in range(steps + 1):
            if k % every == 0:
                mujoco.mj_kinematics(model, data)
                samples.append(
                    {
                        "t": k * dt,
                        "com": [data.xipos[b].tolist() for b in range(1, model.nbody)],
                        "quat": [data.xquat[b].tolist() for b in range(1, model.nbody)],
                    }
                )
                if model.neq:
                    gap = max(gap, float(np.linalg.norm(data.site_xpos[0] - data.site_xpos[1])))
            if k < steps:
                mujoco.mj_step(model, data)
        result["models"][name] = {
            "reference_com": reference,
            "initial": start,
            "samples": samples,
            "loop_gap": gap,
        }
        print(f"{name}: {len(samples)} samples, max loop gap {gap:.2e} m")
    path = os.path.join(ROOT, "tests", "fixtures", "spatial_mujoco.json")
    with open(path, "w") as f:
        json.dump(result, f, indent=1)
    print("wrote", path)


def bench():
    from mujoco import rollout

    print(f"mujoco {mujoco.__version__}, dt = 0.01 s; load {os.getloadavg()}")
    print(f"{'model':<22} {'integrator':<8} {'ns/step':>9} {'max|dE| J':>11} {'1st tenth':>11} {'last tenth':>11}")
    for name, (build, _) in MODELS.items():
        for integ in ["Euler", "RK4"]:
            kw = {"dt": 0.01, "integrator": integ}
            model = mujoco.MjModel.from_xml_string(build(**kw))
            data = mujoco.MjData(model)
            qpos, qvel = initial_state(name, model)
            data.qpos[:] = qpos
            data.qvel[:] = qvel
            mujoco.mj_forward(model, data)
            spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
            state = np.zeros(mujoco.mj_stateSize(model, spec))
            mujoco.mj_getState(model, data, state, spec)
            n = 20000
            times = []
            for _ in range(7):
                t0 = time.perf_counter()
                rollout.rollout(model, data, state[None, :], nstep=n)
                times.append(time.perf_counter() - t0)
            ns = np.median(times) / n * 1e9
            # energy over 10^5 steps
            steps = 100000
            states, _ = rollout.rollout(model, data, state[None, :], nstep=steps)
            e = np.empty(steps + 1)
            d2 = mujoco.MjData(model)
            for k in range(steps + 1):
                s = state if k == 0 else states[0, k - 1]
                mujoco.mj_setState(model, d2, s, spec)
                mujoco.mj_forward(model, d2)
                e[k] = d2.energy[0] + d2.energy[1]
            de = np.abs(e - e[0])
            tenth = (steps + 1) // 10
            print(
                f"{name:<22} {integ:<8} {ns:>9.0f} {de.max():>11.3e} {de[:tenth].max():>11.3e} {de[-tenth:].max():>11.3e}"
            )


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "bench":
        bench()
    else:
        fixtures()
