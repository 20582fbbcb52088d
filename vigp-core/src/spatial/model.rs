//! The description of a spatial mechanism: links (rigid bodies), joints,
//! gravity. `mechanism!` implements [`Spatial`] for every description with
//! a 3-component gravity; a hand-written implementation works the same.
//!
//! # Conventions
//!
//! * Every link has a **frame**: its origin is the link's `start`; with a
//!   `length`, its `end` is at (length, 0, 0) and its `center` at
//!   (length/2, 0, 0). Anchors, the centre of mass and the inertia tensor
//!   are given in this frame.
//! * The **reference configuration** is the one where every joint
//!   coordinate is zero: each link frame has its declared reference
//!   orientation (`frame`, default: parallel to the world frame), and each
//!   joint's child point coincides with its parent point.
//! * A joint's **axis** is given in its parent's frame (world coordinates
//!   when the parent is the world) and is fixed there.
//! * `rel` is the child frame's orientation relative to the parent frame in
//!   the reference configuration, Q = R_p⁰ᵀ·R_c⁰. A revolute joint at angle
//!   θ has R_c = R_p·Rot(a, θ)·Q (right-handed about the axis a); a
//!   prismatic joint at slide s has R_c = R_p·Q and moves the child point by
//!   s·a (in the parent frame); a spherical joint with unit quaternion u has
//!   R_c = R_p·R(u)·Q; a free joint adds a translation d (parent frame) of
//!   the child point to that.
//! * A universal (Hooke, cardan) joint at angles (θ₁, θ₂) has
//!   R_c = R_p·Rot(a₁, θ₁)·Rot(a₂, θ₂)·Q: the first axis a₁ is fixed in the
//!   parent, the second a₂ (given in the parent frame at θ₁ = 0) is carried
//!   by the first rotation, so it is fixed in the child.

use super::geometry::{
    Mat3, Motion3, Pose3, Vec3, add, complement, cross, dot, dot_f, mul_mm, mul_mm_f, mul_mtm,
    mul_mtv, mul_mv_f, sub, vee_skew,
};
use crate::params::Spring;
use crate::real::Real;

/// One rigid link: mass properties in its own frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Link3 {
    /// Mass (kg, > 0).
    pub mass: f64,
    /// Inertia tensor about the centre of mass, in the link frame (kg·m²,
    /// symmetric positive definite).
    pub inertia: [[f64; 3]; 3],
    /// Centre of mass in the link frame (m).
    pub com: [f64; 3],
    /// Length (m): `end` is at (length, 0, 0), `center` at (length/2, 0, 0).
    /// 0 when the description gives none.
    pub length: f64,
}

impl Link3 {
    /// A link whose centre of mass is the DSL's default (length/2, 0, 0).
    /// `mechanism!` emits this when the length is written as an expression
    /// (`length: 2.0 * L`) and `com` is not given.
    pub fn with_default_com(mass: f64, inertia: [[f64; 3]; 3], length: f64) -> Self {
        Link3 {
            mass,
            inertia,
            com: center(length),
            length,
        }
    }
}

/// The `center` anchor of a link of `length`: (length/2, 0, 0).
#[inline]
pub fn center(length: f64) -> [f64; 3] {
    [0.5 * length, 0.0, 0.0]
}

/// What a joint allows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum JointType {
    /// Rotation about the axis; the points coincide. Coordinate: the angle
    /// (rad). 5 constraint equations in maximal coordinates.
    Revolute,
    /// Translation along the axis, orientations locked. Coordinate: the
    /// slide (m). 5 constraint equations.
    Prismatic,
    /// Any rotation about the common point. Coordinates: a unit quaternion
    /// (w, x, y, z) with its unit-norm constraint. 3 constraint equations.
    Spherical,
    /// A weld: no coordinate. 6 constraint equations.
    Fixed,
    /// No constraint: the child point's position in the parent frame (m)
    /// and a unit quaternion, 7 coordinates. 0 constraint equations.
    Free,
    /// A universal (Hooke, cardan) joint: rotation about the joint's `axis`
    /// a₁ (fixed in the parent) and then about `second` a₂ (carried by the
    /// first rotation, fixed in the child); the points coincide.
    /// Coordinates: the two angles (θ₁, θ₂) (rad). 4 constraint equations:
    /// the points coincide (3) and the angle between a₁ and a₂ keeps its
    /// reference value (1; for the usual perpendicular axes they stay
    /// perpendicular).
    Universal {
        /// Unit second axis a₂ in the parent frame at θ₁ = 0 (equivalently
        /// Qᵀa₂ in the child frame), not parallel to the first.
        second: [f64; 3],
    },
}

