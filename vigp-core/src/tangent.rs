//! The tangent space of a discrete state: step derivatives A and B for
//! controllers (LQR, MPC) in 2·DoF coordinates when some coordinates are
//! unit quaternions.
//!
//! A spatial mechanism's minimal view holds each spherical (or free)
//! joint's rotation as a unit quaternion, four coordinates with a norm
//! constraint. Its exact step derivatives A = ∂z₁/∂z₀ and B = ∂z₁/∂u
//! (`Stepper::step_with_derivatives`) are then 2N × 2N and 2N × U in those
//! redundant coordinates; a controller wants them in a chart of the state
//! manifold, 2·DoF × 2·DoF with DoF = N − (number of quaternions).
//!
//! # The chart
//!
//! A discrete state z = (q, v) holds two configurations, q and
//! q⁺ = q + Δt·v. Its tangent coordinates δ = (δq, δv) (each of length
//! DoF, in coordinate order, three entries per quaternion) act by the
//! [retraction](Tangent::retract):
//!
//! * a scalar coordinate (angle or length): q' = q + δq, v' = v + δv;
//! * a quaternion Q = q[i..i+4] (w, x, y, z) with discrete body rate
//!   ω = log(Q⁻¹ ⊗ Q⁺)/Δt: Q' = Q ⊗ exp(δq), ω' = ω + δv,
//!   Q⁺' = Q' ⊗ exp(Δt·ω'), and v' = (Q⁺' − Q')/Δt.
//!
//! So δq is a right (body-frame) rotation of the joint's quaternion and δv
//! a change of its discrete body rate: the velocity convention
//! log(R₀ᵀR₁)/Δt of the Lie-group integrator. The [local map](Tangent::local)
//! is the inverse: the tangent coordinates of z relative to a base state.
//! Without quaternions the chart is the identity (δ = z − z_base).
//!
//! [`Tangent::derivatives`] turns A and B into Ã = P(z₁)·A·E(z₀) and
//! B̃ = P(z₁)·B, with E = ∂retract/∂δ (closed form: quaternion products
//! and the right Jacobian of exp) and P(z₁) = (EᵀE)⁻¹Eᵀ at z₁, which
//! inverts E on the tangent space of the state manifold, where A·E and B
//! map since the step keeps every quaternion on the unit sphere. Ã and B̃
//! are the derivatives of δ₁ = local(z₁, step(retract(z₀, δ₀), u)) with
//! respect to δ₀ and u: they agree with central finite differences
//! through the retraction (tests/step/tangent.rs).
//!
//! Loop constraints are not charted: with loops, δ ranges over the chart
//! of the quaternion manifold, of which the loop manifold is a submanifold.

use crate::forced::StepDerivatives;
use crate::linalg::PartialLu;
use crate::spatial::so3;
use crate::state::{CoordinateKind, State};
use nalgebra::{Quaternion, SMatrix, UnitQuaternion, Vector3};

/// Why a tangent chart or a tangent-space Jacobian could not be formed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TangentError {
    /// The coordinate kinds do not group into whole quaternions: a run of
    /// `Quaternion` coordinates starting at `at` is not a multiple of four
    /// long.
    Layout {
        /// Index of the first coordinate of the run.
        at: usize,
    },
    /// Δt is not finite and positive.
    TimeStep(f64),
    /// The tangent dimension asked for (`T`, or a slice length) is not
    /// 2·DoF.
    Dimension {
        /// 2·DoF of the mechanism.
        expected: usize,
        /// The dimension given.
        got: usize,
    },
    /// A state has NaN or ±∞, or a quaternion of (nearly) zero norm.
    NonFinite,
    /// E(z₁)ᵀE(z₁) is singular (does not happen on a valid state).
    Singular,
}

