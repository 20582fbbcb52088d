//! The variational step on fixed-size data, without allocation: the
//! engine behind every variational integrator in vigp (the std
//! `Variational` wraps it).
//!
//! The discrete Lagrangian is L_d(x_k, x_{k+1}) = Δt·L(x_k + αΔt·v_k, v_k)
//! with v_k = (x_{k+1} − x_k)/Δt: α = 0 is the paper's first-order
//! (rectangle) rule ([`Stepper::new`]), α = ½ the second-order midpoint
//! rule ([`Stepper::midpoint`]). With L = ½ vᵀM(q)v − V(q), Rayleigh
//! dissipation R = ½ vᵀD(q)v and
//! f(q, v) = ½[vᵀ ∂M/∂q_i v]_i − ∇V(q) − D(q)v, one step from the
//! position x₁ = x₀ + Δt·v₀ with momentum p₀ solves for v₁ and the
//! multipliers λ:
//!
//! ```text
//! d(v₁, λ) = p₀ + (1−α)Δt·f(m₁, v₁) − M(m₁)v₁ − G(x₁)ᵀλ = 0,   m₁ = x₁ + αΔt·v₁
//! c(v₁)    = g(x₁ + Δt·v₁) = 0
//! p₀       = M(m₀)v₀ + αΔt·f(m₀, v₀),                           m₀ = x₀ + αΔt·v₀
//! ```
//!
//! and the momentum carried to the next step is p₁ = M(m₁)v₁ + αΔt·f(m₁, v₁)
//! (for α = 0: M(x₁)v₁). All terms come from the model's closed forms
//! ([`Dynamics`]); for α = 0 they are evaluated once per step (x₁ is fixed),
//! for α = ½ once per Newton iteration.
//!
//! Newton's method uses the exact Jacobian
//!
//! ```text
//! ∂d/∂v₁ = (1−α)Δt(Q − D) − M − αΔt·Qᵀ + α(1−α)Δt²·F_q,   Q_ij = (∂M/∂q_i v)_j,
//! ```
//!
//! F_q = ∂f/∂q ([`Dynamics::force_jacobian`]), with a backtracking line
//! search on the scaled residual. For the midpoint rule the matrix of an
//! iteration that contracted the residual at least 100-fold at a full step
//! is kept for the next iteration (a chord step, which saves a force
//! Jacobian per step; a chord direction that does not descend is replaced
//! by the exact one). For the first-order rule with a constant mass matrix
//! and constraints, J = −M − Δt·D and G(x₁)ᵀ are fixed for the step and
//! only G₂ = G(x₁ + Δt·v) moves: the factored Schur complement
//! G₂J⁻¹G(x₁)ᵀ of an iteration, with its G₂, is kept for the next one (a
//! chord step in the constraint row) when that step is predicted to
//! converge (its contraction is about the relative move Δt‖Δv‖ of G₂'s
//! configuration); a chord direction that does not descend is replaced by
//! a fresh one. The convergence test is the same either way.
//!
//! Linear solves: closed forms for N ≤ 2, partial pivoting for trees (the Newton matrix is a perturbation of −M),
//! and for constraints the Schur complement G A⁻¹Gᵀ with complete pivoting
//! (a rank-deficient G, as at a four-bar's folded pose, loses only the
//! deficient multiplier); a diagonal Newton matrix (maximal coordinates)
//! is inverted directly; a singular one with non-singular KKT matrix (a
//! link without rotational inertia in maximal coordinates) is solved by
//! an equivalent regularised system ([`crate::linalg::solve_kkt_regularised`]).
//!
//! Convergence: the momentum residual is scaled by |p₀|∞ + m̄ (m̄ the
//! largest diagonal entry of M: the motion does not depend on the mass
//! unit), the constraint residual by 1 + the largest length coordinate.

use crate::dynamics::{Dynamics, Terms};
use crate::linalg::{
    ConstraintColumns, KktFactors, SchurFactor, solve_kkt_regularised, solve_partial,
};
use crate::state::{CoordinateKind, State};
use nalgebra::{SMatrix, SVector};

/// Options of the Newton solve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepOptions {
    /// Convergence when the scaled residual max-norm is below this
    /// (module docs). Default 1e-12.
    pub tolerance: f64,
    /// Iteration cap (default 25; at least 1).
    pub max_iterations: usize,
    /// Smallest line-search step before Newton is declared stalled
    /// (default 1/256).
    pub min_step: f64,
    /// A stalled Newton iteration (no decrease possible along the exact
    /// Newton direction, as where a loop's constraint Jacobian loses rank
    /// and g is quadratic in the lost direction) is accepted when the
    /// scaled residual is below this (default 1e-10; reported as
    /// [`StepReport::stalled`]). Set it equal to `tolerance` to refuse
    /// stalled steps.
    pub stall_tolerance: f64,
}

impl Default for StepOptions {
    fn default() -> Self {
        Self {
            tolerance: 1e-12,
            max_iterations: 25,
            min_step: 1.0 / 256.0,
            stall_tolerance: 1e-10,
        }
    }
}

impl StepOptions {
    /// Refuse options that cannot work.
    pub fn validate(&self) -> Result<(), StepError> {
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return Err(StepError::InvalidOptions(
                "tolerance must be finite and > 0",
            ));
        }
        if !(self.stall_tolerance.is_finite() && self.stall_tolerance >= self.tolerance) {
            return Err(StepError::InvalidOptions(
                "stall_tolerance must be finite and >= tolerance",
            ));
        }
        if !(self.min_step > 0.0 && self.min_step <= 1.0) {
            return Err(StepError::InvalidOptions("min_step must be in (0, 1]"));
        }
        if self.max_iterations == 0 {
            // no Newton iteration could run: every step would fail
            return Err(StepError::InvalidOptions("max_iterations must be >= 1"));
        }
        Ok(())
    }
}

pub use crate::error::StepError;

/// The default of [`Stepper::continuation_bound`]: a step may bend the
/// discrete path, |Δt·(v₁ − v₀)|∞, by at most 1 rad (or 1 length scale).
pub const DEFAULT_CONTINUATION_BOUND: f64 = 1.0;

