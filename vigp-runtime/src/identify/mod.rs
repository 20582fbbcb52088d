//! Physical parameters from logged positions: masses, first moments,
//! inertias, joint damping and springs, by regression on the discrete
//! Euler–Lagrange (DEL) residual.
//!
//! The DEL residual of a transition (x_{k−1}, x_k, x_{k+1}) is affine in
//! the standard parameters π of every body and joint
//! ([`regressor`]): Y·π − b = residual. It needs positions only — no
//! accelerations differentiated from noisy samples — and, on a log that
//! the variational integrator wrote, it is zero at the true parameters.
//!
//! [`identify`] stacks the rows of every transition of the logs and
//!
//! 1. finds the **base parameters**, the combinations of π that the data
//!    determine, by a rank-revealing QR decomposition, and names them
//!    ([`base`]);
//! 2. estimates π by least squares with a **prior** centred on the declared
//!    values (each standard parameter ~ 𝒩(declared, s²), s stated in
//!    [`Prior`]), treating the **position noise** by instrumental
//!    variables, or by bias-compensated least squares where its size is
//!    known ([`Noise`], [`errors_in_variables`]), and outliers by an
//!    optional **robust loss** ([`Loss`]) ([`estimate`]);
//! 3. keeps the estimate **physically consistent** (every body a positive
//!    mass and a positive definite pseudo-inertia, every joint a damping
//!    and a stiffness ≥ 0, so that the mechanism accepts it) by projecting
//!    an infeasible estimate onto the feasible set, a convex problem solved
//!    by an interior-point method in the estimate's metric with the data's
//!    weight capped, so that the directions the data do not see stay where
//!    the prior puts them ([`consistency`]);
//! 4. gives the **covariance** and the 95 % interval of each base
//!    parameter ([`covariance`]) and a table ([`report`]);
//! 5. optionally ([`Options::output_error`]) **refines** the estimate by
//!    output error: segments of the logs simulated with the parameters,
//!    their initial states estimated with them, exact sensitivities by the
//!    implicit function theorem, Levenberg–Marquardt under the same prior
//!    and consistency ([`output_error`]).
//!
//! [`excitation`] designs the input to log: a Fourier series per actuated
//! joint that maximises the regressor's information about the base
//! parameters within input, position and velocity limits.
//!
//! **Loops** are handled by projecting each transition's rows onto the
//! null space of the constraint Jacobian G(x_k), which removes the term
//! −G(x_k)ᵀλ with the unknown multipliers (the multipliers are not
//! estimated; [`regressor`]).
//!
//! ```
//! use vigp_runtime::identify::{DelRegressor, Log, Options, identify};
//! use vigp_runtime::{Joint, Link, Mechanism, Parameters, Variational};
//! # use vigp_runtime::identify::IdentifyError;
//! # fn demo<M>(model: M, log: Log) -> Result<(), IdentifyError>
//! # where M: Mechanism<1, 0> + Parameters + Copy {
//! // `model`: a mechanism with its declared parameters; `log`: positions
//! // sampled every 10 ms.
//! let regressor = DelRegressor::midpoint(model, 0.01)?;
//! let id = identify(&regressor, &[log], &Options::default())?;
//! println!("{}", id.report());
//! # Ok(()) }
//! ```

pub mod base;
pub mod consistency;
pub mod covariance;
pub mod errors_in_variables;
pub mod estimate;
pub mod excitation;
pub mod noise;
pub mod output_error;
pub mod regressor;
pub mod report;
#[cfg(feature = "urdf")]
pub mod robot;

pub use base::Base;
pub use estimate::Loss;
pub use excitation::{Designed, Evaluation, Excitation, Fourier, Problem};
pub use noise::{Noise, SampleNoise};
pub use output_error::{OutputError, Refinement};
pub use regressor::{
    BodySlots, DelRegressor, JointSlots, ParameterKind, Regressor, Structure, Transition,
};
pub use report::{Report, Status};
#[cfg(feature = "urdf")]
pub use robot::RobotRegressor;

use nalgebra::{DMatrix, DVector};

