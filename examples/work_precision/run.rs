//! Running the integrators: one enum over the six integrators, the timed
//! runs to t = T, the reference solution and the long energy runs.
//!
//! Everything here is generic over the mechanism; the results it returns are
//! plain numbers, so that the analysis and the output need no generics.

use crate::median::median;
use std::hint::black_box;
use std::time::Instant;

use nalgebra::SVector;
use vigp::prelude::*;

/// The six integrators compared.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Method {
    /// `ExplicitEuler` on (q, q̇).
    ExplicitEuler,
    /// `SymplecticEuler` on (q, q̇).
    SymplecticEuler,
    /// `Rk4` on (q, q̇).
    Rk4,
    /// `Variational::new`: the paper's first-order VI.
    Vi1,
    /// `Variational::midpoint`: the second-order VI.
    Vi2,
    /// `Composition::new`: the fourth-order VI (Suzuki's five-stage
    /// composition of the midpoint VI); its state carries the continuous q̇.
    Vi4,
}

impl Method {
    /// All methods, in table order.
    pub const ALL: [Method; 6] = [
        Method::ExplicitEuler,
        Method::SymplecticEuler,
        Method::Rk4,
        Method::Vi1,
        Method::Vi2,
        Method::Vi4,
    ];

    /// Identifier used in the CSV files.
    pub fn id(self) -> &'static str {
        match self {
            Method::ExplicitEuler => "explicit_euler",
            Method::SymplecticEuler => "symplectic_euler",
            Method::Rk4 => "rk4",
            Method::Vi1 => "vi_paper",
            Method::Vi2 => "vi_midpoint",
            Method::Vi4 => "vi_4th_order",
        }
    }

    /// Human-readable name used in tables and legends.
    pub fn label(self) -> &'static str {
        match self {
            Method::ExplicitEuler => "explicit Euler",
            Method::SymplecticEuler => "symplectic Euler",
            Method::Rk4 => "RK4",
            Method::Vi1 => "VI (paper, 1st order)",
            Method::Vi2 => "VI (midpoint, 2nd order)",
            Method::Vi4 => "VI (4th order, Suzuki)",
        }
    }

    /// The known order of accuracy.
    pub fn order(self) -> f64 {
        match self {
            Method::ExplicitEuler | Method::SymplecticEuler | Method::Vi1 => 1.0,
            Method::Vi2 => 2.0,
            Method::Rk4 | Method::Vi4 => 4.0,
        }
    }

    /// `true` for the integrators that solve a Newton iteration every step
    /// (the variational ones), whose error has a solver part.
    pub fn has_solver(self) -> bool {
        matches!(self, Method::Vi1 | Method::Vi2 | Method::Vi4)
    }

    /// `true` for the integrators whose state carries a discrete velocity
    /// (the first-order and midpoint VIs). The fourth-order VI carries the
    /// continuous q̇, like the classical integrators.
    pub fn discrete_velocity(self) -> bool {
        matches!(self, Method::Vi1 | Method::Vi2)
    }
}

/// One of the six integrators, statically dispatched.
pub enum AnyIntegrator<M: Mechanism<N, C>, const N: usize, const C: usize> {
    /// Explicit Euler.
    ExplicitEuler(ExplicitEuler<M, N, C>),
    /// Symplectic Euler.
    SymplecticEuler(SymplecticEuler<M, N, C>),
    /// RK4.
    Rk4(Rk4<M, N, C>),
    /// The first-order or the midpoint variational integrator.
    Variational(Variational<M, N, C>),
    /// The fourth-order variational integrator.
    Composition(Composition<M, N, C>),
}

impl<M: Mechanism<N, C> + Copy, const N: usize, const C: usize> AnyIntegrator<M, N, C> {
    /// The integrator `method` for `model` at time step `dt`.
    pub fn new(method: Method, model: M, dt: f64) -> Self {
        Self::with_tolerance(method, model, dt, None)
    }