impl JointType {
    /// Constraint equations of the joint in maximal coordinates (and as a
    /// loop-closing joint in minimal coordinates).
    pub const fn constraint_rows(self) -> usize {
        match self {
            JointType::Revolute | JointType::Prismatic => 5,
            JointType::Spherical => 3,
            JointType::Fixed => 6,
            JointType::Free => 0,
            JointType::Universal { .. } => 4,
        }
    }

    /// Minimal coordinates of the joint in a tree.
    pub const fn coordinates(self) -> usize {
        match self {
            JointType::Revolute | JointType::Prismatic => 1,
            JointType::Spherical => 4,
            JointType::Fixed => 0,
            JointType::Free => 7,
            JointType::Universal { .. } => 2,
        }
    }

    /// Rates a damper acts on (joint velocities): 1 for revolute and
    /// prismatic joints, 3 (the relative angular velocity) for spherical
    /// and universal joints, none for fixed and free joints.
    pub const fn rates(self) -> usize {
        match self {
            JointType::Revolute | JointType::Prismatic => 1,
            JointType::Spherical | JointType::Universal { .. } => 3,
            JointType::Fixed | JointType::Free => 0,
        }
    }
}

/// One joint, with everything the integrators need as run-time values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Joint3 {
    /// Type.
    pub kind: JointType,
    /// Parent link index (`None`: the world).
    pub parent: Option<usize>,
    /// Child link index.
    pub child: usize,
    /// Parent point: in the parent link frame, or world coordinates.
    pub parent_anchor: [f64; 3],
    /// Child point in the child link frame.
    pub child_anchor: [f64; 3],
    /// Unit axis in the parent frame (revolute, prismatic; the first axis of
    /// a universal joint; ignored otherwise).
    pub axis: [f64; 3],
    /// Reference relative orientation Q = R_p⁰ᵀ·R_c⁰ as a unit quaternion
    /// (w, x, y, z).
    pub rel: [f64; 4],
    /// Viscous damping coefficient on the joint rate(s) (N·m·s/rad or N·s/m).
    pub damping: f64,
}

/// A spatial mechanism with `B` links and `J` joints: what `mechanism!`
/// implements for a description with 3-component gravity.
pub trait Spatial<const B: usize, const J: usize> {
    /// Link names, in declaration order.
    const LINKS: [&'static str; B];
    /// Joint names, in declaration order.
    const JOINTS: [&'static str; J];
    /// The tree (spanning) joints in an order where every parent link is
    /// placed before its children: one per link. The other joints close
    /// loops.
    const TREE: [usize; B];
    /// `true` when some joint declares damping (otherwise the integrators
    /// skip the dissipation terms).
    const DISSIPATIVE: bool;
    /// `true` when some joint has a spring ([`Spatial::springs`]);
    /// otherwise the integrators skip the spring terms. Default: none.
    const ELASTIC: bool = false;
    /// The actuated joints in declaration order: input i drives joint
    /// `INPUT_JOINTS[i]` (a revolute or prismatic joint) with the
    /// generalized force u_i·∇s_i, s_i its coordinate ([`joint_coordinate`]):
    /// a torque about a revolute axis (on the child, and its reaction on
    /// the parent), a force along a prismatic axis. Default: none.
    const INPUT_JOINTS: &'static [usize] = &[];

    /// Gravitational acceleration in world coordinates (m/s²).
    fn gravity(&self) -> [f64; 3];
    /// The links, in declaration order.
    fn links(&self) -> [Link3; B];
    /// The joints, in declaration order.
    fn joints(&self) -> [Joint3; J];
    /// The spring of every joint, in declaration order: potential
    /// ½k(s − rest)² on the joint coordinate s ([`joint_coordinate`]; only
    /// revolute and prismatic joints may have k ≠ 0). Read only when
    /// [`Spatial::ELASTIC`]. Default: none.
    fn springs(&self) -> [Spring; J] {
        [Spring {
            stiffness: 0.0,
            rest: 0.0,
        }; J]
    }
}

/// Why a description cannot be integrated.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ModelError {
    /// A parameter is out of its domain (the message says which).
    Invalid(&'static str),
    /// A const size does not match the description (the message says which).
    Size(&'static str),
}

impl core::fmt::Display for ModelError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ModelError::Invalid(why) => write!(f, "invalid spatial model: {why}"),
            ModelError::Size(why) => write!(f, "spatial model size mismatch: {why}"),
        }
    }
}