/// What can go wrong in identification.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum IdentifyError {
    /// The mechanism's parameter names do not have the documented layout.
    #[error("parameter layout: {message}")]
    Layout {
        /// What is wrong.
        message: String,
    },
    /// A vector of the wrong length.
    #[error("{what}: expected {expected} entries, found {found}")]
    Dimension {
        /// Which vector.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Found length.
        found: usize,
    },
    /// NaN or ±∞ in the input or on the way.
    #[error("not finite: {what}")]
    NonFinite {
        /// Which value.
        what: String,
    },
    /// A standard-parameter vector with no form in the DSL's names (a zero
    /// mass, or k·s₀ ≠ 0 with k = 0).
    #[error("`{parameter}` has no form in the DSL's parameters (zero mass or stiffness)")]
    NoDslForm {
        /// The offending standard parameter.
        parameter: String,
    },
    /// Too few transitions for the number of base parameters.
    #[error("too few data: {rows} rows for {needed} needed")]
    TooFewTransitions {
        /// Rows available.
        rows: usize,
        /// Rows needed.
        needed: usize,
    },
    /// A linear system that should be regular is not.
    #[error("singular system in the estimate")]
    Singular,
    /// Options out of range.
    #[error("options: {message}")]
    Options {
        /// What is wrong.
        message: String,
    },
    /// Physical consistency could not be established.
    #[error("physical consistency: {message}")]
    Inconsistent {
        /// What is wrong.
        message: String,
    },
    /// An excitation design for a mechanism without inputs.
    #[error("the mechanism has no inputs (no `actuated` joint): nothing to excite")]
    NoInputs,
    /// A simulation of the nominal mechanism failed.
    #[error("simulation: {message}")]
    Simulation {
        /// Why.
        message: String,
    },
    /// The optimiser refused the problem.
    #[error("optimiser: {message}")]
    Optimiser {
        /// Why.
        message: String,
    },
}

/// `Ok` when the vector `what` has its `expected` length `found`, else
/// [`IdentifyError::Dimension`].
pub(crate) fn check_length(
    what: &'static str,
    expected: usize,
    found: usize,
) -> Result<(), IdentifyError> {
    if found != expected {
        return Err(IdentifyError::Dimension {
            what,
            expected,
            found,
        });
    }
    Ok(())
}

/// [`IdentifyError::NonFinite`] unless the time step `dt` is finite and
/// positive.
pub(crate) fn check_time_step(dt: f64) -> Result<(), IdentifyError> {
    if dt.is_finite() && dt > 0.0 {
        Ok(())
    } else {
        Err(IdentifyError::NonFinite {
            what: format!("time step {dt}"),
        })
    }
}

/// `Ok` when `values` (the vector `what`) has `expected` entries, all
/// finite: else [`IdentifyError::Dimension`], or
/// [`IdentifyError::NonFinite`] naming `what`.
pub(crate) fn check_finite_vector(
    what: &'static str,
    values: &[f64],
    expected: usize,
) -> Result<(), IdentifyError> {
    check_length(what, expected, values.len())?;
    if values.iter().any(|v| !v.is_finite()) {
        return Err(IdentifyError::NonFinite { what: what.into() });
    }
    Ok(())
}

/// One logged run: positions every Δt (the regressor's time step) and the
/// inputs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Log {
    /// Positions x_0, …, x_K (one vector of the mechanism's coordinates
    /// per sample).
    pub positions: Vec<Vec<f64>>,
    /// Inputs: empty (none), or one vector per sample, `inputs[k]` held
    /// over [t_k, t_{k+1}] (the convention of `vigp::data`: row k's input
    /// drives the step whose new velocity is (x_{k+1} − x_k)/Δt). A forced
    /// rollout from a state (`Variational::rollout_forced`) applies its
    /// input j over [t_{j+1}, t_{j+2}]: the log's `inputs[j + 1]`, with
    /// `inputs[0]` zero.
    pub inputs: Vec<Vec<f64>>,
}

impl Log {
    /// A log of positions without inputs.
    pub fn new(positions: Vec<Vec<f64>>) -> Self {
        Log {
            positions,
            inputs: Vec::new(),
        }
    }

