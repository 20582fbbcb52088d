//! A planar tree as bodies of the tree engine: a planar mechanism is a
//! spatial one confined to the plane z = 0, turning about z.
//!
//! The planar DSL's conventions ([`crate::kinematics`]): a link's frame
//! sits at its `start`, and at angle θ a local point (a, b) is at
//! `origin + a·(sin θ, −cos θ) + b·(cos θ, sin θ)`, so θ = 0 hangs straight
//! down. In 3-D that link frame has the axes x' = (sin θ, −cos θ, 0),
//! y' = (cos θ, sin θ, 0) and z' = z: it is the world frame turned by
//! θ − π/2 about z. A revolute coordinate is the child's angle minus the
//! parent's (counter-clockwise about z); a prismatic one slides the
//! child's anchor along an axis fixed in the parent, orientations equal.
//!
//! So a planar body is a 3-D one ([`super::links3`]) whose link frame, in
//! its parent's, is not turned (Q = 1), or turned by −π/2 about z under
//! the world, with points at z = 0. The scalar inertia I about the centre
//! of mass becomes the lamina's diag(I/2, I/2, I) (the perpendicular-axis
//! theorem; only I acts in the plane).

use super::links3::{Link3Body, link3_tree};
use super::model::{JointKind, TreeArray};
use super::spatial::{IDENTITY, M3};
use crate::params::Link;
use crate::spatial::Link3;

/// What joins a planar body to its parent.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PlanarJoint {
    /// Rotation about z; coordinate: the relative angle (rad).
    Revolute,
    /// Translation along a unit axis fixed in the parent (world
    /// coordinates under the world); coordinate: the slide (m).
    Prismatic {
        /// The unit axis.
        axis: [f64; 2],
    },
}

/// One body of a planar tree in the description's terms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanarBody {
    /// The parent body's index (smaller than this body's), `None` for the
    /// world.
    pub parent: Option<usize>,
    /// The joint to the parent.
    pub joint: PlanarJoint,
    /// Where the joint sits: in the parent link's local coordinates, or in
    /// world coordinates under the world.
    pub at: [f64; 2],
    /// The point of this link that the joint holds, in its local
    /// coordinates (the link's own anchor).
    pub anchor: [f64; 2],
    /// The link's mass, inertia about the centre of mass and centre of
    /// mass (its `length` is read only through `at` and `anchor`).
    pub link: Link,
    /// Viscous damping on the joint rate.
    pub damping: f64,
    /// Spring stiffness on the joint coordinate.
    pub stiffness: f64,
    /// Spring rest coordinate.
    pub rest: f64,
}

/// The world frame turned by −π/2 about z: a link frame at θ = 0
/// (columns: x' = (0, −1, 0), y' = (1, 0, 0), z' = z).
const HANGING: M3 = [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];

/// The bodies of a planar tree, parents first, under gravity (gx, gy).
///
/// ```
/// use vigp_core::Link;
/// use vigp_core::tree::{Engine, Tree};
/// use vigp_core::tree::planar::{planar_tree, PlanarBody, PlanarJoint};
/// // a pendulum of length 1 hanging from the origin
/// let rod = Link::with_defaults(1.0, 1.0, None, None);
/// let pendulum = planar_tree(
///     [PlanarBody {
///         parent: None,
///         joint: PlanarJoint::Revolute,
///         at: [0.0, 0.0],
///         anchor: [0.0, 0.0],
///         link: rod,
///         damping: 0.0,
///         stiffness: 0.0,
///         rest: 0.0,
///     }],
///     [0.0, -9.81],
/// );
/// assert_eq!(pendulum.body(0).com, [0.5, 0.0, 0.0]);
/// assert!(Engine::new(pendulum).is_ok());
/// ```
pub fn planar_tree<const N: usize>(bodies: [PlanarBody; N], gravity: [f64; 2]) -> TreeArray<N> {
    let lift = |p: [f64; 2]| [p[0], p[1], 0.0];
    let body = |b: &PlanarBody| {
        let (joint, axis) = match b.joint {
            PlanarJoint::Revolute => (JointKind::Revolute, [0.0, 0.0, 1.0]),
            // the axis in the joint frame: the parent's frame, or the
            // hanging frame under the world (HANGING transposed)
            PlanarJoint::Prismatic { axis: [x, y] } => match b.parent {
                Some(_) => (JointKind::Prismatic, [x, y, 0.0]),
                None => (JointKind::Prismatic, [-y, x, 0.0]),
            },
        };
        let i = b.link.inertia;
        Link3Body {
            parent: b.parent,
            joint,
            axis,
            rotation: if b.parent.is_some() {
                IDENTITY
            } else {
                HANGING
            },
            at: lift(b.at),
            anchor: lift(b.anchor),
            link: Link3 {
                mass: b.link.mass,
                inertia: [[0.5 * i, 0.0, 0.0], [0.0, 0.5 * i, 0.0], [0.0, 0.0, i]],
                com: lift(b.link.com),
                length: b.link.length,
            },
            damping: b.damping,
            stiffness: b.stiffness,
            rest: b.rest,
        }
    };
    link3_tree(core::array::from_fn(|k| body(&bodies[k])), lift(gravity))
}