impl core::error::Error for ModelError {}

fn finite3(a: &[f64; 3]) -> bool {
    a.iter().all(|x| x.is_finite())
}

/// The smallest sine of the angle between the two axes of a universal
/// joint: below it the axes count as parallel (the joint would lose a
/// degree of freedom, and its angle constraint's gradient, proportional to
/// that sine, would vanish). `mechanism!` applies the same bound at
/// compile time.
pub const UNIVERSAL_MIN_SINE: f64 = 1e-6;

/// `true` when the symmetric 3×3 `m` is positive definite (Cholesky pivots
/// positive).
pub fn positive_definite(m: &[[f64; 3]; 3]) -> bool {
    let a = m[0][0];
    // NaN fails every comparison: written so that NaN is not definite
    if a.is_nan() || a <= 0.0 {
        return false;
    }
    let l10 = m[1][0] / a;
    let l20 = m[2][0] / a;
    let b = m[1][1] - l10 * m[1][0];
    if b.is_nan() || b <= 0.0 {
        return false;
    }
    let l21 = (m[2][1] - l20 * m[1][0]) / b;
    let c = m[2][2] - l20 * m[2][0] - l21 * (m[2][1] - l20 * m[1][0]);
    c > 0.0
}

/// Checks a description: gravity finite; masses finite and > 0; inertias
/// finite, symmetric and positive definite; centres of mass and anchors
/// finite; indices in range; axes and `rel` unit (to 1e-9), the two axes
/// of a universal joint not parallel ([`UNIVERSAL_MIN_SINE`]); damping finite
/// and ≥ 0; spring stiffnesses finite and ≥ 0 with finite rests, on
/// revolute and prismatic joints only; inputs on distinct revolute or
/// prismatic joints; [`Spatial::TREE`] a valid placement order (each link placed
/// once, by a joint whose child it is, parents first).
pub fn validate<S: Spatial<B, J>, const B: usize, const J: usize>(
    sys: &S,
) -> Result<([Link3; B], [Joint3; J]), ModelError> {
    if !finite3(&sys.gravity()) {
        return Err(ModelError::Invalid("gravity must be finite"));
    }
    let links = sys.links();
    let joints = sys.joints();
    for l in &links {
        if !(l.mass.is_finite() && l.mass > 0.0) {
            return Err(ModelError::Invalid("a link mass is not finite and > 0"));
        }
        let i = &l.inertia;
        if !i.iter().all(finite3) {
            return Err(ModelError::Invalid("a link inertia is not finite"));
        }
        let asym = (i[0][1] - i[1][0])
            .abs()
            .max((i[0][2] - i[2][0]).abs())
            .max((i[1][2] - i[2][1]).abs());
        let big = i.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        if asym > 1e-12 * big {
            return Err(ModelError::Invalid("a link inertia is not symmetric"));
        }
        if !positive_definite(i) {
            return Err(ModelError::Invalid(
                "a link inertia is not positive definite",
            ));
        }
        if !(finite3(&l.com) && l.length.is_finite() && l.length >= 0.0) {
            return Err(ModelError::Invalid(
                "a link centre of mass or length is not finite",
            ));
        }
    }
    for j in &joints {
        if j.child >= B || j.parent.is_some_and(|p| p >= B || p == j.child) {
            return Err(ModelError::Invalid("a joint link index is out of range"));
        }
        if !(finite3(&j.parent_anchor) && finite3(&j.child_anchor)) {
            return Err(ModelError::Invalid("a joint anchor is not finite"));
        }
        if matches!(
            j.kind,
            JointType::Revolute | JointType::Prismatic | JointType::Universal { .. }
        ) && !(finite3(&j.axis) && (dot(j.axis, j.axis) - 1.0).abs() <= 1e-9)
        {
            return Err(ModelError::Invalid("a joint axis is not a unit vector"));
        }
        if let JointType::Universal { second } = j.kind {
            if !(finite3(&second) && (dot(second, second) - 1.0).abs() <= 1e-9) {
                return Err(ModelError::Invalid(
                    "a universal joint's second axis is not a unit vector",
                ));
            }
            let c = cross(j.axis, second);
            if dot(c, c) < UNIVERSAL_MIN_SINE * UNIVERSAL_MIN_SINE {
                return Err(ModelError::Invalid(
                    "a universal joint's two axes are parallel",
                ));
            }
        }
        let r = j.rel;
        if ((r[0] * r[0] + r[1] * r[1] + r[2] * r[2] + r[3] * r[3]) - 1.0).abs() > 1e-9 {
            return Err(ModelError::Invalid(
                "a joint's reference rotation is not a unit quaternion",
            ));
        }
        if !(j.damping.is_finite() && j.damping >= 0.0) {
            return Err(ModelError::Invalid(
                "a damping coefficient is negative or not finite",
            ));
        }
    }
    if S::ELASTIC {
        for (s, j) in sys.springs().iter().zip(&joints) {
            if !(s.stiffness.is_finite() && s.stiffness >= 0.0 && s.rest.is_finite()) {
                return Err(ModelError::Invalid(
                    "a spring stiffness is negative or not finite, or its rest is not finite",
                ));
            }
            if s.stiffness != 0.0 && !matches!(j.kind, JointType::Revolute | JointType::Prismatic) {
                return Err(ModelError::Invalid(
                    "a spring on a joint that is not revolute or prismatic",
                ));
            }
        }
    }
    for (i, &k) in S::INPUT_JOINTS.iter().enumerate() {
        let Some(j) = joints.get(k) else {
            return Err(ModelError::Invalid("an input joint index is out of range"));
        };
        if !matches!(j.kind, JointType::Revolute | JointType::Prismatic) {
            return Err(ModelError::Invalid(
                "an input drives a joint that is not revolute or prismatic",
            ));
        }
        if S::INPUT_JOINTS[..i].contains(&k) {
            return Err(ModelError::Invalid("a joint is actuated twice"));
        }
    }
    let mut placed = [false; B];
    for &t in &S::TREE {
        let Some(j) = joints.get(t) else {
            return Err(ModelError::Invalid("a tree joint index is out of range"));
        };
        if placed[j.child] || j.parent.is_some_and(|p| !placed[p]) {
            return Err(ModelError::Invalid(
                "TREE is not a placement order (a link placed twice, or before its parent)",
            ));
        }
        placed[j.child] = true;
    }
    for (k, j) in joints.iter().enumerate() {
        if j.kind == JointType::Free && !S::TREE.contains(&k) {
            return Err(ModelError::Invalid("a free joint cannot close a loop"));
        }
    }
    Ok((links, joints))
}

