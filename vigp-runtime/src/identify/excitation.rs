//! Exciting trajectories: a periodic input, a finite Fourier series per
//! actuated joint, that maximises the information of the DEL regressor
//! about the base parameters.
//!
//! # The input
//!
//! u_i(t) = Σ_{l=1..L} a_il sin(lωt) + b_il cos(lωt), ω = 2π/T, sampled
//! at t_j = j·Δt: sample j drives step j of the forced rollout
//! ([`Fourier::sample`]; the plan format of `vigp simulate --inputs`).
//!
//! # What is maximised
//!
//! The nominal mechanism (the regressor's model, its declared parameters)
//! is rolled out by its own variational integrator (the regressor's rule
//! and Δt; a robot's regressor: the robot's tree engine) from a start at
//! rest under the input; the rows of every
//! transition are stacked ([`super::stack`], least squares) into W. The
//! base parameters are fixed once per problem: the independent columns
//! (a rank-revealing decomposition, [`Base`]) of the rows of the random
//! starts together. With Y_b the columns of W at those indices, each
//! divided by a fixed scale (its norm over the random starts, so units do
//! not decide), the criterion is
//!
//! log det(Y_bᵀY_b / rows + ρ·1),
//!
//! ρ = [`Problem::ridge`] (default 1e-9) only keeps a design that does not
//! excite some base parameter finite. Any other choice of independent
//! columns changes the criterion by a constant (W₁' = W₁·T), so designs
//! compare the same way.
//!
//! # Constraints
//!
//! * **Input amplitude** |u_i(t_j)| ≤ u_max,i exactly: the coefficients are
//!   boxed in [−u_max,i, u_max,i], and an input whose peak over the samples
//!   exceeds u_max,i is scaled down to peak u_max,i before it is simulated
//!   (the designed input is the scaled one).
//! * **Joint positions and velocities** (optional, per coordinate): a
//!   quadratic penalty w·Σ (excess)² over the samples of the simulated
//!   trajectory, w = [`Problem::penalty`]; if the optimum still exceeds a
//!   limit by more than [`Problem::limit_tolerance`], w is raised ×100 and
//!   the optimisation continues, twice at most. The excess that remains is
//!   reported ([`Evaluation::violation`]).
//!
//! # Optimiser
//!
//! The L-BFGS-B of the GP training ([`crate::gp::optimise`]) on
//! −criterion + penalty, from the best of [`Problem::starts`] seeded random
//! inputs. Gradients are central finite differences over the coefficients
//! (step 1e-4·u_max,i): 2 × (inputs × 2L) rollouts per gradient. A rollout
//! that fails (a Newton step that does not converge) makes the point
//! unevaluable, and the optimiser steps back from it.

use super::{
    Base, DelRegressor, IdentifyError, Log, Noise, Regressor, RobotRegressor, check_finite_vector,
    check_length, stack,
};
use crate::gp::optimise;
use crate::mechanism::Mechanism;
use crate::robot::RobotState;
use crate::{State, Variational};
use nalgebra::{DMatrix, SVector};
use vigp_core::{Inputs, Parameters};

/// A periodic input: per input i, u_i(t) = Σ_{l=1..L} a_il sin(lωt) +
/// b_il cos(lωt), ω = 2π/`period`.
#[derive(Clone, Debug, PartialEq)]
pub struct Fourier {
    /// The period T (s).
    pub period: f64,
    /// The number of harmonics L.
    pub harmonics: usize,
    /// Per input, a_i1, …, a_iL, then b_i1, …, b_iL; the inputs one after
    /// another (inputs × 2L entries).
    pub coefficients: Vec<f64>,
}

impl Fourier {
    /// Number of inputs.
    pub fn inputs(&self) -> usize {
        self.coefficients.len() / (2 * self.harmonics).max(1)
    }

