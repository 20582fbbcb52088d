#!/usr/bin/env python3
"""The arm of tests/fixtures/robots/wrist.urdf written in the spatial
`mechanism!` DSL without vigp's URDF reader: prints the links and joints
that tests/dsl/urdf.rs declares by hand (`WristByHand`).

Every link keeps its own frame (the fixed joint stays a `fixed` joint, the
hand is not merged): `frame` rows are the link's axes in world coordinates
at q = 0 (products of the joint origins' rpy rotations,
R = Rz(yaw) Ry(pitch) Rx(roll)); `inertia` is the URDF tensor turned into
the link frame by its inertial origin's rpy, R I Rᵀ; `com` the inertial
origin; anchors the joint origins in the parent link frame; axes the URDF
axes turned into the parent frame by the joint origin's rotation.

    python3 scripts/wrist_by_hand.py
"""
import numpy as np


def rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def rpy(r, p, y):
    return rz(y) @ ry(p) @ rx(r)


def tensor(ixx, ixy, ixz, iyy, iyz, izz):
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


def f(x):
    return repr(float(x))


def vec(v):
    return "[" + ", ".join(f(x) for x in v) + "]"


def mat(m):
    return "[" + ", ".join(vec(r) for r in m) + "]"


A = 0.6435011087932844  # atan2(3, 4): cos 0.8, sin 0.6
B = 0.9272952180016122  # atan2(4, 3): cos 0.6, sin 0.8

# (name, mass, com, inertial rpy, tensor)
links = [
    ("upper", 1.5, [0.1, 0.02, 0.05], (0, 0, A), tensor(0.03, 0.002, -0.001, 0.025, 0.003, 0.012)),
    ("fore", 0.8, [0.15, 0.01, -0.02], (0.3, -0.2, 0.1), tensor(0.002, -0.0003, 0.0002, 0.011, 0.0001, 0.0105)),
    ("hand", 0.3, [0.02, 0.01, 0.0], (0, 0, 0), tensor(0.0004, 0.00005, 0, 0.0003, 0, 0.0003)),
    ("finger", 0.1, [0.01, 0.0, 0.005], (0, 0.4, 0), tensor(0.00002, 0, 0.000003, 0.00004, 0, 0.00003)),
]
# (name, kind, parent, child, xyz, rpy, axis, damping)
joints = [
    ("shoulder", "revolute", None, "upper", [0, 0, 0.2], (A, 0, 0), [0, 0, 1], 0.05),
    ("elbow", "revolute", "upper", "fore", [0.3, 0, 0], (0, B, 0), [0, 1, 0], 0.02),
    ("wrist_weld", "fixed", "fore", "hand", [0.25, 0, 0], (0, 0, A), None, None),
    ("slide", "prismatic", "hand", "finger", [0.05, 0, 0.01], (0.2, 0, 0), [1, 1, 0], None),
]

world = {None: np.eye(3)}
for name, kind, parent, child, xyz, r, axis, d in joints:
    world[child] = world[parent] @ rpy(*r)

print("links {")
for name, m, com, r, t in links:
    ro = rpy(*r)
    print(f"    {name}: {{ mass: {f(m)}, com: {vec(com)},")
    print(f"        inertia: {mat(ro @ t @ ro.T)},")
    print(f"        frame: {mat(world[name].T)} }},")
print("}\njoints {")
for name, kind, parent, child, xyz, r, axis, d in joints:
    p = f"world @ {vec(xyz)}" if parent is None else f"{parent} @ {vec(xyz)}"
    fields = []
    if axis is not None:
        a = np.array(axis, float)
        fields.append(f"axis: {vec(rpy(*r) @ (a / np.linalg.norm(a)))}")
    if d is not None:
        fields.append(f"damping: {f(d)}")
    body = " { " + ", ".join(fields) + " }" if fields else ""
    print(f"    {name}: {kind}({p}, {child}.start){body},")
print("}")
