//! A fourth-order variational integrator: a symmetric composition of the
//! midpoint rule.
//!
//! The midpoint variational integrator is symmetric (its discrete
//! Lagrangian satisfies L_d^{−h}(x₁, x₀) = −L_d^h(x₀, x₁)), so composing it
//! with step sizes γ₁h, γ₂h, …, γ_sh whose coefficients satisfy
//! Σγ_i = 1 and Σγ_i³ = 0 (symmetric) gives a fourth-order method that is
//! still variational: symplectic, momentum-preserving, with bounded energy
//! error, and — since every sub-step solves g(q) = 0 at position level —
//! constraints held to solver tolerance (Yoshida 1990; Suzuki 1990;
//! McLachlan 1995; for constrained systems Reich 1996, composing
//! RATTLE-type steps).
//!
//! Sub-steps chain in position–momentum form (q, p) ↦ (q', p') with
//! p = D₂L_d ([`Stepper::solve`]). **The state's velocity is the
//! continuous q̇** (like RK4's), recovered as the tangent velocity with
//! M(q)q̇ = p + G(q)ᵀμ, G(q)q̇ = 0, accurate to fourth order.
//!
//! **Explicit sub-steps when the model allows them.** For a model with a
//! constant mass matrix, no constraints and no damping (a pendulum on a
//! fixed pivot, prismatic chains, springs between them) the base method is
//! Störmer–Verlet instead, the variational integrator of the trapezoidal
//! discrete Lagrangian L_d = h·[½vᵀMv − ½(V(x₀) + V(x₁))], v = (x₁ − x₀)/h,
//! which is symmetric and second order as the midpoint rule is, and
//! explicit: p½ = p + (h/2)F(q), q' = q + h·M⁻¹p½, p' = p½ + (h/2)F(q') with
//! F = −∇V + B(q)u (the forced discrete Lagrange–d'Alembert principle with
//! the trapezoidal rule). One force evaluation per sub-step, no Newton
//! solve ([`Composition::is_explicit`] says which path a model takes; the
//! decision is made once, when the integrator is built, from the model's
//! terms at q = 0).
//!
//! Two coefficient sets: Yoshida's triple jump (3 sub-steps, one of them
//! negative, γ₁ = 1/(2 − 2^{1/3}) ≈ 1.35) and Suzuki's five-stage fractal
//! (5 sub-steps, γ₁ = γ₂ = γ₄ = γ₅ = 1/(4 − 4^{1/3}) ≈ 0.41): the latter
//! costs 5/3 as much per step but its error constant is about 50 times
//! smaller, which makes it the cheaper way to a given accuracy (the
//! work-precision report measures both).

use crate::dynamics::{Dynamics, Terms};
use crate::linalg::{PartialLu, solve_kkt_regularised};
use crate::state::State;
use crate::step::{RolloutError, Solved, StepError, StepOptions, StepReport, Stepper};
use nalgebra::{SMatrix, SVector};

/// Yoshida's triple jump: γ₁ = γ₃ = 1/(2 − 2^{1/3}), γ₂ = 1 − 2γ₁.
pub const TRIPLE_JUMP: [f64; 3] = [
    1.351_207_191_959_657_6,
    -1.702_414_383_919_315_3,
    1.351_207_191_959_657_6,
];

/// Suzuki's fractal: γ₁ = γ₂ = γ₄ = γ₅ = 1/(4 − 4^{1/3}), γ₃ = 1 − 4γ₁.
pub const SUZUKI5: [f64; 5] = [
    0.414_490_771_794_375_7,
    0.414_490_771_794_375_7,
    -0.657_963_087_177_502_9,
    0.414_490_771_794_375_7,
    0.414_490_771_794_375_7,
];

/// Newton starting guesses for the sub-steps of one step: each sub-step's
/// velocity (x' − x)/h approximates q̇ at the sub-step's midpoint time, so
/// the guess extrapolates linearly in time through the last two known
/// velocities — the step's q̇ at its start, then the solved sub-steps' —
/// with an O(h²) error instead of the O(h) of the previous velocity alone
/// (the composition's sub-steps jump back and forth: γ₃ < 0). A guess only
/// changes where Newton starts, not what it converges to.
struct Predictor<const N: usize> {
    /// (time, velocity) of the last two points, time relative to the step.
    prev: Option<(f64, SVector<f64, N>)>,
    last: (f64, SVector<f64, N>),
    /// Start time of the next sub-step.
    t: f64,
}