    /// u_i(t); `None` for an input i ≥ [`Fourier::inputs`].
    pub fn value(&self, i: usize, t: f64) -> Option<f64> {
        let l_count = self.harmonics;
        let c = self
            .coefficients
            .get(2 * l_count * i..2 * l_count * (i + 1))?;
        if c.is_empty() {
            return None;
        }
        let w = 2.0 * std::f64::consts::PI / self.period;
        Some(
            (0..l_count)
                .map(|l| {
                    let x = (l + 1) as f64 * w * t;
                    c[l] * x.sin() + c[l_count + l] * x.cos()
                })
                .sum(),
        )
    }

    /// The samples u(j·Δt), j = 0, …, `steps` − 1 (one vector of the inputs
    /// per step).
    pub fn sample(&self, steps: usize, dt: f64) -> Vec<Vec<f64>> {
        (0..steps)
            .map(|j| {
                (0..self.inputs())
                    .filter_map(|i| self.value(i, j as f64 * dt))
                    .collect()
            })
            .collect()
    }

    /// max_j |u_i(j·Δt)| over the `steps` samples, per input.
    pub fn peak(&self, steps: usize, dt: f64) -> Vec<f64> {
        let mut peak = vec![0.0f64; self.inputs()];
        for u in self.sample(steps, dt) {
            for (p, v) in peak.iter_mut().zip(u) {
                *p = p.max(v.abs());
            }
        }
        peak
    }

    /// Input i's coefficients multiplied by `factor[i]` (by 1 where
    /// `factor` has no entry).
    pub fn scaled(&self, factor: &[f64]) -> Fourier {
        let two_l = (2 * self.harmonics).max(1);
        let mut out = self.clone();
        for (k, c) in out.coefficients.iter_mut().enumerate() {
            *c *= factor.get(k / two_l).copied().unwrap_or(1.0);
        }
        out
    }
}

/// An excitation problem ([module docs](self)).
#[derive(Clone, Debug, PartialEq)]
pub struct Problem {
    /// The start, at rest (one value per coordinate; a mechanism with
    /// loops has it projected onto its constraints).
    pub start: Vec<f64>,
    /// Steps of the rollout (duration = steps·Δt).
    pub steps: usize,
    /// Harmonics L per input (≥ 1).
    pub harmonics: usize,
    /// The period T (s); `None`: the duration, steps·Δt.
    pub period: Option<f64>,
    /// The largest |u_i| per input (> 0, finite).
    pub amplitude: Vec<f64>,
    /// Position limits [lo, hi] per coordinate (±∞ for none), or empty for
    /// none at all.
    pub position_limits: Vec<(f64, f64)>,
    /// Velocity limits |v_c| ≤ v_max,c per coordinate (∞ for none), or
    /// empty for none at all.
    pub velocity_limits: Vec<f64>,
    /// The penalty weight w on the squared excess over the limits, per
    /// sample (default 1e4).
    pub penalty: f64,
    /// The excess over a limit that is accepted at the end (default 1e-3,
    /// in the coordinate's units).
    pub limit_tolerance: f64,
    /// The ridge ρ of the criterion (default 1e-9).
    pub ridge: f64,
    /// Random inputs evaluated first; the best one starts the optimiser
    /// (default 8, at least 1).
    pub starts: usize,
    /// Seed of the random starts.
    pub seed: u64,
    /// The optimiser's settings (default: 60 iterations, ftol 1e-7).
    pub optimiser: optimise::Options,
}

impl Problem {
    /// A problem from `start`, `steps` steps, `harmonics` harmonics per
    /// input and amplitudes `amplitude`, without position or velocity
    /// limits, the other settings at their defaults.
    pub fn new(start: Vec<f64>, steps: usize, harmonics: usize, amplitude: Vec<f64>) -> Self {
        Problem {
            start,
            steps,
            harmonics,
            period: None,
            amplitude,
            position_limits: Vec::new(),
            velocity_limits: Vec::new(),
            penalty: 1e4,
            limit_tolerance: 1e-3,
            ridge: 1e-9,
            starts: 8,
            seed: 0,
            optimiser: optimise::Options {
                max_iters: 60,
                ftol: 1e-7,
                ..optimise::Options::default()
            },
        }
    }
}

