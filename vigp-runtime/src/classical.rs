//! Classical integrators on the continuous-time dynamics of
//! [`crate::dynamics`]: explicit Euler, symplectic (semi-implicit) Euler and
//! RK4. Their state is (q, q̇) with the **continuous** velocity q̇; constraints
//! enter only at acceleration level, so positions drift off g(q) = 0 (the
//! paper's Fig. 1b). They share the [`Integrator`] trait with the variational
//! integrators, so swapping is one line.

use crate::dynamics::{acceleration_forced_with, acceleration_with};
use crate::integrator::Integrator;
use crate::mechanism::{Mechanism, State};
use crate::newton::StepError;
use nalgebra::SVector;

/// An integrator type `$name` whose step is `$update`: with the time step
/// `$h`, the state `$z` (validated first) and the acceleration
/// `$accel(&q, &q̇)` (with or without inputs) it returns the next state,
/// checked to be finite.
macro_rules! classical {
    (
        $(#[$doc:meta])* $name:ident,
        |$h:ident, $z:ident, $accel:ident| $update:block
    ) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug)]
        pub struct $name<M: Mechanism<N, C>, const N: usize, const C: usize> {
            model: M,
            dt: f64,
            k: Result<M::Constants, StepError>,
        }

        impl<M: Mechanism<N, C>, const N: usize, const C: usize> $name<M, N, C> {
            /// An integrator for `model` with time step `dt` (validated by
            /// `step`, as are the model's run-time parameters).
            pub fn new(model: M, dt: f64) -> Self {
                let k = model.constants();
                Self { model, dt, k }
            }

            /// q̈ at (q, q̇) on the closed-form terms.
            fn accel(&self, q: &nalgebra::SVector<f64, N>, v: &nalgebra::SVector<f64, N>)
                -> Result<nalgebra::SVector<f64, N>, StepError>
            {
                let k = self.k.as_ref().map_err(|e| *e)?;
                acceleration_with(&self.model, k, q, v).map(|(a, _)| a)
            }

            /// The model.
            pub fn model(&self) -> &M {
                &self.model
            }

            /// The update with the acceleration as a parameter (with or
            /// without inputs).
            fn update(
                &self,
                $z: &State<N>,
                $accel: impl Fn(&SVector<f64, N>, &SVector<f64, N>)
                    -> Result<SVector<f64, N>, StepError>,
            ) -> Result<State<N>, StepError> {
                check(self.dt, $z)?;
                let $h = self.dt;
                finite($update)
            }
        }

        impl<M: Mechanism<N, C>, const N: usize, const C: usize> Integrator for $name<M, N, C> {
            type State = State<N>;
            type Error = StepError;
            type Mechanism = M;

            fn dt(&self) -> f64 {
                self.dt
            }
            fn step(&self, z: &State<N>) -> Result<State<N>, StepError> {
                self.update(z, |q, v| self.accel(q, v))
            }
            /// Inputs enter the continuous equations of motion as the
            /// generalized force B(q)u, held over the step.
            fn step_forced<const U: usize>(
                &self,
                z: &State<N>,
                u: &SVector<f64, U>,
            ) -> Result<State<N>, StepError>
            where
                M: vigp_core::Inputs<U>,
            {
                let k = self.k.as_ref().map_err(|e| *e)?;
                self.update(z, |q, v| {
                    acceleration_forced_with(&self.model, k, q, v, u).map(|(a, _)| a)
                })
            }
        }
    };
}

classical! {
    /// Explicit (forward) Euler: q⁺ = q + Δt q̇, q̇⁺ = q̇ + Δt q̈(q, q̇).
    /// First order; energy grows on conservative systems.
    ExplicitEuler,
    |h, z, accel| {
        let a = accel(&z.q, &z.v)?;
        State {
            q: z.q + z.v * h,
            v: z.v + a * h,
        }
    }
}
classical! {
    /// Symplectic (semi-implicit) Euler: q̇⁺ = q̇ + Δt q̈(q, q̇), q⁺ = q + Δt q̇⁺.
    /// First order.
    SymplecticEuler,
    |h, z, accel| {
        let a = accel(&z.q, &z.v)?;
        let v = z.v + a * h;
        State { q: z.q + v * h, v }
    }
}
classical! {
    /// Classical fourth-order Runge–Kutta on (q, q̇).
    Rk4,
    |h, z, accel| {
        let f = |q, v| accel(&q, &v);
        let (q, v) = (z.q, z.v);
        let a1 = f(q, v)?;
        let (q2, v2) = (q + v * (0.5 * h), v + a1 * (0.5 * h));
        let a2 = f(q2, v2)?;
        let (q3, v3) = (q + v2 * (0.5 * h), v + a2 * (0.5 * h));
        let a3 = f(q3, v3)?;
        let (q4, v4) = (q + v3 * h, v + a3 * h);
        let a4 = f(q4, v4)?;
        State {
            q: q + (v + v2 * 2.0 + v3 * 2.0 + v4) * (h / 6.0),
            v: v + (a1 + a2 * 2.0 + a3 * 2.0 + a4) * (h / 6.0),
        }
    }
}

/// Δt as every integrator checks it (finite, > 0, Δt² a normal number:
/// [`vigp_core::step::check_time_step`]), then the state.
fn check<const N: usize>(dt: f64, z: &State<N>) -> Result<(), StepError> {
    vigp_core::step::check_time_step(dt)?;
    if !z.is_finite() {
        return Err(StepError::NonFiniteState { step: None });
    }
    Ok(())
}

/// `z` if it is finite.
fn finite<const N: usize>(z: State<N>) -> Result<State<N>, StepError> {
    if z.is_finite() {
        Ok(z)
    } else {
        Err(StepError::NonFiniteState { step: None })
    }
}
