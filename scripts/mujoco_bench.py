#!/usr/bin/env python3
"""MuJoCo's cost per step and its energy and constraint behaviour on the
same double pendulum and fourbar as vigp (`systems::DoublePendulum`,
`systems::Fourbar`; models in scripts/mujoco_models.py), dt = 0.01 s, for
the Euler (semi-implicit), implicitfast and RK4 integrators.

    pip install mujoco            # the wheel ships libmujoco and its headers
    python3 scripts/mujoco_bench.py [--steps 10000] [--reps 21] [--no-c] [--callgrind]

Time steps run in C, never in a Python loop:
* `C loop`: scripts/mujoco_step.c, compiled here with `cc -O2` against the
  wheel's libmujoco, calls mj_step NSTEP times per repetition;
* `rollout`: mujoco.rollout (nthread=0, the calling thread) over NSTEP steps,
  which also copies the state out after every step.
Each reports the median (and minimum) over --reps repetitions of the time
per step. Record the load average printed in the header with the numbers.
With --callgrind (needs valgrind) the C loop also runs under callgrind at
1000 steps and at 0: the difference of the instruction totals / 1000 is the
instruction count per mj_step, which does not depend on the machine's load.

From the rollout's trajectory (states after each step; analysis in Python,
not timed): the energy drift max_k |E_k - E_0| and the final E_N - E_0 (MuJoCo's
own mj_energyPos + mj_energyVel), and for the fourbar the loop-closure
violation |g| = |B2 - B4| (distance between link2's and link4's ends, the
`connect` equality) and whether the rhombus stays on its parallelogram branch
(B = A + C): the largest |B - (A + C)| and the first time it exceeds 0.1 m.

Before timing, the models are checked against closed forms: M(q) and the
gravity torque of the double pendulum and of both chains of the fourbar at
random q must match to 1e-12.

Initial states: the double pendulum at q = (1.0, -0.5), qdot = (0.5, 1.0)
(the state of vigp's step benchmarks); the fourbar at q = (0.9, -1.3, -0.4, 1.3)
(on the parallelogram branch: g(q) = 0 exactly) with qdot the Euclidean
projection of (0.5, 0, 0, 0) onto the constraint's tangent space.
"""
import argparse
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import mujoco
import mujoco.rollout
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mujoco_models as mm  # noqa: E402

SPEC = mujoco.mjtState.mjSTATE_FULLPHYSICS
HERE = os.path.dirname(os.path.abspath(__file__))

DP_Q = np.array([1.0, -0.5])
DP_QDOT = np.array([0.5, 1.0])
FB_Q = np.array([0.9, -1.3, -0.4, 1.3])


def check_models():
    """Largest deviation of MuJoCo's M(q) and gravity torque from the
    closed forms, over random configurations of both models."""
    rng = np.random.default_rng(1)
    worst = 0.0
    m = mujoco.MjModel.from_xml_string(mm.double_pendulum())
    d = mujoco.MjData(m)
    f = mujoco.MjModel.from_xml_string(mm.fourbar())
    fd = mujoco.MjData(f)
    for _ in range(20):
        q = rng.uniform(-np.pi, np.pi, 4)
        d.qpos[:] = q[:2]
        d.qvel[:] = 0
        mujoco.mj_forward(m, d)
        full = np.zeros((2, 2))
        mujoco.mj_fullM(m, d, full)
        worst = max(worst, np.abs(full - mm.dp_mass_matrix(q[1])).max())
        worst = max(worst, np.abs(d.qfrc_bias - mm.dp_gravity_torque(q[:2])).max())
        # fourbar: two double-pendulum chains (constraint forces are not in
        # M or qfrc_bias)
        fd.qpos[:] = q
        fd.qvel[:] = 0
        mujoco.mj_forward(f, fd)
        full = np.zeros((4, 4))
        mujoco.mj_fullM(f, fd, full)
        ref = np.zeros((4, 4))
        ref[:2, :2] = mm.dp_mass_matrix(q[1])
        ref[2:, 2:] = mm.dp_mass_matrix(q[3])
        worst = max(worst, np.abs(full - ref).max())
        bias = np.concatenate([mm.dp_gravity_torque(q[:2]), mm.dp_gravity_torque(q[2:])])
        worst = max(worst, np.abs(fd.qfrc_bias - bias).max())
    return worst


def fourbar_velocity(m, q, qdot_guess):
    """Euclidean projection of qdot_guess onto {v : J v = 0} at q, with J
    the connect equality's Jacobian."""
    d = mujoco.MjData(m)
    d.qpos[:] = q
    mujoco.mj_forward(m, d)
    jac = d.efc_J.reshape(d.nefc, m.nv) if d.efc_J.size == d.nefc * m.nv else None
    if jac is None:  # sparse Jacobian: densify
        jac = np.zeros((d.nefc, m.nv))
        mujoco.mju_sparse2dense(
            jac, d.efc_J, d.efc_J_rownnz, d.efc_J_rowadr, d.efc_J_colind
        )
    return qdot_guess - np.linalg.pinv(jac) @ (jac @ qdot_guess)