impl core::fmt::Display for TangentError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            TangentError::Layout { at } => write!(
                f,
                "quaternion coordinates from index {at} do not come in groups of four"
            ),
            TangentError::TimeStep(dt) => write!(f, "time step {dt} is not finite and positive"),
            TangentError::Dimension { expected, got } => write!(
                f,
                "tangent dimension {got} asked for, but the state manifold has dimension \
                 {expected} (2·DoF)"
            ),
            TangentError::NonFinite => write!(
                f,
                "state is not finite or has a zero quaternion (vigp::consistent_state makes \
                 a consistent one)"
            ),
            TangentError::Singular => write!(f, "tangent embedding is singular"),
        }
    }
}

impl core::error::Error for TangentError {}

/// The tangent chart of the discrete states of an `N`-coordinate model at
/// time step Δt (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tangent<const N: usize> {
    kinds: [CoordinateKind; N],
    dt: f64,
    dof: usize,
}

/// The derivatives of one step in tangent coordinates: Ã (2·DoF × 2·DoF)
/// and B̃ (2·DoF × U), `T` = 2·DoF.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TangentDerivatives<const T: usize, const U: usize> {
    /// Ã = ∂δ₁/∂δ₀.
    pub a: SMatrix<f64, T, T>,
    /// B̃ = ∂δ₁/∂u.
    pub b: SMatrix<f64, T, U>,
}

/// The tangent embedding E = ∂z/∂δ of one state, by blocks: `q` = ∂q/∂δ,
/// `v` = ∂v/∂δ (each N × T).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Embedding<const N: usize, const T: usize> {
    /// ∂q/∂δ.
    pub q: SMatrix<f64, N, T>,
    /// ∂v/∂δ.
    pub v: SMatrix<f64, N, T>,
}

