//! Inputs and exact step derivatives on the [`Stepper`].
//!
//! # Forced steps
//!
//! An actuated joint i (declared `actuated` in `mechanism!`) applies the
//! generalized force u_i ∇s_i(q), s_i the joint's coordinate: a torque on a
//! revolute joint, a force along a prismatic axis. With the input matrix
//! B(q) = [∇s_1 … ∇s_U] ([`Dynamics::input_matrix`]) the input enters the
//! discrete Euler–Lagrange equations exactly where the damping force −D v
//! enters (the step module's docs), as part of the force
//! F(q, v, u) = f(q, v) + B(q)u:
//!
//! ```text
//! d(v₁, λ) = p₀ + (1−α)Δt·F(m₁, v₁, u) − M(m₁)v₁ − G(x₁)ᵀλ = 0,   m₁ = x₁ + αΔt·v₁
//! p₁       = M(m₁)v₁ + αΔt·F(m₁, v₁, u)
//! ```
//!
//! u is held constant over the interval of the new discrete velocity v₁
//! (from x₁ to x₁ + Δt·v₁). For the first-order rule (α = 0) the whole
//! impulse Δt·B(x₁)u enters the residual and the step is a map
//! z₁ = Φ(z₀, u₀) of the state alone. For the midpoint rule the impulse is
//! split as the damping force's is: (1−α)Δt in this step's residual and αΔt
//! in the momentum p₁ carried to the next step, which is what makes the
//! rule second order for piecewise-constant inputs. A step from a state
//! alone ([`Stepper::step_forced`]) starts from the input-free momentum
//! p₀ = M(m₀)v₀ + αΔt·f(m₀, v₀) ([`Stepper::momentum`]), as if no input
//! acted before; a forced rollout ([`Stepper::steps_forced_into`]) carries
//! p₁, including the previous input's share.
//!
//! There is one step: the unforced methods ([`Stepper::step`],
//! [`Stepper::steps_into`], …) are the forced ones with no inputs (U = 0).
//! With u = 0 a forced step takes the code path of no inputs (the input
//! force is never evaluated): an actuated mechanism steps bit for bit as
//! the same mechanism without `actuated`.
//!
//! # Exact derivatives
//!
//! At the converged solution the residual (d, c) = 0 defines (v₁, λ) as a
//! function of (x₁, p₀, u); the implicit function theorem gives
//!
//! ```text
//! [ J      −G(x₁)ᵀ ] [ ∂v₁ ]     [ ∂d/∂θ ]
//! [ Δt·G₂   0      ] [ ∂λ  ] = − [ ∂c/∂θ ],   θ ∈ {x₁, p₀, u}
//!
//! ∂d/∂x₁ = (1−α)Δt·(F_q + H_u) − Qᵀ − Σ λ_i ∇²g_i(x₁),   ∂d/∂p₀ = I,   ∂d/∂u = (1−α)Δt·B(m₁)
//! ∂c/∂x₁ = G₂ = G(x₁ + Δt·v₁)
//! ```
//!
//! with J the exact Newton matrix ∂d/∂v₁, F_q = [`Dynamics::force_jacobian`],
//! H_u = Σ u_i ∇²s_i ([`Dynamics::input_force_jacobian`]) and Q as in the
//! step module's docs. The derivatives of p₁ follow by the chain rule, and
//! those of p₀ = M(m₀)v₀ + αΔt·f(m₀, v₀) with respect to z₀ likewise. One
//! factorisation of J (and of the Schur complement for constraints) serves
//! every direction. Nothing here allocates.

use crate::dynamics::{Dynamics, Inputs, Terms};
use crate::linalg::{FullPivLu, KKT_SUSPECT_PIVOT_RATIO, PartialLu, solve_kkt_regularised};
use crate::state::State;
use crate::step::{
    RolloutError, StepError, StepReport, StepWorkspace, Stepper, Workspace, max_abs,
};
use nalgebra::{SMatrix, SVector};

/// ∂z₁/∂z₀ of a step, z = (q, v), by N × N blocks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StateJacobian<const N: usize> {
    /// ∂q₁/∂q₀.
    pub q_q: SMatrix<f64, N, N>,
    /// ∂q₁/∂v₀.
    pub q_v: SMatrix<f64, N, N>,
    /// ∂v₁/∂q₀.
    pub v_q: SMatrix<f64, N, N>,
    /// ∂v₁/∂v₀.
    pub v_v: SMatrix<f64, N, N>,
}

/// ∂z₁/∂u of a step, z = (q, v), by N × U blocks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InputJacobian<const N: usize, const U: usize> {
    /// ∂q₁/∂u.
    pub q_u: SMatrix<f64, N, U>,
    /// ∂v₁/∂u.
    pub v_u: SMatrix<f64, N, U>,
}

impl<const N: usize> StateJacobian<N> {
    /// The identity map.
    pub fn identity() -> Self {
        Self {
            q_q: SMatrix::identity(),
            v_v: SMatrix::identity(),
            ..Self::zeros()
        }
    }

    /// All blocks zero.
    pub fn zeros() -> Self {
        Self {
            q_q: SMatrix::zeros(),
            q_v: SMatrix::zeros(),
            v_q: SMatrix::zeros(),
            v_v: SMatrix::zeros(),
        }
    }