/// Whether joint `j` is a tree joint.
pub fn is_tree<S: Spatial<B, J>, const B: usize, const J: usize>(j: usize) -> bool {
    S::TREE.contains(&j)
}

/// Minimal-coordinate layout: for each joint the offset of its first
/// coordinate (tree joints, in declaration order) and of its first loop
/// constraint row; then the quaternion unit-norm rows follow the loop rows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout<const J: usize> {
    /// First coordinate of each tree joint (`usize::MAX` for loop joints).
    pub coordinate: [usize; J],
    /// First constraint row of each loop joint (`usize::MAX` for tree joints).
    pub row: [usize; J],
    /// Number of minimal coordinates.
    pub coordinates: usize,
    /// Number of loop-closure rows.
    pub loop_rows: usize,
    /// Number of quaternion coordinates (each with one unit-norm row).
    pub quaternions: usize,
}

impl<const J: usize> Layout<J> {
    /// The layout of a description.
    pub fn of<S: Spatial<B, J>, const B: usize>(joints: &[Joint3; J]) -> Self {
        let mut out = Self {
            coordinate: [usize::MAX; J],
            row: [usize::MAX; J],
            coordinates: 0,
            loop_rows: 0,
            quaternions: 0,
        };
        for (k, j) in joints.iter().enumerate() {
            if is_tree::<S, B, J>(k) {
                out.coordinate[k] = out.coordinates;
                out.coordinates += j.kind.coordinates();
                if matches!(j.kind, JointType::Spherical | JointType::Free) {
                    out.quaternions += 1;
                }
            } else {
                out.row[k] = out.loop_rows;
                out.loop_rows += j.kind.constraint_rows();
            }
        }
        out
    }