/// One input's score.
#[derive(Clone, Debug)]
pub struct Evaluation {
    /// The criterion log det(Y_bᵀY_b/rows + ρ·1) (module docs).
    pub log_det: f64,
    /// The largest excess of the trajectory over a position or velocity
    /// limit (0 when within them).
    pub violation: f64,
    /// The input's peak |u_i| over the samples, per input.
    pub peak: Vec<f64>,
    /// The log of the nominal rollout under the input (positions and
    /// inputs in [`Log`]'s convention), noise-free.
    pub log: Log,
}

/// A designed input ([`Excitation::design`]).
#[derive(Clone, Debug)]
pub struct Designed {
    /// The input (peak ≤ the amplitude per input).
    pub input: Fourier,
    /// Its score.
    pub evaluation: Evaluation,
    /// The criterion of the best random start.
    pub start_log_det: f64,
    /// Optimiser iterations, over every penalty round.
    pub iterations: usize,
    /// Objective evaluations (each with its finite-difference gradient).
    pub evaluations: usize,
}

/// The nominal model's forced rollout from the problem's start at rest:
/// `plan[j]` drives step j; the result is the positions x_0, …, x_S of the
/// S + 1 states and x_S + Δt·v_S (S + 2 samples, [`Log`]'s convention).
type Rollout<'a> = Box<dyn Fn(&[Vec<f64>]) -> Result<Vec<Vec<f64>>, IdentifyError> + 'a>;

/// The excitation design of one mechanism or robot ([module docs](self)):
/// [`Excitation::new`] for a declared mechanism's [`DelRegressor`],
/// [`Excitation::robot`] for a [`RobotRegressor`]. Both design and score
/// inputs the same way; they differ in the rollout that produces a log.
pub struct Excitation<'a, R> {
    regressor: &'a R,
    rollout: Rollout<'a>,
    problem: Problem,
    period: f64,
    dt: f64,
    inputs: usize,
    base: Vec<usize>,
    scale: Vec<f64>,
    starts: Vec<Fourier>,
}

/// splitmix64: the random starts' generator.
fn next(state: &mut u64) -> f64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

fn options_error(message: String) -> IdentifyError {
    IdentifyError::Options { message }
}

/// Checks `problem` for `n` coordinates, `u` inputs and `p` parameters at
/// time step `dt`; returns the period of the inputs.
fn check_problem(
    problem: &Problem,
    n: usize,
    u: usize,
    p: usize,
    dt: f64,
) -> Result<f64, IdentifyError> {
    if u == 0 {
        return Err(IdentifyError::NoInputs);
    }
    check_finite_vector("start", &problem.start, n)?;
    check_length("amplitudes (one per input)", u, problem.amplitude.len())?;
    if let Some(a) = problem
        .amplitude
        .iter()
        .find(|a| !(a.is_finite() && **a > 0.0))
    {
        return Err(options_error(format!(
            "input amplitude {a}: must be positive and finite"
        )));
    }
    if problem.harmonics == 0 {
        return Err(options_error("at least one harmonic".into()));
    }
    let period = problem.period.unwrap_or(problem.steps as f64 * dt);
    if !(period.is_finite() && period > 0.0) {
        return Err(options_error(format!(
            "period {period}: must be positive and finite"
        )));
    }
    if !problem.position_limits.is_empty() {
        check_length("position limits", n, problem.position_limits.len())?;
        if let Some((lo, hi)) = problem
            .position_limits
            .iter()
            .find(|(lo, hi)| lo.is_nan() || hi.is_nan() || lo >= hi)
        {
            return Err(options_error(format!("position limits [{lo}, {hi}]")));
        }
        if let Some(c) = (0..n).find(|&c| {
            let (lo, hi) = problem.position_limits[c];
            !(lo..=hi).contains(&problem.start[c])
        }) {
            return Err(options_error(format!(
                "the start's coordinate {c} is outside its position limits"
            )));
        }
    }
    if !problem.velocity_limits.is_empty() {
        check_length("velocity limits", n, problem.velocity_limits.len())?;
        if let Some(v) = problem
            .velocity_limits
            .iter()
            .find(|v| v.is_nan() || **v <= 0.0)
        {
            return Err(options_error(format!("velocity limit {v}: must be > 0")));
        }
    }
    let positive = |x: f64| x.is_finite() && x > 0.0;
    if !(positive(problem.penalty) && positive(problem.limit_tolerance) && positive(problem.ridge))
    {
        return Err(options_error(
            "penalty, limit tolerance and ridge must be positive and finite".into(),
        ));
    }
    if problem.starts == 0 {
        return Err(options_error("at least one random start".into()));
    }
    if problem.steps < 2 * p + 2 {
        return Err(IdentifyError::TooFewTransitions {
            rows: problem.steps,
            needed: 2 * p + 2,
        });
    }
    Ok(period)
}

