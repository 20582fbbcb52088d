//! Minimal coordinates of a spatial mechanism: one angle per revolute tree
//! joint, one slide per prismatic tree joint, a quaternion (w, x, y, z) per
//! spherical tree joint, position and quaternion per free joint, nothing
//! for a fixed joint; loop-closing joints and the quaternions' unit norms
//! become constraints g(q) = 0. Everything is generic over [`Real`], so the
//! std runtime evaluates it on dual numbers (its `Mechanism` views) and
//! this crate on jets.
//!
//! Coordinates follow the tree joints in declaration order; constraint rows
//! are the loop joints' rows in declaration order, then one row |u|² − 1
//! per quaternion (in coordinate order).

use super::geometry::{Motion3, Pose3, dot, dot_f, mul_mtv, mul_mv_f};
use super::model::{
    Joint3, JointType, Layout, Link3, Spatial, joint_rates, joint_residual, place_child,
};
use crate::real::Real;
use nalgebra::SVector;

/// The pose of the parent of joint `j` (the world frame for a world parent).
fn parent_of<R: Real, const B: usize>(j: &Joint3, poses: &[Pose3<R>; B]) -> Pose3<R> {
    match j.parent {
        Some(p) => poses[p],
        None => Pose3::identity(),
    }
}

/// Link frame poses for minimal coordinates `q`, in link declaration order.
pub fn poses<S, R, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<R, N>,
) -> [Pose3<R>; B]
where
    S: Spatial<B, J>,
    R: Real,
{
    let joints = sys.joints();
    let layout = Layout::of::<S, B>(&joints);
    let mut out = [Pose3::identity(); B];
    for &t in &S::TREE {
        let j = &joints[t];
        let parent = parent_of(j, &out);
        let o = layout.coordinate[t];
        let c = &q.as_slice()[o..o + j.kind.coordinates()];
        out[j.child] = place_child(j, &parent, None, c, None).0;
    }
    out
}

/// Link frame poses and motions for minimal positions `q` and velocities
/// `v` (any velocity: continuous or discrete).
pub fn poses_and_motions<S, R, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<R, N>,
    v: &SVector<R, N>,
) -> ([Pose3<R>; B], [Motion3<R>; B])
where
    S: Spatial<B, J>,
    R: Real,
{
    let joints = sys.joints();
    let layout = Layout::of::<S, B>(&joints);
    let mut poses = [Pose3::identity(); B];
    let mut motions = [Motion3::zero(); B];
    for &t in &S::TREE {
        let j = &joints[t];
        let (parent, pm) = match j.parent {
            Some(p) => (poses[p], motions[p]),
            None => (Pose3::identity(), Motion3::zero()),
        };
        let o = layout.coordinate[t];
        let n = j.kind.coordinates();
        let c = &q.as_slice()[o..o + n];
        let r = &v.as_slice()[o..o + n];
        let (pose, motion) = place_child(j, &parent, Some(&pm), c, Some(r));
        poses[j.child] = pose;
        motions[j.child] = motion.unwrap_or(pm);
    }
    (poses, motions)
}

/// Kinetic energy ½m|v_com|² + ½ω_bᵀJω_b of one link (ω_b = Rᵀω).
pub fn link_kinetic_energy<R: Real>(link: &Link3, pose: &Pose3<R>, motion: &Motion3<R>) -> R {
    let v = motion.point_velocity(pose, link.com);
    let wb = mul_mtv(&pose.rot, motion.omega);
    let jw = [
        dot_f(wb, link.inertia[0]),
        dot_f(wb, link.inertia[1]),
        dot_f(wb, link.inertia[2]),
    ];
    (dot(v, v) * link.mass + dot(wb, jw)) * 0.5
}

/// Potential energy −m·g·p_com of one link.
pub fn link_potential_energy<R: Real>(link: &Link3, gravity: [f64; 3], pose: &Pose3<R>) -> R {
    dot_f(pose.point(link.com), gravity) * (-link.mass)
}

/// Kinetic energy T(q, v).
pub fn kinetic_energy<S, R, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<R, N>,
    v: &SVector<R, N>,
) -> R
where
    S: Spatial<B, J>,
    R: Real,
{
    let (poses, motions) = poses_and_motions::<S, R, B, J, N>(sys, q, v);
    let links = sys.links();
    let mut t = R::from_f64(0.0);
    for i in 0..B {
        t = t + link_kinetic_energy(&links[i], &poses[i], &motions[i]);
    }
    t
}

