//! Maximal coordinates: every link's centre of mass x ∈ R³ and orientation
//! q ∈ S³ (unit quaternion), every joint a constraint, and the Lie-group
//! variational integrator on them.
//!
//! # The integrator
//!
//! The state of link i at step k is (x, q, v, ω) with the *discrete*
//! velocities of the step to k+1:
//!
//! ```text
//! x_{k+1} = x_k + Δt·v_k,      q_{k+1} = q_k ⊗ exp(Δt·ω_k)
//! ```
//!
//! (ω in the body frame, exp the exact exponential map, so ω is the
//! constant body rate that carries q_k to q_{k+1}). The discrete Lagrangian
//! is the rectangle rule of the continuous one,
//! L_d = Δt·Σ_i [½m|v_k|² + ½ω_kᵀJω_k + m·g·x_k], exactly as in the planar
//! first-order integrator, and its discrete Euler–Lagrange equations with
//! left-trivialised variations q ↦ q ⊗ exp(η) are, per link (unknowns
//! v_{k+1}, ω_{k+1} and the multipliers λ):
//!
//! ```text
//! m·v_k − m·v_{k+1} + Δt·m·g + Δt·F_x − G_x(k+1)ᵀλ = 0
//! μ⁻(ω_k) − μ⁺(ω_{k+1})      + Δt·F_ω − G_η(k+1)ᵀλ = 0
//! g(x_{k+2}, q_{k+2}) = 0
//! ```
//!
//! with μ∓(ω) = J_r(Δt·ω)^{−ᵀ, −1}·Jω ([`so3::momentum`]), F the damping
//! forces −D(k+1)·(v, ω)_{k+1} plus, for a forced step
//! ([`LieStepper::step_forced`]), the inputs' Σ u_i·∂ṡ_i/∂ν at k+1 (ṡ_i
//! the rate of actuated joint i, [`joint_rates`]), and G the constraint
//! Jacobian with respect to (x, η). Joint springs ½k(s − rest)² enter as
//! potential forces −Δt·k(s − rest)·∂s/∂(x, η) at k+1, where gravity's
//! Δt·m·g does (s by [`joint_coordinate`]); inputs and springs are fixed
//! within the step, so the Newton matrix does not change. These are solved by Newton's method on the KKT system with
//! exact Jacobians and a backtracking line search.
//!
//! Consequences: the discrete momentum map Σ x_{k+1} × m·v_k +
//! R(q_{k+1})·μ⁻(ω_k) is conserved exactly by a free system (angular
//! momentum to solver tolerance); a motion about parallel axes reproduces
//! the planar maximal-coordinate integrator (the rotation angle per step is
//! exactly Δt·ω); constraints hold at position level every step; and
//! quaternions are renormalised after every composition, so
//! |‖q‖ − 1| stays at the rounding level.

use super::geometry::{Motion3, Pose3, cross, mul_mv_f};
use super::model::{
    Joint3, Link3, ModelError, Spatial, joint_coordinate, joint_rates, joint_residual, maximal_rows,
};
use super::so3;
use crate::linalg::{FullPivLu, solve_kkt};

mod derivatives;

use crate::params::Spring;
use crate::real::Jet1;
use crate::step::{RolloutError, StepError, StepOptions};
use nalgebra::{Matrix3, SMatrix, SVector, UnitQuaternion, Vector3};

/// The discrete state of a spatial mechanism in maximal coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpatialState<const B: usize> {
    /// Centre of mass of each link, world coordinates (m).
    pub x: [Vector3<f64>; B],
    /// Orientation of each link frame (link → world).
    pub q: [UnitQuaternion<f64>; B],
    /// Discrete linear velocity (x_{k+1} − x_k)/Δt of each centre of mass.
    pub v: [Vector3<f64>; B],
    /// Discrete body angular velocity: q_{k+1} = q_k ⊗ exp(Δt·ω).
    pub w: [Vector3<f64>; B],
}

/// The largest |‖q‖ − 1| a [`SpatialState`]'s orientations may have when
/// it is stepped: the steps keep ‖q‖ at 1 to rounding (≈ 1e-16 per step),
/// so a larger error means a quaternion that was never normalised (e.g.
/// built with `UnitQuaternion::new_unchecked` from rounded data).
pub const UNIT_TOLERANCE: f64 = 1e-9;

/// Whether a quaternion of norm `norm` is farther than [`UNIT_TOLERANCE`]
/// from unit norm (the one test behind [`SpatialState::non_unit`], the
/// normalisation in [`LieStepper::consistent_state`] and the spatial
/// calibration windows' check). NaN is not reported: callers test
/// finiteness first.
pub fn off_unit_sphere(norm: f64) -> bool {
    (norm - 1.0).abs() > UNIT_TOLERANCE
}

impl<const B: usize> SpatialState<B> {
    /// Checks a state before it is stepped: [`StepError::NonFiniteState { step: None }`]
    /// when an entry is NaN or ±∞, [`StepError::NonUnitQuaternion`] when a
    /// link's |‖q‖ − 1| exceeds [`UNIT_TOLERANCE`] (nalgebra's
    /// `UnitQuaternion` does not enforce its norm, and a non-unit q is not
    /// a rotation: the step would scale the link's geometry by ‖q‖²).
    pub fn validate(&self) -> Result<(), StepError> {
        if !self.is_finite() {
            return Err(StepError::NonFiniteState { step: None });
        }
        match self.non_unit() {
            Some((link, norm)) => Err(StepError::NonUnitQuaternion {
                link,
                norm,
                step: None,
            }),
            None => Ok(()),
        }
    }

    /// The first link whose |‖q‖ − 1| exceeds [`UNIT_TOLERANCE`], with its
    /// ‖q‖.
    pub fn non_unit(&self) -> Option<(usize, f64)> {
        self.q
            .iter()
            .map(|q| q.quaternion().norm())
            .enumerate()
            .find(|(_, n)| off_unit_sphere(*n))
    }

    /// `true` when every entry is finite.
    pub fn is_finite(&self) -> bool {
        self.x
            .iter()
            .chain(&self.v)
            .chain(&self.w)
            .all(|a| a.iter().all(|x| x.is_finite()))
            && self
                .q
                .iter()
                .all(|q| q.quaternion().coords.iter().all(|x| x.is_finite()))
    }

    /// The configuration one step ahead, (x + Δt·v, q ⊗ exp(Δt·ω)).
    pub fn advanced(&self, dt: f64) -> ([Vector3<f64>; B], [UnitQuaternion<f64>; B]) {
        (
            core::array::from_fn(|i| self.x[i] + self.v[i] * dt),
            core::array::from_fn(|i| so3::advance(&self.q[i], &self.w[i], dt)),
        )
    }

    /// The state whose step goes from configuration 0 to configuration 1:
    /// v = (x₁ − x₀)/Δt and ω = log(q₀⁻¹q₁)/Δt (the rotation of less than π).
    pub fn from_configurations(
        x0: &[Vector3<f64>; B],
        q0: &[UnitQuaternion<f64>; B],
        x1: &[Vector3<f64>; B],
        q1: &[UnitQuaternion<f64>; B],
        dt: f64,
    ) -> Self {
        Self {
            x: *x0,
            q: *q0,
            v: core::array::from_fn(|i| (x1[i] - x0[i]) / dt),
            w: core::array::from_fn(|i| so3::log(&(q0[i].inverse() * q1[i])) / dt),
        }
    }

    /// max_i |‖q_i‖ − 1|.
    pub fn norm_error(&self) -> f64 {
        self.q
            .iter()
            .map(|q| (q.quaternion().norm() - 1.0).abs())
            .fold(0.0, f64::max)
    }
}