    /// The 2N × 2N matrix A = [[q_q, q_v], [v_q, v_v]]; `Z` must be 2N
    /// (checked at compile time).
    pub fn matrix<const Z: usize>(&self) -> SMatrix<f64, Z, Z> {
        const { assert!(Z == 2 * N, "Z must equal 2N") };
        let mut a = SMatrix::<f64, Z, Z>::zeros();
        a.fixed_view_mut::<N, N>(0, 0).copy_from(&self.q_q);
        a.fixed_view_mut::<N, N>(0, N).copy_from(&self.q_v);
        a.fixed_view_mut::<N, N>(N, 0).copy_from(&self.v_q);
        a.fixed_view_mut::<N, N>(N, N).copy_from(&self.v_v);
        a
    }

    /// The composition `self ∘ first` (the Jacobian of applying the map of
    /// `first`, then that of `self`).
    pub fn after(&self, first: &Self) -> Self {
        Self {
            q_q: self.q_q * first.q_q + self.q_v * first.v_q,
            q_v: self.q_q * first.q_v + self.q_v * first.v_v,
            v_q: self.v_q * first.q_q + self.v_v * first.v_q,
            v_v: self.v_q * first.q_v + self.v_v * first.v_v,
        }
    }

    /// This Jacobian applied to the input Jacobian of an earlier step.
    pub fn times_input<const U: usize>(&self, b: &InputJacobian<N, U>) -> InputJacobian<N, U> {
        InputJacobian {
            q_u: self.q_q * b.q_u + self.q_v * b.v_u,
            v_u: self.v_q * b.q_u + self.v_v * b.v_u,
        }
    }
}

impl<const N: usize, const U: usize> InputJacobian<N, U> {
    /// All blocks zero.
    pub fn zeros() -> Self {
        Self {
            q_u: SMatrix::zeros(),
            v_u: SMatrix::zeros(),
        }
    }

    /// The 2N × U matrix B = [q_u; v_u]; `Z` must be 2N (checked at
    /// compile time).
    pub fn matrix<const Z: usize>(&self) -> SMatrix<f64, Z, U> {
        const { assert!(Z == 2 * N, "Z must equal 2N") };
        let mut b = SMatrix::<f64, Z, U>::zeros();
        b.fixed_view_mut::<N, U>(0, 0).copy_from(&self.q_u);
        b.fixed_view_mut::<N, U>(N, 0).copy_from(&self.v_u);
        b
    }
}

/// The exact derivatives of one step z₁ = Φ(z₀, u) (module docs):
/// A = ∂z₁/∂z₀ and B = ∂z₁/∂u.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepDerivatives<const N: usize, const U: usize> {
    /// A = ∂z₁/∂z₀.
    pub a: StateJacobian<N>,
    /// B = ∂z₁/∂u.
    pub b: InputJacobian<N, U>,
}

/// Caller-owned buffers of a K-step rollout's derivatives
/// ([`Stepper::rollout_derivatives_into`],
/// [`LearnedStepper::rollout_derivatives_into`](crate::LearnedStepper::rollout_derivatives_into)).
#[derive(Debug)]
pub struct RolloutDerivativeBuffers<'b, const N: usize, const U: usize> {
    /// z_1, …, z_K (K entries).
    pub states: &'b mut [State<N>],
    /// ∂z_k/∂z_0 for k = 1, …, K (K entries).
    pub initial: &'b mut [StateJacobian<N>],
    /// ∂z_k/∂u_j row-major, K × K: entry (k − 1)·K + j is ∂z_k/∂u_j for
    /// k = 1, …, K and j = 0, …, K − 1 (zero for j ≥ k: an input acts on
    /// later states only).
    pub inputs: &'b mut [InputJacobian<N, U>],
}

impl<const N: usize, const U: usize> RolloutDerivativeBuffers<'_, N, U> {
    /// Checks the lengths for `k` steps (the buffer's name, the length it
    /// must have and its length, for the first that is wrong) and zeroes
    /// the input Jacobians.
    pub(crate) fn prepare(&mut self, k: usize) -> Result<(), (&'static str, usize, usize)> {
        for (name, expected, got) in [
            ("states", k, self.states.len()),
            ("initial", k, self.initial.len()),
            ("inputs", k * k, self.inputs.len()),
        ] {
            if got != expected {
                return Err((name, expected, got));
            }
        }
        self.inputs.fill(InputJacobian::zeros());
        Ok(())
    }
}

/// The exact derivatives of one step in momentum form,
/// (z₀, p₀, u) ↦ (z₁, p₁) with the momentum p₀ given (carried from the
/// previous step, [`Stepper::step_forced_with_momentum`]): what a rollout's
/// derivatives chain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MomentumDerivatives<const N: usize, const U: usize> {
    /// ∂z₁/∂z₀ at fixed p₀ (z₀ enters through x₁ = q₀ + Δt·v₀).
    pub z_z: StateJacobian<N>,
    /// ∂q₁/∂p₀.
    pub q_p: SMatrix<f64, N, N>,
    /// ∂v₁/∂p₀.
    pub v_p: SMatrix<f64, N, N>,
    /// ∂z₁/∂u.
    pub z_u: InputJacobian<N, U>,
    /// ∂p₁/∂q₀.
    pub p_q: SMatrix<f64, N, N>,
    /// ∂p₁/∂v₀.
    pub p_v: SMatrix<f64, N, N>,
    /// ∂p₁/∂p₀.
    pub p_p: SMatrix<f64, N, N>,
    /// ∂p₁/∂u.
    pub p_u: SMatrix<f64, N, U>,
}