/// Checks a rollout length before anything is allocated: the `steps + 1`
/// states of type `T` a trajectory holds must fit in the address space
/// (at most `isize::MAX` bytes). Returns `steps + 1`. Every rollout that
/// allocates its trajectory calls this first; `usize::MAX` and
/// `usize::MAX / 2` are [`StepError::TooManySteps`], not a panic.
pub fn check_step_count<T>(steps: usize) -> Result<usize, StepError> {
    let len = steps
        .checked_add(1)
        .ok_or(StepError::TooManySteps { steps })?;
    let bytes = len
        .checked_mul(core::mem::size_of::<T>().max(1))
        .ok_or(StepError::TooManySteps { steps })?;
    if bytes > isize::MAX as usize {
        return Err(StepError::TooManySteps { steps });
    }
    Ok(len)
}

/// A step error inside a rollout, with the index of the failing step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RolloutError {
    /// Index of the step that failed (0 = the step from the initial state).
    pub step: usize,
    /// What failed.
    pub error: StepError,
}

impl core::fmt::Display for RolloutError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "rollout step {}: {}", self.step, self.error)
    }
}

impl core::error::Error for RolloutError {}

/// Diagnostics of a converged step (with sub-steps: iterations summed, the
/// largest residual, any sub-step's flags).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct StepReport {
    /// Newton iterations used.
    pub iterations: usize,
    /// Final scaled residual: evaluated, or, for a tree (`C = 0`) with the
    /// first-order rule whose last Newton step was a full one, its
    /// quadratic remainder (Δt/2)[Δvᵀ ∂M/∂q_i Δv]_i (the residual is then
    /// exactly quadratic in v, so this is the residual left by that step,
    /// up to rounding).
    pub residual: f64,
    /// The step was accepted as stalled ([`StepOptions::stall_tolerance`]).
    pub stalled: bool,
    /// Some Newton matrix was singular and the equivalent regularised KKT
    /// system was solved instead.
    pub regularised: bool,
    /// The bend |h·(v₁ − v₀)|∞ of the step's discrete path (largest over
    /// sub-steps; [`Stepper::continuation_bound`]).
    pub continuation: f64,
    /// The solve was restarted from a feasible point after its first run
    /// failed (the std runtime's velocity projection far off the
    /// manifold). The core's own solves do not restart.
    pub restarted: bool,
    /// How often the step halved its sub-step before it converged (the
    /// std runtime's `Variational::max_subdivision`; 0: at once). The
    /// core's [`Stepper`] does not subdivide.
    pub subdivisions: u32,
}

impl StepReport {
    /// The report of one Newton solve of the core (no continuation, no
    /// restart, no subdivision).
    #[inline]
    pub(crate) const fn newton(
        iterations: usize,
        residual: f64,
        stalled: bool,
        regularised: bool,
    ) -> Self {
        StepReport {
            iterations,
            residual,
            stalled,
            regularised,
            continuation: 0.0,
            restarted: false,
            subdivisions: 0,
        }
    }

    pub(crate) fn merge(&mut self, other: &StepReport) {
        self.iterations += other.iterations;
        self.residual = self.residual.max(other.residual);
        self.continuation = self.continuation.max(other.continuation);
        self.stalled |= other.stalled;
        self.regularised |= other.regularised;
        self.restarted |= other.restarted;
        self.subdivisions = self.subdivisions.max(other.subdivisions);
    }
}

/// The most sub-steps per step [`Stepper::substeps`] accepts: 2²⁰, about
/// a million Newton solves per step. More is a mistake (a step that never
/// returns, as `usize::MAX` would give), not a finer integrator: at that
/// point a smaller Δt is the tool.
pub const MAX_SUBSTEPS: usize = 1 << 20;

/// Checks a time step: finite, > 0, and Δt² a normal number (the Newton
/// matrix mixes Δt and Δt² scales; Δt = 1e300 or 1e-300 cannot work).
pub fn check_time_step(dt: f64) -> Result<(), StepError> {
    if dt.is_finite() && dt > 0.0 && (dt * dt).is_normal() {
        Ok(())
    } else {
        Err(StepError::InvalidTimeStep { dt })
    }
}

/// A converged sub-step: v₁, the momentum p₁ and diagnostics.
pub(crate) type Solved<const N: usize> = (SVector<f64, N>, SVector<f64, N>, StepReport);

/// A converged forced sub-step: v₁, p₁, diagnostics and the multipliers λ.
pub(crate) type Forced<const N: usize, const C: usize> = (
    SVector<f64, N>,
    SVector<f64, N>,
    StepReport,
    SVector<f64, C>,
);

/// A variational integrator of a [`Dynamics`] model with a fixed Δt:
/// first order ([`Stepper::new`], the paper's rule) or second order
/// ([`Stepper::midpoint`]); optional sub-steps. Construction validates Δt,
/// the options and the model's run-time parameters and precomputes the
/// model's constants; steps allocate nothing.
#[derive(Clone, Copy, Debug)]
pub struct Stepper<M: Dynamics<N, C>, const N: usize, const C: usize> {
    pub(crate) model: M,
    pub(crate) k: M::Constants,
    pub(crate) dt: f64,
    pub(crate) alpha: f64,
    pub(crate) options: StepOptions,
    pub(crate) substeps: usize,
    pub(crate) continuation: f64,
}

/// max |x_i|, NaN if any entry is NaN or ±∞ (`f64::max` alone would drop
/// a NaN): x·0 is 0 for finite x and NaN otherwise, so adding Σ x_i·0
/// poisons the result without a branch per entry.
#[inline(always)]
pub(crate) fn max_abs<const K: usize>(x: &SVector<f64, K>) -> f64 {
    let mut m = 0.0f64;
    let mut poison = 0.0f64;
    // the slice, not nalgebra's element iterator (whose per-element
    // bookkeeping costs more than the arithmetic here)
    for v in x.as_slice() {
        m = m.max(v.abs());
        poison += v * 0.0;
    }
    m + poison
}

/// `Err(e)`, out of line (see [`Stepper::step`]).
#[cold]
#[inline(never)]
fn failed<T>(e: StepError) -> Result<T, StepError> {
    Err(e)
}

/// The inputs of an unforced step: none. Every step is a forced step; an
/// unforced one is the forced step with U = 0, whose input force the
/// solver never evaluates.
pub(crate) const NO_INPUT: SVector<f64, 0> =
    SVector::from_array_storage(nalgebra::ArrayStorage([[]]));