/// The maximal-coordinate view of a [`Spatial`] description with `B`
/// links, `J` joints, `N` = 6·B velocity unknowns and `C` constraint rows.
/// `mechanism!` returns it from `Name::maximal()` with the right sizes;
/// [`Maximal::check`] verifies them for a hand-written description.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Maximal<S, const B: usize, const J: usize, const N: usize, const C: usize> {
    /// The description.
    pub sys: S,
}

impl<S: Spatial<B, J>, const B: usize, const J: usize, const N: usize, const C: usize>
    Maximal<S, B, J, N, C>
{
    /// Wrap a description (sizes checked by [`Maximal::check`] and by the
    /// stepper).
    pub const fn new(sys: S) -> Self {
        Self { sys }
    }

    /// Validate the description and the sizes: N = 6·B and C = the sum of
    /// the joints' constraint rows.
    pub fn check(&self) -> Result<([Link3; B], [Joint3; J]), ModelError> {
        if N != 6 * B {
            return Err(ModelError::Size("N must be 6 times the number of links"));
        }
        let (links, joints) = super::model::validate(&self.sys)?;
        if maximal_rows(&joints) != C {
            return Err(ModelError::Size(
                "C must be the number of constraint rows of all joints",
            ));
        }
        Ok((links, joints))
    }
}

/// The pose of a link frame from its centre of mass `x` and orientation.
pub fn link_pose(link: &Link3, x: &Vector3<f64>, q: &UnitQuaternion<f64>) -> Pose3<f64> {
    let r = q.to_rotation_matrix();
    let rot: [[f64; 3]; 3] = core::array::from_fn(|i| core::array::from_fn(|j| r[(i, j)]));
    let c = mul_mv_f(&rot, link.com);
    Pose3 {
        origin: [x.x - c[0], x.y - c[1], x.z - c[2]],
        rot,
    }
}

/// The orientation of a rotation matrix (Shepperd's method; the result is
/// normalised, so a slightly non-orthogonal input gives the nearest unit
/// quaternion's direction).
pub fn matrix_to_quaternion(m: &[[f64; 3]; 3]) -> UnitQuaternion<f64> {
    let t = m[0][0] + m[1][1] + m[2][2];
    let q = if t > 0.0 {
        let s = libm::sqrt(t + 1.0) * 2.0;
        nalgebra::Quaternion::new(
            0.25 * s,
            (m[2][1] - m[1][2]) / s,
            (m[0][2] - m[2][0]) / s,
            (m[1][0] - m[0][1]) / s,
        )
    } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
        let s = libm::sqrt(1.0 + m[0][0] - m[1][1] - m[2][2]) * 2.0;
        nalgebra::Quaternion::new(
            (m[2][1] - m[1][2]) / s,
            0.25 * s,
            (m[0][1] + m[1][0]) / s,
            (m[0][2] + m[2][0]) / s,
        )
    } else if m[1][1] > m[2][2] {
        let s = libm::sqrt(1.0 + m[1][1] - m[0][0] - m[2][2]) * 2.0;
        nalgebra::Quaternion::new(
            (m[0][2] - m[2][0]) / s,
            (m[0][1] + m[1][0]) / s,
            0.25 * s,
            (m[1][2] + m[2][1]) / s,
        )
    } else {
        let s = libm::sqrt(1.0 + m[2][2] - m[0][0] - m[1][1]) * 2.0;
        nalgebra::Quaternion::new(
            (m[1][0] - m[0][1]) / s,
            (m[0][2] + m[2][0]) / s,
            (m[1][2] + m[2][1]) / s,
            0.25 * s,
        )
    };
    UnitQuaternion::new_normalize(q)
}

/// A link pose on jets in 12 directions: (δx, η) of the link at `base`
/// (0: parent, 6: child), rot = R·(I + η̂) and origin = x + δx − rot·com,
/// whose first derivatives at zero are those of x + δx, R·exp(η̂).
fn jet_pose(link: &Link3, pose: &Pose3<f64>, x: &Vector3<f64>, base: usize) -> Pose3<Jet1<12>> {
    let e = [
        Jet1::<12>::variable(0.0, base + 3),
        Jet1::variable(0.0, base + 4),
        Jet1::variable(0.0, base + 5),
    ];
    let z = Jet1::constant(0.0);
    let eh = [[z, -e[2], e[1]], [e[2], z, -e[0]], [-e[1], e[0], z]];
    let r = &pose.rot;
    let rot: [[Jet1<12>; 3]; 3] = core::array::from_fn(|i| {
        core::array::from_fn(|c| {
            Jet1::constant(r[i][c]) + eh[0][c] * r[i][0] + eh[1][c] * r[i][1] + eh[2][c] * r[i][2]
        })
    });
    let c = mul_mv_f(&rot, link.com);
    let origin = core::array::from_fn(|i| Jet1::variable(x[i], base + i) - c[i]);
    Pose3 { origin, rot }
}

fn constant_pose(p: &Pose3<f64>) -> Pose3<Jet1<12>> {
    Pose3 {
        origin: p.origin.map(Jet1::constant),
        rot: p.rot.map(|r| r.map(Jet1::constant)),
    }
}

/// Constraint residual g(x, q) of all joints (rows in joint order).
pub fn constraints<const B: usize, const C: usize>(
    links: &[Link3; B],
    joints: &[Joint3],
    x: &[Vector3<f64>; B],
    q: &[UnitQuaternion<f64>; B],
) -> SVector<f64, C> {
    let poses: [Pose3<f64>; B] = core::array::from_fn(|i| link_pose(&links[i], &x[i], &q[i]));
    let mut g = SVector::<f64, C>::zeros();
    let mut row = 0;
    for j in joints {
        let parent = j.parent.map_or_else(Pose3::identity, |p| poses[p]);
        let mut out = [0.0; 6];
        let n = joint_residual(j, &parent, &poses[j.child], &mut out);
        for r in &out[..n] {
            g[row] = *r;
            row += 1;
        }
    }
    g
}

/// Constraint residual and its exact Jacobian G (C × 6B) with respect to
/// (δx_i, η_i) per link, η the left-trivialised (body-frame) rotation.
pub fn constraints_and_jacobian<const B: usize, const N: usize, const C: usize>(
    links: &[Link3; B],
    joints: &[Joint3],
    x: &[Vector3<f64>; B],
    q: &[UnitQuaternion<f64>; B],
) -> (SVector<f64, C>, SMatrix<f64, C, N>) {
    let poses: [Pose3<f64>; B] = core::array::from_fn(|i| link_pose(&links[i], &x[i], &q[i]));
    let mut g = SVector::<f64, C>::zeros();
    let mut jac = SMatrix::<f64, C, N>::zeros();
    let mut row = 0;
    for j in joints {
        let c = j.child;
        let child = jet_pose(&links[c], &poses[c], &x[c], 6);
        let parent = match j.parent {
            Some(p) => jet_pose(&links[p], &poses[p], &x[p], 0),
            None => constant_pose(&Pose3::identity()),
        };
        let mut out = [Jet1::constant(0.0); 6];
        let n = joint_residual(j, &parent, &child, &mut out);
        for r in &out[..n] {
            g[row] = r.v;
            for k in 0..6 {
                jac[(row, 6 * c + k)] = r.g[6 + k];
                if let Some(p) = j.parent {
                    jac[(row, 6 * p + k)] = r.g[k];
                }
            }
            row += 1;
        }
    }
    (g, jac)
}