    /// The integrator `method` with the Newton tolerance `tolerance`
    /// (relative residual; `None`: the default 1e-12). The classical
    /// integrators have no Newton iteration and ignore it.
    pub fn with_tolerance(method: Method, model: M, dt: f64, tolerance: Option<f64>) -> Self {
        let vi = |v: Variational<M, N, C>| {
            Self::Variational(match tolerance {
                Some(t) => v.tolerance(t).expect("the sweep's tolerances are > 0"),
                None => v,
            })
        };
        match method {
            Method::ExplicitEuler => Self::ExplicitEuler(ExplicitEuler::new(model, dt)),
            Method::SymplecticEuler => Self::SymplecticEuler(SymplecticEuler::new(model, dt)),
            Method::Rk4 => Self::Rk4(Rk4::new(model, dt)),
            Method::Vi1 => {
                vi(Variational::new(model, dt).expect("the sweep's Δt and models are valid"))
            }
            Method::Vi2 => {
                vi(Variational::midpoint(model, dt).expect("the sweep's Δt and models are valid"))
            }
            Method::Vi4 => {
                let options = StepOptions {
                    tolerance: tolerance.unwrap_or(StepOptions::default().tolerance),
                    ..StepOptions::default()
                };
                Self::Composition(
                    Composition::new(model, dt)
                        .and_then(|c| c.options(options))
                        .expect("the sweep's Δt, models and tolerances are valid"),
                )
            }
        }
    }

    /// Energy of a state of this integrator: E(q, q̇) for the classical
    /// integrators, E(q + αΔt·v, v) at the rule's quadrature point for the
    /// variational ones (`Variational::energy`; α = 0 for the paper's VI,
    /// ½ for the midpoint VI). The fourth-order VI's state is continuous:
    /// E(q, q̇) as for the classical integrators.
    pub fn energy(&self, model: &M, z: &State<N>) -> f64 {
        match self {
            Self::Variational(vi) => vi.energy(z),
            Self::Composition(vi) => vi.energy(z),
            _ => model.energy(z),
        }
    }
}

impl<M: Mechanism<N, C> + Copy, const N: usize, const C: usize> Integrator
    for AnyIntegrator<M, N, C>
{
    type State = State<N>;
    type Error = StepError;
    type Mechanism = M;

    fn dt(&self) -> f64 {
        match self {
            Self::ExplicitEuler(i) => i.dt(),
            Self::SymplecticEuler(i) => i.dt(),
            Self::Rk4(i) => i.dt(),
            Self::Variational(i) => Integrator::dt(i),
            Self::Composition(i) => i.dt(),
        }
    }

    fn step(&self, z: &State<N>) -> Result<State<N>, StepError> {
        match self {
            Self::ExplicitEuler(i) => i.step(z),
            Self::SymplecticEuler(i) => i.step(z),
            Self::Rk4(i) => i.step(z),
            Self::Variational(i) => Integrator::step(i, z),
            Self::Composition(i) => i.step(z),
        }
    }
}

/// Why a run produced no number.
#[derive(Clone, Debug, PartialEq)]
pub struct Failure {
    /// `true` if the state or a residual became non-finite (a blow-up);
    /// `false` for other solver failures (no convergence, singular matrix).
    pub diverged: bool,
    /// The error message, including the step at which it happened.
    pub message: String,
}

impl Failure {
    /// Classifies a step error.
    pub fn from_step(e: &StepError) -> Self {
        Self {
            diverged: matches!(
                e,
                StepError::NonFiniteState { .. } | StepError::NonFiniteResidual { .. }
            ),
            message: e.to_string(),
        }
    }

    /// `"diverged"` or `"failed"`.
    pub fn status(&self) -> &'static str {
        if self.diverged { "diverged" } else { "failed" }
    }
}

/// One test problem: a model in minimal coordinates and a continuous
/// initial state (q₀, q̇₀), consistent with the constraints, if any.
#[derive(Clone, Copy, Debug)]
pub struct Problem<M, const N: usize, const C: usize> {
    /// Short name used in file names and CSV files.
    pub name: &'static str,
    /// The model (minimal coordinates).
    pub model: M,
    /// Initial configuration.
    pub q0: SVector<f64, N>,
    /// Initial continuous velocity.
    pub qdot0: SVector<f64, N>,
}

impl<M: Mechanism<N, C> + Copy, const N: usize, const C: usize> Problem<M, N, C> {
    /// The initial state of `method` at step `dt`: (q₀, q̇₀) for the classical
    /// integrators and the fourth-order VI (q̇₀ must satisfy G(q₀)q̇₀ = 0 for
    /// loops; the problems here start at rest); (q₀, v₀) with the discrete velocity
    /// v₀ = q̇₀ + ½Δt·q̈₀, projected onto g(q₀ + Δt·v₀) = 0, for the
    /// variational ones (`vigp::dynamics::discrete_velocity`; starting the
    /// midpoint rule from v₀ = q̇₀ would cost it an order).
    pub fn start(&self, method: Method, dt: f64) -> Result<State<N>, StepError> {
        let v = if method.discrete_velocity() {
            vigp::dynamics::discrete_velocity(&self.model, &self.q0, &self.qdot0, dt)?
        } else {
            self.qdot0
        };
        Ok(State { q: self.q0, v })
    }