/// The solver's workspace, reused by the steps of a rollout: the terms,
/// the constraint values and Jacobians of the Newton iterations, and the
/// KKT factors. Held across steps, nothing in it is zeroed per step (its
/// kilobytes of factors would cost a memset each), and the G(x₁ + h·v₁) of
/// a converged step, where the next step's G₁ = G(x₁') is evaluated (x₁' =
/// x₁ + h·v₁, the same floating-point operations), is reused for that G₁:
/// a constraint Jacobian (the model's trigonometry) fewer per step.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Workspace<const N: usize, const C: usize> {
    /// The terms: after a converged solve, at the solution's quadrature
    /// point m₁(v₁) (the derivatives reuse them).
    pub(crate) t: Terms<N>,
    // c and G at four configurations: G₁'s (`g_slot`), the iterate's, the
    // line search's trial point and the one the kept Schur complement was
    // formed at (for chord steps); an accepted trial point or a converged
    // step changes roles by index, without copying G
    cg: [(SVector<f64, C>, SMatrix<f64, C, N>); 4],
    // cg[g_slot] holds c and G at `g_at` (NaN: at no point yet)
    g_slot: usize,
    g_at: SVector<f64, N>,
    factors: KktFactors<N, C>,
    schur: SchurFactor<N, C>,
}

impl<const N: usize, const C: usize> Workspace<N, C> {
    /// A fresh workspace (no G cached).
    // inlined, so that it is formed in the caller's frame (see
    // `Terms::zeros`)
    #[inline(always)]
    pub(crate) fn new() -> Self {
        Self {
            t: Terms::zeros(),
            cg: [(SVector::zeros(), SMatrix::zeros()); 4],
            g_slot: 0,
            g_at: SVector::repeat(f64::NAN),
            factors: KktFactors::default(),
            schur: SchurFactor::default(),
        }
    }
}

/// The scratch space of a step from a state, kept by the caller across
/// steps ([`Stepper::step_in`], and for forced steps
/// [`Stepper::step_forced_in`] and [`Stepper::step_with_derivatives_in`]).
///
/// A step from a state needs the terms workspace (M, ∂M/∂q, ∇V and D:
/// 8·(N³ + 2N² + N) bytes), four constraint Jacobians and the KKT factors;
/// [`Stepper::step`] builds them zeroed at every call. For the fourbar in
/// maximal coordinates (N = 12, C = 10) that is about 24 KB of zeros, a
/// sixth of the step's time. A kept workspace is reset in O(N²) instead
/// (only the terms the model reads are cleared: ∂M/∂q only when the mass
/// matrix moves, D only for a dissipative model), so the results are those
/// of [`Stepper::step`], bit for bit, whatever stepper used the workspace
/// before (another model or other parameters included). No allocation;
/// put one in a `static` or on the stack of the control loop.
#[derive(Clone, Copy, Debug)]
pub struct StepWorkspace<const N: usize, const C: usize> {
    ws: Workspace<N, C>,
}

impl<const N: usize, const C: usize> StepWorkspace<N, C> {
    /// A zeroed workspace.
    pub fn new() -> Self {
        Self {
            ws: Workspace::new(),
        }
    }

    /// Clear what a step of `M` reads before it writes it: M, ∇V, D when
    /// `M::DISSIPATIVE`, ∂M/∂q unless `M::CONSTANT_MASS` (the model's
    /// [`Dynamics::terms`] writes its nonzero entries on top, as into
    /// [`Terms::zeros`]), and the cached G₁ (another stepper may have left
    /// it at the same point).
    #[inline(always)]
    pub(crate) fn reset<M: Dynamics<N, C>>(&mut self) -> &mut Workspace<N, C> {
        let ws = &mut self.ws;
        ws.t.mass = SMatrix::zeros();
        ws.t.dpotential = SVector::zeros();
        if M::DISSIPATIVE {
            ws.t.damping = SMatrix::zeros();
        }
        if !M::CONSTANT_MASS {
            for d in ws.t.dmass.iter_mut() {
                *d = SMatrix::zeros();
            }
        }
        ws.g_at = SVector::repeat(f64::NAN);
        ws
    }
}

impl<const N: usize, const C: usize> Default for StepWorkspace<N, C> {
    fn default() -> Self {
        Self::new()
    }
}

/// Whether `a` and `b` hold the same bits (a point where G was evaluated:
/// −0 and +0 may give G's zeros different signs, NaN never matches).
#[inline(always)]
fn same_bits<const N: usize>(a: &SVector<f64, N>, b: &SVector<f64, N>) -> bool {
    let mut diff = 0u64;
    for (x, y) in a.as_slice().iter().zip(b.as_slice()) {
        diff |= x.to_bits() ^ y.to_bits();
    }
    diff == 0 && !a[0].is_nan()
}

impl<M: Dynamics<N, C>, const N: usize, const C: usize> Stepper<M, N, C> {
    /// The paper's first-order variational integrator with default options.
    pub fn new(model: M, dt: f64) -> Result<Self, StepError> {
        Self::with_options(model, dt, StepOptions::default())
    }

    /// The first-order integrator with the given options.
    pub fn with_options(model: M, dt: f64, options: StepOptions) -> Result<Self, StepError> {
        check_time_step(dt)?;
        options.validate()?;
        let k = model.constants()?;
        Ok(Self {
            model,
            k,
            dt,
            alpha: 0.0,
            options,
            substeps: 1,
            continuation: DEFAULT_CONTINUATION_BOUND,
        })
    }

    /// The same integrator with another continuation bound (default
    /// [`DEFAULT_CONTINUATION_BOUND`], 1 rad). After every converged
    /// (sub-)step of size h the bend of the discrete path,
    /// |h·(v₁ − v₀)|∞ = |x₂ − 2x₁ + x₀|∞ (radians for angles and quaternion
    /// components; lengths in units of 1 + the largest length coordinate),
    /// must not exceed the bound while the step also gains more energy than
    /// ½(|E₀| + |E₁|), else the step is [`StepError::NotContinuation`]
    /// (a stiff, damped link may bend the path by more in one step while
    /// its energy barely changes). A step that resolves the motion
    /// bends its path by h²·|a|, a fraction of a radian (0.15 rad for a
    /// pendulum at Δt = 0.1 s); a step that bends it by more than a radian
    /// has sampled the forces and the velocity terms at configurations the
    /// motion does not pass through, and Newton's root, though it solves
    /// the discrete equations, is no continuation of the motion (the double
    /// pendulum released from rest at Δt = 2 s: 32 rad in its first step,
    /// its energy from −17 J to 59 J, then thousands). The bend is reported
    /// as [`StepReport::continuation`]. `f64::INFINITY` turns the check
    /// off; NaN or a bound ≤ 0 is [`StepError::InvalidOptions`].
    pub fn continuation_bound(mut self, bound: f64) -> Result<Self, StepError> {
        if bound.is_nan() || bound <= 0.0 {
            return Err(StepError::InvalidOptions(
                "continuation bound must be > 0 (f64::INFINITY turns the check off)",
            ));
        }
        self.continuation = bound;
        Ok(self)
    }