    /// `Ok` for a log without inputs or with one input per sample, else
    /// [`IdentifyError::Dimension`].
    pub(crate) fn check_input_count(&self) -> Result<(), IdentifyError> {
        if self.inputs.is_empty() {
            return Ok(());
        }
        check_length(
            "inputs (one per sample)",
            self.positions.len(),
            self.inputs.len(),
        )
    }

    /// Transition k: samples k − 1, k, k + 1 and the inputs u_{k−1}, u_k
    /// (`zeros`, the right length of zeros, for a log without inputs).
    pub(crate) fn transition<'a>(&'a self, k: usize, zeros: &'a [f64]) -> Transition<'a> {
        let input = |j: usize| -> &'a [f64] {
            if self.inputs.is_empty() {
                zeros
            } else {
                &self.inputs[j]
            }
        };
        Transition {
            positions: [
                &self.positions[k - 1],
                &self.positions[k],
                &self.positions[k + 1],
            ],
            inputs: [input(k - 1), input(k)],
        }
    }

    /// A log from a run read by `vigp::data` (the same input convention).
    pub fn from_run<P: crate::data::Positions>(run: &crate::data::RunOf<P>) -> Self {
        Log {
            positions: run.positions.iter().map(|q| q.entries().to_vec()).collect(),
            inputs: run.inputs.clone(),
        }
    }
}

/// The prior on π: independent Gaussians centred on the declared values,
/// standard deviation s_p = `relative` × a scale per parameter:
///
/// * mass: the declared mass m;
/// * first moments: m·ℓ, inertias about the frame origin: m·ℓ², with ℓ
///   the body's radius of gyration about its frame origin (√(I_O/m)
///   planar, √(tr I_O/(2m)) spatial);
/// * joint damping, stiffness, stiffness·rest: |declared|, at least
///   `joint_floor` (SI units).
///
/// The default, `relative` = 0.5, says "within about 50 % of the declared
/// values"; where the data speak, its weight against theirs is (σ/s)² and
/// vanishes as the log grows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prior {
    /// Relative standard deviation.
    pub relative: f64,
    /// Smallest scale of a joint parameter (SI units).
    pub joint_floor: f64,
}

impl Default for Prior {
    fn default() -> Self {
        Prior {
            relative: 0.5,
            joint_floor: 1.0,
        }
    }
}

impl Prior {
    /// The standard deviation of every entry of π (declared values `pi`).
    pub fn sd(&self, structure: &Structure, pi: &[f64]) -> Vec<f64> {
        let mut sd = Vec::with_capacity(pi.len());
        let offsets = structure.body_offsets();
        for (b, o) in structure.bodies.iter().zip(&offsets) {
            let m = pi[*o].abs();
            let l2 = match b {
                BodySlots::Planar { .. } => pi[o + 3].abs() / m,
                BodySlots::Spatial { .. } => (pi[o + 4] + pi[o + 7] + pi[o + 9]).abs() / (2.0 * m),
            };
            let l = l2.sqrt();
            sd.push(self.relative * m);
            let (h, i) = if b.len() == 4 { (2, 1) } else { (3, 6) };
            sd.extend(std::iter::repeat_n(self.relative * m * l, h));
            sd.extend(std::iter::repeat_n(self.relative * m * l2, i));
        }
        for x in &pi[sd.len()..] {
            sd.push(self.relative * x.abs().max(self.joint_floor));
        }
        sd
    }
}