    /// The physical initial energy E(q₀, q̇₀).
    pub fn energy0(&self) -> f64 {
        self.model.energy(&State {
            q: self.q0,
            v: self.qdot0,
        })
    }
}

/// Runs `steps` steps from `z0`; returns the final state (or the error,
/// naming the step) and the wall time of the stepping loop in seconds.
pub fn timed_run<I: Integrator<State = State<N>, Error = StepError>, const N: usize>(
    integrator: &I,
    z0: &State<N>,
    steps: usize,
) -> (Result<State<N>, StepError>, f64) {
    let mut z = black_box(*z0);
    let start = Instant::now();
    for k in 0..steps {
        match integrator.step(&z) {
            Ok(next) => z = next,
            Err(e) => return (Err(e.at_step(k)), start.elapsed().as_secs_f64()),
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    (Ok(black_box(z)), seconds)
}

/// How often and how long to repeat a timed run.
#[derive(Clone, Copy, Debug)]
pub struct Timing {
    /// At least this many timed repetitions.
    pub min_reps: usize,
    /// Repeat until the repetitions took at least this long in total (s) …
    pub min_total: f64,
    /// … but at most this many repetitions.
    pub max_reps: usize,
}

/// A finished run to t = T.
#[derive(Clone, Debug, PartialEq)]
pub struct Measured {
    /// max_i |q_i(T) − q_ref,i(T)| over the minimal coordinates.
    pub error: f64,
    /// |g(q(T))|, the constraint violation at the end (0 without constraints).
    pub constraint_violation: f64,
    /// For the integrators with a Newton iteration: max_i |q_i(T) − q̃_i(T)|
    /// against the same run solved to [`REFERENCE_TOLERANCE`], the part of
    /// the error due to the default solver tolerance (`None`: no solver, or
    /// the tight run failed).
    pub solver_error: Option<f64>,
    /// Median wall time per simulated second (s/s) over the repetitions.
    pub cost: f64,
    /// Fastest repetition (s/s).
    pub cost_min: f64,
    /// Slowest repetition (s/s).
    pub cost_max: f64,
    /// Number of timed repetitions.
    pub reps: usize,
}

/// One point of the work-precision sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepPoint {
    /// The integrator.
    pub method: Method,
    /// Time step (s); `steps · dt = T` exactly.
    pub dt: f64,
    /// Number of steps to T.
    pub steps: usize,
    /// The measurement, or why there is none.
    pub outcome: Result<Measured, Failure>,
}

/// Runs `method` to t = `steps · dt` from the problem's initial state,
/// repeating the timed run as `timing` asks, and compares the final
/// position with `q_ref`. Only the stepping loop is timed (not the
/// initial discrete velocity, not the error evaluation).
pub fn sweep_point<M: Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    problem: &Problem<M, N, C>,
    method: Method,
    steps: usize,
    t_end: f64,
    q_ref: &SVector<f64, N>,
    timing: &Timing,
) -> SweepPoint {
    let dt = t_end / steps as f64;
    let outcome = (|| {
        let z0 = problem.start(method, dt).map_err(|e| Failure {
            message: format!("initial state: {e}"),
            ..Failure::from_step(&e)
        })?;
        let integrator = AnyIntegrator::new(method, problem.model, dt);
        let (end, first) = timed_run(&integrator, &z0, steps);
        let end = end.map_err(|e| Failure::from_step(&e))?;
        let mut times = vec![first];
        while times.len() < timing.min_reps
            || (times.iter().sum::<f64>() < timing.min_total && times.len() < timing.max_reps)
        {
            let (again, t) = timed_run(&integrator, &z0, steps);
            if again.as_ref().ok() != Some(&end) {
                return Err(Failure {
                    diverged: false,
                    message: "a repetition gave a different result".into(),
                });
            }
            times.push(t);
        }
        // the solver's share of the error: the same run at a tight
        // tolerance (untimed)
        let solver_error = method
            .has_solver()
            .then(|| {
                let tight = AnyIntegrator::with_tolerance(
                    method,
                    problem.model,
                    dt,
                    Some(REFERENCE_TOLERANCE),
                );
                timed_run(&tight, &z0, steps)
                    .0
                    .ok()
                    .map(|z| (end.q - z.q).amax())
            })
            .flatten();
        let per_sim_s = |t: f64| t / t_end;
        let cost_min = times.iter().copied().fold(f64::INFINITY, f64::min);
        let cost_max = times.iter().copied().fold(0.0, f64::max);
        let reps = times.len();
        Ok(Measured {
            error: (end.q - q_ref).amax(),
            constraint_violation: problem.model.constraint_violation(&end),
            solver_error,
            cost: per_sim_s(median(&mut times)),
            cost_min: per_sim_s(cost_min),
            cost_max: per_sim_s(cost_max),
            reps,
        })
    })();
    SweepPoint {
        method,
        dt,
        steps,
        outcome,
    }
}