    /// The continuation bound in force ([`Stepper::continuation_bound`]).
    pub fn continuation(&self) -> f64 {
        self.continuation
    }

    /// The continuation test of a converged (sub-)step of size `h` from
    /// velocity `v0` to `v1` at x₁: the bend of the discrete path,
    /// |h|·|v₁ − v₀| per coordinate (the second difference
    /// x₂ − 2x₁ + x₀), in radians for angles and quaternion components
    /// and in units of 1 + the largest length coordinate for lengths,
    /// recorded in `report` and refused above the bound.
    #[inline(always)]
    pub(crate) fn check_continuation(
        &self,
        v0: &SVector<f64, N>,
        v1: &SVector<f64, N>,
        h: f64,
        x1: &SVector<f64, N>,
        report: &mut StepReport,
    ) -> Result<(), StepError> {
        let mut l_scale = 1.0f64;
        for (x, kind) in x1.iter().zip(M::KINDS.iter()) {
            if *kind == CoordinateKind::Length {
                l_scale = l_scale.max(1.0 + x.abs());
            }
        }
        let mut bend = 0.0f64;
        for i in 0..N {
            let d = (h * (v1[i] - v0[i])).abs();
            let d = if M::KINDS[i] == CoordinateKind::Length {
                d / l_scale
            } else {
                d
            };
            bend = bend.max(d);
        }
        report.continuation = bend;
        // A stiff, damped link legitimately bends the path by more than the
        // bound in one step (its relative velocity is damped out) while the
        // energy barely changes. A root no motion has gains energy: refuse a large
        // bend only together with an energy jump beyond the energy's own
        // size, E₁ − E₀ > ½(|E₀| + |E₁|) (the double pendulum released at
        // Δt = 2 s: −17 J → 59 J). Evaluated only past the bound.
        if bend > self.continuation && self.energy_jumps(v0, v1, h, x1) {
            return Err(StepError::NotContinuation {
                ratio: bend,
                bound: self.continuation,
                step: None,
            });
        }
        Ok(())
    }

    /// Whether the (sub-)step of size `h` from (x₁ − h·v₀, v₀) to (x₁, v₁)
    /// gains more energy than half the sum of the two energies' magnitudes
    /// (see [`Stepper::check_continuation`]); NaN counts as a jump.
    fn energy_jumps(
        &self,
        v0: &SVector<f64, N>,
        v1: &SVector<f64, N>,
        h: f64,
        x1: &SVector<f64, N>,
    ) -> bool {
        let x0 = x1 - v0 * h;
        let e0 = self
            .model
            .energy_at(&self.k, &(x0 + v0 * (self.alpha * h)), v0);
        let e1 = self
            .model
            .energy_at(&self.k, &(x1 + v1 * (self.alpha * h)), v1);
        let jump = e1 - e0;
        jump.is_nan() || jump > 0.5 * (e0.abs() + e1.abs())
    }

    /// The second-order variational integrator of the midpoint discrete
    /// Lagrangian L_d = Δt·L((x_k + x_{k+1})/2, (x_{k+1} − x_k)/Δt).
    pub fn midpoint(model: M, dt: f64) -> Result<Self, StepError> {
        let mut s = Self::new(model, dt)?;
        s.alpha = 0.5;
        Ok(s)
    }

    /// The same integrator with other Newton options.
    pub fn options(mut self, options: StepOptions) -> Result<Self, StepError> {
        options.validate()?;
        self.options = options;
        Ok(self)
    }

    /// Each step of Δt becomes `k` variational steps of h = Δt/k: the
    /// integrator is then exactly the variational integrator at h, sampled
    /// every Δt, and **the state's velocity is the discrete velocity of the
    /// sub-step**, v = (q(t + h) − q(t))/h. For motions too fast for the DEL
    /// equations to have a root near v₀ at Δt. `k = 0` and
    /// `k >` [`MAX_SUBSTEPS`] are refused ([`StepError::InvalidOptions`]).
    pub fn substeps(mut self, k: usize) -> Result<Self, StepError> {
        if k == 0 {
            return Err(StepError::InvalidOptions("substeps must be >= 1"));
        }
        if k > MAX_SUBSTEPS {
            return Err(StepError::InvalidOptions(
                "substeps must be <= MAX_SUBSTEPS (2^20)",
            ));
        }
        check_time_step(self.dt / k as f64)?;
        self.substeps = k;
        Ok(self)
    }

    /// The model.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// The model's precomputed constants.
    pub fn constants(&self) -> &M::Constants {
        &self.k
    }

    /// Δt.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// The time step of one sub-step, Δt / substeps.
    pub fn substep_dt(&self) -> f64 {
        self.dt / self.substeps as f64
    }

    /// Number of sub-steps per step.
    pub fn substep_count(&self) -> usize {
        self.substeps
    }

    /// Order of accuracy of the rule (1 or 2).
    pub fn order(&self) -> usize {
        if self.alpha == 0.0 { 1 } else { 2 }
    }

    /// The Newton options.
    pub fn step_options(&self) -> &StepOptions {
        &self.options
    }

    /// f(q, v) = ½[vᵀ ∂M/∂q_i v]_i − ∇V − D v from terms at q.
    pub(crate) fn forces(t: &Terms<N>, v: &SVector<f64, N>) -> SVector<f64, N> {
        let mut f = M::kinetic(t, v).1 - t.dpotential;
        if M::DISSIPATIVE {
            f -= M::damping_times(t, v);
        }
        f
    }

    /// The discrete momentum p₀ of a step from `z` with sub-step size `h`
    /// (module docs): M(x₀)v₀ for the first-order rule.
    // inlined: a step from a state starts with it, and out of line its
    // M(x₀) and p₀ make a round trip through memory
    #[inline(always)]
    fn momentum_at(&self, z: &State<N>, h: f64) -> SVector<f64, N> {
        if self.alpha == 0.0 {
            return self.model.mass(&self.k, &z.q) * z.v;
        }
        let m0 = z.q + z.v * (self.alpha * h);
        let mut t = Terms::zeros();
        self.model.terms(&self.k, &m0, &mut t);
        M::mass_times(&t, &z.v) + Self::forces(&t, &z.v) * (self.alpha * h)
    }