/// Options of [`identify`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Options {
    /// The prior (default: 50 % of the declared values).
    pub prior: Prior,
    /// The noise treatment (default: [`Noise::IV`], instrumental
    /// variables: unbiased under position noise where least squares is
    /// biased). A log too short for the instruments' window enters by
    /// least squares; and least squares runs on every transition where the
    /// instruments would leave too few rows, or where the rows are exact
    /// (a noise-free log: least squares is then exact and better
    /// conditioned). [`Identification::instrumented`] says what ran.
    pub noise: Noise,
    /// The loss (default: squares).
    pub loss: Loss,
    /// Rank tolerance of the base-parameter decomposition, relative to the
    /// largest pivot of the unit-norm columns (default 1e-8).
    pub rank_tolerance: f64,
    /// Project an infeasible estimate (an unrealisable body, a negative
    /// joint damping or stiffness) onto the feasible set (default true).
    pub consistent: bool,
    /// The covariance model of the intervals (default: position noise).
    pub intervals: Intervals,
    /// The second stage: refine the estimate by output error
    /// ([`output_error`]). Unbiased under position noise; costs a
    /// simulation of every log with exact sensitivities per iteration.
    /// Loops are simulated with their multipliers.
    ///
    /// `None` (the default) runs the regression alone, except on logs where
    /// no input acts: their rows are homogeneous in π, and the regression
    /// on noisy rows pulls the overall scale of π towards zero (its data
    /// term shrinks with π). There output error runs with its default
    /// options from the declared values: the simulation does not change
    /// with the scale, so the data fix the ratios and the prior the scale
    /// ([`Refinement::homogeneous`]).
    pub output_error: Option<OutputError>,
}

/// How the covariance of the estimate is computed ([`covariance`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Intervals {
    /// Independent rows with variance σ_j² per row position.
    Independent,
    /// Independent noise on every logged position coordinate, σ_q
    /// estimated from the residuals, propagated through the exact
    /// dependence of each residual on its three samples (neighbouring
    /// transitions share samples: their errors are correlated).
    PositionNoise,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            prior: Prior::default(),
            noise: Noise::IV,
            loss: Loss::Squared,
            rank_tolerance: 1e-8,
            consistent: true,
            intervals: Intervals::PositionNoise,
            output_error: None,
        }
    }
}

/// The result of [`identify`].
#[derive(Clone, Debug)]
pub struct Identification {
    /// The layout of π.
    pub structure: Structure,
    /// Declared π (the prior's centre).
    pub declared: Vec<f64>,
    /// The prior's standard deviations.
    pub prior_sd: Vec<f64>,
    /// The identified π: physically consistent (realisable bodies, joint
    /// dampings and stiffnesses ≥ 0) unless [`Options::consistent`] is off.
    pub estimate: Vec<f64>,
    /// The estimate before the consistency projection.
    pub unconstrained: Vec<f64>,
    /// The links whose unconstrained estimate was not realisable (indices
    /// into `structure.bodies`); with [`Self::projected_joints`], empty
    /// exactly when the consistency projection did not run.
    pub projected: Vec<usize>,
    /// The joint dampings and stiffnesses whose unconstrained estimate was
    /// negative (indices into π).
    pub projected_joints: Vec<usize>,
    /// Posterior covariance of π (independent rows).
    pub covariance: DMatrix<f64>,
    /// The base parameters.
    pub base: Base,
    /// Their names (combinations of standard names).
    pub base_names: Vec<String>,
    /// Their declared values K·π₀.
    pub base_declared: Vec<f64>,
    /// Their identified values K·π̂ (of the consistent estimate).
    pub base_estimate: Vec<f64>,
    /// Half-widths of their 95 % intervals.
    pub base_half_width: Vec<f64>,
    /// Whether the data informed each base parameter (posterior variance
    /// below half the prior's).
    pub base_informed: Vec<bool>,
    /// Noise standard deviation per row position (residual units).
    pub sigma: Vec<f64>,
    /// The position noise σ_q estimated from the residuals (with
    /// [`Intervals::PositionNoise`]).
    pub position_sigma: Option<f64>,
    /// The covariance of the base parameters behind the intervals.
    pub base_covariance: DMatrix<f64>,
    /// Transitions used.
    pub transitions: usize,
    /// Of these, the transitions whose rows had instruments
    /// ([`Noise::InstrumentalVariables`]). The others, from logs too short
    /// to hold the instruments' window (2·`half_window` + 3 samples),
    /// entered by least squares, which is biased under position noise;
    /// 0 with [`Noise::LeastSquares`].
    pub instrumented: usize,
    /// What the output-error stage did, when it ran
    /// ([`Options::output_error`]); the estimate, covariances and
    /// intervals are then its own.
    pub refinement: Option<Refinement>,
}