/// The damping matrix D (6B × 6B, symmetric positive semidefinite) at a
/// configuration: the dissipation ½·Σ_j c_j·|rate_j|² is ½·νᵀDν for the
/// velocities ν = (v_i, ω_i) (ω in the body frame).
pub fn damping_matrix<const B: usize, const N: usize>(
    links: &[Link3; B],
    joints: &[Joint3],
    x: &[Vector3<f64>; B],
    q: &[UnitQuaternion<f64>; B],
) -> SMatrix<f64, N, N> {
    let poses: [Pose3<f64>; B] = core::array::from_fn(|i| link_pose(&links[i], &x[i], &q[i]));
    let mut d = SMatrix::<f64, N, N>::zeros();
    for j in joints {
        if j.damping == 0.0 {
            continue;
        }
        let mut rates = [Jet1::constant(0.0); 3];
        let n = rate_jets(links, &poses, j, &mut rates);
        // columns of the two links in the global ordering
        let col = |k: usize| -> Option<usize> {
            if k < 6 {
                j.parent.map(|p| 6 * p + k)
            } else {
                Some(6 * j.child + k - 6)
            }
        };
        for r in &rates[..n] {
            for a in 0..12 {
                let Some(ia) = col(a) else { continue };
                if r.g[a] == 0.0 {
                    continue;
                }
                for b in 0..12 {
                    if let Some(ib) = col(b) {
                        d[(ia, ib)] += j.damping * r.g[a] * r.g[b];
                    }
                }
            }
        }
    }
    d
}

/// The motion of link `i` at pose `poses[i]` with its velocities
/// (v_com, ω_body) as jets in directions `base..base + 6`.
fn jet_motion<const B: usize>(
    links: &[Link3; B],
    poses: &[Pose3<f64>; B],
    i: usize,
    base: usize,
) -> (Pose3<Jet1<12>>, Motion3<Jet1<12>>) {
    let p = &poses[i];
    let wb = [
        Jet1::<12>::variable(0.0, base + 3),
        Jet1::variable(0.0, base + 4),
        Jet1::variable(0.0, base + 5),
    ];
    let rot = p.rot.map(|r| r.map(Jet1::constant));
    let omega = super::geometry::mul_mv(&rot, wb);
    let vcom = [
        Jet1::variable(0.0, base),
        Jet1::variable(0.0, base + 1),
        Jet1::variable(0.0, base + 2),
    ];
    let arm = mul_mv_f(&rot, links[i].com);
    let velocity = super::geometry::sub(vcom, cross(omega, arm));
    (constant_pose(p), Motion3 { velocity, omega })
}

/// The rates of joint `j` ([`joint_rates`]) as linear forms in the
/// velocities of its parent (directions 0..6) and child (6..12).
fn rate_jets<const B: usize>(
    links: &[Link3; B],
    poses: &[Pose3<f64>; B],
    j: &Joint3,
    out: &mut [Jet1<12>; 3],
) -> usize {
    let (cp, cm) = jet_motion(links, poses, j.child, 6);
    let (pp, pm) = match j.parent {
        Some(p) => jet_motion(links, poses, p, 0),
        None => (constant_pose(&Pose3::identity()), Motion3::zero()),
    };
    joint_rates(j, (&pp, &pm), (&cp, &cm), out)
}

/// Adds `w`·(a 12-entry row over the parent's and child's (δx, η) or
/// (v, ω) columns) into `out`.
fn scatter<const N: usize>(out: &mut SVector<f64, N>, j: &Joint3, row: &[f64; 12], w: f64) {
    for k in 0..6 {
        out[6 * j.child + k] += w * row[6 + k];
        if let Some(p) = j.parent {
            out[6 * p + k] += w * row[k];
        }
    }
}

/// The coordinate s of joint `j` ([`joint_coordinate`], branch within π of
/// `near`) at the configuration (x, q) with its gradient with respect to
/// the parent's (δx, η) (entries 0..6) and the child's (6..12).
fn coordinate_jet<const B: usize>(
    links: &[Link3; B],
    poses: &[Pose3<f64>; B],
    x: &[Vector3<f64>; B],
    j: &Joint3,
    near: f64,
) -> Jet1<12> {
    let c = j.child;
    let child = jet_pose(&links[c], &poses[c], &x[c], 6);
    let parent = match j.parent {
        Some(p) => jet_pose(&links[p], &poses[p], &x[p], 0),
        None => constant_pose(&Pose3::identity()),
    };
    joint_coordinate(j, &parent, &child, near)
}

/// The joint coordinates s_j of every joint at the configuration (x, q)
/// (0 for spherical, fixed and free joints), revolute angles on the branch
/// (near_j − π, near_j + π] ([`joint_coordinate`]).
pub fn joint_coordinates<const B: usize, const J: usize>(
    links: &[Link3; B],
    joints: &[Joint3; J],
    x: &[Vector3<f64>; B],
    q: &[UnitQuaternion<f64>; B],
    near: &[f64; J],
) -> [f64; J] {
    let poses: [Pose3<f64>; B] = core::array::from_fn(|i| link_pose(&links[i], &x[i], &q[i]));
    core::array::from_fn(|k| {
        let j = &joints[k];
        let parent = j.parent.map_or_else(Pose3::identity, |p| poses[p]);
        joint_coordinate(j, &parent, &poses[j.child], near[k])
    })
}

/// The smallest link inertia [`LieStepper`] accepts, relative to the
/// mechanism's scale: a link's mass must be at least this fraction of the
/// largest link mass m_max, and its smallest principal moment of inertia at
/// least this fraction of max(J_max, m_max·L²) (J_max the largest principal
/// moment of any link, L the mechanism's length: the largest link length,
/// centre of mass or link-frame joint anchor distance). These are the
/// diagonal entries of the maximal view's Newton matrix in one unit (kg,
/// rotations scaled by L), so the bound caps their spread at 1e8: with
/// rounding 2.2e-16 the constraint forces on the lightest link are then
/// resolved to ~2e-8 of themselves, and the step's 1e-12 tolerance is still
/// reached. Measured on a Hooke pendulum (a 1 kg, 1 m rod under a cross
/// link between two revolute joints, cross inertia 1e-3·m): the largest
/// |g| over 2 s at Δt = 1 ms grows from 1e-15 at a cross mass ratio 1e-5 to
/// 7e-13 at 1e-8 and 2e-12 at 1e-9, and the first step fails (line search)
/// at 1e-11; a spatial four-bar with a 1e-9 kg cross failed at step 36.
pub const NEGLIGIBLE_INERTIA: f64 = 1e-8;

/// The smallest and largest eigenvalues of a symmetric positive definite
/// 3×3 matrix (trigonometric closed form).
fn principal_extremes(m: &[[f64; 3]; 3]) -> (f64, f64) {
    let p1 = m[0][1] * m[0][1] + m[0][2] * m[0][2] + m[1][2] * m[1][2];
    let d = [m[0][0], m[1][1], m[2][2]];
    if p1 == 0.0 {
        let lo = d[0].min(d[1]).min(d[2]);
        let hi = d[0].max(d[1]).max(d[2]);
        return (lo, hi);
    }
    let q = (d[0] + d[1] + d[2]) / 3.0;
    let p2 = (d[0] - q) * (d[0] - q) + (d[1] - q) * (d[1] - q) + (d[2] - q) * (d[2] - q) + 2.0 * p1;
    let p = libm::sqrt(p2 / 6.0);
    let b = |i: usize, j: usize| (m[i][j] - if i == j { q } else { 0.0 }) / p;
    let det = b(0, 0) * (b(1, 1) * b(2, 2) - b(1, 2) * b(2, 1))
        - b(0, 1) * (b(1, 0) * b(2, 2) - b(1, 2) * b(2, 0))
        + b(0, 2) * (b(1, 0) * b(2, 1) - b(1, 1) * b(2, 0));
    let phi = libm::acos((det / 2.0).clamp(-1.0, 1.0)) / 3.0;
    let hi = q + 2.0 * p * libm::cos(phi);
    let lo = q + 2.0 * p * libm::cos(phi + 2.0 * core::f64::consts::PI / 3.0);
    (lo, hi)
}