impl<const N: usize> Tangent<N> {
    /// The chart for coordinates of kinds `kinds` (a model's
    /// `Dynamics::KINDS`) at time step `dt`.
    pub fn new(kinds: [CoordinateKind; N], dt: f64) -> Result<Self, TangentError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(TangentError::TimeStep(dt));
        }
        let mut i = 0;
        let mut dof = 0;
        while i < N {
            if kinds[i] == CoordinateKind::Quaternion {
                let run = kinds[i..]
                    .iter()
                    .take_while(|k| **k == CoordinateKind::Quaternion)
                    .count();
                if run % 4 != 0 {
                    return Err(TangentError::Layout { at: i });
                }
                dof += 3 * run / 4;
                i += run;
            } else {
                dof += 1;
                i += 1;
            }
        }
        Ok(Self { kinds, dt, dof })
    }

    /// Degrees of freedom (without loop constraints): N minus one per
    /// quaternion.
    pub fn dof(&self) -> usize {
        self.dof
    }

    /// The tangent dimension 2·DoF.
    pub fn dim(&self) -> usize {
        2 * self.dof
    }

    /// The time step of the chart.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// Calls `f(coordinate index, tangent index, is_quaternion)` for every
    /// scalar coordinate and every quaternion, in order.
    fn blocks(&self, mut f: impl FnMut(usize, usize, bool)) {
        let (mut i, mut t) = (0, 0);
        while i < N {
            if self.kinds[i] == CoordinateKind::Quaternion {
                f(i, t, true);
                i += 4;
                t += 3;
            } else {
                f(i, t, false);
                i += 1;
                t += 1;
            }
        }
    }

    fn check(&self, z: &State<N>) -> Result<(), TangentError> {
        if z.is_finite() {
            Ok(())
        } else {
            Err(TangentError::NonFinite)
        }
    }

    /// [`TangentError::Dimension`] unless `got` is the tangent dimension
    /// 2·DoF.
    fn check_dim(&self, got: usize) -> Result<(), TangentError> {
        if got == self.dim() {
            Ok(())
        } else {
            Err(TangentError::Dimension {
                expected: self.dim(),
                got,
            })
        }
    }

    /// The state retract(z, δ) (module docs); `delta` has length 2·DoF.
    pub fn retract(&self, z: &State<N>, delta: &[f64]) -> Result<State<N>, TangentError> {
        self.check(z)?;
        self.check_dim(delta.len())?;
        let (d, dt) = (self.dof, self.dt);
        let mut out = *z;
        let mut bad = false;
        self.blocks(|i, t, quat| {
            if quat {
                let Some((q0, w)) = rotation(z, i, dt) else {
                    bad = true;
                    return;
                };
                let xi = Vector3::new(delta[t], delta[t + 1], delta[t + 2]);
                let zeta = Vector3::new(delta[d + t], delta[d + t + 1], delta[d + t + 2]);
                let q0n = q0 * so3::exp(&xi);
                let q1n = q0n * so3::exp(&((w + zeta) * dt));
                for (k, (a, b)) in coords(&q0n).into_iter().zip(coords(&q1n)).enumerate() {
                    out.q[i + k] = a;
                    out.v[i + k] = (b - a) / dt;
                }
            } else {
                out.q[i] = z.q[i] + delta[t];
                out.v[i] = z.v[i] + delta[d + t];
            }
        });
        if bad {
            Err(TangentError::NonFinite)
        } else {
            Ok(out)
        }
    }

    /// The tangent coordinates of `z` relative to `base`, written into
    /// `out` (length 2·DoF): the inverse of [`retract`](Self::retract)
    /// for states on the unit-quaternion manifold (quaternions are
    /// normalised first; the rotation is taken the short way round).
    pub fn local(
        &self,
        base: &State<N>,
        z: &State<N>,
        out: &mut [f64],
    ) -> Result<(), TangentError> {
        self.check(base)?;
        self.check(z)?;
        self.check_dim(out.len())?;
        let (d, dt) = (self.dof, self.dt);
        let mut bad = false;
        self.blocks(|i, t, quat| {
            if quat {
                let (Some((qb, wb)), Some((q, w))) = (rotation(base, i, dt), rotation(z, i, dt))
                else {
                    bad = true;
                    return;
                };
                let xi = so3::log(&(qb.inverse() * q));
                let zeta = w - wb;
                for k in 0..3 {
                    out[t + k] = xi[k];
                    out[d + t + k] = zeta[k];
                }
            } else {
                out[t] = z.q[i] - base.q[i];
                out[d + t] = z.v[i] - base.v[i];
            }
        });
        if bad {
            Err(TangentError::NonFinite)
        } else {
            Ok(())
        }
    }

    /// E = ∂retract(z, δ)/∂δ at δ = 0, `T` = 2·DoF.
    pub fn embedding<const T: usize>(&self, z: &State<N>) -> Result<Embedding<N, T>, TangentError> {
        self.check(z)?;
        self.check_dim(T)?;
        let (d, dt) = (self.dof, self.dt);
        let mut e = Embedding {
            q: SMatrix::<f64, N, T>::zeros(),
            v: SMatrix::<f64, N, T>::zeros(),
        };
        let mut bad = false;
        self.blocks(|i, t, quat| {
            if !quat {
                e.q[(i, t)] = 1.0;
                e.v[(i, d + t)] = 1.0;
                return;
            }
            let Some((q0, w)) = rotation(z, i, dt) else {
                bad = true;
                return;
            };
            let step = so3::exp(&(w * dt));
            let q1 = q0 * step;
            let jr = so3::right_jacobian(&(w * dt));
            for k in 0..3 {
                // ∂/∂ξ_k: Q' = Q ⊗ (0, e_k/2), Q⁺' = Q ⊗ (0, e_k/2) ⊗ exp(Δtω)
                let half = pure(&(Vector3::ith(k, 0.5)));
                let dq0 = q0.quaternion() * half;
                let dq1 = dq0 * step.quaternion();
                // ∂/∂ζ_k: Q⁺' = Q⁺ ⊗ (0, Δt·J_r(Δtω)e_k/2)
                let dq1z = q1.quaternion() * pure(&(jr.column(k) * (0.5 * dt)));
                for (r, ((a, b), c)) in coords_q(&dq0)
                    .into_iter()
                    .zip(coords_q(&dq1))
                    .zip(coords_q(&dq1z))
                    .enumerate()
                {
                    e.q[(i + r, t + k)] = a;
                    e.v[(i + r, t + k)] = (b - a) / dt;
                    e.v[(i + r, d + t + k)] = c / dt;
                }
            }
        });
        if bad {
            Err(TangentError::NonFinite)
        } else {
            Ok(e)
        }
    }

    /// A and B of one step z₀ → z₁ (`Stepper::step_with_derivatives`)
    /// in tangent coordinates: Ã = P(z₁)·A·E(z₀), B̃ = P(z₁)·B (module
    /// docs). `T` must be 2·DoF ([`dim`](Self::dim)).
    pub fn derivatives<const T: usize, const U: usize>(
        &self,
        z0: &State<N>,
        z1: &State<N>,
        d: &StepDerivatives<N, U>,
    ) -> Result<TangentDerivatives<T, U>, TangentError> {
        let e0 = self.embedding::<T>(z0)?;
        let e1 = self.embedding::<T>(z1)?;
        let a = &d.a;
        // A·E(z₀) by blocks
        let ae_q = a.q_q * e0.q + a.q_v * e0.v;
        let ae_v = a.v_q * e0.q + a.v_v * e0.v;
        let gram = e1.q.transpose() * e1.q + e1.v.transpose() * e1.v;
        // the Gram matrix is symmetric positive definite (E has full column
        // rank on a valid state); partial pivoting is ample
        let lu = PartialLu::new(gram, 1e-14).ok_or(TangentError::Singular)?;
        let a_t = lu.solve_matrix(&(e1.q.transpose() * ae_q + e1.v.transpose() * ae_v));
        let b_t = lu.solve_matrix(&(e1.q.transpose() * d.b.q_u + e1.v.transpose() * d.b.v_u));
        if !(a_t.iter().chain(b_t.iter()).all(|x| x.is_finite())) {
            return Err(TangentError::Singular);
        }
        Ok(TangentDerivatives { a: a_t, b: b_t })
    }
}

