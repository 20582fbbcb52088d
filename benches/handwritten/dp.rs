//! A hand-written closed-form first-order variational step of the planar
//! double pendulum: the baseline that the generated fixed-size step
//! (`vigp::embedded::Stepper`) is measured against.
//!
//! It solves the same equations as `Stepper` and the std
//! `Variational::new` (the paper's first-order variational integrator,
//! eq. 5–6), in the same coordinates, with the same Newton iteration,
//! stopping rule and scaling — only the mechanical terms are written out by
//! hand instead of being computed from the generated kinematics.
//!
//! # Model
//!
//! Relative joint coordinates q = (q₁, q₂): q₁ the upper link's angle from
//! the downward vertical, q₂ the lower link's angle relative to the upper
//! one (counter-clockwise positive), gravity (0, −g). Upper link: mass m₁,
//! length l₁, centre of mass at distance c₁ from the shoulder on the link
//! axis, inertia J₁ about it; lower link: m₂, centre of mass at c₂ from the
//! elbow, J₂. Viscous joint damping d₁, d₂ on the joint rates.
//!
//! ```text
//! M(q)  = [ a + b + 2k cos q₂   b + k cos q₂ ]     a = m₁c₁² + J₁ + m₂l₁²
//!         [ b + k cos q₂        b            ]     b = m₂c₂² + J₂,  k = m₂l₁c₂
//! ∂M/∂q₁ = 0,   ∂M/∂q₂ = −k sin q₂ [2 1; 1 0]
//! ∇V(q) = g·(e₁ sin q₁ + e₂ sin(q₁+q₂),  e₂ sin(q₁+q₂)),  e₁ = m₁c₁ + m₂l₁, e₂ = m₂c₂
//! D     = diag(d₁, d₂)
//! ```
//!
//! # Step
//!
//! With x₁ = x₀ + Δt·v₀ and p₀ = M(x₀)v₀, solve for v₁
//!
//! ```text
//! d(v) = p₀ − Δt∇V − (M + ΔtD) v + (Δt/2)[vᵀ ∂M/∂q_i v]_i = 0     (all at x₁)
//! ```
//!
//! by Newton's method on A = ∂d/∂v = ΔtQ − (M + ΔtD), Q_ij = (∂M/∂q_i v)_j,
//! solved by Cramer's rule; stop when |d|∞ / (|p₀|∞ + max_i M_ii) ≤ tol
//! (default 1e-12, at most 25 iterations), accept a full step without
//! re-evaluating d when its quadratic remainder (Δt/2)|Δvᵀ ∂M/∂q₂ Δv| is
//! within tol/2 of that scale, otherwise backtrack (halving, down to 1/256)
//! on the scaled residual. This is the iteration of `vigp-core`'s
//! `Stepper` for a tree. Differences: a nearly singular Newton matrix
//! (never the case here: A ≈ −M, M positive definite) is an error instead
//! of a fallback to elimination, and a NaN component of the residual makes
//! the residual norm NaN (an error) where a max-norm built from `f64::max`
//! would skip it.
//!
//! The sine and cosine are the standard library's (`f64::sin_cos`).

// The bench and the test include this file and use different parts of it.
#![allow(dead_code)]

/// Physical parameters of the double pendulum.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Params {
    /// Upper link mass m₁ (kg).
    pub m1: f64,
    /// Lower link mass m₂ (kg).
    pub m2: f64,
    /// Upper link length l₁ (m): shoulder to elbow.
    pub l1: f64,
    /// Distance c₁ from the shoulder to the upper link's centre of mass (m).
    pub c1: f64,
    /// Distance c₂ from the elbow to the lower link's centre of mass (m).
    pub c2: f64,
    /// Upper link inertia J₁ about its centre of mass (kg·m²).
    pub j1: f64,
    /// Lower link inertia J₂ about its centre of mass (kg·m²).
    pub j2: f64,
    /// Gravitational acceleration g (m/s²), pointing along −y.
    pub g: f64,
    /// Shoulder damping d₁ (N·m·s/rad).
    pub d1: f64,
    /// Elbow damping d₂ (N·m·s/rad).
    pub d2: f64,
}

impl Default for Params {
    /// The paper's double pendulum: 1 kg, 1 m thin rods (J = m·l²/12),
    /// g = 9.81 m/s², no damping.
    fn default() -> Self {
        Self {
            m1: 1.0,
            m2: 1.0,
            l1: 1.0,
            c1: 0.5,
            c2: 0.5,
            j1: 1.0 / 12.0,
            j2: 1.0 / 12.0,
            g: 9.81,
            d1: 0.0,
            d2: 0.0,
        }
    }
}

/// Why a step failed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Error {
    /// Δt or an option is invalid (not finite, not positive).
    Invalid,
    /// The state or momentum holds NaN or ±∞.
    NonFiniteState,
    /// The residual became NaN or ±∞.
    NonFiniteResidual,
    /// The Newton matrix is singular.
    Singular,
    /// The line search found no decrease down to the minimal step.
    LineSearchFailed,
    /// The iteration cap was reached.
    NotConverged,
}

