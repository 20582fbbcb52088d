//! The kinematic tree as data: one body per joint coordinate, parents
//! before children, and the [`Tree`] trait through which the engine reads
//! the per-body constants (run-time data and compile-time constants alike).

use super::spatial::{M3, V3, dot};

/// What a tree joint allows (fixed joints are merged into their parent
/// before a tree is built; floating and planar joints are not trees of
/// single coordinates).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum JointKind {
    /// Rotation about the axis through the joint frame's origin;
    /// coordinate: the angle (rad).
    Revolute,
    /// Translation along the axis; coordinate: the slide (m).
    Prismatic,
}

/// Joint limits, kept in the model (the engine does not enforce them).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    /// Lowest coordinate (rad or m; −∞: none).
    pub lower: f64,
    /// Highest coordinate (rad or m; +∞: none).
    pub upper: f64,
    /// Largest effort (N·m or N; +∞: none).
    pub effort: f64,
    /// Largest rate (rad/s or m/s; +∞: none).
    pub velocity: f64,
}

impl Limits {
    /// No limits.
    pub const NONE: Limits = Limits {
        lower: f64::NEG_INFINITY,
        upper: f64::INFINITY,
        effort: f64::INFINITY,
        velocity: f64::INFINITY,
    };
}

/// One body of a tree with the joint that connects it to its parent.
///
/// Frames (URDF's): the joint frame is placed in the parent body's frame by
/// `rotation` and `translation` (the joint origin); at coordinate 0 the
/// body frame is the joint frame. A revolute joint at angle θ turns the
/// body frame by Rot(axis, θ) about the joint frame's origin; a prismatic
/// joint at s moves it by s·axis. `axis` is a unit vector in the joint
/// (= body) frame. The centre of mass and the inertia are in the body frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Body {
    /// The parent body's index (smaller than this body's), `None` for the
    /// fixed base (the world).
    pub parent: Option<usize>,
    /// The joint type.
    pub joint: JointKind,
    /// Unit joint axis in the joint frame.
    pub axis: V3,
    /// Orientation of the joint frame in the parent frame.
    pub rotation: M3,
    /// Origin of the joint frame in the parent frame (m).
    pub translation: V3,
    /// Mass (kg, ≥ 0).
    pub mass: f64,
    /// Centre of mass in the body frame (m).
    pub com: V3,
    /// Rotational inertia about the centre of mass in body axes (kg·m²,
    /// symmetric positive semi-definite).
    pub inertia: M3,
    /// Viscous damping on the joint rate (N·m·s/rad or N·s/m, ≥ 0).
    pub damping: f64,
    /// Spring stiffness on the joint coordinate (≥ 0): potential ½k(q − rest)².
    pub stiffness: f64,
    /// Spring rest coordinate.
    pub rest: f64,
    /// Limits (kept for the user; not enforced).
    pub limits: Limits,
}

/// The per-body constants of a tree: what the engine reads. Run-time data
/// ([`TreeRef`], or a `Vec`-backed model in the std runtime) and generated
/// constants implement it alike, so that one algorithm serves both.
pub trait Tree {
    /// Number of bodies = number of coordinates.
    fn len(&self) -> usize;
    /// Whether the tree has no body.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Body `i` (0 ≤ i < [`Tree::len`]); parents come before children.
    fn body(&self, i: usize) -> &Body;
    /// Gravitational acceleration in world coordinates (m/s²).
    fn gravity(&self) -> V3;
}

impl<T: Tree + ?Sized> Tree for &T {
    #[inline(always)]
    fn len(&self) -> usize {
        (**self).len()
    }
    #[inline(always)]
    fn body(&self, i: usize) -> &Body {
        (**self).body(i)
    }
    #[inline(always)]
    fn gravity(&self) -> V3 {
        (**self).gravity()
    }
}

/// A tree as a list of bodies, parents first, and gravity: borrowed
/// ([`TreeRef`]), held by value ([`TreeArray`], what `mechanism!`'s
/// `Name::tree()` builds from the run-time parameters), or in a `Vec`
/// (the std runtime's `vigp::robot::RobotTree`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bodies<B> {
    /// The bodies, parents first.
    pub bodies: B,
    /// Gravity in world coordinates (m/s²).
    pub gravity: V3,
}

impl<B: AsRef<[Body]>> Tree for Bodies<B> {
    #[inline(always)]
    fn len(&self) -> usize {
        self.bodies.as_ref().len()
    }
    #[inline(always)]
    fn body(&self, i: usize) -> &Body {
        &self.bodies.as_ref()[i]
    }
    #[inline(always)]
    fn gravity(&self) -> V3 {
        self.gravity
    }
}

/// A tree over borrowed bodies: no allocation.
pub type TreeRef<'a> = Bodies<&'a [Body]>;

/// A tree of `N` bodies held by value, so that a `no_std` program steps
/// it without allocating or borrowing.
pub type TreeArray<const N: usize> = Bodies<[Body; N]>;

