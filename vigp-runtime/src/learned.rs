//! The paper's learned integrators (§3): a Gaussian process learns the
//! velocity map z_k ↦ v_{k+1} on top of a prior (the nominal variational
//! step, eq. 7, or a constant mean), and for constrained models the
//! prediction is projected onto the constraint manifold (eq. 8).
//!
//! Positions are never learned: x_{k+1} = x_k + Δt·v_k is exact for discrete
//! velocities, so training targets are v_{k+1} = (x_{k+2} − x_{k+1})/Δt from
//! positions sampled at Δt ([`transitions`]).

use crate::gp::{Gp, GpError, PriorMean, TrainOptions, TrainReport, Workspace};
use crate::mechanism::{CoordinateKind, Mechanism, State};
use crate::newton::{NewtonOptions, StepError};
use crate::projection::{consistent_state, project_velocity};
use crate::variational::{Integrator, Variational};
use nalgebra::SVector;

mod embedded;
mod file;
pub use embedded::{EmbeddedExport, ExportSize};
pub use file::{LoadError, SavedKind, SavedLearned, SavedNewton};

/// How a state z = (q, v) is presented to the GP (saved as `"raw"` or
/// `"sincos"`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Encoding {
    /// The model's own coordinates and velocities (minimal or maximal).
    Raw,
    /// Every angle coordinate θ replaced by (sin θ, cos θ); velocities as is.
    SinCos,
}

impl Encoding {
    /// Input dimension of the encoding for a model with coordinate `kinds`.
    pub fn dim(self, kinds: &[CoordinateKind]) -> usize {
        match self {
            Encoding::Raw => 2 * kinds.len(),
            Encoding::SinCos => {
                2 * kinds.len()
                    + kinds
                        .iter()
                        .filter(|k| **k == CoordinateKind::Angle)
                        .count()
            }
        }
    }

    /// Write the encoding of `z` into `out` (length [`Encoding::dim`]).
    pub fn encode<const N: usize>(
        self,
        kinds: &[CoordinateKind; N],
        z: &State<N>,
        out: &mut [f64],
    ) {
        let mut k = 0;
        for (i, kind) in kinds.iter().enumerate() {
            if self == Encoding::SinCos && *kind == CoordinateKind::Angle {
                let (s, c) = z.q[i].sin_cos();
                out[k] = s;
                out[k + 1] = c;
                k += 2;
            } else {
                out[k] = z.q[i];
                k += 1;
            }
        }
        for i in 0..N {
            out[k + i] = z.v[i];
        }
    }

    /// Inverse of [`Encoding::encode`]: the state whose encoding is `input`
    /// (length [`Encoding::dim`]). With [`Encoding::SinCos`] an angle comes
    /// back as atan2(sin, cos) ∈ (−π, π], i.e. modulo 2π.
    pub fn decode<const N: usize>(self, kinds: &[CoordinateKind; N], input: &[f64]) -> State<N> {
        let mut z = State {
            q: SVector::zeros(),
            v: SVector::zeros(),
        };
        let mut k = 0;
        for (i, kind) in kinds.iter().enumerate() {
            if self == Encoding::SinCos && *kind == CoordinateKind::Angle {
                z.q[i] = input[k].atan2(input[k + 1]);
                k += 2;
            } else {
                z.q[i] = input[k];
                k += 1;
            }
        }
        for i in 0..N {
            z.v[i] = input[k + i];
        }
        z
    }
}

/// The prior mean of the learned velocity map (saved as `"nominal"` or
/// `"constant"`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Prior {
    /// The nominal variational step v̄(z) (paper eq. 7): the GP learns the
    /// residual v_{k+1} − v̄(z_k).
    Nominal,
    /// No prior model: the constant mean of the training targets.
    Constant,
}

/// One training pair: a discrete state and the next discrete velocity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transition<const N: usize> {
    /// z_k = (x_k, v_k), v_k = (x_{k+1} − x_k)/Δt.
    pub z: State<N>,
    /// v_{k+1} = (x_{k+2} − x_{k+1})/Δt.
    pub v_next: SVector<f64, N>,
}