def initial_state(m, q, qdot):
    d = mujoco.MjData(m)
    d.qpos[:] = q
    d.qvel[:] = qdot
    s = np.zeros(mujoco.mj_stateSize(m, SPEC))
    mujoco.mj_getState(m, d, s, SPEC)
    return s


def time_rollout(m, q, qdot, nstep, reps):
    """Median and minimum ns per step of mujoco.rollout, and the
    trajectory (nstep x nstate)."""
    s0 = initial_state(m, q, qdot)[None, :]
    d = mujoco.MjData(m)
    out = np.zeros((1, nstep, s0.shape[1]))
    times = []
    with mujoco.rollout.Rollout(nthread=0) as r:
        r.rollout(m, d, s0, nstep=nstep, state=out)  # warm-up, checked call
        for _ in range(reps):
            t0 = time.perf_counter_ns()
            r.rollout([m], [d], s0, None, skip_checks=True, nstep=nstep, state=out)
            times.append((time.perf_counter_ns() - t0) / nstep)
    return statistics.median(times), min(times), out[0]


def build_c():
    """Compile scripts/mujoco_step.c against the wheel's libmujoco; the
    path of the binary, or None (with a note) if that fails."""
    cc = shutil.which(os.environ.get("CC", "cc"))
    if cc is None:
        print("no C compiler (cc): C-loop timings skipped")
        return None
    pkg = os.path.dirname(mujoco.__file__)
    libs = sorted(f for f in os.listdir(pkg) if f.startswith("libmujoco.so"))
    if not libs:
        print(f"no libmujoco.so in {pkg}: C-loop timings skipped")
        return None
    exe = os.path.join(tempfile.mkdtemp(prefix="vigp_mujoco_"), "mujoco_step")
    cmd = [cc, "-O2", "-o", exe, os.path.join(HERE, "mujoco_step.c"),
           "-I" + os.path.join(pkg, "include"), os.path.join(pkg, libs[0]),
           "-Wl,-rpath," + pkg]
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        print("building the C loop failed, C-loop timings skipped:\n" + res.stderr)
        return None
    return exe


def time_c(exe, xml, q, qdot, nstep, reps):
    path = os.path.join(os.path.dirname(exe), "model.xml")
    with open(path, "w") as fh:
        fh.write(xml)
    args = [exe, path, str(nstep), str(reps)] + [repr(float(x)) for x in (*q, *qdot)]
    out = subprocess.run(args, capture_output=True, text=True, check=True).stdout
    fields = dict(kv.split("=", 1) for kv in out.split())
    qend = np.array([float(x) for x in fields["qpos_end"].split(",")])
    return float(fields["median_ns"]), float(fields["min_ns"]), qend, int(fields["warnings"])


def callgrind_per_step(exe, xml, q, qdot, nstep=1000):
    """Instructions per mj_step: callgrind totals at nstep and 0 steps."""
    path = os.path.join(os.path.dirname(exe), "model.xml")
    with open(path, "w") as fh:
        fh.write(xml)
    totals = []
    for n in (nstep, 0):
        out = os.path.join(os.path.dirname(exe), f"callgrind.{n}")
        args = ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", exe,
                path, str(n), "1"] + [repr(float(x)) for x in (*q, *qdot)]
        res = subprocess.run(args, capture_output=True, text=True, check=True)
        line = [ln for ln in res.stderr.splitlines() if "Collected" in ln][0]
        totals.append(int(line.split(":")[-1].strip().replace(",", "")))
    return (totals[0] - totals[1]) / nstep