impl<'a, M, const N: usize, const C: usize> Excitation<'a, DelRegressor<M, N, C>>
where
    M: Mechanism<N, C> + Parameters + Copy,
{
    /// Checks `problem`, simulates its random starts and fixes the base
    /// parameters and the column scales of the criterion. `U` is the
    /// mechanism's number of inputs (`Dynamics::INPUTS`); the rollouts are
    /// the mechanism's own variational integrator of the regressor's rule,
    /// from the start projected onto the loops' constraints.
    pub fn new<const U: usize>(
        regressor: &'a DelRegressor<M, N, C>,
        problem: &Problem,
    ) -> Result<Self, IdentifyError>
    where
        M: Inputs<U>,
    {
        let dt = regressor.dt();
        let declared = <M as vigp_core::Dynamics<N, C>>::INPUTS;
        check_length("inputs (the mechanism's actuated joints)", declared, U)?;
        let period = check_problem(problem, N, U, regressor.structure().len(), dt)?;
        let model = *regressor.model();
        let vi = if regressor.alpha() == 0.0 {
            Variational::new(model, dt)
        } else {
            Variational::midpoint(model, dt)
        }
        .map_err(|e| IdentifyError::Simulation {
            message: e.to_string(),
        })?;
        let q0 = SVector::<f64, N>::from_column_slice(&problem.start);
        let z0 = if C == 0 {
            State {
                q: q0,
                v: SVector::zeros(),
            }
        } else {
            crate::projection::consistent_state(&model, &q0, &SVector::zeros(), dt).map_err(
                |e| IdentifyError::Simulation {
                    message: format!("the start cannot be projected onto the loops: {e}"),
                },
            )?
        };
        let rollout: Rollout<'a> = Box::new(move |plan: &[Vec<f64>]| {
            let plan: Vec<SVector<f64, U>> =
                plan.iter().map(|u| SVector::from_column_slice(u)).collect();
            let traj = vi
                .rollout_forced(&z0, &plan)
                .map_err(|e| IdentifyError::Simulation {
                    message: e.to_string(),
                })?;
            let mut positions: Vec<Vec<f64>> =
                traj.iter().map(|z| z.q.as_slice().to_vec()).collect();
            if let Some(last) = traj.last() {
                positions.push((last.q + last.v * dt).as_slice().to_vec());
            }
            Ok(positions)
        });
        Self::with_rollout(regressor, problem, period, dt, U, rollout)
    }
}