    /// Number of minimal-coordinate constraint rows (loops + unit norms).
    pub fn constraints(&self) -> usize {
        self.loop_rows + self.quaternions
    }
}

/// Number of constraint rows of all joints (the maximal view's `C`).
pub fn maximal_rows(joints: &[Joint3]) -> usize {
    joints.iter().map(|j| j.kind.constraint_rows()).sum()
}

/// The rotation matrix of a unit quaternion given as (w, x, y, z) in f64.
pub fn rel_matrix(q: [f64; 4]) -> [[f64; 3]; 3] {
    super::geometry::quat_matrix(q)
}

/// The constraint residual of joint `j` between the `parent` pose (the
/// world frame for a world parent) and the `child` pose, written to
/// `out[..rows]`; returns the number of rows
/// ([`JointType::constraint_rows`]).
///
/// With P, C the world positions of the parent and child points, d = C − P,
/// E = R_pᵀ·R_c·Qᵀ the rotation away from the reference relative
/// orientation, a the axis and (b₁, b₂) its [`complement`]:
///
/// * revolute: d (3), b₁·(E a), b₂·(E a) (2): E keeps the axis;
/// * prismatic: b₁·(R_pᵀd), b₂·(R_pᵀd) (2), vee((E − Eᵀ)/2) (3);
/// * spherical: d (3);
/// * fixed: d (3), vee((E − Eᵀ)/2) (3);
/// * free: none;
/// * universal: d (3), a₁·(E a₂) − a₁·a₂ (1): the second axis, carried by
///   the child, keeps its angle to the first, fixed in the parent
///   (E a₂ = Rot(a₁, θ₁)·a₂ exactly on the joint's configurations).
///
/// Generic over [`Real`]: the maximal view differentiates it with jets, the
/// minimal view evaluates it on dual numbers.
pub fn joint_residual<R: Real>(
    j: &Joint3,
    parent: &Pose3<R>,
    child: &Pose3<R>,
    out: &mut [R; 6],
) -> usize {
    let d = sub(child.point(j.child_anchor), parent.point(j.parent_anchor));
    let q = rel_matrix(j.rel);
    match j.kind {
        JointType::Revolute => {
            let (b1, b2) = complement(j.axis);
            // E a = R_pᵀ R_c (Qᵀ a)
            let qa = [
                q[0][0] * j.axis[0] + q[1][0] * j.axis[1] + q[2][0] * j.axis[2],
                q[0][1] * j.axis[0] + q[1][1] * j.axis[1] + q[2][1] * j.axis[2],
                q[0][2] * j.axis[0] + q[1][2] * j.axis[1] + q[2][2] * j.axis[2],
            ];
            let ea = mul_mtv(&parent.rot, mul_mv_f(&child.rot, qa));
            out[..3].copy_from_slice(&d);
            out[3] = dot_f(ea, b1);
            out[4] = dot_f(ea, b2);
            5
        }
        JointType::Prismatic => {
            let (b1, b2) = complement(j.axis);
            let local = mul_mtv(&parent.rot, d);
            out[0] = dot_f(local, b1);
            out[1] = dot_f(local, b2);
            let e = relative(parent, child, &q);
            out[2..5].copy_from_slice(&vee_skew(&e));
            5
        }
        JointType::Spherical => {
            out[..3].copy_from_slice(&d);
            3
        }
        JointType::Fixed => {
            out[..3].copy_from_slice(&d);
            let e = relative(parent, child, &q);
            out[3..6].copy_from_slice(&vee_skew(&e));
            6
        }
        JointType::Free => 0,
        JointType::Universal { second } => {
            // E a₂ = R_pᵀ R_c (Qᵀ a₂)
            let qa = [
                q[0][0] * second[0] + q[1][0] * second[1] + q[2][0] * second[2],
                q[0][1] * second[0] + q[1][1] * second[1] + q[2][1] * second[2],
                q[0][2] * second[0] + q[1][2] * second[1] + q[2][2] * second[2],
            ];
            let ea = mul_mtv(&parent.rot, mul_mv_f(&child.rot, qa));
            out[..3].copy_from_slice(&d);
            out[3] = dot_f(ea, j.axis) - dot(j.axis, second);
            4
        }
    }
}

