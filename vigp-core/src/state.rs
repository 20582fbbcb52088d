//! The discrete state of a model and what its coordinates measure.

use nalgebra::SVector;

/// What a generalized coordinate measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CoordinateKind {
    /// An angle in radians (revolute joint, or a link orientation).
    Angle,
    /// A length in metres (prismatic slide, or a position).
    Length,
    /// A component of a unit quaternion (dimensionless, in [−1, 1]): the
    /// four coordinates of a spatial mechanism's spherical or free joint in
    /// minimal coordinates, held on the unit sphere by a constraint.
    Quaternion,
}

/// A discrete state z = (q, v) of an `N`-coordinate model.
///
/// `v` is the **discrete** velocity v_k = (q_{k+1} − q_k)/Δt of the
/// variational integrators (paper eq. 5–6), not a continuous-time velocity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct State<const N: usize> {
    /// Generalized positions q.
    pub q: SVector<f64, N>,
    /// (Discrete) generalized velocities v.
    pub v: SVector<f64, N>,
}

impl<const N: usize> State<N> {
    /// A state from position and velocity arrays.
    pub fn new(q: [f64; N], v: [f64; N]) -> Self {
        Self {
            q: SVector::from(q),
            v: SVector::from(v),
        }
    }

    /// The discrete state at `q0` whose configuration Δt later is `q1`:
    /// (q₀, (q₁ − q₀)/Δt), the velocity convention of every variational
    /// integrator here (paper eq. 5–6). Δt is not checked: with Δt = 0,
    /// NaN or ±∞ the velocities are not finite, which every step refuses.
    pub fn from_positions(q0: SVector<f64, N>, q1: &SVector<f64, N>, dt: f64) -> Self {
        Self {
            v: discrete_velocity(&q0, q1, dt),
            q: q0,
        }
    }

    /// `true` when every entry is finite (no NaN, no ±∞).
    pub fn is_finite(&self) -> bool {
        self.q.iter().chain(self.v.iter()).all(|x| x.is_finite())
    }
}

/// The discrete velocity (q₁ − q₀)/Δt between two configurations Δt apart
/// ([`State::from_positions`]).
pub fn discrete_velocity<const N: usize>(
    q0: &SVector<f64, N>,
    q1: &SVector<f64, N>,
    dt: f64,
) -> SVector<f64, N> {
    (q1 - q0) / dt
}