impl<'a> Excitation<'a, RobotRegressor> {
    /// [`Excitation::new`] for a robot loaded from URDF: the rollouts are
    /// the robot's tree engine ([`crate::robot::Robot::rollout_with`], the
    /// first-order rule) from the start at rest, whichever rule the
    /// regressor stacks (a midpoint regressor of a first-order log only
    /// scores the design; it does not change the rollout).
    pub fn robot(regressor: &'a RobotRegressor, problem: &Problem) -> Result<Self, IdentifyError> {
        let dt = regressor.dt();
        let robot = regressor.robot();
        let (n, u) = (robot.dof(), robot.input_names().len());
        let period = check_problem(problem, n, u, regressor.structure().len(), dt)?;
        let z0 = RobotState::new(problem.start.clone(), vec![0.0; n]);
        let rollout: Rollout<'a> = Box::new(move |plan: &[Vec<f64>]| {
            let run = robot
                .rollout_with(&z0, dt, plan.len(), |k, _| plan[k].clone())
                .map_err(|e| IdentifyError::Simulation {
                    message: e.to_string(),
                })?;
            let mut positions: Vec<Vec<f64>> = run.states.iter().map(|z| z.q.clone()).collect();
            if let Some(last) = run.states.last() {
                positions.push(
                    last.q
                        .iter()
                        .zip(&last.v)
                        .map(|(q, v)| q + dt * v)
                        .collect(),
                );
            }
            Ok(positions)
        });
        Self::with_rollout(regressor, problem, period, dt, u, rollout)
    }
}

impl<'a, R: Regressor> Excitation<'a, R> {
    /// Simulates the random starts of a checked problem and fixes the base
    /// parameters and the column scales of the criterion.
    fn with_rollout(
        regressor: &'a R,
        problem: &Problem,
        period: f64,
        dt: f64,
        inputs: usize,
        rollout: Rollout<'a>,
    ) -> Result<Self, IdentifyError> {
        let p = regressor.structure().len();
        let mut me = Excitation {
            regressor,
            rollout,
            problem: problem.clone(),
            period,
            dt,
            inputs,
            base: Vec::new(),
            scale: Vec::new(),
            starts: Vec::new(),
        };
        // The random starts; the base and the scales from their rows.
        let mut rows: Vec<DMatrix<f64>> = Vec::new();
        let mut seed = problem.seed;
        let mut tries = 0;
        let mut last_error = None;
        while me.starts.len() < problem.starts && tries < 4 * problem.starts {
            tries += 1;
            let input = me.random_with(&mut seed);
            match me.simulate(&input) {
                Ok((w, _)) => {
                    rows.push(w);
                    me.starts.push(input);
                }
                Err(e) => last_error = Some(e),
            }
        }
        if me.starts.is_empty() {
            return Err(IdentifyError::Simulation {
                message: format!(
                    "no random start could be simulated{}",
                    last_error.map_or(String::new(), |e| format!(" (the last: {e})"))
                ),
            });
        }
        let total: usize = rows.iter().map(|w| w.nrows()).sum();
        let mut all = DMatrix::zeros(total, p);
        let mut at = 0;
        for w in &rows {
            all.rows_mut(at, w.nrows()).copy_from(w);
            at += w.nrows();
        }
        let base = Base::new(&all, 1e-8);
        if base.rank() == 0 {
            return Err(IdentifyError::Singular);
        }
        me.scale = base
            .independent
            .iter()
            .map(|&j| all.column(j).norm() / (total as f64).sqrt())
            .collect();
        me.base = base.independent;
        Ok(me)
    }

    /// The indices (into π) of the base parameters' independent columns
    /// that the criterion uses.
    pub fn base(&self) -> &[usize] {
        &self.base
    }

    /// The period of the inputs (s).
    pub fn period(&self) -> f64 {
        self.period
    }

    /// A random input: coefficients uniform in [−u_max, u_max], scaled so
    /// that its peak over the samples is u_max per input.
    pub fn random(&self, seed: u64) -> Fourier {
        let mut s = seed;
        self.random_with(&mut s)
    }