impl Identification {
    /// The table: parameter, declared, identified, ±95 %, status.
    pub fn report(&self) -> Report {
        report::build(self)
    }

    /// Whether each standard parameter is identifiable by itself (no
    /// direction that the data cannot see moves it).
    pub fn standard_identifiable(&self) -> Vec<bool> {
        (0..self.structure.len())
            .map(|i| self.base.identifiable(i))
            .collect()
    }
}

/// Stack the rows of every transition of `logs` (and the instruments).
pub fn stack<R: Regressor>(
    regressor: &R,
    logs: &[Log],
    noise: Noise,
) -> Result<(estimate::Stack, usize), IdentifyError> {
    let (n, u) = (regressor.coordinates(), regressor.inputs());
    let p = regressor.structure().len();
    let block = regressor.rows();
    let instruments = match noise {
        Noise::LeastSquares | Noise::ErrorsInVariables(_) => None,
        Noise::InstrumentalVariables {
            half_window,
            degree,
        } => Some(estimate::leave_out_weights(half_window, degree)?),
    };
    let reach = match noise {
        Noise::LeastSquares | Noise::ErrorsInVariables(_) => 1,
        Noise::InstrumentalVariables { half_window, .. } => half_window + 1,
    };
    let zeros = vec![0.0; u];
    let mut w_rows: Vec<DMatrix<f64>> = Vec::new();
    // the instrument rows of a windowed transition; `None`: its own rows
    let mut z_rows: Vec<Option<DMatrix<f64>>> = Vec::new();
    let mut b_rows: Vec<DVector<f64>> = Vec::new();
    let mut origin = Vec::new();
    let mut instrumented = 0;
    for (li, log) in logs.iter().enumerate() {
        for x in &log.positions {
            check_length("positions", n, x.len())?;
        }
        log.check_input_count()?;
        for x in &log.inputs {
            check_length("input vector", u, x.len())?;
        }
        let k_count = log.positions.len();
        // a log too short for the instruments' window enters by least
        // squares (its rows are their own instruments)
        let windowed = instruments.is_some() && k_count > 2 * reach;
        let edge = if windowed { reach } else { 1 };
        if k_count < 2 * edge + 1 {
            continue;
        }
        for k in edge..k_count - edge {
            let t = log.transition(k, &zeros);
            let (y, b) = regressor.transition(&t)?;
            if instruments.is_some() && !windowed {
                z_rows.push(None);
            } else if let Some((taus, weights)) = &instruments {
                let smooth: Vec<Vec<f64>> = (0..3)
                    .map(|e| {
                        (0..n)
                            .map(|c| {
                                taus.iter()
                                    .enumerate()
                                    .map(|(j, tau)| {
                                        weights[(e, j)]
                                            * log.positions[(k as i64 + tau) as usize][c]
                                    })
                                    .sum()
                            })
                            .collect()
                    })
                    .collect();
                let tz = Transition {
                    positions: [&smooth[0], &smooth[1], &smooth[2]],
                    inputs: t.inputs,
                };
                z_rows.push(Some(regressor.transition(&tz)?.0));
                instrumented += 1;
            }
            w_rows.push(y);
            b_rows.push(b);
            origin.push((li, k));
        }
    }
    let transitions = w_rows.len();
    let rows = transitions * block;
    let mut w = DMatrix::zeros(rows, p);
    let mut b = DVector::zeros(rows);
    // no log held a window: least squares throughout, without instruments
    let mut z = (instrumented > 0).then(|| DMatrix::zeros(rows, p));
    for (t, (y, bb)) in w_rows.iter().zip(&b_rows).enumerate() {
        w.rows_mut(t * block, block).copy_from(y);
        b.rows_mut(t * block, block).copy_from(bb);
        if let Some(z) = z.as_mut() {
            z.rows_mut(t * block, block)
                .copy_from(z_rows[t].as_ref().unwrap_or(y));
        }
    }
    let slot = (0..rows).map(|i| i % block.max(1)).collect();
    Ok((
        estimate::Stack {
            w,
            b,
            z,
            slot,
            origin,
            block,
            instrumented,
        },
        transitions,
    ))
}