/// Newton tolerance of the reference runs (relative residual). The default
/// 1e-12 leaves a solver error that accumulates to ~1e-9 over 10⁵ steps and
/// does not shrink with h, which would spoil the extrapolation; 1e-15 is
/// reached in 1–2 iterations.
pub const REFERENCE_TOLERANCE: f64 = 1e-15;

/// Final positions of the midpoint VI at step `t_end / steps`, solved to
/// [`REFERENCE_TOLERANCE`].
pub fn midpoint_positions<M: Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    problem: &Problem<M, N, C>,
    steps: usize,
    t_end: f64,
) -> Result<SVector<f64, N>, StepError> {
    final_positions(problem, Method::Vi2, steps, t_end, |h| {
        Variational::midpoint(problem.model, h)?.tolerance(REFERENCE_TOLERANCE)
    })
}

/// Final positions of RK4 at step `t_end / steps`.
pub fn rk4_positions<M: Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    problem: &Problem<M, N, C>,
    steps: usize,
    t_end: f64,
) -> Result<SVector<f64, N>, StepError> {
    final_positions(problem, Method::Rk4, steps, t_end, |h| {
        Ok(Rk4::new(problem.model, h))
    })
}

/// Final positions at step h = `t_end / steps` of the integrator that
/// `integrator(h)` makes, from `method`'s start state.
fn final_positions<I, M, const N: usize, const C: usize>(
    problem: &Problem<M, N, C>,
    method: Method,
    steps: usize,
    t_end: f64,
    integrator: impl FnOnce(f64) -> Result<I, StepError>,
) -> Result<SVector<f64, N>, StepError>
where
    I: Integrator<State = State<N>, Error = StepError>,
    M: Mechanism<N, C> + Copy,
{
    let h = t_end / steps as f64;
    let z0 = problem.start(method, h)?;
    let (end, _) = timed_run(&integrator(h)?, &z0, steps);
    Ok(end?.q)
}

/// Richardson extrapolation of a second-order method from steps h and h/2:
/// (4·q(h/2) − q(h))/3, which removes the h² term of the error.
pub fn richardson<const N: usize>(
    coarse: &SVector<f64, N>,
    fine: &SVector<f64, N>,
) -> SVector<f64, N> {
    (fine * 4.0 - coarse) / 3.0
}

/// An independent check of the reference: a name and a function that
/// computes q(T) another way.
pub type Check<'a, const N: usize> = (String, &'a dyn Fn() -> Result<SVector<f64, N>, StepError>);

/// The reference solution q_ref(T) and what is known about its accuracy.
#[derive(Clone, Debug)]
pub struct Reference<const N: usize> {
    /// q_ref(T): the midpoint VI at h/2 and h/4, Richardson-extrapolated.
    pub q: SVector<f64, N>,
    /// The coarsest reference step h (s).
    pub h: f64,
    /// max |q_mid(h/2) − q_mid(h/4)|: the raw midpoint VI's own convergence.
    pub raw_difference: f64,
    /// max |R(h, h/2) − R(h/2, h/4)|: the difference between the
    /// extrapolations from two pairs of resolutions, an (over-)estimate of
    /// the error of the reference R(h/2, h/4).
    pub error_estimate: f64,
    /// Independent checks: (description, max |q_check(T) − q_ref(T)| or why
    /// the check produced no number).
    pub checks: Vec<(String, Result<f64, Failure>)>,
    /// Wall time spent on the reference and the checks (s).
    pub seconds: f64,
}