    fn random_with(&self, seed: &mut u64) -> Fourier {
        let (two_l, u) = (2 * self.problem.harmonics, self.inputs);
        let coefficients = (0..u * two_l)
            .map(|k| self.problem.amplitude[k / two_l] * (2.0 * next(seed) - 1.0))
            .collect();
        let f = Fourier {
            period: self.period,
            harmonics: self.problem.harmonics,
            coefficients,
        };
        let peak = f.peak(self.problem.steps, self.dt);
        let factor: Vec<f64> = (0..u)
            .map(|i| {
                if peak[i] > 0.0 {
                    self.problem.amplitude[i] / peak[i]
                } else {
                    1.0
                }
            })
            .collect();
        f.scaled(&factor)
    }

    /// The input with its peak brought down to the amplitude where it
    /// exceeds it.
    fn clipped(&self, input: &Fourier) -> Fourier {
        let peak = input.peak(self.problem.steps, self.dt);
        let factor: Vec<f64> = (0..self.inputs)
            .map(|i| {
                let a = self.problem.amplitude[i];
                if peak[i] > a { a / peak[i] } else { 1.0 }
            })
            .collect();
        input.scaled(&factor)
    }

    /// The rollout under `input` (as given): the stacked rows W and the
    /// noise-free log.
    fn simulate(&self, input: &Fourier) -> Result<(DMatrix<f64>, Log), IdentifyError> {
        let plan = input.sample(self.problem.steps, self.dt);
        let positions = (self.rollout)(&plan)?;
        // Rollout input j acts over [t_{j+1}, t_{j+2}]: log row j + 1.
        let mut inputs = vec![vec![0.0; self.inputs]];
        inputs.extend(plan);
        inputs.push(vec![0.0; self.inputs]);
        let log = Log { positions, inputs };
        let (st, _) = stack(
            self.regressor,
            std::slice::from_ref(&log),
            Noise::LeastSquares,
        )?;
        Ok((st.w, log))
    }

    fn criterion(&self, w: &DMatrix<f64>) -> Option<f64> {
        let r = self.base.len();
        let rows = w.nrows();
        if rows < r {
            return None;
        }
        let yb = DMatrix::from_fn(rows, r, |i, c| w[(i, self.base[c])] / self.scale[c]);
        let f = yb.tr_mul(&yb) / rows as f64 + DMatrix::identity(r, r) * self.problem.ridge;
        let chol = f.cholesky()?;
        let ld: f64 = chol.l().diagonal().iter().map(|d| 2.0 * d.ln()).sum();
        ld.is_finite().then_some(ld)
    }

    /// The largest excess over the limits, and Σ excess² over the samples.
    fn excess(&self, log: &Log) -> (f64, f64) {
        let dt = self.dt;
        let (mut worst, mut sum) = (0.0f64, 0.0);
        let mut add = |e: f64| {
            if e > 0.0 {
                worst = worst.max(e);
                sum += e * e;
            }
        };
        for (k, x) in log.positions.iter().enumerate() {
            for (c, &xc) in x.iter().enumerate() {
                if let Some((lo, hi)) = self.problem.position_limits.get(c) {
                    add(lo - xc);
                    add(xc - hi);
                }
                if let (Some(vmax), Some(next)) = (
                    self.problem.velocity_limits.get(c),
                    log.positions.get(k + 1),
                ) {
                    add(((next[c] - xc) / dt).abs() - vmax);
                }
            }
        }
        (worst, sum)
    }

