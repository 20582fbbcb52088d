//! The map between the two views of a spatial mechanism: a minimal
//! configuration gives every link's centre of mass and orientation
//! (forward kinematics); a consistent maximal configuration gives back the
//! joint coordinates (angles, slides, quaternions) of the tree joints.
//!
//! Discrete states map through their two configurations, so that a
//! maximal discrete trajectory is exactly the image of the minimal one:
//! X_k = X(q_k), X_{k+1} = X(q_k + Δt·v_k).

use super::geometry::{Mat3, Pose3, dot, mul_mm_f, mul_mtm, mul_mtv, sub, vee_skew};
use super::maximal::{SpatialState, link_pose, matrix_to_quaternion};
use super::minimal::poses;
use super::model::{JointType, Layout, Spatial, rel_matrix};
use crate::state::State;
use nalgebra::{SVector, UnitQuaternion, Vector3};

/// The minimal coordinates of the reference configuration: every angle
/// and slide zero, every quaternion (1, 0, 0, 0), every free joint's
/// translation zero.
pub fn reference<S: Spatial<B, J>, const B: usize, const J: usize, const N: usize>(
    sys: &S,
) -> SVector<f64, N> {
    let joints = sys.joints();
    let layout = Layout::of::<S, B>(&joints);
    let mut q = SVector::<f64, N>::zeros();
    for (k, j) in joints.iter().enumerate() {
        let o = layout.coordinate[k];
        match j.kind {
            JointType::Spherical if o != usize::MAX => q[o] = 1.0,
            JointType::Free if o != usize::MAX => q[o + 3] = 1.0,
            _ => {}
        }
    }
    q
}

/// Centres of mass and orientations of every link for minimal coordinates
/// `q` (quaternion coordinates are used as given: keep them unit).
pub fn configuration<S: Spatial<B, J>, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<f64, N>,
) -> ([Vector3<f64>; B], [UnitQuaternion<f64>; B]) {
    let p = poses::<S, f64, B, J, N>(sys, q);
    let links = sys.links();
    (
        core::array::from_fn(|i| {
            let c = p[i].point(links[i].com);
            Vector3::new(c[0], c[1], c[2])
        }),
        core::array::from_fn(|i| matrix_to_quaternion(&p[i].rot)),
    )
}

/// The maximal discrete state of a minimal discrete state.
///
/// Δt must be a valid time step ([`crate::step::check_time_step`]): the
/// conversion has no error path and does not check it; with Δt = 0, NaN or
/// ±∞ the velocities are not finite, which every step then refuses
/// ([`crate::StepError::NonFiniteState { step: None }`]).
pub fn to_maximal<S: Spatial<B, J>, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    z: &State<N>,
    dt: f64,
) -> SpatialState<B> {
    let (x0, q0) = configuration::<S, B, J, N>(sys, &z.q);
    let (x1, q1) = configuration::<S, B, J, N>(sys, &(z.q + z.v * dt));
    SpatialState::from_configurations(&x0, &q0, &x1, &q1, dt)
}

fn wrap_near(theta: f64, near: f64) -> f64 {
    let two_pi = 2.0 * core::f64::consts::PI;
    theta + two_pi * libm::round((near - theta) / two_pi)
}

/// The angles (θ₁, θ₂) in (−π, π] of a universal joint with axes `a1`,
/// `a2` (unit, not parallel) from its relative rotation
/// E = Rot(a₁, θ₁)·Rot(a₂, θ₂) (exact when E is of that form): θ₁ turns a₂
/// into E a₂ about a₁ (both projected on the plane normal to a₁), θ₂ is
/// the angle of Rot(a₁, −θ₁)·E about a₂.
pub fn universal_angles(e: &Mat3<f64>, a1: [f64; 3], a2: [f64; 3]) -> (f64, f64) {
    use super::geometry::{axis_angle, cross, mul_mm, mul_mv_f, scale_f};
    let ea2 = mul_mv_f(e, a2);
    let p = sub(a2, scale_f(a1, dot(a1, a2)));
    let pe = sub(ea2, scale_f(a1, dot(a1, ea2)));
    let t1 = libm::atan2(dot(a1, cross(p, pe)), dot(p, pe));
    let f = mul_mm(&axis_angle(a1, -t1), e);
    let s = dot(vee_skew(&f), a2);
    let c = 0.5 * (f[0][0] + f[1][1] + f[2][2] - 1.0);
    (t1, libm::atan2(s, c))
}