/// Refuses a link whose mass or smallest principal moment is below
/// [`NEGLIGIBLE_INERTIA`] of the mechanism's scale
/// ([`StepError::NegligibleInertia`], naming the link).
fn negligible_inertia<const B: usize>(
    names: &[&'static str; B],
    links: &[Link3; B],
    joints: &[Joint3],
) -> Result<(), StepError> {
    let norm = |a: [f64; 3]| libm::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
    let mut length = 0.0f64;
    for l in links {
        length = length.max(l.length).max(norm(l.com));
    }
    for j in joints {
        length = length.max(norm(j.child_anchor));
        if j.parent.is_some() {
            length = length.max(norm(j.parent_anchor));
        }
    }
    let moments = links.map(|l| principal_extremes(&l.inertia));
    let m_max = links.iter().fold(0.0f64, |a, l| a.max(l.mass));
    let j_max = moments.iter().fold(0.0f64, |a, m| a.max(m.1));
    let rotational = j_max.max(m_max * length * length);
    for (i, l) in links.iter().enumerate() {
        let (mass_bound, moment_bound) =
            (NEGLIGIBLE_INERTIA * m_max, NEGLIGIBLE_INERTIA * rotational);
        if l.mass < mass_bound {
            return Err(StepError::NegligibleInertia {
                link: names[i],
                what: "mass",
                value: l.mass,
                bound: mass_bound,
            });
        }
        if moments[i].0 < moment_bound {
            return Err(StepError::NegligibleInertia {
                link: names[i],
                what: "smallest principal moment of inertia",
                value: moments[i].0,
                bound: moment_bound,
            });
        }
    }
    Ok(())
}

/// The compile-time check of an input vector's length `u` against the
/// number of actuated joints (`inputs`): equal, or 0 (no input). Call it
/// in a `const` block.
const fn check_input_count(u: usize, inputs: usize) {
    assert!(
        u == inputs || u == 0,
        "U must equal the number of inputs (or 0: no input)"
    )
}

/// Diagnostics of a converged step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LieStepReport {
    /// Newton iterations used.
    pub iterations: usize,
    /// KKT matrices evaluated and factored (at most `iterations`: the
    /// chord/Newton hybrid reuses one while Newton contracts fast).
    pub factorizations: usize,
    /// Final scaled residual (max-norm).
    pub residual: f64,
}

/// The Lie-group variational integrator of a [`Maximal`] view with a fixed
/// Δt (module docs). Fixed sizes, no allocation.
///
/// Cost per Newton iteration: the constraint Jacobian (one 12-direction
/// jet pass per joint), a 6B × 6B LU and a C × C Schur complement.
#[derive(Clone, Copy, Debug)]
pub struct LieStepper<S, const B: usize, const J: usize, const N: usize, const C: usize> {
    view: Maximal<S, B, J, N, C>,
    links: [Link3; B],
    joints: [Joint3; J],
    inertia: [Matrix3<f64>; B],
    gravity: Vector3<f64>,
    dissipative: bool,
    springs: [Spring; J],
    elastic: bool,
    dt: f64,
    options: StepOptions,
}