/// Why a tree cannot be integrated: the body's index and what is wrong.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InvalidTree {
    /// The offending body (`usize::MAX`: the tree as a whole, e.g. gravity).
    pub body: usize,
    /// What is wrong.
    pub why: &'static str,
}

impl core::fmt::Display for InvalidTree {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        if self.body == usize::MAX {
            write!(f, "invalid tree: {}", self.why)
        } else {
            write!(f, "invalid tree body {}: {}", self.body, self.why)
        }
    }
}

impl core::error::Error for InvalidTree {}

fn finite3(a: &V3) -> bool {
    a.iter().all(|x| x.is_finite())
}

/// Checks a tree: gravity finite; each parent index smaller than its
/// child's; axes unit (to 1e-9); rotations orthonormal (to 1e-9) and
/// right-handed; translations, centres of mass finite; masses finite and
/// ≥ 0; inertias finite and symmetric (to 1e-12 relative) with
/// non-negative diagonal; damping and stiffness finite and ≥ 0; rests
/// finite; limits not NaN with lower ≤ upper. (A mass matrix that is
/// singular, e.g. a massless leaf, is found by the step's factorisation.)
pub fn validate<T: Tree + ?Sized>(tree: &T) -> Result<(), InvalidTree> {
    let bad = |body, why| Err(InvalidTree { body, why });
    if !finite3(&tree.gravity()) {
        return bad(usize::MAX, "gravity is not finite");
    }
    for i in 0..tree.len() {
        let b = tree.body(i);
        if b.parent.is_some_and(|p| p >= i) {
            return bad(i, "the parent index is not smaller than the body's");
        }
        if !finite3(&b.axis) || (dot(b.axis, b.axis) - 1.0).abs() > 1e-9 {
            return bad(i, "the joint axis is not a finite unit vector");
        }
        let r = &b.rotation;
        if !r.iter().all(finite3) {
            return bad(i, "the joint rotation is not finite");
        }
        for a in 0..3 {
            for c in 0..3 {
                let e = dot(r[a], r[c]) - if a == c { 1.0 } else { 0.0 };
                if e.abs() > 1e-9 {
                    return bad(i, "the joint rotation is not orthonormal");
                }
            }
        }
        let det = dot(r[0], super::spatial::cross(r[1], r[2]));
        if det <= 0.0 {
            return bad(i, "the joint rotation is not right-handed");
        }
        if !finite3(&b.translation) {
            return bad(i, "the joint translation is not finite");
        }
        if !(b.mass.is_finite() && b.mass >= 0.0) {
            return bad(i, "the mass is not finite and >= 0");
        }
        if !finite3(&b.com) {
            return bad(i, "the centre of mass is not finite");
        }
        let m = &b.inertia;
        if !m.iter().all(finite3) {
            return bad(i, "the inertia is not finite");
        }
        let big = m.iter().flatten().fold(0.0f64, |a, x| a.max(x.abs()));
        let asym = (m[0][1] - m[1][0])
            .abs()
            .max((m[0][2] - m[2][0]).abs())
            .max((m[1][2] - m[2][1]).abs());
        if asym > 1e-12 * big {
            return bad(i, "the inertia is not symmetric");
        }
        if m[0][0] < 0.0 || m[1][1] < 0.0 || m[2][2] < 0.0 {
            return bad(i, "the inertia has a negative diagonal entry");
        }
        if !(b.damping.is_finite() && b.damping >= 0.0) {
            return bad(i, "the damping is not finite and >= 0");
        }
        if !(b.stiffness.is_finite() && b.stiffness >= 0.0 && b.rest.is_finite()) {
            return bad(
                i,
                "the spring stiffness is not finite and >= 0, or its rest not finite",
            );
        }
        let l = &b.limits;
        if l.lower.is_nan()
            || l.upper.is_nan()
            || l.lower > l.upper
            || l.effort.is_nan()
            || l.velocity.is_nan()
        {
            return bad(i, "the limits are NaN or lower > upper");
        }
    }
    Ok(())
}

/// Whether the tree branches enough for the derivatives to factor their
/// Newton matrix in the tree's pattern: that work, Σ depth², is at most a
/// quarter of a dense factorisation's N³/3. A chain (the Panda, the UR5)
/// has Σ depth² ≈ N³/3 and is factored densely, where the dense code's
/// contiguous loops are faster; four 3-joint legs (Solo-12) have 56
/// against 576, the G1 humanoid's legs, waist and arms far less than a
/// chain of 29.
pub(super) fn branched<T: Tree>(tree: &T) -> bool {
    let n = tree.len();
    let mut work = 0usize;
    for k in 0..n {
        let depth = ancestors(tree, k).count() + 1;
        work += depth * depth;
    }
    12 * work <= n * n * n
}

/// The ancestors of body `k`, its parent first.
pub(super) fn ancestors<T: Tree>(tree: &T, k: usize) -> impl Iterator<Item = usize> + '_ {
    core::iter::successors(tree.body(k).parent, move |&a| tree.body(a).parent)
}