    /// The score of `input` (its peak brought down to the amplitude first,
    /// where it exceeds it).
    pub fn evaluate(&self, input: &Fourier) -> Result<Evaluation, IdentifyError> {
        if input.harmonics != self.problem.harmonics
            || input.coefficients.len() != 2 * self.problem.harmonics * self.inputs
        {
            return Err(IdentifyError::Dimension {
                what: "Fourier coefficients",
                expected: 2 * self.problem.harmonics * self.inputs,
                found: input.coefficients.len(),
            });
        }
        if input.coefficients.iter().any(|c| !c.is_finite())
            || !(input.period.is_finite() && input.period > 0.0)
        {
            return Err(IdentifyError::NonFinite {
                what: "Fourier input".into(),
            });
        }
        let input = self.clipped(input);
        let (w, log) = self.simulate(&input)?;
        let log_det = self.criterion(&w).ok_or(IdentifyError::Singular)?;
        let (violation, _) = self.excess(&log);
        Ok(Evaluation {
            log_det,
            violation,
            peak: input.peak(self.problem.steps, self.dt),
            log,
        })
    }

    /// −criterion + w·Σ excess² of the clipped input with coefficients `c`.
    fn objective(&self, c: &[f64], weight: f64) -> Option<f64> {
        let input = self.clipped(&Fourier {
            period: self.period,
            harmonics: self.problem.harmonics,
            coefficients: c.to_vec(),
        });
        let (w, log) = self.simulate(&input).ok()?;
        let ld = self.criterion(&w)?;
        let (_, sum) = self.excess(&log);
        Some(-ld + weight * sum)
    }

    /// The designed input ([module docs](self)).
    pub fn design(&self) -> Result<Designed, IdentifyError> {
        let mut weight = self.problem.penalty;
        let scored: Vec<(f64, &Fourier)> = self
            .starts
            .iter()
            .filter_map(|f| self.objective(&f.coefficients, weight).map(|v| (v, f)))
            .collect();
        let Some(&(_, best)) = scored.iter().min_by(|a, b| a.0.total_cmp(&b.0)) else {
            return Err(IdentifyError::Simulation {
                message: "no random start could be scored".into(),
            });
        };
        let start_log_det = self.evaluate(best)?.log_det;
        let two_l = 2 * self.problem.harmonics;
        let hi: Vec<f64> = (0..self.inputs * two_l)
            .map(|k| self.problem.amplitude[k / two_l])
            .collect();
        let lo: Vec<f64> = hi.iter().map(|h| -h).collect();
        let steps: Vec<f64> = hi.iter().map(|h| 1e-4 * h).collect();
        let mut x = best.coefficients.clone();
        let (mut iterations, mut evaluations) = (0, 0);
        for round in 0..3 {
            let f = |c: &[f64]| -> Option<(f64, Vec<f64>)> {
                let v = self.objective(c, weight)?;
                let mut g = vec![0.0; c.len()];
                let mut cp = c.to_vec();
                for (k, &h) in steps.iter().enumerate() {
                    cp[k] = c[k] + h;
                    let fp = self.objective(&cp, weight)?;
                    cp[k] = c[k] - h;
                    let fm = self.objective(&cp, weight)?;
                    cp[k] = c[k];
                    g[k] = (fp - fm) / (2.0 * h);
                }
                Some((v, g))
            };
            let m = optimise::minimise(f, &x, &lo, &hi, &self.problem.optimiser).map_err(|e| {
                IdentifyError::Optimiser {
                    message: e.to_string(),
                }
            })?;
            iterations += m.iterations;
            evaluations += m.evaluations;
            x = m.x;
            let input = Fourier {
                period: self.period,
                harmonics: self.problem.harmonics,
                coefficients: x.clone(),
            };
            let e = self.evaluate(&input)?;
            if e.violation <= self.problem.limit_tolerance || round == 2 {
                break;
            }
            weight *= 100.0;
        }
        let input = self.clipped(&Fourier {
            period: self.period,
            harmonics: self.problem.harmonics,
            coefficients: x,
        });
        let evaluation = self.evaluate(&input)?;
        Ok(Designed {
            input,
            evaluation,
            start_log_det,
            iterations,
            evaluations,
        })
    }
}