/// The coordinate s of a revolute or prismatic joint `j` read from its
/// parent and child poses, zero in the reference configuration (the
/// convention of the minimal coordinates, [`place_child`]):
///
/// * revolute: the angle θ of E = R_pᵀ·R_c·Qᵀ about the axis a, measured
///   as atan2(b₂·E b₁, b₁·E b₁) ((b₁, b₂) the axis' [`complement`]) on the
///   branch (near − π, near + π]: orientations carry no winding count;
/// * prismatic: the slide (R_p a)·(C − P) (parent point P, child point C);
/// * other joints: 0.
///
/// On consistent poses its rate is [`joint_rates`]' row; generic over
/// [`Real`], so jets and dual numbers differentiate it (spring forces,
/// inputs on loop joints, the maximal view).
pub fn joint_coordinate<R: Real>(j: &Joint3, parent: &Pose3<R>, child: &Pose3<R>, near: f64) -> R {
    match j.kind {
        JointType::Revolute => {
            let q = rel_matrix(j.rel);
            let (b1, b2) = complement(j.axis);
            let e = relative(parent, child, &q);
            let eb1 = [dot_f(e[0], b1), dot_f(e[1], b1), dot_f(e[2], b1)];
            let (c, s) = (dot_f(eb1, b1), dot_f(eb1, b2));
            // rotate (c, s) by −near so that atan2's cut sits opposite `near`
            let (sn, cn) = libm::sincos(near);
            let (y, x) = (s * cn - c * sn, c * cn + s * sn);
            y.atan2(x) + near
        }
        JointType::Prismatic => {
            let a = parent.direction(j.axis);
            let d = sub(child.point(j.child_anchor), parent.point(j.parent_anchor));
            dot(a, d)
        }
        _ => R::from_f64(0.0),
    }
}

/// E = R_pᵀ·R_c·Qᵀ.
fn relative<R: Real>(parent: &Pose3<R>, child: &Pose3<R>, q: &[[f64; 3]; 3]) -> Mat3<R> {
    let qt = [
        [q[0][0], q[1][0], q[2][0]],
        [q[0][1], q[1][1], q[2][1]],
        [q[0][2], q[1][2], q[2][2]],
    ];
    mul_mm_f(&mul_mtm(&parent.rot, &child.rot), &qt)
}

/// The joint rates a damper acts on, written to `out[..n]`; returns n
/// ([`JointType::rates`]). Linear in the motions:
///
/// * revolute: (R_p a)·(ω_c − ω_p), the rate of the joint angle;
/// * prismatic: d/dt[(R_p a)·(C − P)] = (ω_p × R_p a)·d + (R_p a)·(Ċ − Ṗ),
///   the rate of the slide;
/// * spherical, universal: ω_c − ω_p (world), the relative angular
///   velocity (for a universal joint θ̇₁·R_p a₁ + θ̇₂·R_c Qᵀa₂, so with
///   perpendicular axes the dissipation is ½c(θ̇₁² + θ̇₂²));
/// * fixed, free: none.
///
/// The dissipation function of the joint is ½·c·Σ rate².
pub fn joint_rates<R: Real>(
    j: &Joint3,
    parent: (&Pose3<R>, &Motion3<R>),
    child: (&Pose3<R>, &Motion3<R>),
    out: &mut [R; 3],
) -> usize {
    let (pp, pm) = parent;
    let (cp, cm) = child;
    match j.kind {
        JointType::Revolute => {
            let a = pp.direction(j.axis);
            out[0] = dot(a, sub(cm.omega, pm.omega));
            1
        }
        JointType::Prismatic => {
            let a = pp.direction(j.axis);
            let d = sub(cp.point(j.child_anchor), pp.point(j.parent_anchor));
            let dd = sub(
                cm.point_velocity(cp, j.child_anchor),
                pm.point_velocity(pp, j.parent_anchor),
            );
            out[0] = dot(cross(pm.omega, a), d) + dot(a, dd);
            1
        }
        JointType::Spherical | JointType::Universal { .. } => {
            out.copy_from_slice(&sub(cm.omega, pm.omega));
            3
        }
        JointType::Fixed | JointType::Free => 0,
    }
}