impl<const N: usize> Predictor<N> {
    fn new(v0: &SVector<f64, N>) -> Self {
        Self {
            prev: None,
            last: (0.0, *v0),
            t: 0.0,
        }
    }

    /// Guess for the next sub-step of size `h`.
    fn guess(&self, h: f64) -> SVector<f64, N> {
        let tm = self.t + 0.5 * h;
        match self.prev {
            Some((t0, v0)) if self.last.0 != t0 => {
                let (t1, v1) = self.last;
                let w = (tm - t1) / (t1 - t0);
                let g = v1 + (v1 - v0) * w;
                if g.iter().all(|x| x.is_finite()) {
                    g
                } else {
                    v1
                }
            }
            _ => self.last.1,
        }
    }

    /// The predictor of the next step, with time restarted at its start:
    /// the last sub-step's point and the step's end velocity `v_end`.
    fn restart(self, v_end: SVector<f64, N>) -> Self {
        let (t1, v1) = self.last;
        Self {
            prev: Some((t1 - self.t, v1)),
            last: (0.0, v_end),
            t: 0.0,
        }
    }

    /// Record the solved sub-step of size `h` with velocity `v`.
    fn push(&mut self, h: f64, v: SVector<f64, N>) {
        let tm = self.t + 0.5 * h;
        self.prev = Some(self.last);
        self.last = (tm, v);
        self.t += h;
    }
}

/// The fourth-order composition of the midpoint variational integrator of a
/// [`Dynamics`] model (module docs). State: positions and **continuous**
/// velocities. No allocation.
#[derive(Clone, Copy, Debug)]
pub struct Composition<M: Dynamics<N, C>, const N: usize, const C: usize> {
    midpoint: Stepper<M, N, C>,
    gammas: &'static [f64],
    /// M⁻¹ when the sub-steps are explicit Störmer–Verlet steps (module
    /// docs): constant mass, no constraints, no damping.
    explicit: Option<SMatrix<f64, N, N>>,
}

impl<M: Dynamics<N, C>, const N: usize, const C: usize> Composition<M, N, C> {
    /// Suzuki's five-stage composition (the default fourth-order VI).
    pub fn new(model: M, dt: f64) -> Result<Self, StepError> {
        Self::with_coefficients(model, dt, &SUZUKI5)
    }

    /// Yoshida's triple jump.
    pub fn triple_jump(model: M, dt: f64) -> Result<Self, StepError> {
        Self::with_coefficients(model, dt, &TRIPLE_JUMP)
    }

    /// A symmetric composition with the given sub-step coefficients (they
    /// must sum to 1; symmetric sets with Σγ³ = 0 give fourth order).
    pub fn with_coefficients(model: M, dt: f64, gammas: &'static [f64]) -> Result<Self, StepError> {
        let sum: f64 = gammas.iter().sum();
        if gammas.is_empty() || (sum - 1.0).abs() > 1e-12 {
            return Err(StepError::InvalidOptions(
                "composition coefficients must sum to 1",
            ));
        }
        // the user's Δt first, then each stage's (errors name the user's Δt)
        crate::step::check_time_step(dt)?;
        for g in gammas {
            crate::step::check_time_step(g.abs() * dt)
                .map_err(|_| StepError::InvalidTimeStep { dt })?;
        }
        let midpoint = Stepper::midpoint(model, dt)?;
        Ok(Self {
            explicit: Self::explicit_inverse(&midpoint),
            midpoint,
            gammas,
        })
    }

    /// M⁻¹ if the model has a constant mass matrix, no constraints and no
    /// damping (its damping matrix is then constant: the joint coordinates
    /// are the generalized coordinates; it is checked at q = 0), else
    /// `None`.
    fn explicit_inverse(s: &Stepper<M, N, C>) -> Option<SMatrix<f64, N, N>> {
        if !(M::CONSTANT_MASS && C == 0) {
            return None;
        }
        let mut t = Terms::zeros();
        s.model().terms(s.constants(), &SVector::zeros(), &mut t);
        if t.damping.as_slice().iter().any(|x| *x != 0.0) {
            return None;
        }
        let inv = PartialLu::new(t.mass, 1e-14)?.solve_matrix(&SMatrix::identity());
        inv.as_slice().iter().all(|x| x.is_finite()).then_some(inv)
    }

    /// Whether the sub-steps are explicit Störmer–Verlet steps (module
    /// docs) rather than midpoint-rule Newton solves.
    pub fn is_explicit(&self) -> bool {
        self.explicit.is_some()
    }