/// The nominal first-order VI step of the prior (the fixed-size engine
/// on the model's closed-form terms, as [`Variational::new`] runs it).
fn nominal_step<M, const N: usize, const C: usize>(
    model: &M,
    dt: f64,
    options: &NewtonOptions,
    z: &State<N>,
) -> Result<State<N>, StepError>
where
    M: Mechanism<N, C> + Clone,
{
    Variational::new(model.clone(), dt)
        .with_options(*options)
        .step(z)
}

/// Transitions of a trajectory of positions sampled every Δt (K positions
/// give K − 2 transitions).
pub fn transitions<const N: usize>(positions: &[SVector<f64, N>], dt: f64) -> Vec<Transition<N>> {
    positions
        .windows(3)
        .map(|w| Transition {
            z: State {
                q: w[0],
                v: (w[1] - w[0]) / dt,
            },
            v_next: (w[2] - w[1]) / dt,
        })
        .collect()
}

/// Why training or prediction of a learned integrator failed.
#[derive(Debug, thiserror::Error)]
pub enum LearnError {
    /// The GP could not be trained or evaluated.
    #[error(transparent)]
    Gp(#[from] GpError),
    /// A nominal step or a projection failed.
    #[error(transparent)]
    Step(#[from] StepError),
    /// No training data.
    #[error("no training transitions")]
    Empty,
    /// A setting is out of its domain.
    #[error("invalid setting {what}: {value}")]
    InvalidSetting {
        /// Which setting.
        what: &'static str,
        /// The offending value.
        value: f64,
    },
    /// A training transition contains NaN or ±∞.
    #[error("training transition {0} is not finite")]
    NonFinite(usize),
}

/// Diagnostics of one learned step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LearnedStepInfo<const N: usize> {
    /// The unprojected prediction v_u (eq. 7).
    pub unprojected: SVector<f64, N>,
    /// Posterior standard deviation σ_i(z) of each velocity component.
    pub std_dev: SVector<f64, N>,
    /// Size ‖v − v_u‖ of the projection's correction (0 without constraints).
    pub correction: f64,
}

/// A learned integrator: prior + GP velocity map (+ projection when the
/// model has constraints and projection is on).
///
/// Complexity per step: one nominal VI step (with [`Prior::Nominal`]),
/// O(N·d) per output for the GP mean (N training samples, d input
/// dimensions: N·d subtract-multiply-adds and N exponentials), O(N²) more
/// per output for the variance (only [`Learned::step_with`] and the error
/// bound need it; [`Integrator::step`] and rollouts use the mean), and a
/// Newton projection for constrained models.
#[derive(Clone, Debug)]
pub struct Learned<M, const N: usize, const C: usize> {
    model: M,
    dt: f64,
    prior: Prior,
    encoding: Encoding,
    project: bool,
    gp: Gp,
    options: NewtonOptions,
}

impl<M: Mechanism<N, C> + Clone, const N: usize, const C: usize> Learned<M, N, C> {
    /// Train on transitions. `model` supplies the prior (for
    /// [`Prior::Nominal`]), the angle kinds for [`Encoding::SinCos`], and the
    /// constraints for the projection (on whenever C > 0). The GP options'
    /// `mean` is overridden by `prior`.
    pub fn train(
        model: M,
        dt: f64,
        data: &[Transition<N>],
        encoding: Encoding,
        prior: Prior,
        options: &TrainOptions,
    ) -> Result<(Self, TrainReport), LearnError> {
        if data.is_empty() {
            return Err(LearnError::Empty);
        }
        if !(dt.is_finite() && dt > 0.0) {
            return Err(StepError::InvalidTimeStep { dt }.into());
        }
        let d = encoding.dim(&M::KINDS);
        let mut inputs = vec![0.0; data.len() * d];
        let mut targets = Vec::with_capacity(data.len() * N);
        let nominal = NewtonOptions::default();
        for (i, t) in data.iter().enumerate() {
            if !(t.z.is_finite() && t.v_next.iter().all(|x| x.is_finite())) {
                return Err(LearnError::NonFinite(i));
            }
            encoding.encode(&M::KINDS, &t.z, &mut inputs[i * d..(i + 1) * d]);
            let base = match prior {
                // With constraints, a noisy state is off the manifold and the
                // nominal step would spend Δv ≈ |g|/Δt re-closing it: evaluate
                // the prior at the nearest consistent state instead, as it is
                // at prediction time (predictions are projected).
                Prior::Nominal if C > 0 => {
                    let z = consistent_state(&model, &t.z.q, &t.z.v, dt)?;
                    nominal_step(&model, dt, &nominal, &z)?.v
                }
                Prior::Nominal => nominal_step(&model, dt, &nominal, &t.z)?.v,
                Prior::Constant => SVector::zeros(),
            };
            targets.extend((t.v_next - base).iter());
        }
        let mut opts = options.clone();
        opts.mean = match prior {
            Prior::Nominal => PriorMean::Zero,
            Prior::Constant => PriorMean::Constant,
        };
        let (gp, report) = Gp::train(&inputs, d, &targets, N, &opts)?;
        Ok((
            Self {
                model,
                dt,
                prior,
                encoding,
                project: C > 0,
                gp,
                // near a folded loop the projection converges linearly
                options: NewtonOptions {
                    max_iterations: 100,
                    ..NewtonOptions::default()
                },
            },
            report,
        ))
    }

