//! The [`Mechanism`] trait that `mechanism!`-generated code implements, the
//! scalar bound it is generic over, and the discrete state.

use nalgebra::SVector;
use num_dual::DualNum;

/// The scalar every generated function is generic over: `f64`, or any
/// num-dual number over `f64` (dual, dual-vector, hyper-dual, nested).
///
/// One function body serves values and exact derivatives of any order.
pub trait Scalar: DualNum<Primitive = f64> + Copy + vigp_core::Real {}
impl<T: DualNum<Primitive = f64> + Copy> Scalar for T {}

pub use vigp_core::state::{CoordinateKind, State};

/// A planar mechanical model with `N` generalized coordinates and `C` scalar
/// holonomic constraints g(q) = 0.
///
/// Implemented by the code that `mechanism!` generates, once per coordinate
/// view (minimal, maximal), on top of its closed-form terms
/// ([`vigp_core::Dynamics`], which every integrator runs on; it also holds
/// [`Dynamics::KINDS`](vigp_core::Dynamics::KINDS) and
/// [`Dynamics::DISSIPATIVE`](vigp_core::Dynamics::DISSIPATIVE)).
///
/// The functions of this trait are the **reference path**: the Lagrangian,
/// Rayleigh function and constraints generic over the [`Scalar`], so that
/// exact first and second derivatives follow by evaluating the same body on
/// dual numbers ([`crate::del`], [`crate::dynamics`]). They are independent of
/// the symbolic derivation behind the closed forms, and the tests check one
/// against the other.
pub trait Mechanism<const N: usize, const C: usize>: vigp_core::Dynamics<N, C> {
    /// Names of the generalized coordinates, in order.
    const COORDINATES: [&'static str; N];

    /// Kinetic energy T(q, v).
    fn kinetic_energy<D: Scalar>(&self, q: &SVector<D, N>, v: &SVector<D, N>) -> D;

    /// Potential energy V(q) (gravity).
    fn potential_energy<D: Scalar>(&self, q: &SVector<D, N>) -> D;

    /// Lagrangian L(q, v) = T − V.
    fn lagrangian<D: Scalar>(&self, q: &SVector<D, N>, v: &SVector<D, N>) -> D {
        self.kinetic_energy(q, v) - self.potential_energy(q)
    }

    /// Rayleigh dissipation function R(q, v) = ½ Σ c_j ṡ_j², with ṡ_j the rate
    /// of joint j. The generalized non-conservative force is F = −∂R/∂v.
    fn dissipation<D: Scalar>(&self, q: &SVector<D, N>, v: &SVector<D, N>) -> D {
        let _ = (q, v);
        D::zero()
    }

    /// Virtual work of the inputs W(q; u) = Σ_i u_i s_i(q), s_i the
    /// coordinate of actuated joint i (in declaration order; missing
    /// entries of `u` count as 0): the generalized input force is ∇_q W
    /// ([`Mechanism::input_force`]). Zero for an unactuated mechanism.
    fn input_work<D: Scalar>(&self, q: &SVector<D, N>, u: &[f64]) -> D {
        let _ = (q, u);
        D::zero()
    }

    /// Generalized input force B(q)u = ∇_q W(q; u) (exact, by dual
    /// numbers): the reference of the generated
    /// [`input_matrix`](vigp_core::Dynamics::input_matrix).
    fn input_force<D: Scalar>(&self, q: &SVector<D, N>, u: &[f64]) -> SVector<D, N> {
        if <Self as vigp_core::Dynamics<N, C>>::INPUTS == 0 {
            return SVector::from_element(D::zero());
        }
        num_dual::gradient(|x| self.input_work(&x, u), q).1
    }

    /// Holonomic constraints g(q) (empty for a tree in minimal coordinates).
    fn constraints<D: Scalar>(&self, q: &SVector<D, N>) -> SVector<D, C> {
        let _ = q;
        SVector::from_element(D::zero())
    }

    /// Total energy T + V of a state, with its discrete velocity.
    fn energy(&self, z: &State<N>) -> f64 {
        self.kinetic_energy(&z.q, &z.v) + self.potential_energy(&z.q)
    }

    /// Euclidean norm |g(q)| of the constraint violation (0 for a tree).
    fn constraint_violation(&self, z: &State<N>) -> f64 {
        if C == 0 {
            return 0.0;
        }
        self.constraints(&z.q).norm()
    }

    /// Generalized non-conservative forces F(q, v) = −∂R/∂v (exact, by
    /// dual numbers).
    fn generalized_forces<D: Scalar>(&self, q: &SVector<D, N>, v: &SVector<D, N>) -> SVector<D, N> {
        if !<Self as vigp_core::Dynamics<N, C>>::DISSIPATIVE {
            return SVector::from_element(D::zero());
        }
        let q = q.map(num_dual::DualVec::from_re);
        let (_, grad) = num_dual::gradient(|v| self.dissipation(&q, &v), v);
        -grad
    }

    /// Constraint Jacobian G(q) = ∂g/∂q (C × N), exact.
    fn constraint_jacobian(&self, q: &SVector<f64, N>) -> nalgebra::SMatrix<f64, C, N> {
        if C == 0 {
            return nalgebra::SMatrix::zeros();
        }
        num_dual::jacobian(|q| self.constraints(&q), q).1
    }

    /// A state from position and velocity arrays (see [`State::new`]).
    fn state(&self, q: [f64; N], v: [f64; N]) -> State<N> {
        State::new(q, v)
    }
}

/// Scale for constraint residuals: 1 + the largest |coordinate| among the
/// length coordinates (angles are left out: a link that has spun many turns
/// must not loosen the tolerance on its joints).
pub fn length_scale<M: Mechanism<N, C>, const N: usize, const C: usize>(
    q: &SVector<f64, N>,
) -> f64 {
    let mut s = 0.0f64;
    for (x, kind) in q.iter().zip(<M as vigp_core::Dynamics<N, C>>::KINDS.iter()) {
        if *kind == CoordinateKind::Length {
            s = s.max(x.abs());
        }
    }
    1.0 + s
}

/// The map between a mechanism's minimal coordinates (`N`) and its maximal
/// coordinates (`M` = 3 per link: x, y of the centre of mass and θ),
/// implemented by the generated minimal view.
pub trait Coordinates<const N: usize, const M: usize> {
    /// Maximal positions X(q) (exact, generic so that derivatives follow).
    fn maximal_positions<D: Scalar>(&self, q: &SVector<D, N>) -> SVector<D, M>;

