"""Logs of three actuated mechanisms under zero-order-held inputs, written by
two truths that are not vigp: SciPy's RK45 on MuJoCo's continuous dynamics
(tight tolerances: the continuous motion), and MuJoCo's own `implicitfast`
integrator at 1 ms (what a user's simulated robot log looks like). They are
the fixtures of tests/learn/held_inputs.rs (`peer_truths`).

    pip install mujoco scipy numpy
    python3 scripts/held_inputs_truths.py    # writes tests/fixtures/held_inputs/

The mechanisms are tests/learn/held_inputs.rs's `HeldPendulum`, `HeldAcrobot` and
`HeldCartpole`, in MuJoCo's x-z plane as in scripts/mujoco_models.py: every
hinge turns about -y so that qpos equals vigp's minimal coordinates
(relative angles, 0 hanging straight down); thin rods with inertia m*l^2/12
about the centre of mass, given explicitly; joint damping as vigp's; a motor
of gear 1 on each actuated joint, so that ctrl is vigp's input.

Each file has the columns `run,length,u0..,q0..`. Runs 0-5 are training logs
of 72 samples whose input segments have random lengths 1..20; runs 6-25 are
test logs of 42 samples whose segments all have length `length` = 1..20.
Row k holds the sample x_k at t_k = k*dt and the input u_k held over
[t_k, t_{k+1}] (vigp's convention); every log starts at rest with u_0 = 0
from a random q_0. Written with repr(), which round-trips every float.
"""

import pathlib

import mujoco
import numpy as np
from scipy.integrate import solve_ivp

DT = 0.01
G = 9.81
TRAIN_RUNS, TRAIN_SAMPLES = 6, 72
STARTS, HORIZON = 20, 20
TEST_SAMPLES = STARTS + HORIZON + 2
MUJOCO_SUBSTEPS = 10
OUT = pathlib.Path(__file__).resolve().parent.parent / "tests/fixtures/held_inputs"


def rod(name, pos, mass, length, damping, children=""):
    i = mass * length**2 / 12.0
    return f"""
      <body name="{name}" pos="{pos}">
        <joint name="{name}" type="hinge" axis="0 -1 0" damping="{damping!r}"/>
        <inertial pos="0 0 {-length / 2!r}" mass="{mass!r}" diaginertia="{i!r} {i!r} {i!r}"/>
        {children}
      </body>"""


def model(name, bodies, actuated):
    motors = "".join(f'<motor joint="{j}" gear="1"/>' for j in actuated)
    return f"""<mujoco model="{name}">
  <option timestep="{DT / MUJOCO_SUBSTEPS!r}" gravity="0 0 {-G!r}" integrator="implicitfast">
    <flag contact="disable"/>
  </option>
  <worldbody>{bodies}
  </worldbody>
  <actuator>{motors}</actuator>
</mujoco>"""


def pendulum():
    return model("pendulum", rod("pivot", "0 0 0", 1.0, 1.0, 0.5), ["pivot"])


def acrobot():
    lower = rod("elbow", "0 0 -1.0", 1.0, 1.0, 0.1)
    return model("acrobot", rod("shoulder", "0 0 0", 1.0, 1.0, 0.1, lower), ["elbow"])


def cartpole():
    ic = 1.0 * 0.5**2 / 12.0
    pole = rod("hinge", "0 0 0", 0.3, 0.8, 0.05)
    cart = f"""
      <body name="cart" pos="0 0 0">
        <joint name="rail" type="slide" axis="1 0 0" damping="0.3"/>
        <inertial pos="0 0 0" mass="1.0" diaginertia="{ic!r} {ic!r} {ic!r}"/>
        {pole}
      </body>"""
    return model("cartpole", cart, ["rail"])


# name, model, input scale, start range, seed (as tests/learn/held_inputs.rs)
SYSTEMS = [
    ("pendulum", pendulum, 4.0, [1.5], 1),
    ("acrobot", acrobot, 4.0, [0.8, 0.8], 3),
    ("cartpole", cartpole, 5.0, [0.3, 0.8], 5),
]


def held_inputs(rng, samples, nu, scale, length):
    out = [np.zeros(nu)]
    while len(out) < samples:
        u = rng.uniform(-scale, scale, nu)
        out.extend([u] * length(rng))
    return out[:samples]


def rk45(m, d, q0, inputs):
    """Positions at t_k under the held inputs: RK45 on MuJoCo's forward
    dynamics, restarted at each sample (the input jumps there)."""
    nq = m.nq

    def f(_t, y, u):
        d.qpos[:], d.qvel[:], d.ctrl[:] = y[:nq], y[nq:], u
        mujoco.mj_forward(m, d)
        return np.concatenate([y[nq:], d.qacc])

    y = np.concatenate([q0, np.zeros(nq)])
    out = [q0.copy()]
    for u in inputs[:-1]:
        sol = solve_ivp(f, (0.0, DT), y, method="RK45", rtol=1e-11, atol=1e-13, args=(u,))
        assert sol.success, sol.message
        y = sol.y[:, -1]
        out.append(y[:nq].copy())
    return out


def mujoco_steps(m, d, q0, inputs):
    """Positions at t_k from MuJoCo's implicitfast integrator at DT/10."""
    mujoco.mj_resetData(m, d)
    d.qpos[:] = q0
    out = [q0.copy()]
    for u in inputs[:-1]:
        d.ctrl[:] = u
        for _ in range(MUJOCO_SUBSTEPS):
            mujoco.mj_step(m, d)
        out.append(d.qpos.copy())
    return out


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    for name, build, scale, q_range, seed in SYSTEMS:
        m = mujoco.MjModel.from_xml_string(build())
        d = mujoco.MjData(m)
        rng = np.random.default_rng(seed)
        logs = []
        for _ in range(TRAIN_RUNS):
            inputs = held_inputs(rng, TRAIN_SAMPLES, m.nu, scale, lambda r: int(r.integers(1, 21)))
            logs.append((0, inputs, rng.uniform(-1, 1, m.nq) * q_range))
        for length in range(1, 21):
            inputs = held_inputs(rng, TEST_SAMPLES, m.nu, scale, lambda r, n=length: n)
            logs.append((length, inputs, rng.uniform(-1, 1, m.nq) * q_range))
        for truth, run in [("rk45", rk45), ("mujoco", mujoco_steps)]:
            path = OUT / f"{name}_{truth}.csv"
            with open(path, "w") as fh:
                us = ",".join(f"u{i}" for i in range(m.nu))
                qs = ",".join(f"q{i}" for i in range(m.nq))
                fh.write(f"run,length,{us},{qs}\n")
                for r, (length, inputs, q0) in enumerate(logs):
                    for u, q in zip(inputs, run(m, d, q0, inputs)):
                        row = [repr(float(x)) for x in (*u, *q)]
                        fh.write(f"{r},{length}," + ",".join(row) + "\n")
            print(f"{path}: {len(logs)} runs")


if __name__ == "__main__":
    main()
