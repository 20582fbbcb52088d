#!/usr/bin/env python3
"""Fixtures of vigp-runtime/tests/robot.rs: two robots of example-robot-data (PyPI) with
visuals and collisions stripped, and Pinocchio's dynamics of them.

Writes tests/fixtures/robots/{panda,ur5,solo12,g1}.urdf and pin.json: the
Panda arm, the UR5, the Solo-12 quadruped and the Unitree G1 humanoid (29
joints), both legged robots on a fixed base (the URDF's root link). The
Panda's finger joints are made fixed (a 7-DoF arm carrying its hand and
fingers): the second finger is a mimic joint, which vigp refuses.

pin.json holds, per robot and per configuration, Pinocchio's
  mass   M(q) (crba, symmetrised),
  nle    rnea(q, v, 0) = C(q, v)v + g(q),
  gravity computeGeneralizedGravity(q),
  kinetic / potential energies,
with the joint names in Pinocchio's coordinate order.

    pip install pin example-robot-data
    python3 scripts/robot_pin_fixtures.py
"""
import json
import os
import re
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "tests", "fixtures", "robots")


def erd_dir():
    """The robots folder of the installed example-robot-data distribution
    (a data-only wheel: share/example-robot-data/robots in its prefix)."""
    from importlib.metadata import distribution
    dist = distribution("example-robot-data")
    for f in dist.files:
        if str(f).endswith("panda_description/urdf/panda.urdf"):
            path = str(dist.locate_file(f))
            return os.path.normpath(os.path.join(os.path.dirname(path), "..", ".."))
    raise SystemExit("example-robot-data robots not found (pip install example-robot-data)")


def strip(src, dst, fixed=()):
    tree = ET.parse(src)
    robot = tree.getroot()
    for link in robot.findall("link"):
        for tag in ("visual", "collision"):
            for e in link.findall(tag):
                link.remove(e)
    for tag in ("material", "gazebo", "transmission"):
        for e in robot.findall(tag):
            robot.remove(e)
    for joint in robot.findall("joint"):
        if joint.get("name") in fixed:
            joint.set("type", "fixed")
            for tag in ("mimic", "limit", "axis", "dynamics", "safety_controller"):
                for e in joint.findall(tag):
                    joint.remove(e)
    ET.indent(tree, space="  ")
    tree.write(dst, encoding="unicode", xml_declaration=True)
    text = open(dst).read()
    text = re.sub(r"\n\s*\n", "\n", text)
    open(dst, "w").write(text + "\n")


def dynamics(path, seed):
    model = pin.buildModelFromUrdf(path)
    data = model.createData()
    rng = np.random.default_rng(seed)
    names = list(model.names)[1:]
    cases = []
    for k in range(4):
        if k == 0:
            q = np.zeros(model.nq)
            v = np.zeros(model.nv)
        else:
            q = rng.uniform(-1.5, 1.5, model.nq)
            v = rng.uniform(-2.0, 2.0, model.nv)
        m = pin.crba(model, data, q).copy()
        m = np.triu(m) + np.triu(m, 1).T
        nle = pin.rnea(model, data, q, v, np.zeros(model.nv)).copy()
        g = pin.computeGeneralizedGravity(model, data, q).copy()
        ke = pin.computeKineticEnergy(model, data, q, v)
        pe = pin.computePotentialEnergy(model, data, q)
        cases.append({
            "q": q.tolist(), "v": v.tolist(), "mass": m.tolist(),
            "nle": nle.tolist(), "gravity": g.tolist(),
            "kinetic": float(ke), "potential": float(pe),
        })
    return {"joints": names, "cases": cases}


def main():
    os.makedirs(OUT, exist_ok=True)
    robots = erd_dir()
    panda = os.path.join(OUT, "panda.urdf")
    ur5 = os.path.join(OUT, "ur5.urdf")
    strip(os.path.join(robots, "panda_description", "urdf", "panda.urdf"), panda,
          fixed=("panda_finger_joint1", "panda_finger_joint2"))
    strip(os.path.join(robots, "ur_description", "urdf", "ur5_robot.urdf"), ur5)
    solo = os.path.join(OUT, "solo12.urdf")
    g1 = os.path.join(OUT, "g1.urdf")
    strip(os.path.join(robots, "solo_description", "robots", "solo12.urdf"), solo)
    strip(os.path.join(robots, "g1_description", "urdf", "g1_29dof_rev_1_0.urdf"), g1)
    out = {
        "pinocchio": pin.__version__,
        "panda": dynamics(panda, 1),
        "ur5": dynamics(ur5, 2),
        "solo12": dynamics(solo, 3),
        "g1": dynamics(g1, 4),
    }
    with open(os.path.join(OUT, "pin.json"), "w") as f:
        json.dump(out, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()