    /// The discrete momentum p₀ of a step from `z` (the momentum a rollout
    /// carries; module docs).
    pub fn momentum(&self, z: &State<N>) -> SVector<f64, N> {
        self.momentum_at(z, self.substep_dt())
    }

    /// Energy of a discrete state at the rule's quadrature point,
    /// E(x + αh·v, v): for the midpoint rule the discrete velocity belongs to
    /// the interval's midpoint, which makes the measured energy error second
    /// order. Equals the model's energy of `z` for the first-order rule.
    pub fn energy(&self, z: &State<N>) -> f64 {
        let h = self.substep_dt();
        let q = z.q + z.v * (self.alpha * h);
        self.model.energy_at(&self.k, &q, &z.v)
    }

    /// One step from `z`: [`Stepper::step_forced`] with no inputs (U = 0),
    /// which is the same code.
    pub fn step(&self, z: &State<N>) -> Result<State<N>, StepError> {
        match self.step_with_report(z) {
            Ok((z1, _)) => Ok(z1),
            // out of line: merged with the error paths' stores, the state
            // was written one number at a time (at offsets chosen by the
            // variant), and the caller's load of v stalled on them
            Err(e) => failed(e),
        }
    }

    /// One step from `z` with solver diagnostics
    /// ([`Stepper::step_forced_with_report`] with no inputs).
    pub fn step_with_report(&self, z: &State<N>) -> Result<(State<N>, StepReport), StepError> {
        self.step_forced_with_report(z, &NO_INPUT)
    }

    /// [`Stepper::step`] in a kept workspace: the same state, bit for bit,
    /// without zeroing the solver's scratch at every call (see
    /// [`StepWorkspace`]; for N = 12 about a sixth of the step). For
    /// callers that step from many states (shooting, MPC candidates); a
    /// rollout ([`Stepper::rollout_into`]) keeps its workspace itself.
    pub fn step_in(
        &self,
        z: &State<N>,
        ws: &mut StepWorkspace<N, C>,
    ) -> Result<State<N>, StepError> {
        match self.step_with_report_in(z, ws) {
            Ok((z1, _)) => Ok(z1),
            // out of line, as in `step`
            Err(e) => failed(e),
        }
    }

    /// [`Stepper::step_with_report`] in a kept workspace (see
    /// [`Stepper::step_in`]).
    pub fn step_with_report_in(
        &self,
        z: &State<N>,
        ws: &mut StepWorkspace<N, C>,
    ) -> Result<(State<N>, StepReport), StepError> {
        self.step_forced_with_report_in(z, &NO_INPUT, ws)
    }

    /// One step from `z` with its momentum `p0` known (from the previous
    /// step, see [`Stepper::momentum`]); returns the new state, its momentum
    /// and diagnostics ([`Stepper::step_forced_with_momentum`] with no
    /// inputs).
    pub fn step_with_momentum(
        &self,
        z: &State<N>,
        p0: &SVector<f64, N>,
    ) -> Result<(State<N>, SVector<f64, N>, StepReport), StepError> {
        self.step_forced_with_momentum(z, p0, &NO_INPUT)
    }

    /// Fills `out` with the trajectory from `z0`: `out[0] = z0`, then one
    /// step per entry (see [`Stepper::steps_into`]). No allocation.
    pub fn rollout_into(&self, z0: &State<N>, out: &mut [State<N>]) -> Result<(), RolloutError> {
        let Some((first, rest)) = out.split_first_mut() else {
            return Ok(());
        };
        *first = *z0;
        self.steps_into(z0, rest)
    }

    /// Fills `out` with the states after 1, 2, …, `out.len()` steps from
    /// `z0` ([`Stepper::steps_forced_into`] with no inputs). The momentum is
    /// carried from step to step, and Newton starts from the linear
    /// extrapolation 2v_k − v_{k−1} (the converged step is the same to the
    /// solver tolerance). No allocation.
    pub fn steps_into(&self, z0: &State<N>, out: &mut [State<N>]) -> Result<(), RolloutError> {
        self.roll_into(z0, core::iter::repeat(&NO_INPUT), out)
    }

    /// One variational step of size `h` from position `x1` with momentum
    /// `p0` (module docs), Newton started at `guess`: returns v₁, the new
    /// momentum p₁ and diagnostics. This is the position–momentum form of
    /// the integrator, (x₁, p₀) ↦ (x₁ + h·v₁, p₁), which composition
    /// methods chain with different `h` ([`Stepper::solve_forced`] with no
    /// inputs).
    #[inline(always)]
    pub fn solve(
        &self,
        x1: &SVector<f64, N>,
        p0: &SVector<f64, N>,
        h: f64,
        guess: &SVector<f64, N>,
    ) -> Result<Solved<N>, StepError> {
        self.solve_forced_any(x1, p0, h, guess, &NO_INPUT, &mut Workspace::new())
            .map(|(v, p, r, _)| (v, p, r))
    }