impl<S: Spatial<B, J>, const B: usize, const J: usize, const N: usize, const C: usize>
    LieStepper<S, B, J, N, C>
{
    /// A stepper with default options (tolerance 1e-12).
    pub fn new(view: Maximal<S, B, J, N, C>, dt: f64) -> Result<Self, StepError> {
        Self::with_options(view, dt, StepOptions::default())
    }

    /// A stepper with the given options. Checks Δt, the options and the
    /// description ([`Maximal::check`], reported as
    /// [`StepError::InvalidModel`]), and refuses a link of negligible mass
    /// or rotational inertia ([`NEGLIGIBLE_INERTIA`],
    /// [`StepError::NegligibleInertia`] naming the link).
    pub fn with_options(
        view: Maximal<S, B, J, N, C>,
        dt: f64,
        options: StepOptions,
    ) -> Result<Self, StepError> {
        crate::step::check_time_step(dt)?;
        if !(options.tolerance.is_finite() && options.tolerance > 0.0) {
            return Err(StepError::InvalidOptions(
                "tolerance must be finite and > 0",
            ));
        }
        if !(options.min_step > 0.0 && options.min_step <= 1.0) {
            return Err(StepError::InvalidOptions("min_step must be in (0, 1]"));
        }
        let (links, joints) = view.check().map_err(|e| match e {
            ModelError::Invalid(why) | ModelError::Size(why) => StepError::InvalidModel(why),
        })?;
        negligible_inertia(&S::LINKS, &links, &joints)?;
        let inertia = links.map(|l| Matrix3::from_fn(|i, j| l.inertia[i][j]));
        let g = view.sys.gravity();
        let springs = if S::ELASTIC {
            view.sys.springs()
        } else {
            [Spring {
                stiffness: 0.0,
                rest: 0.0,
            }; J]
        };
        Ok(Self {
            view,
            links,
            joints,
            inertia,
            gravity: Vector3::new(g[0], g[1], g[2]),
            dissipative: S::DISSIPATIVE && joints.iter().any(|j| j.damping > 0.0),
            springs,
            elastic: springs.iter().any(|s| s.stiffness != 0.0),
            dt,
            options,
        })
    }

    /// The view.
    pub fn view(&self) -> &Maximal<S, B, J, N, C> {
        &self.view
    }

    /// Δt.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// The links (validated) in declaration order.
    pub fn links(&self) -> &[Link3; B] {
        &self.links
    }

    /// The joints (validated) in declaration order.
    pub fn joints(&self) -> &[Joint3; J] {
        &self.joints
    }

    /// Total energy of a state with its discrete velocities:
    /// Σ ½m|v|² + ½ωᵀJω − m·g·x, plus the springs' Σ ½k(s − rest)².
    pub fn energy(&self, z: &SpatialState<B>) -> f64 {
        let e: f64 = (0..B)
            .map(|i| {
                let m = self.links[i].mass;
                0.5 * m * z.v[i].norm_squared() + 0.5 * z.w[i].dot(&(self.inertia[i] * z.w[i]))
                    - m * self.gravity.dot(&z.x[i])
            })
            .sum();
        if !self.elastic {
            return e;
        }
        let rest = self.springs.map(|s| s.rest);
        let s = joint_coordinates(&self.links, &self.joints, &z.x, &z.q, &rest);
        e + self
            .springs
            .iter()
            .zip(s)
            .map(|(sp, s)| 0.5 * sp.stiffness * (s - sp.rest) * (s - sp.rest))
            .sum::<f64>()
    }

    /// The joint coordinates at the state's configuration, in joint
    /// declaration order (0 for spherical, fixed and free joints): the same
    /// zero as the minimal coordinates; a revolute angle on the branch
    /// within π of its spring's rest angle (0 without a spring), since
    /// orientations carry no winding count.
    pub fn joint_coordinates(&self, z: &SpatialState<B>) -> [f64; J] {
        let rest = self.springs.map(|s| s.rest);
        joint_coordinates(&self.links, &self.joints, &z.x, &z.q, &rest)
    }

    /// Constraint residual g at the state's configuration.
    pub fn constraints(&self, z: &SpatialState<B>) -> SVector<f64, C> {
        constraints(&self.links, &self.joints, &z.x, &z.q)
    }

    /// |g| at the state's configuration.
    pub fn constraint_violation(&self, z: &SpatialState<B>) -> f64 {
        self.constraints(z).norm()
    }

    /// The discrete momentum map of the step from `z`: linear momentum
    /// Σ m·v and angular momentum about the world origin
    /// Σ x_{k+1} × m·v + R(q_{k+1})·μ⁻(ω) (world frame). A free system
    /// conserves both exactly (to solver tolerance); gravity changes the
    /// linear momentum by Δt·Σm·g per step and conserves the angular
    /// momentum's component along g.
    pub fn momentum(&self, z: &SpatialState<B>) -> (Vector3<f64>, Vector3<f64>) {
        let (x1, q1) = z.advanced(self.dt);
        let mut p = Vector3::zeros();
        let mut l = Vector3::zeros();
        for i in 0..B {
            let mv = z.v[i] * self.links[i].mass;
            p += mv;
            l += x1[i].cross(&mv) + q1[i] * so3::momentum(&self.inertia[i], &z.w[i], self.dt, -1.0);
        }
        (p, l)
    }

    /// One step.
    pub fn step(&self, z: &SpatialState<B>) -> Result<SpatialState<B>, StepError> {
        self.step_with_report(z).map(|(z, _)| z)
    }

    /// One step with solver diagnostics.
    pub fn step_with_report(
        &self,
        z: &SpatialState<B>,
    ) -> Result<(SpatialState<B>, LieStepReport), StepError> {
        z.validate()?;
        let guess = pack(&z.v, &z.w);
        self.solve(z, &guess, &[])
    }

    /// One step under inputs `u` (one per actuated joint in declaration
    /// order, [`Spatial::INPUT_JOINTS`]; `U` must equal their number, or be
    /// 0 for no input, checked at compile time), held over the step: input i adds the
    /// generalized force u_i·∂ṡ_i/∂ν at configuration k+1 to the DEL,
    /// where the damping force −D·ν enters (a torque about a revolute
    /// axis on the child and its reaction on the parent, a force along a
    /// prismatic axis). With u = 0 this is [`Self::step`], bit for bit.
    pub fn step_forced<const U: usize>(
        &self,
        z: &SpatialState<B>,
        u: &SVector<f64, U>,
    ) -> Result<SpatialState<B>, StepError>
    where
        S: crate::Inputs<U>,
    {
        self.step_forced_with_report(z, u).map(|(z, _)| z)
    }

    /// [`Self::step_forced`] with solver diagnostics.
    pub fn step_forced_with_report<const U: usize>(
        &self,
        z: &SpatialState<B>,
        u: &SVector<f64, U>,
    ) -> Result<(SpatialState<B>, LieStepReport), StepError>
    where
        S: crate::Inputs<U>,
    {
        const { check_input_count(U, S::INPUT_JOINTS.len()) };
        z.validate()?;
        if !u.iter().all(|x| x.is_finite()) {
            return Err(StepError::NonFiniteInput { step: None });
        }
        let guess = pack(&z.v, &z.w);
        self.solve(z, &guess, u.as_slice())
    }

    /// Fills `out` with the forced trajectory from `z0`: `out[0] = z0`,
    /// then `out[k + 1]` after the step under `inputs[k]` (`inputs` needs
    /// at least `out.len() − 1` entries); Newton starts from the
    /// extrapolation 2ν_k − ν_{k−1}, as [`Self::rollout_into`]. No
    /// allocation.
    pub fn rollout_forced_into<const U: usize>(
        &self,
        z0: &SpatialState<B>,
        inputs: &[SVector<f64, U>],
        out: &mut [SpatialState<B>],
    ) -> Result<(), RolloutError>
    where
        S: crate::Inputs<U>,
    {
        const { check_input_count(U, S::INPUT_JOINTS.len()) };
        let Some((first, rest)) = out.split_first_mut() else {
            return Ok(());
        };
        let fail = |step, error| RolloutError { step, error };
        z0.validate().map_err(|error| fail(0, error))?;
        if inputs.len() < rest.len() {
            return Err(fail(inputs.len(), StepError::NonFiniteInput { step: None }));
        }
        *first = *z0;
        let mut z = *z0;
        let mut prev = pack(&z0.v, &z0.w);
        for (k, (slot, u)) in rest.iter_mut().zip(inputs).enumerate() {
            if !u.iter().all(|x| x.is_finite()) {
                return Err(fail(k, StepError::NonFiniteInput { step: None }));
            }
            let now = pack(&z.v, &z.w);
            let guess = now * 2.0 - prev;
            let (z1, _) = self
                .solve(&z, &guess, u.as_slice())
                .map_err(|error| fail(k, error))?;
            *slot = z1;
            prev = now;
            z = z1;
        }
        Ok(())
    }

    /// Fills `out` with the trajectory from `z0`: `out[0] = z0`, then one
    /// step per entry; Newton starts from the extrapolation 2ν_k − ν_{k−1}.
    /// No allocation.
    pub fn rollout_into(
        &self,
        z0: &SpatialState<B>,
        out: &mut [SpatialState<B>],
    ) -> Result<(), RolloutError> {
        let Some((first, rest)) = out.split_first_mut() else {
            return Ok(());
        };
        z0.validate()
            .map_err(|error| RolloutError { step: 0, error })?;
        *first = *z0;
        let mut z = *z0;
        let mut prev = pack(&z0.v, &z0.w);
        for (k, slot) in rest.iter_mut().enumerate() {
            let now = pack(&z.v, &z.w);
            let guess = now * 2.0 - prev;
            let (z1, _) = self
                .solve(&z, &guess, &[])
                .map_err(|error| RolloutError { step: k, error })?;
            *slot = z1;
            prev = now;
            z = z1;
        }
        Ok(())
    }

    /// Project a configuration onto g(x, q) = 0 by Gauss–Newton
    /// minimum-norm corrections in (δx, η) (x_i += δx_i, q_i ← q_i ⊗
    /// exp(η_i)): the nearest consistent configuration to first order.
    /// Returns the iterations used.
    pub fn project_configuration(
        &self,
        x: &mut [Vector3<f64>; B],
        q: &mut [UnitQuaternion<f64>; B],
    ) -> Result<usize, StepError> {
        if C == 0 {
            return Ok(0);
        }
        for iteration in 0..=self.options.max_iterations {
            let (g, jac) = constraints_and_jacobian::<B, N, C>(&self.links, &self.joints, x, q);
            let scale = 1.0 + x.iter().map(|x| x.amax()).fold(0.0, f64::max);
            let err = g.amax() / scale;
            if !err.is_finite() {
                return Err(StepError::non_finite_residual(iteration));
            }
            if err <= self.options.tolerance {
                return Ok(iteration);
            }
            if iteration == self.options.max_iterations {
                return Err(StepError::not_converged(
                    iteration,
                    err,
                    self.options.tolerance,
                ));
            }
            let y = FullPivLu::new(jac * jac.transpose(), 1e-13).solve(&g);
            let d = jac.transpose() * y;
            for i in 0..B {
                x[i] -= d.fixed_rows::<3>(6 * i);
                q[i] = so3::advance(&q[i], &(-d.fixed_rows::<3>(6 * i + 3)), 1.0);
            }
        }
        unreachable!("the loop returns on its last iteration")
    }

    /// The velocity projection (the spatial form of paper eq. 8): the
    /// velocities ν = (v_i, ω_i) nearest to `nu` (Euclidean) such that the
    /// configuration one step after (x1, q1) is consistent,
    /// g(x1 + Δt·v, q1 ⊗ exp(Δt·ω)) = 0, by Newton on the KKT system
    /// [I  Ĝᵀ; Ĝ  0] (Ĝ = ∂g/∂ν) with a backtracking line search. The
    /// unit norm of the quaternions holds by construction.
    ///
    /// The matrix leaves out the constraints' curvature Σλ_i∇²c_i, which
    /// grows with the multipliers (λ ~ |correction|/Δt): a large correction
    /// then converges linearly, and a full step may lower |c| while raising
    /// the stationarity residual. A step is therefore accepted when it
    /// lowers the larger of the two scaled residuals, or, failing that,
    /// when it satisfies Armijo's condition on the exact ℓ1 merit function
    /// ½‖ν − ν₀‖² + μ‖c‖₁ (μ above every multiplier), for which the step is
    /// a descent direction (Nocedal & Wright, Numerical Optimization,
    /// §18.3).
    pub fn project_velocity(
        &self,
        x1: &[Vector3<f64>; B],
        q1: &[UnitQuaternion<f64>; B],
        nu: &SVector<f64, N>,
    ) -> Result<SVector<f64, N>, StepError> {
        if !nu.iter().all(|v| v.is_finite()) {
            return Err(StepError::NonFiniteState { step: None });
        }
        if C == 0 {
            return Ok(*nu);
        }
        let d = StepData::<B, N, C> {
            x1: *x1,
            q1: *q1,
            b: SVector::zeros(),
            g1t: SMatrix::zeros(),
            damping: SMatrix::zeros(),
            p_scale: 1.0,
            l_scale: 1.0 + x1.iter().map(|x| x.amax()).fold(0.0, f64::max),
        };
        let v_scale = 1.0 + nu.amax();
        let target = *nu;
        let eval = |v: &SVector<f64, N>, l: &SVector<f64, C>, gh: &SMatrix<f64, C, N>| {
            let (x2, q2) = self.config2(&d, v);
            let c = constraints::<B, C>(&self.links, &self.joints, &x2, &q2);
            let r = v - target + gh.transpose() * l;
            let err = (r.amax() / v_scale).max(c.amax() / d.l_scale);
            (r, c, err)
        };
        let mut v = *nu;
        let mut lambda = SVector::<f64, C>::zeros();
        let mut gh = self.jacobian(&d, &v).1;
        let (mut r, mut c, mut err) = eval(&v, &lambda, &gh);
        let eye = SMatrix::<f64, N, N>::identity();
        // the ℓ1 merit function's penalty, raised above the multipliers
        let mut mu = 0.0f64;
        let merit = |v: &SVector<f64, N>, c: &SVector<f64, C>, mu: f64| {
            0.5 * (v - target).norm_squared() + mu * c.lp_norm(1)
        };
        for iteration in 0..=self.options.max_iterations {
            if !err.is_finite() {
                return Err(StepError::non_finite_residual(iteration));
            }
            if err <= self.options.tolerance {
                return Ok(v);
            }
            if iteration == self.options.max_iterations {
                break;
            }
            let Some((dv, dl)) = solve_kkt(&eye, &gh.transpose(), &gh, &(-r), &(-c)) else {
                return Err(StepError::singular(iteration));
            };
            mu = mu.max(1.1 * (lambda + dl).amax());
            let phi = merit(&v, &c, mu);
            // directional derivative of the merit along (dv, Ĝ·dv = −c)
            let slope = (v - target).dot(&dv) - mu * c.lp_norm(1);
            let mut alpha = 1.0;
            loop {
                let (vn, ln) = (v + dv * alpha, lambda + dl * alpha);
                let ghn = self.jacobian(&d, &vn).1;
                let (rn, cn, errn) = eval(&vn, &ln, &ghn);
                let armijo = slope < 0.0 && merit(&vn, &cn, mu) <= phi + 1e-4 * alpha * slope;
                if errn.is_finite() && (errn < err || errn <= self.options.tolerance || armijo) {
                    (v, lambda, gh, r, c, err) = (vn, ln, ghn, rn, cn, errn);
                    break;
                }
                alpha *= 0.5;
                if alpha < self.options.min_step {
                    return Err(StepError::line_search_failed(iteration, err));
                }
            }
        }
        Err(StepError::not_converged(
            self.options.max_iterations,
            err,
            self.options.tolerance,
        ))
    }

    /// A consistent initial state near `z`: its configuration projected
    /// onto g = 0 ([`Self::project_configuration`]) and its velocities
    /// projected so that the next configuration is consistent too
    /// ([`Self::project_velocity`]). A state whose velocities only satisfy
    /// Ġ = 0 would leave the first step off the manifold by O(Δt²). The
    /// guess's quaternions farther than [`UNIT_TOLERANCE`] from unit norm
    /// are normalised first (projected onto the unit sphere, as its
    /// configuration onto the joints), so a guess from rounded data need
    /// not be unit; a zero quaternion is [`StepError::NonUnitQuaternion`].
    /// An already consistent state is returned bit for bit.
    pub fn consistent_state(&self, z: &SpatialState<B>) -> Result<SpatialState<B>, StepError> {
        if !z.is_finite() {
            return Err(StepError::NonFiniteState { step: None });
        }
        let (mut x, mut q) = (z.x, z.q);
        for (link, qi) in q.iter_mut().enumerate() {
            let norm = qi.quaternion().norm();
            if norm.is_nan() || norm <= f64::MIN_POSITIVE {
                return Err(StepError::NonUnitQuaternion {
                    link,
                    norm,
                    step: None,
                });
            }
            // a quaternion the steps accept keeps its bits (a consistent
            // state is returned unchanged)
            if off_unit_sphere(norm) {
                *qi = UnitQuaternion::new_unchecked(qi.quaternion() / norm);
            }
        }
        self.project_configuration(&mut x, &mut q)?;
        let nu = self.project_velocity(&x, &q, &pack(&z.v, &z.w))?;
        let (v, w) = unpack(&nu);
        Ok(SpatialState { x, q, v, w })
    }

    /// The per-step data of the step from `z` under inputs `u` (empty or
    /// zero: none): configuration k+1 and the terms fixed within the step.
    fn prepare(&self, z: &SpatialState<B>, u: &[f64]) -> StepData<B, N, C> {
        let h = self.dt;
        let (x1, q1) = z.advanced(h);
        // b = (m v_k + Δt m g, μ⁻(ω_k)) per link: the ν-independent terms
        let mut b = SVector::<f64, N>::zeros();
        let mut m_bar = 0.0f64;
        for i in 0..B {
            let m = self.links[i].mass;
            let t = z.v[i] * m + self.gravity * (m * h);
            let r = so3::momentum(&self.inertia[i], &z.w[i], h, -1.0);
            b.fixed_rows_mut::<3>(6 * i).copy_from(&t);
            b.fixed_rows_mut::<3>(6 * i + 3).copy_from(&r);
            let jmax = (0..3).map(|k| self.inertia[i][(k, k)]).fold(0.0, f64::max);
            m_bar = m_bar.max(m).max(jmax);
        }
        let forced = u.iter().any(|x| *x != 0.0);
        if self.elastic || forced {
            let poses: [Pose3<f64>; B] =
                core::array::from_fn(|i| link_pose(&self.links[i], &x1[i], &q1[i]));
            // springs: Δt·(−k(s − rest)∇s) at configuration k+1, the
            // potential's place in the DEL (as gravity's Δt·m·g)
            if self.elastic {
                for (j, sp) in self.joints.iter().zip(&self.springs) {
                    if sp.stiffness == 0.0 {
                        continue;
                    }
                    let s = coordinate_jet(&self.links, &poses, &x1, j, sp.rest);
                    scatter(&mut b, j, &s.g, -h * sp.stiffness * (s.v - sp.rest));
                }
            }
            // inputs: Δt·u_i·∂ṡ_i/∂ν at configuration k+1, the damping
            // force's place
            if forced {
                for (&k, &ui) in S::INPUT_JOINTS.iter().zip(u) {
                    if ui == 0.0 {
                        continue;
                    }
                    let j = &self.joints[k];
                    let mut rates = [Jet1::constant(0.0); 3];
                    rate_jets(&self.links, &poses, j, &mut rates);
                    scatter(&mut b, j, &rates[0].g, h * ui);
                }
            }
        }
        let g1t: SMatrix<f64, N, C> = if C > 0 {
            constraints_and_jacobian::<B, N, C>(&self.links, &self.joints, &x1, &q1)
                .1
                .transpose()
        } else {
            SMatrix::zeros()
        };
        let damping: SMatrix<f64, N, N> = if self.dissipative {
            damping_matrix::<B, N>(&self.links, &self.joints, &x1, &q1) * h
        } else {
            SMatrix::zeros()
        };
        StepData {
            p_scale: b.amax() + m_bar,
            l_scale: 1.0 + x1.iter().map(|x| x.amax()).fold(0.0, f64::max),
            x1,
            q1,
            b,
            g1t,
            damping,
        }
    }

    /// Configuration k+2 for the unknowns ν.
    fn config2(
        &self,
        d: &StepData<B, N, C>,
        nu: &SVector<f64, N>,
    ) -> ([Vector3<f64>; B], [UnitQuaternion<f64>; B]) {
        let h = self.dt;
        (
            core::array::from_fn(|i| d.x1[i] + nu.fixed_rows::<3>(6 * i) * h),
            core::array::from_fn(|i| {
                so3::advance(&d.q1[i], &nu.fixed_rows::<3>(6 * i + 3).into_owned(), h)
            }),
        )
    }

    /// The DEL residual r(ν, λ) and the constraint residual c(ν).
    fn residual(
        &self,
        d: &StepData<B, N, C>,
        nu: &SVector<f64, N>,
        lambda: &SVector<f64, C>,
    ) -> (SVector<f64, N>, SVector<f64, C>) {
        let mut r = d.b;
        for i in 0..B {
            let m = self.links[i].mass;
            let v = nu.fixed_rows::<3>(6 * i);
            let w = nu.fixed_rows::<3>(6 * i + 3).into_owned();
            let mut t = r.fixed_rows_mut::<3>(6 * i);
            t -= v * m;
            let mut rr = r.fixed_rows_mut::<3>(6 * i + 3);
            rr -= so3::momentum(&self.inertia[i], &w, self.dt, 1.0);
        }
        if self.dissipative {
            r -= d.damping * nu;
        }
        if C > 0 {
            r -= d.g1t * lambda;
        }
        let c = if C > 0 {
            let (x2, q2) = self.config2(d, nu);
            constraints::<B, C>(&self.links, &self.joints, &x2, &q2)
        } else {
            SVector::zeros()
        };
        (r, c)
    }

    /// The exact Jacobians ∂r/∂ν (N × N) and ∂c/∂ν (C × N); ∂r/∂λ = −G₁ᵀ
    /// and ∂c/∂λ = 0.
    fn jacobian(
        &self,
        d: &StepData<B, N, C>,
        nu: &SVector<f64, N>,
    ) -> (SMatrix<f64, N, N>, SMatrix<f64, C, N>) {
        let g2 = if C > 0 {
            self.constraint_rate_jacobian(d, nu)
        } else {
            SMatrix::zeros()
        };
        (self.newton_matrix(d, nu), g2)
    }

    /// ∂r/∂ν = blockdiag(−m I, −∂μ⁺/∂ω) − Δt D.
    fn newton_matrix(&self, d: &StepData<B, N, C>, nu: &SVector<f64, N>) -> SMatrix<f64, N, N> {
        let h = self.dt;
        let mut a = -d.damping;
        for i in 0..B {
            let m = self.links[i].mass;
            let w = nu.fixed_rows::<3>(6 * i + 3).into_owned();
            for k in 0..3 {
                a[(6 * i + k, 6 * i + k)] -= m;
            }
            let dm = so3::momentum_jacobian(&self.inertia[i], &w, h, 1.0);
            let mut blk = a.fixed_view_mut::<3, 3>(6 * i + 3, 6 * i + 3);
            blk -= dm;
        }
        a
    }

    /// ∂c/∂ν: G(x₂, q₂) with Δt on the v columns and Δt·J_r(Δt ω) on the
    /// ω columns (q₂ = q₁ ⊗ exp(Δt ω)).
    fn constraint_rate_jacobian(
        &self,
        d: &StepData<B, N, C>,
        nu: &SVector<f64, N>,
    ) -> SMatrix<f64, C, N> {
        let h = self.dt;
        let (x2, q2) = self.config2(d, nu);
        let mut g2 = constraints_and_jacobian::<B, N, C>(&self.links, &self.joints, &x2, &q2).1;
        for i in 0..B {
            let w = nu.fixed_rows::<3>(6 * i + 3).into_owned();
            let jr = so3::right_jacobian(&(w * h)) * h;
            let mut vcols = g2.fixed_view_mut::<C, 3>(0, 6 * i);
            vcols *= h;
            let wcols = g2.fixed_view::<C, 3>(0, 6 * i + 3) * jr;
            g2.fixed_view_mut::<C, 3>(0, 6 * i + 3).copy_from(&wcols);
        }
        g2
    }

    /// The residual of the step from `z` at unknowns ν = (v_i, ω_i)_{k+1}
    /// and multipliers λ: the DEL rows r (N) and the constraint rows
    /// c = g(x_{k+2}, q_{k+2}) (C). Zero at the solution of [`Self::step`].
    pub fn del_residual(
        &self,
        z: &SpatialState<B>,
        nu: &SVector<f64, N>,
        lambda: &SVector<f64, C>,
    ) -> (SVector<f64, N>, SVector<f64, C>) {
        self.residual(&self.prepare(z, &[]), nu, lambda)
    }

    /// The exact Jacobian of [`Self::del_residual`] used by Newton:
    /// (∂r/∂ν, ∂r/∂λ, ∂c/∂ν) (∂c/∂λ = 0).
    pub fn del_jacobian(
        &self,
        z: &SpatialState<B>,
        nu: &SVector<f64, N>,
    ) -> (SMatrix<f64, N, N>, SMatrix<f64, N, C>, SMatrix<f64, C, N>) {
        let d = self.prepare(z, &[]);
        let (a, g2) = self.jacobian(&d, nu);
        (a, -d.g1t, g2)
    }

    fn solve(
        &self,
        z: &SpatialState<B>,
        guess: &SVector<f64, N>,
        u: &[f64],
    ) -> Result<(SpatialState<B>, LieStepReport), StepError> {
        self.solve_full(z, guess, u).map(|(z, r, _)| (z, r))
    }

    /// [`Self::solve`] that also returns the multipliers λ.
    #[allow(clippy::type_complexity)]
    fn solve_full(
        &self,
        z: &SpatialState<B>,
        guess: &SVector<f64, N>,
        u: &[f64],
    ) -> Result<(SpatialState<B>, LieStepReport, SVector<f64, C>), StepError> {
        let d = self.prepare(z, u);
        let eval = |nu: &SVector<f64, N>, lambda: &SVector<f64, C>| {
            let (r, c) = self.residual(&d, nu, lambda);
            let err = (r.amax() / d.p_scale).max(c.amax() / d.l_scale);
            (r, c, err)
        };
        let mut nu = if guess.iter().all(|x| x.is_finite()) {
            *guess
        } else {
            pack(&z.v, &z.w)
        };
        let mut lambda = SVector::<f64, C>::zeros();
        let (mut r, mut c, mut err) = eval(&nu, &lambda);
        // Chord/Newton hybrid: the factored KKT matrix is kept while Newton
        // contracts fast (error down by 1e-2 or more per iteration) and
        // refreshed at the current iterate otherwise, or when a line search
        // had to backtrack. The converged step is the same (same residual,
        // same tolerance); only the path to it changes.
        let mut kkt: Option<Kkt<B, N, C>> = None;
        let mut factorizations = 0;
        for iteration in 0..=self.options.max_iterations {
            if !err.is_finite() {
                return Err(StepError::non_finite_residual(iteration));
            }
            if err <= self.options.tolerance {
                let (v, w) = unpack(&nu);
                return Ok((
                    SpatialState {
                        x: d.x1,
                        q: d.q1,
                        v,
                        w,
                    },
                    LieStepReport {
                        iterations: iteration,
                        factorizations,
                        residual: err,
                    },
                    lambda,
                ));
            }
            if iteration == self.options.max_iterations {
                break;
            }
            let fresh = kkt.is_none();
            if fresh {
                factorizations += 1;
                kkt = Some(self.factor(&d, &nu).ok_or(StepError::singular(iteration))?);
            }
            let Some(factor) = kkt.as_ref() else {
                return Err(StepError::singular(iteration));
            };
            let (dnu, dl) = factor.solve(&(-r), &(-c));
            let mut alpha = 1.0;
            loop {
                let (nn, ln) = (nu + dnu * alpha, lambda + dl * alpha);
                let (rn, cn, errn) = eval(&nn, &ln);
                if errn.is_finite() && (errn < err || errn <= self.options.tolerance) {
                    if alpha < 1.0 || errn > 1e-2 * err {
                        kkt = None;
                    }
                    (nu, lambda, r, c, err) = (nn, ln, rn, cn, errn);
                    break;
                }
                alpha *= 0.5;
                if alpha < self.options.min_step {
                    if !fresh {
                        // no decrease along the stale direction: refresh
                        kkt = None;
                        break;
                    }
                    return Err(StepError::line_search_failed(iteration, err));
                }
            }
        }
        Err(StepError::not_converged(
            self.options.max_iterations,
            err,
            self.options.tolerance,
        ))
    }

    /// The KKT matrix [A  −G₁ᵀ; Ĝ₂  0] at ν, factored: A⁻¹ blockwise
    /// (A = blockdiag(−m I, −∂μ⁺/∂ω) without damping) or by LU with
    /// complete pivoting (with damping, which couples the links), and the
    /// Schur complement S = Ĝ₂A⁻¹(−G₁ᵀ) by LU with complete pivoting (a
    /// rank-deficient S drops only the deficient multiplier). `None` when
    /// A is singular.
    fn factor(&self, d: &StepData<B, N, C>, nu: &SVector<f64, N>) -> Option<Kkt<B, N, C>> {
        let h = self.dt;
        let inverse = if self.dissipative {
            let lu = FullPivLu::new(self.newton_matrix(d, nu), 1e-14);
            if lu.rank() < N {
                return None;
            }
            AInverse::Dense(lu)
        } else {
            // A = blockdiag(−m I, −∂μ⁺/∂ω): invert per link without forming A
            let mut blocks = [(0.0, Matrix3::zeros()); B];
            for (i, blk) in blocks.iter_mut().enumerate() {
                let w = nu.fixed_rows::<3>(6 * i + 3).into_owned();
                let dm = so3::momentum_jacobian(&self.inertia[i], &w, h, 1.0);
                *blk = (-1.0 / self.links[i].mass, (-dm).try_inverse()?);
            }
            AInverse::Blocks(blocks)
        };
        let g2 = if C > 0 {
            self.constraint_rate_jacobian(d, nu)
        } else {
            SMatrix::zeros()
        };
        let ainv_b = inverse.apply_matrix(&d.g1t) * -1.0;
        let s = g2 * ainv_b;
        if !(ainv_b.iter().chain(s.iter()).all(|x| x.is_finite())) {
            return None;
        }
        Some(Kkt {
            inverse,
            ainv_b,
            g2,
            schur: FullPivLu::new(s, 1e-13),
        })
    }
}