    /// Minimal positions q(X) of a maximal configuration (each tree joint's
    /// relative angle or slide, read off the link poses). Exact inverse of
    /// [`Coordinates::maximal_positions`] on consistent configurations.
    fn minimal_positions(&self, x: &SVector<f64, M>) -> SVector<f64, N>;

    /// Continuous maximal velocity Ẋ = (∂X/∂q)·q̇ (exact, by a dual number).
    fn maximal_velocity(&self, q: &SVector<f64, N>, qdot: &SVector<f64, N>) -> SVector<f64, M> {
        // q + ε·q̇: the ε part of X carries (∂X/∂q)·q̇
        self.maximal_positions(&q.zip_map(qdot, num_dual::Dual::new))
            .map(|x| x.eps)
    }

    /// A discrete minimal state as a discrete maximal state: X_k = X(q_k) and
    /// V_k = (X(q_k + Δt·v_k) − X(q_k))/Δt, so that the maximal discrete
    /// trajectory is exactly the image of the minimal one.
    ///
    /// Δt must be a valid time step (`vigp_core::step::check_time_step`):
    /// the conversion has no error path and does not check it; with Δt = 0,
    /// NaN or ±∞ the velocities are not finite, which every step then
    /// refuses ([`crate::newton::StepError::NonFiniteState`]).
    fn to_maximal(&self, z: &State<N>, dt: f64) -> State<M> {
        let x0 = self.maximal_positions(&z.q);
        let x1 = self.maximal_positions(&(z.q + z.v * dt));
        State::from_positions(x0, &x1, dt)
    }

    /// A discrete maximal state as a discrete minimal state (the inverse of
    /// [`Coordinates::to_maximal`] on consistent states).
    ///
    /// Δt must be a valid time step (`vigp_core::step::check_time_step`):
    /// the conversion has no error path and does not check it; with Δt = 0,
    /// NaN or ±∞ the velocities are not finite, which every step then
    /// refuses ([`crate::newton::StepError::NonFiniteState`]).
    fn to_minimal(&self, z: &State<M>, dt: f64) -> State<N> {
        let q0 = self.minimal_positions(&z.q);
        let q1 = self.minimal_positions(&(z.q + z.v * dt));
        State::from_positions(q0, &q1, dt)
    }
}