    /// The Störmer–Verlet sub-steps of one step (module docs), with the
    /// generalized input force `input(q)` = B(q)u.
    fn verlet(
        &self,
        minv: &SMatrix<f64, N, N>,
        q: &SVector<f64, N>,
        p: &SVector<f64, N>,
        input: impl Fn(&SVector<f64, N>) -> SVector<f64, N>,
    ) -> Result<(SVector<f64, N>, SVector<f64, N>), StepError> {
        let model = self.midpoint.model();
        let k = self.midpoint.constants();
        let mut t = Terms::zeros();
        // the force −∇V(q) + B(q)u
        let mut force = |q: &SVector<f64, N>| {
            model.terms(k, q, &mut t);
            input(q) - t.dpotential
        };
        let dt = self.midpoint.dt();
        let (mut q, mut p) = (*q, *p);
        let mut f = force(&q);
        for g in self.gammas {
            let h = g * dt;
            let half = p + f * (0.5 * h);
            q += minv * half * h;
            f = force(&q);
            p = half + f * (0.5 * h);
        }
        if q.iter().chain(p.iter()).all(|x| x.is_finite()) {
            Ok((q, p))
        } else {
            Err(StepError::non_finite_residual(0))
        }
    }

    /// The same integrator with other Newton options.
    pub fn options(mut self, options: StepOptions) -> Result<Self, StepError> {
        self.midpoint = self.midpoint.options(options)?;
        Ok(self)
    }

    /// The model.
    pub fn model(&self) -> &M {
        self.midpoint.model()
    }

    /// Δt.
    pub fn dt(&self) -> f64 {
        self.midpoint.dt()
    }

    /// Number of midpoint sub-steps per step.
    pub fn stages(&self) -> usize {
        self.gammas.len()
    }

    /// The momentum p = M(q)q̇ of a continuous state.
    pub fn momentum(&self, z: &State<N>) -> SVector<f64, N> {
        let m = self.midpoint.model();
        m.mass(self.midpoint.constants(), &z.q) * z.v
    }

    /// The tangent velocity q̇ of a momentum at q: M q̇ − Gᵀμ = p, G q̇ = 0
    /// (q̇ = M⁻¹p without constraints).
    pub fn velocity(
        &self,
        q: &SVector<f64, N>,
        p: &SVector<f64, N>,
    ) -> Result<SVector<f64, N>, StepError> {
        let model = self.midpoint.model();
        let k = self.midpoint.constants();
        let mass = model.mass(k, q);
        let g = if C > 0 {
            model.constraints_and_jacobian(k, q).1
        } else {
            nalgebra::SMatrix::zeros()
        };
        let ((v, _), _) = solve_kkt_regularised(&mass, &(-g.transpose()), &g, p, &SVector::zeros())
            .ok_or(StepError::singular(0))?;
        if v.iter().all(|x| x.is_finite()) {
            Ok(v)
        } else {
            Err(StepError::NonFiniteState { step: None })
        }
    }

    /// Energy ½ q̇ᵀM(q)q̇ + V(q) of a continuous state.
    pub fn energy(&self, z: &State<N>) -> f64 {
        self.midpoint
            .model()
            .energy_at(self.midpoint.constants(), &z.q, &z.v)
    }

    /// One step in position–momentum form: (q, p) ↦ (q', p').
    pub fn step_momentum(
        &self,
        q: &SVector<f64, N>,
        p: &SVector<f64, N>,
        guess: &SVector<f64, N>,
    ) -> Result<(SVector<f64, N>, SVector<f64, N>, StepReport), StepError> {
        self.step_predicted(q, p, Predictor::new(guess))
            .map(|(q, p, r, _)| (q, p, r))
    }

    /// [`Composition::step_momentum`] with the sub-steps' guesses from
    /// `predictor`; returns it advanced past the step (a rollout carries it
    /// into the next step).
    fn step_predicted(
        &self,
        q: &SVector<f64, N>,
        p: &SVector<f64, N>,
        predictor: Predictor<N>,
    ) -> Result<(SVector<f64, N>, SVector<f64, N>, StepReport, Predictor<N>), StepError> {
        self.run_stages(
            q,
            p,
            predictor,
            |_| SVector::zeros(),
            |q, p, h, guess| self.midpoint.solve(q, p, h, guess),
        )
    }