/// A⁻¹ of the Newton matrix's momentum block.
#[derive(Clone, Copy, Debug)]
enum AInverse<const B: usize, const N: usize> {
    /// Per link: 1/(−m) for the translation and the inverse of −∂μ⁺/∂ω.
    Blocks([(f64, Matrix3<f64>); B]),
    /// LU with complete pivoting of the whole matrix (damped links couple).
    Dense(FullPivLu<N>),
}

impl<const B: usize, const N: usize> AInverse<B, N> {
    fn apply(&self, r: &SVector<f64, N>) -> SVector<f64, N> {
        match self {
            AInverse::Dense(lu) => lu.solve(r),
            AInverse::Blocks(blocks) => {
                let mut x = SVector::<f64, N>::zeros();
                for (i, (inv_m, w)) in blocks.iter().enumerate() {
                    let t = r.fixed_rows::<3>(6 * i) * *inv_m;
                    x.fixed_rows_mut::<3>(6 * i).copy_from(&t);
                    let o = w * r.fixed_rows::<3>(6 * i + 3);
                    x.fixed_rows_mut::<3>(6 * i + 3).copy_from(&o);
                }
                x
            }
        }
    }

    fn apply_matrix<const K: usize>(&self, m: &SMatrix<f64, N, K>) -> SMatrix<f64, N, K> {
        match self {
            AInverse::Dense(lu) => lu.solve_matrix(m),
            AInverse::Blocks(blocks) => {
                let mut out = SMatrix::<f64, N, K>::zeros();
                for (i, (inv_m, w)) in blocks.iter().enumerate() {
                    let t = m.fixed_view::<3, K>(6 * i, 0) * *inv_m;
                    out.fixed_view_mut::<3, K>(6 * i, 0).copy_from(&t);
                    let o = w * m.fixed_view::<3, K>(6 * i + 3, 0);
                    out.fixed_view_mut::<3, K>(6 * i + 3, 0).copy_from(&o);
                }
                out
            }
        }
    }
}