/// A state: positions q and discrete velocities v = (q_{k+1} − q_k)/Δt.
pub type State = ([f64; 2], [f64; 2]);

/// The first-order variational step of one double pendulum with a fixed Δt.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClosedForm {
    a_plus_b: f64,
    b: f64,
    k: f64,
    ge1: f64,
    ge2: f64,
    d1: f64,
    d2: f64,
    dt: f64,
    tolerance: f64,
    max_iterations: usize,
    min_step: f64,
}

impl ClosedForm {
    /// The step for `p` with time step `dt` and the default Newton options
    /// (tolerance 1e-12, 25 iterations, smallest line-search step 1/256).
    pub fn new(p: &Params, dt: f64) -> Result<Self, Error> {
        let ok = |x: f64| x.is_finite() && x >= 0.0;
        let params = [p.m1, p.m2, p.l1, p.c1, p.c2, p.j1, p.j2, p.d1, p.d2];
        let valid = dt.is_finite() && dt > 0.0 && p.g.is_finite() && params.iter().all(|&x| ok(x));
        if !valid {
            return Err(Error::Invalid);
        }
        let a = p.m1 * p.c1 * p.c1 + p.j1 + p.m2 * p.l1 * p.l1;
        let b = p.m2 * p.c2 * p.c2 + p.j2;
        Ok(Self {
            a_plus_b: a + b,
            b,
            k: p.m2 * p.l1 * p.c2,
            ge1: p.g * (p.m1 * p.c1 + p.m2 * p.l1),
            ge2: p.g * p.m2 * p.c2,
            d1: p.d1,
            d2: p.d2,
            dt,
            tolerance: 1e-12,
            max_iterations: 25,
            min_step: 1.0 / 256.0,
        })
    }

    /// The same step with another residual tolerance (finite, > 0).
    pub fn with_tolerance(mut self, tolerance: f64) -> Result<Self, Error> {
        if !(tolerance.is_finite() && tolerance > 0.0) {
            return Err(Error::Invalid);
        }
        self.tolerance = tolerance;
        Ok(self)
    }

    /// Mass matrix entries (M₁₁, M₁₂, M₂₂) at elbow angle q₂ via cos q₂.
    #[inline]
    fn mass(&self, cos_q2: f64) -> (f64, f64, f64) {
        let kc = self.k * cos_q2;
        (self.a_plus_b + 2.0 * kc, self.b + kc, self.b)
    }

    /// M(q) as a 2×2 array (for tests).
    pub fn mass_matrix(&self, q: [f64; 2]) -> [[f64; 2]; 2] {
        let (m11, m12, m22) = self.mass(q[1].cos());
        [[m11, m12], [m12, m22]]
    }

    /// ∇V(q) (for tests).
    pub fn potential_gradient(&self, q: [f64; 2]) -> [f64; 2] {
        let s12 = (q[0] + q[1]).sin();
        [self.ge1 * q[0].sin() + self.ge2 * s12, self.ge2 * s12]
    }

    /// Discrete momentum p = M(q)v.
    #[inline]
    pub fn momentum(&self, z: &State) -> [f64; 2] {
        let (q, v) = z;
        let (m11, m12, m22) = self.mass(q[1].cos());
        [m11 * v[0] + m12 * v[1], m12 * v[0] + m22 * v[1]]
    }

    /// One step from the state `z`.
    #[inline]
    pub fn step(&self, z: &State) -> Result<State, Error> {
        let (q, v) = z;
        if !(q.iter().chain(v.iter()).all(|x| x.is_finite())) {
            return Err(Error::NonFiniteState);
        }
        let p0 = self.momentum(z);
        if !p0.iter().all(|x| x.is_finite()) {
            return Err(Error::NonFiniteState);
        }
        self.solve(z, &p0, &z.1).map(|(z1, _, _)| z1)
    }