/// Derivatives of one converged sub-step (x₁, p₀, u) ↦ (v₁, p₁).
struct Local<const N: usize, const U: usize> {
    /// ∂v₁/∂x₁, ∂v₁/∂p₀, ∂v₁/∂u.
    sx: SMatrix<f64, N, N>,
    sp: SMatrix<f64, N, N>,
    su: SMatrix<f64, N, U>,
    /// ∂p₁/∂x₁ at fixed v₁, ∂p₁/∂v₁ (total), ∂p₁/∂u at fixed v₁.
    px: SMatrix<f64, N, N>,
    pv: SMatrix<f64, N, N>,
    pu: SMatrix<f64, N, U>,
}

/// Sensitivities of (x, p) and of the last v along W seed directions.
#[derive(Clone, Copy)]
struct Seeds<const N: usize, const W: usize> {
    x: SMatrix<f64, N, W>,
    p: SMatrix<f64, N, W>,
    v: SMatrix<f64, N, W>,
}

impl<const N: usize, const W: usize> Seeds<N, W> {
    fn new(x: SMatrix<f64, N, W>, p: SMatrix<f64, N, W>) -> Self {
        Self {
            x,
            p,
            v: SMatrix::zeros(),
        }
    }
}

/// The seed groups of [`Stepper::propagate`]: directions of q₀, v₀, p₀
/// and u.
#[derive(Clone, Copy)]
struct Groups<const N: usize, const U: usize> {
    q: Seeds<N, N>,
    v: Seeds<N, N>,
    p: Seeds<N, N>,
    u: Seeds<N, U>,
}

impl<const N: usize, const U: usize> Groups<N, U> {
    /// ∂z₁/∂z₀ read from propagated groups.
    #[inline]
    fn state_jacobian(&self) -> StateJacobian<N> {
        StateJacobian {
            q_q: self.q.x,
            q_v: self.v.x,
            v_q: self.q.v,
            v_v: self.v.v,
        }
    }

    /// ∂z₁/∂u read from propagated groups.
    #[inline]
    fn input_jacobian(&self) -> InputJacobian<N, U> {
        InputJacobian {
            q_u: self.u.x,
            v_u: self.u.v,
        }
    }
}

impl<M: Dynamics<N, C>, const N: usize, const C: usize> Stepper<M, N, C> {
    /// Refuses an input vector with NaN or ±∞; `U` must equal
    /// [`Dynamics::INPUTS`], or be 0 for the input-free step: the public
    /// forced steps are bounded by `M: Inputs<U>`; this `const` assertion is
    /// the backstop against an `Inputs` implementation that contradicts
    /// [`Dynamics::INPUTS`].
    fn check_input<const U: usize>(u: &SVector<f64, U>) -> Result<(), StepError> {
        const { crate::dynamics::check_input_count(U, M::INPUTS) };
        if max_abs(u).is_nan() {
            Err(StepError::NonFiniteInput { step: None })
        } else {
            Ok(())
        }
    }

    /// The checks of a step from a state: a finite `z`, then a finite `u`
    /// ([`Stepper::check_input`]).
    #[inline(always)]
    fn check_start<const U: usize>(z: &State<N>, u: &SVector<f64, U>) -> Result<(), StepError> {
        if !z.is_finite() {
            return Err(StepError::NonFiniteState { step: None });
        }
        Self::check_input(u)
    }

    /// One forced sub-step (module docs), u = 0 on the unforced path.
    #[inline(always)]
    pub(crate) fn solve_forced_any<const U: usize>(
        &self,
        x1: &SVector<f64, N>,
        p0: &SVector<f64, N>,
        h: f64,
        guess: &SVector<f64, N>,
        u: &SVector<f64, U>,
        t: &mut Workspace<N, C>,
    ) -> Result<crate::step::Forced<N, C>, StepError> {
        let zero = u.iter().all(|x| *x == 0.0);
        let (model, k) = (&self.model, &self.k);
        let force = |q: &SVector<f64, N>| model.input_matrix::<U>(k, q) * u;
        let jac = |q: &SVector<f64, N>| model.input_force_jacobian::<U>(k, q, u);
        match (self.alpha == 0.0, zero) {
            (true, true) => self.solve_forced_rule::<false, false>(x1, p0, h, guess, force, jac, t),
            (true, false) => self.solve_forced_rule::<false, true>(x1, p0, h, guess, force, jac, t),
            (false, true) => self.solve_forced_rule::<true, false>(x1, p0, h, guess, force, jac, t),
            (false, false) => self.solve_forced_rule::<true, true>(x1, p0, h, guess, force, jac, t),
        }
    }

    /// The position–momentum form with inputs: one sub-step of size `h`
    /// from position `x1` with momentum `p0` under inputs `u` (module
    /// docs); returns v₁, the momentum p₁ (including αh·B(m₁)u) and
    /// diagnostics. `U` must equal [`Dynamics::INPUTS`].
    pub fn solve_forced<const U: usize>(
        &self,
        x1: &SVector<f64, N>,
        p0: &SVector<f64, N>,
        h: f64,
        guess: &SVector<f64, N>,
        u: &SVector<f64, U>,
    ) -> Result<(SVector<f64, N>, SVector<f64, N>, StepReport), StepError>
    where
        M: Inputs<U>,
    {
        Self::check_input(u)?;
        self.solve_forced_any(x1, p0, h, guess, u, &mut Workspace::new())
            .map(|(v, p, r, _)| (v, p, r))
    }