/// The joint coordinates of the tree joints read off a maximal
/// configuration (exact on consistent configurations). With `near`,
/// angles are unwrapped to the nearest multiple of 2π and quaternion signs
/// chosen to match it; otherwise angles are in (−π, π] and quaternions have
/// w ≥ 0.
pub fn minimal_coordinates<S: Spatial<B, J>, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    x: &[Vector3<f64>; B],
    q: &[UnitQuaternion<f64>; B],
    near: Option<&SVector<f64, N>>,
) -> SVector<f64, N> {
    let links = sys.links();
    let joints = sys.joints();
    let layout = Layout::of::<S, B>(&joints);
    let poses: [Pose3<f64>; B] = core::array::from_fn(|i| link_pose(&links[i], &x[i], &q[i]));
    let mut out = SVector::<f64, N>::zeros();
    for (k, j) in joints.iter().enumerate() {
        let o = layout.coordinate[k];
        if o == usize::MAX {
            continue;
        }
        let parent = j.parent.map_or_else(Pose3::identity, |p| poses[p]);
        let child = &poses[j.child];
        let rel = rel_matrix(j.rel);
        let rel_t = [
            [rel[0][0], rel[1][0], rel[2][0]],
            [rel[0][1], rel[1][1], rel[2][1]],
            [rel[0][2], rel[1][2], rel[2][2]],
        ];
        // E = R_pᵀ R_c Qᵀ
        let e: Mat3<f64> = mul_mm_f(&mul_mtm(&parent.rot, &child.rot), &rel_t);
        let d = sub(child.point(j.child_anchor), parent.point(j.parent_anchor));
        let quat = |first: usize, out: &mut SVector<f64, N>| {
            let u = matrix_to_quaternion(&e);
            let mut u = [u.w, u.i, u.j, u.k];
            let flip = match near {
                Some(n) => (0..4).map(|i| u[i] * n[first + i]).sum::<f64>() < 0.0,
                None => u[0] < 0.0,
            };
            if flip {
                u = u.map(|x| -x);
            }
            for (i, c) in u.iter().enumerate() {
                out[first + i] = *c;
            }
        };
        match j.kind {
            JointType::Revolute => {
                let s = dot(vee_skew(&e), j.axis);
                let c = 0.5 * (e[0][0] + e[1][1] + e[2][2] - 1.0);
                let th = libm::atan2(s, c);
                out[o] = near.map_or(th, |n| wrap_near(th, n[o]));
            }
            JointType::Prismatic => {
                out[o] = dot(mul_mtv(&parent.rot, d), j.axis);
            }
            JointType::Spherical => quat(o, &mut out),
            JointType::Free => {
                let local = mul_mtv(&parent.rot, d);
                for (i, c) in local.iter().enumerate() {
                    out[o + i] = *c;
                }
                quat(o + 3, &mut out);
            }
            JointType::Fixed => {}
            JointType::Universal { second } => {
                let (t1, t2) = universal_angles(&e, j.axis, second);
                out[o] = near.map_or(t1, |n| wrap_near(t1, n[o]));
                out[o + 1] = near.map_or(t2, |n| wrap_near(t2, n[o + 1]));
            }
        }
    }
    out
}

/// The minimal discrete state of a consistent maximal state (the inverse
/// of [`to_maximal`]): q_k from configuration k, q_{k+1} from configuration
/// k+1 unwrapped near q_k, v = (q_{k+1} − q_k)/Δt.
///
/// Δt must be a valid time step ([`crate::step::check_time_step`]): the
/// conversion has no error path and does not check it; with Δt = 0, NaN or
/// ±∞ the velocities are not finite, which every step then refuses
/// ([`crate::StepError::NonFiniteState { step: None }`]).
pub fn to_minimal<S: Spatial<B, J>, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    z: &SpatialState<B>,
    dt: f64,
) -> State<N> {
    let q0 = minimal_coordinates::<S, B, J, N>(sys, &z.x, &z.q, None);
    let (x1, qq1) = z.advanced(dt);
    let q1 = minimal_coordinates::<S, B, J, N>(sys, &x1, &qq1, Some(&q0));
    State::from_positions(q0, &q1, dt)
}