    /// Switch the projection off (eq. 7 even for a constrained model), e.g.
    /// to measure what the projection buys.
    pub fn without_projection(mut self) -> Self {
        self.project = false;
        self
    }

    /// The trained GP.
    pub fn gp(&self) -> &Gp {
        &self.gp
    }

    /// The model (prior and constraints).
    pub fn model(&self) -> &M {
        &self.model
    }

    /// The encoding of GP inputs.
    pub fn encoding(&self) -> Encoding {
        self.encoding
    }

    /// The prior.
    pub fn prior(&self) -> Prior {
        self.prior
    }

    /// `true` when predictions are projected onto the constraints.
    pub fn projects(&self) -> bool {
        self.project
    }

    /// A GP workspace for [`Learned::step_with`].
    pub fn workspace(&self) -> Workspace {
        self.gp.workspace()
    }

    /// The prior v̄(z): the nominal variational step, or 0 for a constant
    /// prior (whose constant is part of the GP mean).
    fn prior_velocity(&self, z: &State<N>) -> Result<SVector<f64, N>, StepError> {
        Ok(match self.prior {
            Prior::Nominal => nominal_step(&self.model, self.dt, &self.options, z)?.v,
            Prior::Constant => SVector::zeros(),
        })
    }

    /// Encodes `z` into a stack buffer (heap only above 64 input
    /// dimensions) and passes the GP input to `f`.
    fn with_input<T>(
        &self,
        z: &State<N>,
        f: impl FnOnce(&[f64]) -> Result<T, StepError>,
    ) -> Result<T, StepError> {
        let d = self.encoding.dim(&M::KINDS);
        let mut x = [0.0f64; 64];
        let mut heap;
        let input: &mut [f64] = if d <= x.len() {
            &mut x[..d]
        } else {
            heap = vec![0.0; d];
            &mut heap
        };
        self.encoding.encode(&M::KINDS, z, input);
        f(input)
    }

    /// The unprojected prediction v_u = prior(z) + μ(z) (eq. 7) and the
    /// posterior standard deviations. Cost O(p·N·(d + N)) for the GP (the
    /// variance needs a triangular solve per output) plus the prior.
    pub fn predict_velocity(
        &self,
        z: &State<N>,
        ws: &mut Workspace,
    ) -> Result<(SVector<f64, N>, SVector<f64, N>), StepError> {
        let mut mean = SVector::<f64, N>::zeros();
        let mut var = SVector::<f64, N>::zeros();
        self.with_input(z, |input| {
            self.gp
                .predict_into(input, mean.as_mut_slice(), var.as_mut_slice(), ws)
                .map_err(|_| StepError::Prediction { step: None })
        })?;
        let v = self.prior_velocity(z)? + mean;
        if !v.iter().all(|x| x.is_finite()) {
            return Err(StepError::Prediction { step: None });
        }
        Ok((v, var.map(|s| s.max(0.0).sqrt())))
    }

