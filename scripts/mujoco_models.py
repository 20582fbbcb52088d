"""MJCF models of vigp's `systems::DoublePendulum` and `systems::Fourbar`,
shared by scripts/mujoco_bench.py and scripts/mujoco_derivatives.py.

vigp's plane (x right, y up, gravity -y) is MuJoCo's x-z plane (gravity -z).
Every hinge turns about -y, so that a positive angle is counter-clockwise
seen with x to the right and z up, as in vigp: qpos then equals vigp's
minimal coordinates (relative joint angles, 0 = hanging straight down).

Every link: mass 1 kg, length 1 m, centre of mass at its middle, inertia
m*l^2/12 about the hinge axis through the centre of mass, given by an
explicit <inertial> so that MuJoCo does not derive it from geoms (there
are none: contacts are off). No damping, no armature, dt = 0.01 s.

The fourbar is a rhombus of four links hanging from one pivot P: link1
P->A, link2 A->B (child of link1), link3 P->C, link4 C->B (child of link3),
closed at B by a `connect` equality between a site at link2's end and a
site at link4's end.
"""

import numpy as np

MASS = 1.0
LENGTH = 1.0
INERTIA = MASS * LENGTH**2 / 12.0
GRAVITY = 9.81
DT = 0.01
INTEGRATORS = ("Euler", "implicitfast", "RK4")


def _link(name, pos, children="", actuated=False, site_at_end=None):
    site = (
        f'<site name="{site_at_end}" pos="0 0 {-LENGTH!r}"/>' if site_at_end else ""
    )
    i = repr(INERTIA)
    return f"""
      <body name="{name}" pos="{pos}">
        <joint name="{name}_hinge" type="hinge" axis="0 -1 0"/>
        <inertial pos="0 0 {-LENGTH / 2!r}" mass="{MASS!r}" diaginertia="{i} {i} {i}"/>
        {site}{children}
      </body>"""


def _model(name, bodies, integrator, extra=""):
    return f"""<mujoco model="{name}">
  <option timestep="{DT!r}" gravity="0 0 {-GRAVITY!r}" integrator="{integrator}">
    <flag contact="disable"/>
  </option>
  <worldbody>{bodies}
  </worldbody>{extra}
</mujoco>
"""


def double_pendulum(integrator="Euler", actuated=False):
    """The double pendulum: qpos = (shoulder, elbow). With `actuated`, a
    motor (gear 1, unlimited) on each joint, so that transition
    derivatives have a B matrix."""
    lower = _link("lower", f"0 0 {-LENGTH!r}")
    bodies = _link("upper", "0 0 0", children=lower)
    extra = ""
    if actuated:
        extra = """
  <actuator>
    <motor joint="upper_hinge" gear="1"/>
    <motor joint="lower_hinge" gear="1"/>
  </actuator>"""
    return _model("double_pendulum", bodies, integrator, extra)


def fourbar(integrator="Euler"):
    """The fourbar: qpos = (top1, middle1, top2, middle2) as vigp's minimal
    coordinates; the loop joint `bottom` is the connect equality."""
    link2 = _link("link2", f"0 0 {-LENGTH!r}", site_at_end="B2")
    link4 = _link("link4", f"0 0 {-LENGTH!r}", site_at_end="B4")
    bodies = _link("link1", "0 0 0", children=link2, site_at_end="A") + _link(
        "link3", "0 0 0", children=link4, site_at_end="C"
    )
    extra = """
  <equality>
    <connect site1="B2" site2="B4"/>
  </equality>"""
    return _model("fourbar", bodies, integrator, extra)


# Closed forms of the same mechanics, for the scripts' equivalence checks
# (relative coordinates, thin rods of mass m and length l).
def dp_mass_matrix(q2):
    """M(q) of the double pendulum (depends on q2 only)."""
    a = MASS * (LENGTH / 2) ** 2 + INERTIA + MASS * LENGTH**2
    b = MASS * (LENGTH / 2) ** 2 + INERTIA
    k = MASS * LENGTH * LENGTH / 2
    c = np.cos(q2)
    return np.array([[a + b + 2 * k * c, b + k * c], [b + k * c, b]])


def dp_gravity_torque(q):
    """grad V(q) of the double pendulum (V = potential energy)."""
    s1, s12 = np.sin(q[0]), np.sin(q[0] + q[1])
    e1 = GRAVITY * (MASS * LENGTH / 2 + MASS * LENGTH)
    e2 = GRAVITY * MASS * LENGTH / 2
    return np.array([e1 * s1 + e2 * s12, e2 * s12])


def fourbar_points(q):
    """Positions in vigp's plane of A, C, B (link2's end) and B' (link4's
    end) for minimal coordinates q (relative angles)."""
    t1, t3 = q[0], q[2]
    t2, t4 = q[0] + q[1], q[2] + q[3]
    u = lambda t: LENGTH * np.array([np.sin(t), -np.cos(t)])
    a, c = u(t1), u(t3)
    return a, c, a + u(t2), c + u(t4)