    /// The step from `z` with momentum `p0`, Newton started at `guess` (all
    /// finite); returns the new state, its momentum M(x₁)v₁ and the number
    /// of Newton iterations.
    #[inline(always)]
    pub fn solve(
        &self,
        z: &State,
        p0: &[f64; 2],
        guess: &[f64; 2],
    ) -> Result<(State, [f64; 2], usize), Error> {
        let h = self.dt;
        let (q0, v0) = z;
        let x1 = [q0[0] + v0[0] * h, q0[1] + v0[1] * h];
        let (s1, c1) = x1[0].sin_cos();
        let (s2, c2) = x1[1].sin_cos();
        let s12 = s1 * c2 + c1 * s2;
        let (m11, m12, m22) = self.mass(c2);
        // ∂M/∂q₂ = ks·[2 1; 1 0] with ks = −k sin q₂.
        let ks = -self.k * s2;
        // b = p₀ − Δt∇V, M_h = M + ΔtD.
        let b = [
            p0[0] - h * (self.ge1 * s1 + self.ge2 * s12),
            p0[1] - h * (self.ge2 * s12),
        ];
        let (mh11, mh12, mh22) = (m11 + h * self.d1, m12, m22 + h * self.d2);
        let p_scale = match p0[0].abs().max(p0[1].abs()) + m11.abs().max(m22.abs()) {
            0.0 => 1.0,
            s => s,
        };
        let inv_p_scale = 1.0 / p_scale;
        // d(v) = b − M_h v + (Δt/2)(0, vᵀ∂M/∂q₂ v); vᵀ∂M/∂q₂ v = 2ks·v₀(v₀ + v₁).
        let eval = |v: &[f64; 2]| {
            let d = [
                b[0] - (mh11 * v[0] + mh12 * v[1]),
                b[1] - (mh12 * v[0] + mh22 * v[1]) + h * ks * v[0] * (v[0] + v[1]),
            ];
            // `f64::max` drops a NaN operand; keep it, so that a NaN
            // residual is an error and never an accepted step.
            let err = match d[0].is_nan() || d[1].is_nan() {
                true => f64::NAN,
                false => d[0].abs().max(d[1].abs()) * inv_p_scale,
            };
            (d, err)
        };
        let mut v = *guess;
        let (mut d, mut err) = eval(&v);
        for iteration in 0..self.max_iterations {
            if !err.is_finite() {
                return Err(Error::NonFiniteResidual);
            }
            if err <= self.tolerance {
                return Ok((
                    (x1, v),
                    [m11 * v[0] + m12 * v[1], m12 * v[0] + m22 * v[1]],
                    iteration,
                ));
            }
            // A = ΔtQ − M_h; row 1 of Q is zero, row 2 is (∂M/∂q₂ v)ᵀ =
            // ks·(2v₀ + v₁, v₀).
            let (a11, a12) = (-mh11, -mh12);
            let (a21, a22) = (h * ks * (2.0 * v[0] + v[1]) - mh12, h * ks * v[0] - mh22);
            // Cramer's rule for A Δ = −d, with the same singularity test as
            // the engine's 2×2 solve (|det| > 1e-14·|A|max²).
            let amax = a11.abs().max(a12.abs()).max(a21.abs()).max(a22.abs());
            let det = a11 * a22 - a12 * a21;
            if !(det.abs() > 1e-14 * amax * amax && det.is_finite()) {
                return Err(Error::Singular);
            }
            let r = 1.0 / det;
            let dv = [
                (-d[0] * a22 + a12 * d[1]) * r,
                (-a11 * d[1] + a21 * d[0]) * r,
            ];
            // d is exactly quadratic in v: after a full step the residual is
            // (Δt/2)(0, Δᵀ∂M/∂q₂Δ) up to rounding; accept if within tol/2.
            let bound = (h * ks * dv[0] * (dv[0] + dv[1])).abs() * inv_p_scale;
            if bound <= 0.5 * self.tolerance {
                let v1 = [v[0] + dv[0], v[1] + dv[1]];
                if v1[0].is_finite() && v1[1].is_finite() {
                    return Ok((
                        (x1, v1),
                        [m11 * v1[0] + m12 * v1[1], m12 * v1[0] + m22 * v1[1]],
                        iteration + 1,
                    ));
                }
            }
            // Backtracking on the scaled residual.
            let mut alpha = 1.0;
            loop {
                let vn = [v[0] + dv[0] * alpha, v[1] + dv[1] * alpha];
                let (dn, errn) = eval(&vn);
                if errn.is_finite() && (errn < err || errn <= self.tolerance) {
                    (v, d, err) = (vn, dn, errn);
                    break;
                }
                alpha *= 0.5;
                if alpha < self.min_step {
                    return Err(Error::LineSearchFailed);
                }
            }
        }
        if err <= self.tolerance {
            return Ok((
                (x1, v),
                [m11 * v[0] + m12 * v[1], m12 * v[0] + m22 * v[1]],
                self.max_iterations,
            ));
        }
        Err(Error::NotConverged)
    }

    /// Fills `out` with the trajectory from `z0` (`out[0] = z0`): the
    /// momentum is carried from step to step and Newton starts from the
    /// extrapolation 2v_k − v_{k−1}, as `Stepper::rollout_into` does. On
    /// failure returns the index of the failing step.
    pub fn rollout_into(&self, z0: &State, out: &mut [State]) -> Result<(), (usize, Error)> {
        let Some((first, rest)) = out.split_first_mut() else {
            return Ok(());
        };
        let (q, v) = z0;
        if !(q.iter().chain(v.iter()).all(|x| x.is_finite())) {
            return Err((0, Error::NonFiniteState));
        }
        *first = *z0;
        let (mut z, mut p, mut v_prev) = (*z0, self.momentum(z0), z0.1);
        if !p.iter().all(|x| x.is_finite()) {
            return Err((0, Error::NonFiniteState));
        }
        for (k, slot) in rest.iter_mut().enumerate() {
            let guess = [2.0 * z.1[0] - v_prev[0], 2.0 * z.1[1] - v_prev[1]];
            let (z1, p1, _) = self.solve(&z, &p, &guess).map_err(|e| (k, e))?;
            *slot = z1;
            v_prev = z.1;
            (z, p) = (z1, p1);
        }
        Ok(())
    }
}