/// Identify the standard parameters of `regressor`'s mechanism from
/// `logs` (module docs).
pub fn identify<R: Regressor>(
    regressor: &R,
    logs: &[Log],
    options: &Options,
) -> Result<Identification, IdentifyError> {
    let positive = |x: f64| x > 0.0 && x.is_finite();
    if !(positive(options.prior.relative)
        && positive(options.prior.joint_floor)
        && options.rank_tolerance > 0.0
        && options.rank_tolerance < 1.0)
    {
        return Err(IdentifyError::Options {
            message: "the prior's scales must be positive and finite, the rank tolerance in (0, 1)"
                .into(),
        });
    }
    if let Noise::ErrorsInVariables(noise) = options.noise {
        noise.validate()?;
        if options.loss != Loss::Squared {
            return Err(IdentifyError::Options {
                message: "a robust loss does not combine with Noise::ErrorsInVariables".into(),
            });
        }
    }
    if let Loss::Huber(k) | Loss::Cauchy(k) = options.loss
        && !(k > 0.0 && k.is_finite())
    {
        return Err(IdentifyError::Options {
            message: format!("robust loss threshold {k}"),
        });
    }
    let structure = regressor.structure().clone();
    let declared = regressor.standard();
    let prior_sd = options.prior.sd(&structure, &declared);
    if let Some(i) = prior_sd.iter().position(|s| !(s.is_finite() && *s > 0.0)) {
        return Err(IdentifyError::NonFinite {
            what: format!(
                "prior scale of `{}` (declared mass zero?)",
                structure.names[i]
            ),
        });
    }
    let (mut stack, mut transitions) = stack(regressor, logs, options.noise)?;
    let mut base = Base::new(&stack.w, options.rank_tolerance);
    if stack.instrumented > 0 && !instruments_serve(&stack, &base, &declared) {
        (stack, transitions) = self::stack(regressor, logs, Noise::LeastSquares)?;
        base = Base::new(&stack.w, options.rank_tolerance);
    }
    let homogeneous = homogeneous(&stack, &declared);
    let fit = match options.noise {
        Noise::ErrorsInVariables(noise) => {
            errors_in_variables::solve(regressor, logs, &stack, &base, &declared, &prior_sd, noise)?
        }
        _ => estimate::solve(&stack, &base, &declared, &prior_sd, options.loss)?,
    };
    let unconstrained: Vec<f64> = fit.pi.iter().cloned().collect();
    let bad = consistency::inconsistent_bodies(&structure, &unconstrained);
    let negative = consistency::negative_joint_parameters(&structure, &unconstrained);
    let estimate = if options.consistent && !(bad.is_empty() && negative.is_empty()) {
        // The objective |R(Kπ − θ_data)|² + |S⁻¹(π − π₀)|², the data's
        // information capped (consistency::DATA_CAP).
        let (theta_data, r) = &fit.data;
        let metric =
            consistency::Metric::of_estimate(&base.k, r, theta_data, &declared, &prior_sd)?;
        let start = consistency::interior_start(&structure, &declared, &prior_sd);
        consistency::project(&structure, &metric, &start)?.0
    } else {
        unconstrained.clone()
    };
    let k = &base.k;
    let pv = DVector::from_column_slice(&estimate);
    let base_estimate: Vec<f64> = (k * &pv).iter().cloned().collect();
    let base_declared: Vec<f64> = (k * DVector::from_column_slice(&declared))
        .iter()
        .cloned()
        .collect();
    let (base_covariance, position_sigma) = match options.intervals {
        Intervals::Independent => (fit.base_covariance.clone(), None),
        Intervals::PositionNoise => {
            // at the estimate reported (physically consistent: a source of
            // rows may refuse an unrealisable body, as the tree engine does)
            let pi_hat = DVector::from_column_slice(&estimate);
            let mut jacs = Vec::with_capacity(stack.origin.len());
            let zeros = vec![0.0; regressor.inputs()];
            for &(li, k) in &stack.origin {
                let t = logs[li].transition(k, &zeros);
                jacs.push(regressor.noise_jacobian(&t, pi_hat.as_slice())?);
            }
            let offsets: Vec<usize> = logs
                .iter()
                .scan(0, |o, l| {
                    let at = *o;
                    *o += l.positions.len();
                    Some(at)
                })
                .collect();
            let first: Vec<usize> = stack
                .origin
                .iter()
                .map(|(li, k)| offsets[*li] + k - 1)
                .collect();
            let (sq, b) = covariance::position_noise(
                &fit,
                &jacs,
                &first,
                regressor.coordinates(),
                base.rank(),
            );
            let hinv = &fit.base_covariance;
            (hinv * (b + &fit.prior_precision) * hinv, Some(sq))
        }
    };
    let base_half_width = covariance::half_widths(&base_covariance);
    let s2 = DMatrix::from_diagonal(&DVector::from_iterator(
        prior_sd.len(),
        prior_sd.iter().map(|s| s * s),
    ));
    let prior_base = k * s2 * k.transpose();
    let base_informed = (0..base.rank())
        .map(|i| base_covariance[(i, i)] < 0.5 * prior_base[(i, i)])
        .collect();
    let base_names = base.names(&structure.names);
    let first = Identification {
        declared,
        prior_sd,
        estimate,
        unconstrained,
        projected: if options.consistent { bad } else { Vec::new() },
        projected_joints: if options.consistent {
            negative
        } else {
            Vec::new()
        },
        covariance: fit.covariance,
        base,
        base_names,
        base_declared,
        base_estimate,
        base_half_width,
        base_informed,
        sigma: fit.sigma,
        position_sigma,
        base_covariance,
        transitions,
        instrumented: stack.instrumented,
        structure,
        refinement: None,
    };
    // Homogeneous rows: the regression pulls the scale towards zero (its
    // data term shrinks with π), so output error runs there unasked, from
    // the declared values.
    match options
        .output_error
        .or(homogeneous.then(OutputError::default))
    {
        Some(oe) => output_error::refine(
            regressor,
            logs,
            &first,
            &oe,
            options.consistent,
            homogeneous,
        ),
        None => Ok(first),
    }
}