    /// The unprojected mean prediction v_u = prior(z) + μ(z) (eq. 7) without
    /// the variance: O(p·N·d) for the GP plus the prior. Equal bit for bit
    /// to the first component of [`predict_velocity`](Self::predict_velocity).
    pub fn predict_mean_velocity(
        &self,
        z: &State<N>,
        ws: &mut Workspace,
    ) -> Result<SVector<f64, N>, StepError> {
        let mut mean = SVector::<f64, N>::zeros();
        self.with_input(z, |input| {
            self.gp
                .predict_mean_into(input, mean.as_mut_slice(), ws)
                .map_err(|_| StepError::Prediction { step: None })
        })?;
        let v = self.prior_velocity(z)? + mean;
        if !v.iter().all(|x| x.is_finite()) {
            return Err(StepError::Prediction { step: None });
        }
        Ok(v)
    }

    /// One learned step using only the posterior mean (what a rollout
    /// needs): like [`step_with`](Self::step_with) without the variances,
    /// so O(p·N·d) instead of O(p·N·(d + N)) for the GP. Same next state as
    /// `step_with`, bit for bit. No allocation for inputs of up to 64
    /// dimensions.
    pub fn step_mean_with(&self, z: &State<N>, ws: &mut Workspace) -> Result<State<N>, StepError> {
        self.check_step(z)?;
        let x1 = z.q + z.v * self.dt;
        let vu = self.predict_mean_velocity(z, ws)?;
        let v = if self.project && C > 0 {
            project_velocity(&self.model, &x1, &vu, self.dt, &self.options)?.0
        } else {
            vu
        };
        Ok(State { q: x1, v })
    }

    fn check_step(&self, z: &State<N>) -> Result<(), StepError> {
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return Err(StepError::InvalidTimeStep { dt: self.dt });
        }
        if !z.is_finite() {
            return Err(StepError::NonFiniteState { step: None });
        }
        Ok(())
    }

    /// One learned step with a caller-owned GP workspace (no allocation for
    /// inputs of up to 64 dimensions).
    pub fn step_with(
        &self,
        z: &State<N>,
        ws: &mut Workspace,
    ) -> Result<(State<N>, LearnedStepInfo<N>), StepError> {
        self.check_step(z)?;
        let x1 = z.q + z.v * self.dt;
        let (vu, std_dev) = self.predict_velocity(z, ws)?;
        let v = if self.project && C > 0 {
            project_velocity(&self.model, &x1, &vu, self.dt, &self.options)?.0
        } else {
            vu
        };
        Ok((
            State { q: x1, v },
            LearnedStepInfo {
                unprojected: vu,
                std_dev,
                correction: (v - vu).norm(),
            },
        ))
    }
}

impl<M: Mechanism<N, C> + Clone, const N: usize, const C: usize> Integrator<N>
    for Learned<M, N, C>
{
    fn dt(&self) -> f64 {
        self.dt
    }

    /// One step (mean only, [`Learned::step_mean_with`]); allocates a GP
    /// workspace per call (use `step_mean_with` in loops).
    fn step(&self, z: &State<N>) -> Result<State<N>, StepError> {
        let mut ws = self.gp.workspace();
        self.step_mean_with(z, &mut ws)
    }

    /// Mean-only steps ([`Learned::step_mean_with`]) with one workspace.
    fn rollout_into(&self, z0: &State<N>, out: &mut [State<N>]) -> Result<(), StepError> {
        let mut ws = self.gp.workspace();
        let mut z = *z0;
        for (k, slot) in out.iter_mut().enumerate() {
            z = self.step_mean_with(&z, &mut ws).map_err(|e| e.at_step(k))?;
            *slot = z;
        }
        Ok(())
    }
}