def analyse(m, traj, q, qdot, fourbar):
    """Energy drift, and for the fourbar |g| and the branch, along traj."""
    m = mujoco.MjModel.from_xml_string(m)  # a copy with energy computed
    m.opt.enableflags |= mujoco.mjtEnableBit.mjENBL_ENERGY
    d = mujoco.MjData(m)
    d.qpos[:] = q
    d.qvel[:] = qdot
    mujoco.mj_forward(m, d)
    e0 = d.energy.sum()
    drift, g_max, branch_max, left_at = 0.0, 0.0, 0.0, None
    nonfinite = False
    for k, s in enumerate(traj):
        mujoco.mj_setState(m, d, s, SPEC)
        if not np.all(np.isfinite(d.qpos)):
            nonfinite = True
            break
        mujoco.mj_forward(m, d)
        drift = max(drift, abs(d.energy.sum() - e0))
        if fourbar:
            a, c, b2, b4 = mm.fourbar_points(d.qpos)
            g_max = max(g_max, np.linalg.norm(b2 - b4))
            off = np.linalg.norm(b2 - (a + c))
            branch_max = max(branch_max, off)
            if left_at is None and off > 0.1:
                left_at = (k + 1) * mm.DT
    return {
        "e0": e0,
        "drift": drift,
        "final": d.energy.sum() - e0,
        "g": g_max,
        "branch": branch_max,
        "left_at": left_at,
        "nonfinite": nonfinite,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=10_000, help="steps per run (default 10000)")
    ap.add_argument("--reps", type=int, default=21, help="timed repetitions (default 21)")
    ap.add_argument("--no-c", action="store_true", help="skip the C loop")
    ap.add_argument("--callgrind", action="store_true",
                    help="also count instructions per mj_step with valgrind")
    args = ap.parse_args()

    load = os.getloadavg()
    print(f"MuJoCo {mujoco.__version__}, numpy {np.__version__}, Python "
          f"{platform.python_version()}, {os.cpu_count()} CPUs, load average "
          f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    print(f"dt = {mm.DT} s, {args.steps} steps per run, median (min) of {args.reps} runs")
    dev = check_models()
    print(f"model check: max deviation of M(q) and gravity torque from the closed forms = {dev:.1e}")
    if not dev < 1e-12:
        sys.exit("the MJCF models do not match the closed forms")

    exe = None if args.no_c else build_c()
    if args.callgrind and (exe is None or shutil.which("valgrind") is None):
        sys.exit("--callgrind needs the C loop and valgrind")
    fb_model = mujoco.MjModel.from_xml_string(mm.fourbar())
    fb_qdot = fourbar_velocity(fb_model, FB_Q, np.array([0.5, 0.0, 0.0, 0.0]))
    print(f"fourbar initial qdot = {np.array2string(fb_qdot, precision=6)}")

    rows = []
    for name, make, q, qdot in [
        ("double_pendulum", mm.double_pendulum, DP_Q, DP_QDOT),
        ("fourbar", mm.fourbar, FB_Q, fb_qdot),
    ]:
        for integ in mm.INTEGRATORS:
            xml = make(integ)
            m = mujoco.MjModel.from_xml_string(xml)
            r_med, r_min, traj = time_rollout(m, q, qdot, args.steps, args.reps)
            c = time_c(exe, xml, q, qdot, args.steps, args.reps) if exe else None
            a = analyse(xml, traj, q, qdot, name == "fourbar")
            if c is not None:
                # the C loop and the rollout run the same steps
                a["c_vs_rollout"] = np.abs(c[2] - traj[-1][1 : 1 + m.nq]).max()
                if args.callgrind:
                    a["instructions"] = callgrind_per_step(exe, xml, q, qdot)
            rows.append((name, integ, c, (r_med, r_min), a))

    t = args.steps * mm.DT
    print(f"\n| system | integrator | C loop ns/step | rollout ns/step | "
          f"max abs(E-E0) over {t:g} s (J) | E_end-E0 (J) | max abs(g) (m) | parallelogram branch |")
    print("|---|---|---|---|---|---|---|---|")
    for name, integ, c, r, a in rows:
        cs = f"{c[0]:.0f} ({c[1]:.0f})" if c else "-"
        if name == "fourbar":
            g = f"{a['g']:.1e}"
            br = (f"left at t = {a['left_at']:.2f} s (max off {a['branch']:.2f} m)"
                  if a["left_at"] is not None else f"kept (max off {a['branch']:.1e} m)")
        else:
            g, br = "-", "-"
        drift = "non-finite state" if a["nonfinite"] else f"{a['drift']:.2e}"
        print(f"| {name} | {integ} | {cs} | {r[0]:.0f} ({r[1]:.0f}) | {drift} | "
              f"{a['final']:+.2e} | {g} | {br} |")
    if exe:
        diff = max(a["c_vs_rollout"] for *_, a in rows)
        warns = sum(c[3] for _, _, c, _, _ in rows)
        print(f"\nC loop vs rollout: largest difference of the final qpos {diff:.1e} "
              f"(0 = the same steps); MuJoCo warnings in the C loop: {warns}")
    if args.callgrind:
        print("\ninstructions per mj_step (callgrind, C loop): " + ", ".join(
            f"{name}/{integ} {a['instructions']:.0f}" for name, integ, _, _, a in rows))
    print(f"\nE0: double pendulum {rows[0][4]['e0']:.6f} J, fourbar {rows[3][4]['e0']:.6f} J "
          "(MuJoCo's potential zero: body origins at z = 0)")


if __name__ == "__main__":
    main()