/// Whether the instrumented rows should be used, or least squares on
/// every transition instead (what [`Identification::instrumented`] then
/// reports as 0):
/// * the instruments leave too few rows for the base parameters (short
///   logs lose 2·`half_window` transitions each), or
/// * the rows are exact: least squares on the independent columns fits
///   b to 1e-8 of |b| (a log that the integrator itself wrote, solved to
///   its Newton tolerance). There is no noise to correct, least squares is
///   exact, and it is better conditioned than the instruments (on a
///   fourbar's noise-free log, 4e-9 against 2e-8 largest relative error).
///   Logs where no input acts have b = 0 and keep their instruments.
fn instruments_serve(stack: &estimate::Stack, base: &Base, declared: &[f64]) -> bool {
    let r = base.rank();
    if r == 0 || stack.w.nrows() < r + stack.block {
        return false;
    }
    if homogeneous(stack, declared) {
        return true;
    }
    let w1 = DMatrix::from_fn(stack.w.nrows(), r, |i, c| stack.w[(i, base.independent[c])]);
    let Ok(theta) = w1.clone().svd(true, true).solve(&stack.b, 0.0) else {
        return true;
    };
    let residual = (&stack.b - &w1 * theta).norm();
    // NaN counts as noise: the instruments stay
    let exact = residual <= 1e-8 * stack.b.norm();
    !exact
}

/// Whether every stacked row is homogeneous in π (b = 0 to rounding: no
/// input acts on the logs). The DEL residual of free motion does not change
/// when π is scaled, so such logs fix every ratio of π but not its scale.
fn homogeneous(stack: &estimate::Stack, declared: &[f64]) -> bool {
    let size = (0..stack.w.nrows())
        .map(|i| {
            (0..stack.w.ncols())
                .map(|j| (stack.w[(i, j)] * declared[j]).abs())
                .sum::<f64>()
        })
        .fold(0.0, f64::max);
    stack.b.amax() <= 1e-10 * size
}