/// The unit quaternions Q = q[i..i+4] and Q⁺ = Q + Δt·v[i..i+4]
/// (normalised), as Q and the discrete body rate ω = log(Q⁻¹Q⁺)/Δt.
fn rotation<const N: usize>(
    z: &State<N>,
    i: usize,
    dt: f64,
) -> Option<(UnitQuaternion<f64>, Vector3<f64>)> {
    let q = Quaternion::new(z.q[i], z.q[i + 1], z.q[i + 2], z.q[i + 3]);
    let p = q + Quaternion::new(z.v[i], z.v[i + 1], z.v[i + 2], z.v[i + 3]) * dt;
    let (nq, np) = (q.norm(), p.norm());
    if !(nq > 1e-12 && np > 1e-12 && nq.is_finite() && np.is_finite()) {
        return None;
    }
    let q0 = UnitQuaternion::new_unchecked(q / nq);
    let q1 = UnitQuaternion::new_unchecked(p / np);
    Some((q0, so3::log(&(q0.inverse() * q1)) / dt))
}

/// The pure quaternion (0, v).
fn pure(v: &Vector3<f64>) -> Quaternion<f64> {
    Quaternion::new(0.0, v.x, v.y, v.z)
}

/// (w, x, y, z) of a unit quaternion.
fn coords(q: &UnitQuaternion<f64>) -> [f64; 4] {
    coords_q(q.quaternion())
}

/// (w, x, y, z) of a quaternion.
fn coords_q(q: &Quaternion<f64>) -> [f64; 4] {
    [q.w, q.i, q.j, q.k]
}