    /// All sub-steps of one step from `z` with momentum `p0` under inputs
    /// `u`, the first Newton solve started at `guess`; `t` is the terms
    /// workspace (a rollout reuses one: every call of [`Dynamics::terms`]
    /// rewrites the same entries, the others stay zero).
    #[inline(always)]
    pub(crate) fn advance<const U: usize>(
        &self,
        z: &State<N>,
        p0: &SVector<f64, N>,
        guess: &SVector<f64, N>,
        u: &SVector<f64, U>,
        t: &mut Workspace<N, C>,
    ) -> Result<(State<N>, SVector<f64, N>, StepReport), StepError> {
        if max_abs(p0).is_nan() {
            return Err(StepError::NonFiniteState { step: None });
        }
        if self.substeps == 1 {
            let x1 = z.q + z.v * self.dt;
            let (v1, p1, mut r, _) = self.solve_forced_any(&x1, p0, self.dt, guess, u, t)?;
            self.check_continuation(&z.v, &v1, self.dt, &x1, &mut r)?;
            return Ok((State { q: x1, v: v1 }, p1, r));
        }
        let h = self.substep_dt();
        let (mut z, mut p) = (*z, *p0);
        let mut report = StepReport::default();
        for i in 0..self.substeps {
            let x1 = z.q + z.v * h;
            let g = if i == 0 { *guess } else { z.v };
            let (v1, p1, mut r, _) = self.solve_forced_any(&x1, &p, h, &g, u, t)?;
            self.check_continuation(&z.v, &v1, h, &x1, &mut r)?;
            report.merge(&r);
            (z, p) = (State { q: x1, v: v1 }, p1);
        }
        Ok((z, p, report))
    }

    /// One step from `z` under inputs `u` (one per actuated joint, in
    /// declaration order; `U` must equal [`Dynamics::INPUTS`]), starting
    /// from the input-free momentum of `z` (module docs). With u = 0 this
    /// is [`Stepper::step`], bit for bit.
    pub fn step_forced<const U: usize>(
        &self,
        z: &State<N>,
        u: &SVector<f64, U>,
    ) -> Result<State<N>, StepError>
    where
        M: Inputs<U>,
    {
        self.step_forced_with_report(z, u).map(|(z, _)| z)
    }

    /// [`Stepper::step_forced`] with solver diagnostics.
    pub fn step_forced_with_report<const U: usize>(
        &self,
        z: &State<N>,
        u: &SVector<f64, U>,
    ) -> Result<(State<N>, StepReport), StepError>
    where
        M: Inputs<U>,
    {
        self.step_from_state(z, u, &mut Workspace::new())
    }

    /// The step from `z` under `u` in the workspace `ws`: the checks, the
    /// momentum p₀ of `z`, then the solve started at v₀.
    #[inline(always)]
    fn step_from_state<const U: usize>(
        &self,
        z: &State<N>,
        u: &SVector<f64, U>,
        ws: &mut Workspace<N, C>,
    ) -> Result<(State<N>, StepReport), StepError> {
        Self::check_start(z, u)?;
        let p0 = self.momentum(z);
        self.advance(z, &p0, &z.v, u, ws).map(|(z1, _, r)| (z1, r))
    }

    /// [`Stepper::step_forced`] in a kept workspace: the same state, bit for
    /// bit, without zeroing the solver's scratch at every call (see
    /// [`StepWorkspace`]; for the candidates of a shooting or MPC method,
    /// stepped from many states).
    pub fn step_forced_in<const U: usize>(
        &self,
        z: &State<N>,
        u: &SVector<f64, U>,
        ws: &mut StepWorkspace<N, C>,
    ) -> Result<State<N>, StepError>
    where
        M: Inputs<U>,
    {
        self.step_forced_with_report_in(z, u, ws).map(|(z1, _)| z1)
    }

    /// [`Stepper::step_forced_with_report`] in a kept workspace (see
    /// [`Stepper::step_forced_in`]).
    pub fn step_forced_with_report_in<const U: usize>(
        &self,
        z: &State<N>,
        u: &SVector<f64, U>,
        ws: &mut StepWorkspace<N, C>,
    ) -> Result<(State<N>, StepReport), StepError>
    where
        M: Inputs<U>,
    {
        self.step_from_state(z, u, ws.reset::<M>())
    }

    /// One forced step from `z` with its momentum `p0` known (carried from
    /// the previous step); returns the new state, its momentum (with the
    /// input's αΔt share for the midpoint rule) and diagnostics.
    pub fn step_forced_with_momentum<const U: usize>(
        &self,
        z: &State<N>,
        p0: &SVector<f64, N>,
        u: &SVector<f64, U>,
    ) -> Result<(State<N>, SVector<f64, N>, StepReport), StepError>
    where
        M: Inputs<U>,
    {
        Self::check_start(z, u)?;
        self.advance(z, p0, &z.v, u, &mut Workspace::new())
    }

    /// Fills `out` with the states after 1, 2, …, `out.len()` forced steps
    /// from `z0`, step k under `inputs[k]` (`inputs` must be at least as
    /// long as `out`), carrying the momentum between steps (module docs).
    /// No allocation.
    pub fn steps_forced_into<const U: usize>(
        &self,
        z0: &State<N>,
        inputs: &[SVector<f64, U>],
        out: &mut [State<N>],
    ) -> Result<(), RolloutError>
    where
        M: Inputs<U>,
    {
        if z0.is_finite() && inputs.len() < out.len() {
            return Err(RolloutError {
                step: inputs.len(),
                error: StepError::NonFiniteInput { step: None },
            });
        }
        self.roll_into(z0, inputs.iter(), out)
    }