/// A factored KKT matrix of one Newton step (see `LieStepper::factor`).
#[derive(Clone, Copy, Debug)]
struct Kkt<const B: usize, const N: usize, const C: usize> {
    inverse: AInverse<B, N>,
    ainv_b: SMatrix<f64, N, C>,
    g2: SMatrix<f64, C, N>,
    schur: FullPivLu<C>,
}

impl<const B: usize, const N: usize, const C: usize> Kkt<B, N, C> {
    /// Solve [A  B; Ĝ₂  0][x; y] = [r; c] (B = −G₁ᵀ).
    fn solve(
        &self,
        r: &SVector<f64, N>,
        c: &SVector<f64, C>,
    ) -> (SVector<f64, N>, SVector<f64, C>) {
        let ar = self.inverse.apply(r);
        if C == 0 {
            return (ar, SVector::zeros());
        }
        let y = self.schur.solve(&(self.g2 * ar - c));
        (ar - self.ainv_b * y, y)
    }
}

/// What a step fixes before its Newton iterations.
#[derive(Clone, Copy, Debug)]
struct StepData<const B: usize, const N: usize, const C: usize> {
    x1: [Vector3<f64>; B],
    q1: [UnitQuaternion<f64>; B],
    b: SVector<f64, N>,
    g1t: SMatrix<f64, N, C>,
    damping: SMatrix<f64, N, N>,
    p_scale: f64,
    l_scale: f64,
}

/// (v_i, ω_i) stacked per link.
pub fn pack<const B: usize, const N: usize>(
    v: &[Vector3<f64>; B],
    w: &[Vector3<f64>; B],
) -> SVector<f64, N> {
    let mut nu = SVector::<f64, N>::zeros();
    for i in 0..B {
        nu.fixed_rows_mut::<3>(6 * i).copy_from(&v[i]);
        nu.fixed_rows_mut::<3>(6 * i + 3).copy_from(&w[i]);
    }
    nu
}

/// The inverse of [`pack`].
pub fn unpack<const B: usize, const N: usize>(
    nu: &SVector<f64, N>,
) -> ([Vector3<f64>; B], [Vector3<f64>; B]) {
    (
        core::array::from_fn(|i| nu.fixed_rows::<3>(6 * i).into_owned()),
        core::array::from_fn(|i| nu.fixed_rows::<3>(6 * i + 3).into_owned()),
    )
}