    /// The sub-step of [`Stepper::solve`] with the generalized input force
    /// `input(q)` = B(q)u and its configuration derivative `input_jac(q)`
    /// when `FORCED` (`crate::forced`: B(m₁)u joins the forces f(m₁, v₁)
    /// in the residual and in the momentum carried on); also returns the
    /// multipliers λ. With `FORCED = false` neither is called and the code
    /// is that of the unforced step. `t` is the solver's workspace; after a
    /// converged solve it holds the terms at the solution's quadrature
    /// point m₁(v₁) = x₁ + αh·v₁ (the derivatives reuse them).
    #[inline(always)]
    #[expect(
        clippy::too_many_arguments,
        reason = "internal: the sub-step's data, the two input closures and the terms workspace"
    )]
    pub(crate) fn solve_forced_rule<const MID: bool, const FORCED: bool>(
        &self,
        x1: &SVector<f64, N>,
        p0: &SVector<f64, N>,
        h: f64,
        guess: &SVector<f64, N>,
        input_force: impl Fn(&SVector<f64, N>) -> SVector<f64, N>,
        input_jac: impl Fn(&SVector<f64, N>) -> SMatrix<f64, N, N>,
        ws: &mut Workspace<N, C>,
    ) -> Result<Forced<N, C>, StepError> {
        let alpha = if MID { 0.5 } else { 0.0 };
        let Workspace {
            t,
            cg,
            g_slot,
            g_at,
            factors,
            schur,
        } = ws;
        let model = &self.model;
        let k = &self.k;
        let opts = &self.options;
        // G's structural zeros as index lists, evaluated at compile time
        // (a constant: the Schur complement's loops unroll over it)
        let cols: &ConstraintColumns<N, C> =
            const { &ConstraintColumns::new(&M::CONSTRAINT_PATTERN) };
        let mut v = if max_abs(guess).is_nan() {
            SVector::zeros()
        } else {
            *guess
        };
        // terms at x₁ (first order: once per step) or at m₁(v)
        let at = |v: &SVector<f64, N>| {
            if MID { x1 + v * (alpha * h) } else { *x1 }
        };
        model.terms(k, &at(&v), t);
        // generalized input force B(m₁)u (first order: once per step)
        let input = |q: &SVector<f64, N>| {
            if FORCED {
                input_force(q)
            } else {
                SVector::<f64, N>::zeros()
            }
        };
        let mut bu = input(&at(&v));
        let mut m_bar = 0.0f64;
        for i in 0..N {
            m_bar = m_bar.max(t.mass[(i, i)].abs());
        }
        if !m_bar.is_normal() {
            // M = 0 (every link massless, or masses so small that M
            // underflows): the DEL equations do not determine v₁, and every
            // guess would pass the residual test
            return Err(StepError::singular(0));
        }
        let p_scale = match max_abs(p0) + m_bar {
            0.0 => 1.0,
            s => s,
        };
        let mut l_scale = 1.0f64;
        for (x, kind) in x1.as_slice().iter().zip(M::KINDS.iter()) {
            if *kind == CoordinateKind::Length {
                l_scale = l_scale.max(1.0 + x.abs());
            }
        }
        let (inv_p, inv_l) = (1.0 / p_scale, 1.0 / l_scale);
        // G₁ = G(x₁), fixed for the step, and G₁ᵀ for the constraint
        // forces −G₁ᵀλ (J⁻¹B, B = −G₁ᵀ, is read from G₁'s columns)
        // (`cg[i1]`: the previous step's G at its solution when that was
        // at x₁, see `Workspace`)
        let i1 = *g_slot;
        if C > 0 && !same_bits(g_at, x1) {
            cg[i1] = model.constraints_and_jacobian(k, x1);
            *g_at = *x1;
        }
        let g1t = cg[i1].1.transpose();
        let a1 = (1.0 - alpha) * h;
        // residual d(v, λ) and Q (row l = (∂M/∂q_l v)ᵀ, which the Newton
        // matrix reuses); constraint c(v) and its Jacobian G(x₁ + h v)
        // (Q is written to `q_out` only where the mass matrix moves: with
        // a constant one it is zero and unused, and carrying it would cost
        // a zeroed and a copied N × N matrix per residual)
        let residual = |t: &Terms<N>,
                        bu: &SVector<f64, N>,
                        v: &SVector<f64, N>,
                        lambda: &SVector<f64, C>,
                        q_out: &mut SMatrix<f64, N, N>| {
            let (q, kin) = M::kinetic(t, v);
            if !M::CONSTANT_MASS {
                *q_out = q;
            }
            let mut f = kin - t.dpotential;
            if M::DISSIPATIVE {
                f -= M::damping_times(t, v);
            }
            if FORCED {
                f += bu;
            }
            let mut d = p0 + f * a1 - M::mass_times(t, v);
            if C > 0 {
                // G₁ᵀλ as nalgebra's `g1t * lambda` forms it (gemv: the
                // product with λ₀ stored, then λ_j times column j added
                // for j = 1, 2, … — the same roundings), inline: out of
                // line the product and its result make a round trip
                // through memory. G₁ᵀ stored: its columns are contiguous,
                // so the loop vectorises across rows.
                let mut gl = [0.0f64; N];
                for (j, (col, lj)) in g1t
                    .as_slice()
                    .chunks_exact(N)
                    .zip(lambda.as_slice())
                    .enumerate()
                {
                    for (y, g) in gl.iter_mut().zip(col) {
                        *y = if j == 0 { g * lj } else { *y + g * lj };
                    }
                }
                d -= SVector::from(gl);
            }
            d
        };
        let constraint = |v: &SVector<f64, N>| {
            if C > 0 {
                model.constraints_and_jacobian(k, &(x1 + v * h))
            } else {
                (SVector::zeros(), SMatrix::zeros())
            }
        };
        // NaN-propagating: f64::max would drop a NaN residual part (an
        // overflowed kinetic term) and report the other one
        let error = |d: &SVector<f64, N>, c: &SVector<f64, C>| {
            let a = max_abs(d) * inv_p;
            if C == 0 {
                // a is ≥ 0, +∞ or NaN (max_abs poisons): the combination
                // below would only turn +∞ into NaN, and every use of the
                // error treats both alike (non-finite). Four dependent
                // operations fewer per residual of a tree.
                return a;
            }
            let b = max_abs(c) * inv_l;
            a.max(b) + (a + b) * 0.0
        };
        let mut lambda = SVector::<f64, C>::zeros();
        // Q at the iterate and at the trial point (unused with a constant
        // mass matrix)
        let (mut qm, mut qn) = (SMatrix::<f64, N, N>::zeros(), SMatrix::<f64, N, N>::zeros());
        let mut d = residual(t, &bu, &v, &lambda, &mut qm);
        // c and G₂ at the iterate (`cg[cur]`) and at the line search's
        // trial point (`cg[trial]`): a trial point is accepted by
        // switching the two, without copying G₂ (C × N numbers)
        // `spare`: where the kept S was formed after a fresh KKT solve
        // (the chord steps' A), or free
        let (mut cur, mut trial, mut spare) = match i1 {
            0 => (1, 2, 3),
            1 => (2, 3, 0),
            2 => (3, 0, 1),
            _ => (0, 1, 2),
        };
        cg[cur] = constraint(&v);
        let mut err = error(&d, &cg[cur].0);
        let mut regularised = false;
        let momentum = |t: &Terms<N>, bu: &SVector<f64, N>, v: &SVector<f64, N>| {
            if MID {
                let mut f = Self::forces(t, v);
                if FORCED {
                    f += bu;
                }
                M::mass_times(t, v) + f * (alpha * h)
            } else {
                M::mass_times(t, v)
            }
        };
        let mut jac = SMatrix::<f64, N, N>::zeros();
        let mut reuse_jac = false;
        // first-order rule with a constant mass matrix: the terms stay at
        // x₁, so J = −M − a₁·D(x₁) is the same in every iteration
        let jac_constant = !MID && M::CONSTANT_MASS;
        // J's factorisation and J⁻¹B (B = −G₁ᵀ is fixed for the step),
        // formed in place at the first KKT solve when `jac_constant`
        // (`factored`); `factors_ok` false after that = J needs the robust
        // solve

        let (mut factored, mut factors_ok) = (false, false);
        // B = −G₁ᵀ for the general KKT solve, formed at its first use
        let mut neg_g1t: Option<SMatrix<f64, N, C>> = None;
        // with them: the factored Schur complement S = G₂J⁻¹B of the last
        // fresh KKT solve and the G₂ it was formed from, and whether the
        // next iteration is a chord step with them (`keep_schur`, below)
        schur.clear();
        let mut keep_schur = false;
        'newton: for iteration in 0..opts.max_iterations {
            if !err.is_finite() {
                return Err(StepError::non_finite_residual(iteration));
            }
            if err <= opts.tolerance {
                let report = StepReport::newton(iteration, err, false, regularised);
                if C > 0 {
                    // c and G at x₁ + h·v, the next step's x₁
                    (*g_slot, *g_at) = (cur, x1 + v * h);
                }
                return Ok((v, momentum(t, &bu, &v), report, lambda));
            }
            // Newton matrix ∂d/∂v (module docs). Midpoint rule: after an
            // iteration that contracted the residual 100-fold at a full
            // step, the previous matrix is kept (a chord step: the matrix
            // moves with v only through the O(Δt²) F_q term and the O(Δt) Q
            // terms, so the contraction stays far below the one observed;
            // an iteration that contracts less recomputes it). This skips
            // one force Jacobian — the model's trigonometry again — per
            // sub-step of the fourth-order composition.
            if !((MID && reuse_jac) || (jac_constant && iteration > 0)) {
                // −M − a₁·D in one pass over the storage (nalgebra's
                // element-wise operators iterate with per-element
                // bookkeeping that costs more than the arithmetic), read
                // from M and D where they are (copying M into J first costs
                // a memcpy of N² numbers)
                let mass = t.mass.as_slice().iter();
                if M::DISSIPATIVE {
                    let md = mass.zip(t.damping.as_slice());
                    for (j, (m, dmp)) in jac.as_mut_slice().iter_mut().zip(md) {
                        *j = -*m - a1 * dmp;
                    }
                } else {
                    for (j, m) in jac.as_mut_slice().iter_mut().zip(mass) {
                        *j = -*m;
                    }
                }
                if !M::CONSTANT_MASS {
                    jac += qm * a1;
                    if MID {
                        jac -= qm.transpose() * (alpha * h);
                    }
                }
                if MID {
                    let mut fq = model.force_jacobian(k, &at(&v), &v);
                    if FORCED {
                        fq += input_jac(&at(&v));
                    }
                    jac += fq * (alpha * a1 * h);
                }
            }
            let singular = StepError::singular(iteration);
            // this iteration's direction comes from a kept S (first-order
            // rule with constraints and a constant J)
            let mut chord = false;
            // this iteration's direction formed a kept S at `cur`
            let mut fresh = false;
            let (dv, dl) = if C == 0 {
                let dv = solve_partial(&jac, &(-d)).ok_or(singular)?;
                // First-order rule, tree: with x₁ fixed d is exactly
                // quadratic in v, so after a full Newton step the residual
                // is the quadratic remainder (Δt/2)[Δvᵀ ∂M/∂q_i Δv]_i up to
                // the O(ε·scale) rounding of d(v) and of the solve, cheaper
                // than evaluating d again. Within half the tolerance (the
                // other half covers the rounding) the step is accepted.
                if !MID {
                    let bound = 0.5 * h.abs() * M::quadratic_max(t, &dv) * inv_p;
                    if bound <= 0.5 * opts.tolerance {
                        let v1 = v + dv;
                        if v1.iter().all(|x| x.is_finite()) {
                            let report =
                                StepReport::newton(iteration + 1, bound, false, regularised);
                            return Ok((v1, M::mass_times(t, &v1), report, lambda));
                        }
                    }
                }
                (dv, SVector::zeros())
            } else {
                // J Δv − G₁ᵀΔλ = −d,  G₂ Δv = −c/h
                let (r, cc) = (-d, cg[cur].0 / -h);
                // only where J is kept across iterations: elsewhere the
                // factors would serve one solve and cost their copies
                if jac_constant && !factored {
                    // in place: returned in an Option, the factors
                    // (kilobytes) would be copied on the way
                    factors_ok = factors.factor_constraint_jacobian(&jac, &cg[i1].1);
                    factored = true;
                }
                let fast = if jac_constant && factors_ok {
                    // a chord step: S and G₂ (in the constraint row) of
                    // an earlier iterate, see `keep_schur`; d and c are
                    // evaluated exactly, so the tolerance means the same.
                    // Skips forming S (O(nnz(G₂)·C)) and its O(C³/3)
                    // factorisation.
                    chord = keep_schur && schur.is_formed();
                    let sol = if chord {
                        factors.solve_chord(schur, &cg[spare].1, &r, &cc)
                    } else {
                        None
                    };
                    if sol.is_some() {
                        sol
                    } else {
                        chord = false;
                        fresh = true;
                        factors.solve_keeping(&cg[cur].1, cols, &r, &cc, schur)
                    }
                } else {
                    None
                };
                match fast {
                    Some(sol) => sol,
                    None => {
                        // B = −G₁ᵀ, formed at the step's first general
                        // KKT solve (J moves with v, or J's factors failed)
                        let b = neg_g1t.get_or_insert_with(|| -g1t);
                        let (sol, reg) =
                            solve_kkt_regularised(&jac, b, &cg[cur].1, &r, &cc).ok_or(singular)?;
                        regularised |= reg;
                        sol
                    }
                }
            };
            // backtracking on the scaled residual
            let mut step = 1.0;
            loop {
                let (vn, ln) = (v + dv * step, lambda + dl * step);
                if MID {
                    model.terms(k, &at(&vn), t);
                    if FORCED {
                        bu = input(&at(&vn));
                    }
                }
                let dn = residual(t, &bu, &vn, &ln, &mut qn);
                cg[trial] = constraint(&vn);
                let errn = error(&dn, &cg[trial].0);
                if errn.is_finite() && (errn < err || errn <= opts.tolerance) {
                    reuse_jac = step == 1.0 && errn <= 0.01 * err;
                    if jac_constant && C > 0 {
                        // S moves with v only through G₂ = G(x₁ + h·v), so
                        // a chord step after this one contracts the
                        // residual by about the relative move h‖Δv‖ of G₂'s
                        // configuration (G's entries are sines and cosines
                        // of angles times lengths). S is kept when that
                        // step is predicted to converge: a chord iteration
                        // that contracts less than Newton's would add
                        // iterations (steps from a state, whose first
                        // Newton step moves v by O(Δt·v̇), rather than from
                        // a rollout's extrapolated guess).
                        keep_schur = step == 1.0 && h.abs() * max_abs(&dv) * errn <= opts.tolerance;
                    }
                    (v, lambda, d, err) = (vn, ln, dn, errn);
                    if !M::CONSTANT_MASS {
                        qm = qn;
                    }
                    if fresh {
                        // the iterate's G goes with S
                        (cur, trial, spare) = (trial, spare, cur);
                    } else {
                        (cur, trial) = (trial, cur);
                    }
                    break;
                }
                step *= 0.5;
                if step < opts.min_step {
                    if MID {
                        // terms back at the current iterate
                        model.terms(k, &at(&v), t);
                        if FORCED {
                            bu = input(&at(&v));
                        }
                    }
                    if (MID && reuse_jac) || chord {
                        // a chord direction that does not descend: retry
                        // with the exact Newton matrix (or a fresh S)
                        reuse_jac = false;
                        keep_schur = false;
                        continue 'newton;
                    }
                    // no decrease along the exact Newton direction: accept
                    // at the attainable accuracy, or fail
                    if err <= opts.stall_tolerance {
                        let report = StepReport::newton(iteration + 1, err, true, regularised);
                        if C > 0 {
                            // c and G at x₁ + h·v, the next step's x₁
                            (*g_slot, *g_at) = (cur, x1 + v * h);
                        }
                        return Ok((v, momentum(t, &bu, &v), report, lambda));
                    }
                    return Err(StepError::line_search_failed(iteration, err));
                }
            }
        }
        if err <= opts.tolerance {
            let report = StepReport::newton(opts.max_iterations, err, false, regularised);
            if C > 0 {
                // c and G at x₁ + h·v, the next step's x₁
                (*g_slot, *g_at) = (cur, x1 + v * h);
            }
            return Ok((v, momentum(t, &bu, &v), report, lambda));
        }
        Err(StepError::not_converged(
            opts.max_iterations,
            err,
            opts.tolerance,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two coordinates with unit masses (M = I), no forces, one constraint
    /// ψ(q₀) = B·ψ₀(q₀/L) = 0 whose slope changes sign at a kink:
    /// ψ₀(z) = 1 − z left of 0.99, K(z − m)² − e right of it (continuous
    /// there, root m + √(e/K)). Newton from z = 0 lands at z = 1, the
    /// residual cut 200-fold to 5e-10 after a move of 1e-5 (the chord step
    /// is predicted to converge), where the slope is
    /// +8.5 instead of −1: that chord step on S raises |ψ| at every step
    /// length.
    #[derive(Clone, Copy, Debug)]
    struct Kinked;

    const B: f64 = 1e-7;
    const L: f64 = 1e-5;
    const K: f64 = 1000.0;
    const M: f64 = 0.99575;
    const E: f64 = 0.0230625;

    /// ψ and ψ'.
    fn psi(q: f64) -> (f64, f64) {
        let z = q / L;
        let (p, slope) = if z < 0.99 {
            (1.0 - z, -1.0)
        } else {
            (K * (z - M) * (z - M) - E, 2.0 * K * (z - M))
        };
        (B * p, B / L * slope)
    }

    impl Dynamics<2, 1> for Kinked {
        const KINDS: [CoordinateKind; 2] = [CoordinateKind::Angle; 2];
        const DISSIPATIVE: bool = false;
        const CONSTANT_MASS: bool = true;
        type Constants = ();

        fn constants(&self) -> Result<(), StepError> {
            Ok(())
        }

        fn mass(&self, _: &(), _: &SVector<f64, 2>) -> SMatrix<f64, 2, 2> {
            SMatrix::identity()
        }

        fn potential(&self, _: &(), _: &SVector<f64, 2>) -> f64 {
            0.0
        }

        fn terms(&self, _: &(), _: &SVector<f64, 2>, out: &mut Terms<2>) {
            out.mass = SMatrix::identity();
        }

        fn force_jacobian(
            &self,
            _: &(),
            _: &SVector<f64, 2>,
            _: &SVector<f64, 2>,
        ) -> SMatrix<f64, 2, 2> {
            SMatrix::zeros()
        }

        fn constraint_values(&self, _: &(), q: &SVector<f64, 2>) -> SVector<f64, 1> {
            SVector::from([psi(q[0]).0])
        }

        fn constraints_and_jacobian(
            &self,
            _: &(),
            q: &SVector<f64, 2>,
        ) -> (SVector<f64, 1>, SMatrix<f64, 1, 2>) {
            let (g, slope) = psi(q[0]);
            (SVector::from([g]), SMatrix::from([[slope], [0.0]]))
        }
    }

    /// A chord step on the Schur complement that does not descend is
    /// retried with a fresh one, and the step converges to the root
    /// (without the retry it fails: `LineSearchFailed` at iteration 1 with
    /// the residual 5e-10, above the stall tolerance).
    #[test]
    fn failed_chord_step_is_retried_with_a_fresh_schur_complement() {
        let s = Stepper::new(Kinked, 1.0).unwrap();
        let zero = SVector::<f64, 2>::zeros();
        // x₁ = 0, h = 1: the constraint is ψ(v₀)
        let (v, _, report) = s.solve(&zero, &zero, 1.0, &zero).unwrap();
        let tol = s.step_options().tolerance;
        assert!(!report.stalled && !report.regularised, "{report:?}");
        assert!(report.residual <= tol, "{report:?}");
        // |ψ| ≤ tol within tol/ψ' of the root
        let root = L * (M + (E / K).sqrt());
        let slope = psi(root).1;
        assert!((v[0] - root).abs() <= 2.0 * tol / slope, "{v} {root}");
        assert_eq!(v[1], 0.0);
    }
}