    /// The rollout of [`Stepper::steps_forced_into`] and
    /// [`Stepper::steps_into`]: step k under the k-th of `inputs` (at least
    /// `out.len()` of them). Newton starts from the linear extrapolation
    /// 2v_k − v_{k−1}.
    pub(crate) fn roll_into<'u, const U: usize>(
        &self,
        z0: &State<N>,
        inputs: impl Iterator<Item = &'u SVector<f64, U>>,
        out: &mut [State<N>],
    ) -> Result<(), RolloutError> {
        let fail = |step, error| RolloutError { step, error };
        if !z0.is_finite() {
            return Err(fail(0, StepError::NonFiniteState { step: None }));
        }
        if out.is_empty() {
            return Ok(());
        }
        let (mut z, mut p, mut v_prev) = (*z0, self.momentum(z0), z0.v);
        // one terms workspace for the whole rollout (zeroing it is not free:
        // ∂M/∂q alone is N³ numbers)
        let mut t = Workspace::new();
        for (k, (slot, u)) in out.iter_mut().zip(inputs).enumerate() {
            Self::check_input(u).map_err(|e| fail(k, e))?;
            let guess = if self.substeps == 1 {
                z.v * 2.0 - v_prev
            } else {
                z.v
            };
            let (z1, p1, _) = self
                .advance(&z, &p, &guess, u, &mut t)
                .map_err(|e| fail(k, e))?;
            *slot = z1;
            v_prev = z.v;
            (z, p) = (z1, p1);
        }
        Ok(())
    }

    /// Π(m, v) = M(m)v + αh·(f(m, v) + B(m)u) and its derivatives
    /// ∂Π/∂m (with the input's), ∂Π/∂v (at fixed m), from terms at m.
    fn momentum_parts<const U: usize>(
        &self,
        t: &Terms<N>,
        m: &SVector<f64, N>,
        v: &SVector<f64, N>,
        h: f64,
        hu: &SMatrix<f64, N, N>,
    ) -> (SMatrix<f64, N, N>, SMatrix<f64, N, N>) {
        let (qm, _) = M::kinetic(t, v);
        let ah = self.alpha * h;
        if self.alpha == 0.0 {
            return (qm.transpose(), t.mass);
        }
        let fq = self.model.force_jacobian(&self.k, m, v) + hu;
        let mut fv = qm;
        if M::DISSIPATIVE {
            fv -= t.damping;
        }
        (qm.transpose() + fq * ah, t.mass + fv * ah)
    }

    /// The derivatives of a converged sub-step at (x₁, v₁, λ) under `u`
    /// (module docs), with `t` the terms at m₁ = x₁ + αh·v₁ (as the solver
    /// leaves them).
    fn local<const U: usize>(
        &self,
        x1: &SVector<f64, N>,
        v1: &SVector<f64, N>,
        lambda: &SVector<f64, C>,
        h: f64,
        u: &SVector<f64, U>,
        t: &Terms<N>,
    ) -> Result<Local<N, U>, StepError> {
        let (model, k) = (&self.model, &self.k);
        let alpha = self.alpha;
        let (ah, a1) = (alpha * h, (1.0 - alpha) * h);
        let m1 = x1 + v1 * ah;
        let forced = U > 0 && u.iter().any(|x| *x != 0.0);
        let (b, hu) = if U > 0 {
            let b = model.input_matrix::<U>(k, &m1);
            let hu = if forced {
                model.input_force_jacobian::<U>(k, &m1, u)
            } else {
                SMatrix::zeros()
            };
            (b, hu)
        } else {
            (SMatrix::zeros(), SMatrix::zeros())
        };
        let (qm, _) = M::kinetic(t, v1);
        let fq = model.force_jacobian(k, &m1, v1) + hu;
        // Newton matrix J = ∂d/∂v₁
        let mut jac = -t.mass;
        if !M::CONSTANT_MASS {
            jac += qm * a1;
            jac -= qm.transpose() * ah;
        }
        if M::DISSIPATIVE {
            jac -= t.damping * a1;
        }
        jac += fq * (ah * a1);
        // ∂d/∂x₁
        let mut dx = fq * a1 - qm.transpose();
        let (g1t, g2) = if C > 0 {
            dx -= model.constraint_hessian(k, x1, lambda);
            (
                model.constraints_and_jacobian(k, x1).1.transpose(),
                model.constraints_and_jacobian(k, &(x1 + v1 * h)).1,
            )
        } else {
            (SMatrix::zeros(), SMatrix::zeros())
        };
        let singular = StepError::singular(0);
        let neg_i = -SMatrix::<f64, N, N>::identity();
        let (sx, sp, su) = kkt_solve3(&jac, &g1t, &(g2 * h), &(-dx), &(-g2), &neg_i, &(b * -a1))
            .ok_or(singular)?;
        // p₁ = Π(m₁, v₁) + αh·B(m₁)u
        let (pm, pv) = self.momentum_parts::<U>(t, &m1, v1, h, &hu);
        let pv_total = pm * ah + pv;
        Ok(Local {
            sx,
            sp,
            su,
            px: pm,
            pv: pv_total,
            pu: b * ah,
        })
    }

    /// ∂p₀/∂q₀ and ∂p₀/∂v₀ of the input-free momentum p₀ of `z` with
    /// sub-step `h` ([`Stepper::momentum`]), with the terms evaluated into
    /// `t`, whose entries the model does not write are zero (as
    /// [`Terms::zeros`]).
    fn momentum_derivatives_at(
        &self,
        z: &State<N>,
        h: f64,
        t: &mut Terms<N>,
    ) -> (SMatrix<f64, N, N>, SMatrix<f64, N, N>) {
        let ah = self.alpha * h;
        let m0 = z.q + z.v * ah;
        self.model.terms(&self.k, &m0, t);
        let (pm, pv) = self.momentum_parts::<0>(t, &m0, &z.v, h, &SMatrix::zeros());
        (pm, pm * ah + pv)
    }

    /// ∂p/∂q and ∂p/∂v of the momentum of `z` ([`Stepper::momentum`]),
    /// exact: the first link of a rollout's derivative chain.
    pub fn momentum_derivatives(&self, z: &State<N>) -> (SMatrix<f64, N, N>, SMatrix<f64, N, N>) {
        self.momentum_derivatives_at(z, self.substep_dt(), &mut Terms::zeros())
    }

    /// Propagates seeds through all sub-steps of a step from `z` with
    /// momentum `p0` under `u`, solving each sub-step once: the seeds of
    /// (x₁, p₀) in the directions of q₀, v₀ and p₀ (N each) and of u
    /// (U, with the input's own direct effect). Returns the new state and
    /// momentum, the diagnostics and the seeds of (q₁, v₁, p₁) per group.
    /// Without `track_p` the p₀ group, zero on entry, is left at zero.
    fn propagate<const U: usize>(
        &self,
        z: &State<N>,
        p0: &SVector<f64, N>,
        u: &SVector<f64, U>,
        mut seeds: Groups<N, U>,
        track_p: bool,
        t: &mut Workspace<N, C>,
    ) -> Result<(State<N>, SVector<f64, N>, StepReport, Groups<N, U>), StepError> {
        let h = self.substep_dt();
        let (mut zc, mut pc) = (*z, *p0);
        let mut report = StepReport::default();
        let eye_u = SMatrix::<f64, U, U>::identity();
        for i in 0..self.substeps {
            if i > 0 {
                seeds.q.x += seeds.q.v * h;
                seeds.v.x += seeds.v.v * h;
                if track_p {
                    seeds.p.x += seeds.p.v * h;
                }
                seeds.u.x += seeds.u.v * h;
            }
            let x1 = zc.q + zc.v * h;
            // the solver leaves the terms at m₁(v₁) in `t`: the
            // derivatives reuse them
            let (v1, p1, r, lambda) = self.solve_forced_any(&x1, &pc, h, &zc.v, u, t)?;
            report.merge(&r);
            let l = self.local(&x1, &v1, &lambda, h, u, &t.t)?;
            for g in [&mut seeds.q, &mut seeds.v] {
                g.v = l.sx * g.x + l.sp * g.p;
                g.p = l.px * g.x + l.pv * g.v;
            }
            // seeds that start at zero stay zero (A and B alone)
            if track_p {
                let g = &mut seeds.p;
                g.v = l.sx * g.x + l.sp * g.p;
                g.p = l.px * g.x + l.pv * g.v;
            }
            let g = &mut seeds.u;
            g.v = l.sx * g.x + l.sp * g.p + l.su * eye_u;
            g.p = l.px * g.x + l.pv * g.v + l.pu;
            (zc, pc) = (State { q: x1, v: v1 }, p1);
        }
        Ok((zc, pc, report, seeds))
    }

    /// One forced step from `z` (as [`Stepper::step_forced`]) with its exact
    /// derivatives A = ∂z₁/∂z₀ and B = ∂z₁/∂u (module docs). `U` must
    /// equal [`Dynamics::INPUTS`], or be 0: then the step is input-free
    /// (that of [`Stepper::step`]) and A comes alone, for any mechanism.
    /// No allocation.
    pub fn step_with_derivatives<const U: usize>(
        &self,
        z: &State<N>,
        u: &SVector<f64, U>,
    ) -> Result<(State<N>, StepDerivatives<N, U>), StepError>
    where
        M: Inputs<U>,
    {
        self.derivatives_from_state(z, u, &mut Workspace::new())
    }

    /// [`Stepper::step_with_derivatives`] in a kept workspace: the same
    /// state and derivatives, bit for bit, without zeroing the solver's
    /// scratch at every call (see [`StepWorkspace`]).
    pub fn step_with_derivatives_in<const U: usize>(
        &self,
        z: &State<N>,
        u: &SVector<f64, U>,
        ws: &mut StepWorkspace<N, C>,
    ) -> Result<(State<N>, StepDerivatives<N, U>), StepError>
    where
        M: Inputs<U>,
    {
        self.derivatives_from_state(z, u, ws.reset::<M>())
    }

    /// The step with derivatives from `z` in the workspace `t` (fresh or
    /// reset: the entries the model does not write are zero). The terms at
    /// the start's quadrature point (for the momentum's derivatives) and
    /// then the solver's share `t`, as a rollout's steps do: every call of
    /// [`Dynamics::terms`] rewrites the same entries.
    #[inline(always)]
    fn derivatives_from_state<const U: usize>(
        &self,
        z: &State<N>,
        u: &SVector<f64, U>,
        t: &mut Workspace<N, C>,
    ) -> Result<(State<N>, StepDerivatives<N, U>), StepError> {
        Self::check_start(z, u)?;
        let h = self.substep_dt();
        let p0 = self.momentum(z);
        let (pq, pv) = self.momentum_derivatives_at(z, h, &mut t.t);
        let eye = SMatrix::<f64, N, N>::identity();
        let seeds = Groups {
            q: Seeds::new(eye, pq),
            v: Seeds::new(eye * h, pv),
            p: Seeds::new(SMatrix::zeros(), SMatrix::zeros()),
            u: Seeds::new(SMatrix::zeros(), SMatrix::zeros()),
        };
        let (z1, _, _, s) = self.propagate(z, &p0, u, seeds, false, t)?;
        Ok((
            z1,
            StepDerivatives {
                a: s.state_jacobian(),
                b: s.input_jacobian(),
            },
        ))
    }

    /// A forced rollout from `z0`, step k under `inputs[k]` (K =
    /// `inputs.len()` steps), with the exact derivatives of every state
    /// with respect to z_0 and to every input, into caller-owned buffers.
    /// The derivatives chain through the carried momentum (the Markov
    /// state of a forced midpoint rollout is (z, p)), so they are exact for
    /// both rules: with P_k = ∂p_k/∂(·) carried alongside,
    ///
    /// ```text
    /// ∂z_{k+1} = ∂z₁/∂z₀·∂z_k + ∂z₁/∂p₀·P_k (+ ∂z₁/∂u for u_k)
    /// P_{k+1}  = ∂p₁/∂z₀·∂z_k + ∂p₁/∂p₀·P_k (+ ∂p₁/∂u for u_k)
    /// ```
    ///
    /// from each step's [`Stepper::step_with_momentum_derivatives`]. Each
    /// step starts Newton from the previous velocity and carries the
    /// momentum, so the states solve the equations of
    /// [`Stepper::steps_forced_into`] to the solver's tolerance (not bit
    /// for bit: that rollout extrapolates its start). `momentum` is scratch
    /// for ∂p_k/∂u_j, K entries. Buffers of the wrong length are
    /// [`StepError::InvalidOptions`] at step 0, before any step; a failing
    /// step returns its index with the error. No allocation. Cost: K steps
    /// with derivatives plus K²/2 products of N × N by N × U blocks.
    pub fn rollout_derivatives_into<const U: usize>(
        &self,
        z0: &State<N>,
        inputs: &[SVector<f64, U>],
        out: RolloutDerivativeBuffers<'_, N, U>,
        momentum: &mut [SMatrix<f64, N, U>],
    ) -> Result<(), RolloutError>
    where
        M: Inputs<U>,
    {
        let k_steps = inputs.len();
        let fail = |step, error| RolloutError { step, error };
        let mut out = out;
        if out.prepare(k_steps).is_err() || momentum.len() != k_steps {
            return Err(fail(
                0,
                StepError::InvalidOptions(
                    "rollout derivative buffers: K states, K state Jacobians, K × K input \
                     Jacobians and K momentum Jacobians for K inputs",
                ),
            ));
        }
        if !z0.is_finite() {
            return Err(fail(0, StepError::NonFiniteState { step: None }));
        }
        let RolloutDerivativeBuffers {
            states,
            initial,
            inputs: wrt_u,
        } = out;
        // (`momentum[j]` is written at step j before it is read)
        let (mut p_q, mut p_v) = self.momentum_derivatives(z0);
        let (mut z, mut p) = (*z0, self.momentum(z0));
        let mut prev = StateJacobian::identity();
        for (k, u) in inputs.iter().enumerate() {
            let (z1, p1, d) = self
                .step_with_momentum_derivatives(&z, &p, u)
                .map_err(|e| fail(k, e))?;
            let next = StateJacobian {
                q_q: d.z_z.q_q * prev.q_q + d.z_z.q_v * prev.v_q + d.q_p * p_q,
                q_v: d.z_z.q_q * prev.q_v + d.z_z.q_v * prev.v_v + d.q_p * p_v,
                v_q: d.z_z.v_q * prev.q_q + d.z_z.v_v * prev.v_q + d.v_p * p_q,
                v_v: d.z_z.v_q * prev.q_v + d.z_z.v_v * prev.v_v + d.v_p * p_v,
            };
            let np_q = d.p_q * prev.q_q + d.p_v * prev.v_q + d.p_p * p_q;
            let np_v = d.p_q * prev.q_v + d.p_v * prev.v_v + d.p_p * p_v;
            (p_q, p_v) = (np_q, np_v);
            // row k (∂z_k/∂u_j; zero for k = 0) into row k + 1
            let (done, rest) = wrt_u.split_at_mut(k * k_steps);
            let row_next = &mut rest[..k_steps];
            for (j, p_u) in momentum.iter_mut().enumerate().take(k + 1) {
                let (q_u, v_u, pu) = if j == k {
                    (d.z_u.q_u, d.z_u.v_u, d.p_u)
                } else {
                    let b = done[(k - 1) * k_steps + j];
                    (
                        d.z_z.q_q * b.q_u + d.z_z.q_v * b.v_u + d.q_p * *p_u,
                        d.z_z.v_q * b.q_u + d.z_z.v_v * b.v_u + d.v_p * *p_u,
                        d.p_q * b.q_u + d.p_v * b.v_u + d.p_p * *p_u,
                    )
                };
                row_next[j] = InputJacobian { q_u, v_u };
                *p_u = pu;
            }
            initial[k] = next;
            states[k] = z1;
            prev = next;
            (z, p) = (z1, p1);
        }
        Ok(())
    }

    /// One forced step in momentum form (as
    /// [`Stepper::step_forced_with_momentum`]) with the exact derivatives of
    /// (z₁, p₁) with respect to (z₀, p₀, u): the link a rollout's
    /// derivatives chain (the Markov state of a forced midpoint rollout is
    /// (z, p)).
    pub fn step_with_momentum_derivatives<const U: usize>(
        &self,
        z: &State<N>,
        p0: &SVector<f64, N>,
        u: &SVector<f64, U>,
    ) -> Result<(State<N>, SVector<f64, N>, MomentumDerivatives<N, U>), StepError>
    where
        M: Inputs<U>,
    {
        if !z.is_finite() || max_abs(p0).is_nan() {
            return Err(StepError::NonFiniteState { step: None });
        }
        Self::check_input(u)?;
        let h = self.substep_dt();
        let (eye, zero) = (
            SMatrix::<f64, N, N>::identity(),
            SMatrix::<f64, N, N>::zeros(),
        );
        let seeds = Groups {
            q: Seeds::new(eye, zero),
            v: Seeds::new(eye * h, zero),
            p: Seeds::new(zero, eye),
            u: Seeds::new(SMatrix::zeros(), SMatrix::zeros()),
        };
        let (z1, p1, _, s) = self.propagate(z, p0, u, seeds, true, &mut Workspace::new())?;
        Ok((
            z1,
            p1,
            MomentumDerivatives {
                z_z: s.state_jacobian(),
                q_p: s.p.x,
                v_p: s.p.v,
                z_u: s.input_jacobian(),
                p_q: s.q.p,
                p_v: s.v.p,
                p_p: s.p.p,
                p_u: s.u.p,
            },
        ))
    }
}