    /// The sub-steps of one step: explicit Störmer–Verlet steps with the
    /// generalized input force `input(q)` when the model allows them (module
    /// docs), else midpoint-rule stages solved by `solve(q, p, h, guess)`
    /// from the predictor's guesses. Returns the predictor advanced past
    /// the step.
    fn run_stages(
        &self,
        q: &SVector<f64, N>,
        p: &SVector<f64, N>,
        mut predictor: Predictor<N>,
        input: impl Fn(&SVector<f64, N>) -> SVector<f64, N>,
        solve: impl Fn(
            &SVector<f64, N>,
            &SVector<f64, N>,
            f64,
            &SVector<f64, N>,
        ) -> Result<Solved<N>, StepError>,
    ) -> Result<(SVector<f64, N>, SVector<f64, N>, StepReport, Predictor<N>), StepError> {
        if let Some(minv) = &self.explicit {
            let (q, p) = self.verlet(minv, q, p, input)?;
            return Ok((q, p, StepReport::default(), predictor));
        }
        let dt = self.midpoint.dt();
        let (mut q, mut p) = (*q, *p);
        let mut report = StepReport::default();
        for g in self.gammas {
            let h = g * dt;
            let (v1, p1, r) = solve(&q, &p, h, &predictor.guess(h))?;
            report.merge(&r);
            q += v1 * h;
            p = p1;
            predictor.push(h, v1);
        }
        Ok((q, p, report, predictor))
    }

    /// [`Composition::step_momentum`] under inputs `u` held over the step
    /// (each midpoint stage forced as in [`crate::forced`]; for constant u
    /// this is the composition of the midpoint rule of L + uᵀs(q), so it
    /// keeps the fourth order).
    pub fn step_momentum_forced<const U: usize>(
        &self,
        q: &SVector<f64, N>,
        p: &SVector<f64, N>,
        guess: &SVector<f64, N>,
        u: &SVector<f64, U>,
    ) -> Result<(SVector<f64, N>, SVector<f64, N>, StepReport), StepError>
    where
        M: crate::Inputs<U>,
    {
        // the midpoint stages check u themselves; the explicit ones here
        if self.explicit.is_some() && u.iter().any(|x| !x.is_finite()) {
            return Err(StepError::NonFiniteInput { step: None });
        }
        let model = self.midpoint.model();
        let k = self.midpoint.constants();
        self.run_stages(
            q,
            p,
            Predictor::new(guess),
            |q| model.input_matrix(k, q) * u,
            |q, p, h, guess| self.midpoint.solve_forced(q, p, h, guess, u),
        )
        .map(|(q, p, r, _)| (q, p, r))
    }

    /// One step from a continuous state under inputs `u` (`U` must equal
    /// [`Dynamics::INPUTS`]); u = 0 is [`Composition::step`] bit for bit.
    pub fn step_forced<const U: usize>(
        &self,
        z: &State<N>,
        u: &SVector<f64, U>,
    ) -> Result<State<N>, StepError>
    where
        M: crate::Inputs<U>,
    {
        if !z.is_finite() {
            return Err(StepError::NonFiniteState { step: None });
        }
        let p = self.momentum(z);
        let (q, p, _) = self.step_momentum_forced(&z.q, &p, &z.v, u)?;
        Ok(State {
            v: self.velocity(&q, &p)?,
            q,
        })
    }

    /// One step from a continuous state (q, q̇) (consistent for loops:
    /// g(q) = 0, G(q)q̇ = 0).
    pub fn step(&self, z: &State<N>) -> Result<State<N>, StepError> {
        if !z.is_finite() {
            return Err(StepError::NonFiniteState { step: None });
        }
        let p = self.momentum(z);
        let (q, p, _) = self.step_momentum(&z.q, &p, &z.v)?;
        Ok(State {
            v: self.velocity(&q, &p)?,
            q,
        })
    }

    /// The states after 1, 2, …, `out.len()` steps from `z0`, carrying the
    /// momentum between steps. No allocation.
    pub fn steps_into(&self, z0: &State<N>, out: &mut [State<N>]) -> Result<(), RolloutError> {
        let fail = |step, error| RolloutError { step, error };
        if !z0.is_finite() {
            return Err(fail(0, StepError::NonFiniteState { step: None }));
        }
        let (mut q, mut p) = (z0.q, self.momentum(z0));
        let mut predictor = Predictor::new(&z0.v);
        for (k, slot) in out.iter_mut().enumerate() {
            let (q1, p1, _, pr) = self
                .step_predicted(&q, &p, predictor)
                .map_err(|e| fail(k, e))?;
            let v = self.velocity(&q1, &p1).map_err(|e| fail(k, e))?;
            // the next step's first guess extrapolates from this step's
            // last sub-step and its end velocity
            predictor = pr.restart(v);
            (q, p) = (q1, p1);
            *slot = State { q, v };
        }
        Ok(())
    }
}