/// The reference at t = `t_end` from the midpoint VI at steps h, h/2, h/4
/// (h = `t_end / steps`), plus RK4 at h/4 as an independent check; `extra`
/// adds further checks (e.g. the same system in maximal coordinates).
pub fn reference<M: Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    problem: &Problem<M, N, C>,
    steps: usize,
    t_end: f64,
    extra: &[Check<'_, N>],
) -> Result<Reference<N>, Failure> {
    let start = Instant::now();
    let fail = |e: StepError| Failure::from_step(&e);
    let q1 = midpoint_positions(problem, steps, t_end).map_err(fail)?;
    let q2 = midpoint_positions(problem, 2 * steps, t_end).map_err(fail)?;
    let q4 = midpoint_positions(problem, 4 * steps, t_end).map_err(fail)?;
    let r12 = richardson(&q1, &q2);
    let r24 = richardson(&q2, &q4);
    let h = t_end / steps as f64;
    let mut checks = vec![(
        format!("RK4 at h/4 = {:.3e} s", h / 4.0),
        rk4_positions(problem, 4 * steps, t_end)
            .map(|q| (q - r24).amax())
            .map_err(fail),
    )];
    for (name, f) in extra {
        checks.push((name.clone(), f().map(|q| (q - r24).amax()).map_err(fail)));
    }
    Ok(Reference {
        q: r24,
        h,
        raw_difference: (q2 - q4).amax(),
        error_estimate: (r12 - r24).amax(),
        checks,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// One long energy run.
#[derive(Clone, Debug, PartialEq)]
pub struct EnergyPoint {
    /// The integrator.
    pub method: Method,
    /// Time step (s).
    pub dt: f64,
    /// Steps asked for (`steps · dt` = the horizon).
    pub steps: usize,
    /// The measurement, or why there is none.
    pub outcome: Result<EnergyMeasured, Failure>,
}

/// Result of a long energy run.
#[derive(Clone, Debug, PartialEq)]
pub struct EnergyMeasured {
    /// max_k |E_k − E(q₀, q̇₀)| over the whole run (J).
    pub max_de: f64,
    /// The same over the first tenth of the steps.
    pub max_de_first_tenth: f64,
    /// The same over the last tenth of the steps.
    pub max_de_last_tenth: f64,
    /// max_k |g(q_k)| (0 without constraints).
    pub max_constraint_violation: f64,
    /// Wall time of the stepping per simulated second (s/s), one run.
    pub cost: f64,
}

/// Runs `method` for `steps` steps of `horizon / steps` and records the
/// energy error against the physical initial energy E(q₀, q̇₀) after every
/// step. The steps are timed in chunks; the energy evaluations are not timed.
pub fn energy_run<M: Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    problem: &Problem<M, N, C>,
    method: Method,
    steps: usize,
    horizon: f64,
) -> EnergyPoint {
    const CHUNK: usize = 256;
    let dt = horizon / steps as f64;
    let outcome = (|| {
        let model = problem.model;
        let z0 = problem.start(method, dt).map_err(|e| Failure {
            message: format!("initial state: {e}"),
            ..Failure::from_step(&e)
        })?;
        let integrator = AnyIntegrator::new(method, model, dt);
        let e0 = problem.energy0();
        let tenth = (steps / 10).max(1);
        let mut buf = [z0; CHUNK];
        let mut z = z0;
        let (mut max_de, mut first, mut last, mut max_g) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        let mut seconds = 0.0;
        let mut done = 0;
        while done < steps {
            let n = CHUNK.min(steps - done);
            let start = Instant::now();
            for (k, slot) in buf[..n].iter_mut().enumerate() {
                z = integrator
                    .step(&z)
                    .map_err(|e| Failure::from_step(&e.at_step(done + k)))?;
                *slot = z;
            }
            seconds += start.elapsed().as_secs_f64();
            for (k, s) in buf[..n].iter().enumerate() {
                let index = done + k; // the state after step index + 1
                let de = (integrator.energy(&model, s) - e0).abs();
                if !de.is_finite() {
                    return Err(Failure {
                        diverged: true,
                        message: format!("non-finite energy after step {index}"),
                    });
                }
                max_de = max_de.max(de);
                if index < tenth {
                    first = first.max(de);
                }
                if index >= steps - tenth {
                    last = last.max(de);
                }
                max_g = max_g.max(model.constraint_violation(s));
            }
            done += n;
        }
        Ok(EnergyMeasured {
            max_de,
            max_de_first_tenth: first,
            max_de_last_tenth: last,
            max_constraint_violation: max_g,
            cost: seconds / horizon,
        })
    })();
    EnergyPoint {
        method,
        dt,
        steps,
        outcome,
    }
}