/// Solves the KKT system [J, −G₁ᵀ; A, 0][X; Λ] = [R; S] for three
/// right-hand sides (R₁ with S₁; R₂, R₃ with S = 0), returning the X
/// parts. One factorisation of J and of the Schur complement A J⁻¹ G₁ᵀ;
/// a singular J, or one that looks ill-conditioned (pivot ratio below
/// [`KKT_SUSPECT_PIVOT_RATIO`]: quaternion coordinates, where M is
/// singular along each quaternion), falls back to the solve of
/// [`solve_kkt_regularised`] column by column, which checks residuals.
#[allow(clippy::too_many_arguments)]
fn kkt_solve3<const N: usize, const C: usize, const U: usize>(
    j: &SMatrix<f64, N, N>,
    g1t: &SMatrix<f64, N, C>,
    a: &SMatrix<f64, C, N>,
    r1: &SMatrix<f64, N, N>,
    s1: &SMatrix<f64, C, N>,
    r2: &SMatrix<f64, N, N>,
    r3: &SMatrix<f64, N, U>,
) -> Option<(SMatrix<f64, N, N>, SMatrix<f64, N, N>, SMatrix<f64, N, U>)> {
    if let Some(lu) = PartialLu::new(*j, 1e-12)
        && lu.pivot_ratio() >= KKT_SUSPECT_PIVOT_RATIO
    {
        // J x − G₁ᵀ y = r, A x = s:  x = J⁻¹(r + G₁ᵀ y),  (A J⁻¹ G₁ᵀ) y = s − A J⁻¹ r
        let (x1, x2, x3) = (
            lu.solve_matrix(r1),
            lu.solve_matrix(r2),
            lu.solve_matrix(r3),
        );
        if C == 0 {
            return Some((x1, x2, x3));
        }
        let jg = lu.solve_matrix(g1t);
        let schur = FullPivLu::new(a * jg, 1e-13);
        let y1 = schur.solve_matrix(&(s1 - a * x1));
        let y2 = schur.solve_matrix(&(-(a * x2)));
        let y3 = schur.solve_matrix(&(-(a * x3)));
        let out = (x1 + jg * y1, x2 + jg * y2, x3 + jg * y3);
        let finite = out
            .0
            .iter()
            .chain(out.1.iter())
            .chain(out.2.iter())
            .all(|x| x.is_finite());
        return finite.then_some(out);
    }
    let b = -g1t;
    let mut x1 = SMatrix::<f64, N, N>::zeros();
    let mut x2 = SMatrix::<f64, N, N>::zeros();
    let mut x3 = SMatrix::<f64, N, U>::zeros();
    for col in 0..N {
        let ((x, _), _) = solve_kkt_regularised(
            j,
            &b,
            a,
            &r1.column(col).into_owned(),
            &s1.column(col).into_owned(),
        )?;
        x1.set_column(col, &x);
        let ((x, _), _) =
            solve_kkt_regularised(j, &b, a, &r2.column(col).into_owned(), &SVector::zeros())?;
        x2.set_column(col, &x);
    }
    for col in 0..U {
        let ((x, _), _) =
            solve_kkt_regularised(j, &b, a, &r3.column(col).into_owned(), &SVector::zeros())?;
        x3.set_column(col, &x);
    }
    Some((x1, x2, x3))
}