/// Potential energy V(q) (gravity).
pub fn potential_energy<S, R, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<R, N>,
) -> R
where
    S: Spatial<B, J>,
    R: Real,
{
    let poses = poses::<S, R, B, J, N>(sys, q);
    let (links, g) = (sys.links(), sys.gravity());
    let mut v = R::from_f64(0.0);
    for i in 0..B {
        v = v + link_potential_energy(&links[i], g, &poses[i]);
    }
    v
}

/// Lagrangian T − V in one pass of the kinematics.
pub fn lagrangian<S, R, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<R, N>,
    v: &SVector<R, N>,
) -> R
where
    S: Spatial<B, J>,
    R: Real,
{
    let (poses, motions) = poses_and_motions::<S, R, B, J, N>(sys, q, v);
    let (links, g) = (sys.links(), sys.gravity());
    let mut l = R::from_f64(0.0);
    for i in 0..B {
        l = l + link_kinetic_energy(&links[i], &poses[i], &motions[i])
            - link_potential_energy(&links[i], g, &poses[i]);
    }
    l
}

/// Rayleigh dissipation ½·Σ_j c_j·|rate_j|² over every damped joint (tree
/// and loop), rates by [`joint_rates`].
pub fn dissipation<S, R, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<R, N>,
    v: &SVector<R, N>,
) -> R
where
    S: Spatial<B, J>,
    R: Real,
{
    let (poses, motions) = poses_and_motions::<S, R, B, J, N>(sys, q, v);
    let mut out = R::from_f64(0.0);
    for j in sys.joints().iter() {
        if j.damping == 0.0 {
            continue;
        }
        let (pp, pm) = match j.parent {
            Some(p) => (poses[p], motions[p]),
            None => (Pose3::identity(), Motion3::zero()),
        };
        let mut rates = [R::from_f64(0.0); 3];
        let n = joint_rates(
            j,
            (&pp, &pm),
            (&poses[j.child], &motions[j.child]),
            &mut rates,
        );
        for r in &rates[..n] {
            out = out + *r * *r * (0.5 * j.damping);
        }
    }
    out
}

/// Constraints g(q): loop rows, then |u|² − 1 per quaternion.
pub fn constraints<S, R, const B: usize, const J: usize, const N: usize, const C: usize>(
    sys: &S,
    q: &SVector<R, N>,
) -> SVector<R, C>
where
    S: Spatial<B, J>,
    R: Real,
{
    let joints = sys.joints();
    let layout = Layout::of::<S, B>(&joints);
    let mut g = SVector::<R, C>::from_element(R::from_f64(0.0));
    if layout.loop_rows > 0 {
        let poses = poses::<S, R, B, J, N>(sys, q);
        for (k, j) in joints.iter().enumerate() {
            let row = layout.row[k];
            if row == usize::MAX {
                continue;
            }
            let parent = parent_of(j, &poses);
            let mut out = [R::from_f64(0.0); 6];
            let n = joint_residual(j, &parent, &poses[j.child], &mut out);
            for (i, r) in out[..n].iter().enumerate() {
                g[row + i] = *r;
            }
        }
    }
    let mut row = layout.loop_rows;
    for (k, j) in joints.iter().enumerate() {
        let o = layout.coordinate[k];
        let first = match j.kind {
            JointType::Spherical if o != usize::MAX => o,
            JointType::Free if o != usize::MAX => o + 3,
            _ => continue,
        };
        let u = &q.as_slice()[first..first + 4];
        g[row] = u[0] * u[0] + u[1] * u[1] + u[2] * u[2] + u[3] * u[3] - 1.0;
        row += 1;
    }
    g
}

/// World position of each link's centre of mass for poses `poses`.
pub fn centres_of_mass<R: Real, const B: usize>(
    links: &[Link3; B],
    poses: &[Pose3<R>; B],
) -> [[R; 3]; B] {
    core::array::from_fn(|i| poses[i].point(links[i].com))
}

/// The direction of the link-frame vector `local` of link `i` (a helper for
/// readouts such as "where does the pendulum point").
pub fn direction<R: Real>(pose: &Pose3<R>, local: [f64; 3]) -> [R; 3] {
    mul_mv_f(&pose.rot, local)
}