/// The pose of a child link placed by tree joint `j` from its parent pose
/// and the joint's coordinates `c` (`c.len()` = [`JointType::coordinates`]),
/// and, when `rates` is given, its motion from the parent's motion.
pub fn place_child<R: Real>(
    j: &Joint3,
    parent: &Pose3<R>,
    parent_motion: Option<&Motion3<R>>,
    c: &[R],
    rates: Option<&[R]>,
) -> (Pose3<R>, Option<Motion3<R>>) {
    use super::geometry::{axis_angle, mul_mv, quat_matrix, quat_rate, scale};
    let q = rel_matrix(j.rel);
    let anchor = parent.point(j.parent_anchor);
    let (rot, point, omega_rel, point_rel_vel): (Mat3<R>, Vec3<R>, Option<Vec3<R>>, _) =
        match j.kind {
            JointType::Revolute => {
                let rot = mul_mm_f(&mul_mm(&parent.rot, &axis_angle(j.axis, c[0])), &q);
                let w = rates.map(|r| scale(parent.direction(j.axis), r[0]));
                (rot, anchor, w, None)
            }
            JointType::Prismatic => {
                let rot = mul_mm_f(&parent.rot, &q);
                let a = parent.direction(j.axis);
                let point = add(anchor, scale(a, c[0]));
                // the slide point moves with the parent and along the axis
                let extra = rates.map(|r| (a, c[0], r[0]));
                (rot, point, None, extra)
            }
            JointType::Spherical => {
                let u = [c[0], c[1], c[2], c[3]];
                let rot = mul_mm_f(&mul_mm(&parent.rot, &quat_matrix(u)), &q);
                let w = rates.map(|r| mul_mv(&parent.rot, quat_rate(u, [r[0], r[1], r[2], r[3]])));
                (rot, anchor, w, None)
            }
            JointType::Fixed => (mul_mm_f(&parent.rot, &q), anchor, None, None),
            JointType::Universal { second } => {
                let first = axis_angle(j.axis, c[0]);
                let rot = mul_mm_f(
                    &mul_mm(&mul_mm(&parent.rot, &first), &axis_angle(second, c[1])),
                    &q,
                );
                // ω_rel = R_p (a₁ θ̇₁ + Rot(a₁, θ₁) a₂ θ̇₂)
                let w = rates.map(|r| {
                    let carried = mul_mv(&first, super::geometry::lift(second));
                    let local = add(
                        scale(super::geometry::lift(j.axis), r[0]),
                        scale(carried, r[1]),
                    );
                    mul_mv(&parent.rot, local)
                });
                (rot, anchor, w, None)
            }
            JointType::Free => {
                let u = [c[3], c[4], c[5], c[6]];
                let rot = mul_mm_f(&mul_mm(&parent.rot, &quat_matrix(u)), &q);
                let dw = mul_mv(&parent.rot, [c[0], c[1], c[2]]);
                let w = rates.map(|r| mul_mv(&parent.rot, quat_rate(u, [r[3], r[4], r[5], r[6]])));
                (rot, add(anchor, dw), w, None)
            }
        };
    let origin = sub(point, mul_mv_f(&rot, j.child_anchor));
    let pose = Pose3 { origin, rot };
    let motion = match (parent_motion, rates) {
        (Some(pm), Some(r)) => {
            let omega = match omega_rel {
                Some(w) => add(pm.omega, w),
                None => pm.omega,
            };
            // velocity of the child point
            let mut vp = pm.point_velocity(parent, j.parent_anchor);
            if let Some((a, s, sdot)) = point_rel_vel {
                // d/dt (s·R_p a) = ṡ·R_p a + s·ω_p × R_p a
                vp = add(vp, add(scale(a, sdot), scale(cross(pm.omega, a), s)));
            }
            if j.kind == JointType::Free {
                // d/dt (R_p d) = R_p ḋ + ω_p × R_p d
                let dw = mul_mv(&parent.rot, [c[0], c[1], c[2]]);
                let ddw = mul_mv(&parent.rot, [r[0], r[1], r[2]]);
                vp = add(vp, add(ddw, cross(pm.omega, dw)));
            }
            let velocity = sub(vp, cross(omega, pose.direction(j.child_anchor)));
            Some(Motion3 { velocity, omega })
        }
        _ => None,
    };
    (pose, motion)
}
