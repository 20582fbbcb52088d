//! The learned integrator in space (paper eq. 7 and 8, maximal
//! coordinates): a Gaussian process learns the velocity map
//! z_k ↦ ν_{k+1} = (v_i, ω_i)_{k+1} on top of a prior (the nominal
//! Lie-group variational step, or a constant mean); the prediction is then
//! projected onto the joint constraints of the next configuration. The
//! configuration update x_{k+1} = x_k + Δt·v_k, q_{k+1} = q_k ⊗ exp(Δt·ω_k)
//! is exact and never learned, so the unit quaternions stay unit to
//! rounding whatever the GP predicts, and the projection keeps every joint
//! to solver tolerance.
//!
//! # GP inputs: which rotation representation
//!
//! Per link: the centre of mass x, the orientation, v and ω (body frame).
//! The orientation enters as the nine entries of its rotation matrix
//! ([`Rotation::Matrix`], the default): a continuous, one-to-one image of
//! the rotation group, so that physically equal states are equal GP inputs
//! and nearby rotations are nearby inputs, which is what a stationary
//! kernel assumes. The alternative, the quaternion's four components
//! ([`Rotation::Quaternion`]), double-covers the rotations: q and −q are
//! the same orientation but far apart as inputs, and a link that turns
//! once about an axis comes back as −q. A GP trained on q then knows
//! nothing at −q and falls back to its prior there; canonicalising the
//! sign (w ≥ 0) instead makes the input jump at half turns.
//! `tests/spatial_learned.rs` measures the difference.

use super::{SpatialError, SpatialIntegrator};
use crate::gp::{Gp, PriorMean, TrainOptions, TrainReport, Workspace};
use crate::learned::Prior;
use nalgebra::{SVector, UnitQuaternion, Vector3};
use vigp_core::spatial::maximal::{pack, unpack};
use vigp_core::spatial::{LieStepper, Spatial, SpatialState, so3};

/// How an orientation is presented to the GP.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Rotation {
    /// The nine entries of the rotation matrix (row-major).
    Matrix,
    /// The quaternion (w, x, y, z) as the state carries it.
    Quaternion,
}

impl Rotation {
    /// Input dimensions per orientation.
    pub fn dim(self) -> usize {
        match self {
            Rotation::Matrix => 9,
            Rotation::Quaternion => 4,
        }
    }

    /// GP input dimension for `B` links: per link x (3), the orientation,
    /// v (3) and ω (3).
    pub fn input_dim(self, links: usize) -> usize {
        links * (9 + self.dim())
    }

    /// Write the GP input of `z` into `out` (length [`Rotation::input_dim`]).
    pub fn encode<const B: usize>(self, z: &SpatialState<B>, out: &mut [f64]) {
        let mut k = 0;
        let mut put = |x: f64| {
            out[k] = x;
            k += 1;
        };
        for i in 0..B {
            z.x[i].iter().for_each(|x| put(*x));
            match self {
                Rotation::Matrix => {
                    let r = z.q[i].to_rotation_matrix();
                    for a in 0..3 {
                        for b in 0..3 {
                            put(r[(a, b)]);
                        }
                    }
                }
                Rotation::Quaternion => {
                    let q = z.q[i].quaternion();
                    [q.w, q.i, q.j, q.k].iter().for_each(|x| put(*x));
                }
            }
            z.v[i].iter().for_each(|x| put(*x));
            z.w[i].iter().for_each(|x| put(*x));
        }
    }
}

/// One training pair: a discrete state and the next discrete velocities.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpatialTransition<const B: usize> {
    /// z_k: configuration k and the velocities of the step to k+1.
    pub z: SpatialState<B>,
    /// Linear velocities of the step from k+1 to k+2.
    pub v_next: [Vector3<f64>; B],
    /// Body angular velocities of the step from k+1 to k+2.
    pub w_next: [Vector3<f64>; B],
}

/// A sampled configuration: centres of mass and orientations of every link.
pub type Configuration<const B: usize> = ([Vector3<f64>; B], [UnitQuaternion<f64>; B]);

/// Transitions of a trajectory of configurations sampled every Δt (K
/// configurations give K − 2 transitions): the discrete velocities are
/// (x_{k+1} − x_k)/Δt and log(q_k⁻¹ q_{k+1})/Δt, so that the configuration
/// update is exact and the GP learns only the velocity map.
pub fn transitions<const B: usize>(
    configurations: &[Configuration<B>],
    dt: f64,
) -> Vec<SpatialTransition<B>> {
    let vel =
        |a: &Configuration<B>, b: &Configuration<B>| -> ([Vector3<f64>; B], [Vector3<f64>; B]) {
            (
                std::array::from_fn(|i| (b.0[i] - a.0[i]) / dt),
                std::array::from_fn(|i| so3::log(&(a.1[i].inverse() * b.1[i])) / dt),
            )
        };
    configurations
        .windows(3)
        .map(|w| {
            let (v, ww) = vel(&w[0], &w[1]);
            let (v_next, w_next) = vel(&w[1], &w[2]);
            SpatialTransition {
                z: SpatialState {
                    x: w[0].0,
                    q: w[0].1,
                    v,
                    w: ww,
                },
                v_next,
                w_next,
            }
        })
        .collect()
}

/// Why training or prediction of a learned spatial integrator failed.
#[derive(Debug, thiserror::Error)]
pub enum LearnSpatialError {
    /// The GP could not be trained or evaluated.
    #[error(transparent)]
    Gp(#[from] crate::gp::GpError),
    /// A nominal step or a projection failed.
    #[error(transparent)]
    Step(#[from] vigp_core::StepError),
    /// No training data.
    #[error("no training transitions")]
    Empty,
    /// A training transition contains NaN or ±∞.
    #[error("training transition {0} is not finite")]
    NonFinite(usize),
}

/// A learned spatial integrator: prior + GP velocity map, projected onto
/// the joint constraints (when the mechanism has any and projection is on).
///
/// Cost per step: the nominal Lie-group step (with [`Prior::Nominal`]), the
/// GP mean (O(N·d) per output: N samples, d inputs, 6B outputs) and the
/// velocity projection (a few Newton iterations on a (6B + C) KKT system).
#[derive(Clone, Debug)]
pub struct LearnedSpatial<S, const B: usize, const J: usize, const N: usize, const C: usize> {
    stepper: LieStepper<S, B, J, N, C>,
    gp: Gp,
    prior: Prior,
    rotation: Rotation,
    project: bool,
}

impl<S: Spatial<B, J>, const B: usize, const J: usize, const N: usize, const C: usize>
    LearnedSpatial<S, B, J, N, C>
{
    /// Train on transitions. `stepper` is the nominal model: the prior
    /// (for [`Prior::Nominal`]), Δt, and the constraints of the projection.
    /// With constraints, the prior of a (noisy, inconsistent) training state
    /// is evaluated at its consistent neighbour, as at prediction time.
    pub fn train(
        stepper: LieStepper<S, B, J, N, C>,
        data: &[SpatialTransition<B>],
        rotation: Rotation,
        prior: Prior,
        options: &TrainOptions,
    ) -> Result<(Self, TrainReport), LearnSpatialError> {
        if data.is_empty() {
            return Err(LearnSpatialError::Empty);
        }
        let d = rotation.input_dim(B);
        let mut inputs = vec![0.0; data.len() * d];
        let mut targets = Vec::with_capacity(data.len() * N);
        for (i, t) in data.iter().enumerate() {
            let next: SVector<f64, N> = pack(&t.v_next, &t.w_next);
            if !(t.z.is_finite() && next.iter().all(|x| x.is_finite())) {
                return Err(LearnSpatialError::NonFinite(i));
            }
            rotation.encode(&t.z, &mut inputs[i * d..(i + 1) * d]);
            let base: SVector<f64, N> = match prior {
                Prior::Nominal => {
                    let z = if C > 0 {
                        stepper.consistent_state(&t.z)?
                    } else {
                        t.z
                    };
                    let z1 = stepper.step(&z)?;
                    pack(&z1.v, &z1.w)
                }
                Prior::Constant => SVector::zeros(),
            };
            targets.extend((next - base).iter());
        }
        let mut opts = options.clone();
        opts.mean = match prior {
            Prior::Nominal => PriorMean::Zero,
            Prior::Constant => PriorMean::Constant,
        };
        let (gp, report) = Gp::train(&inputs, d, &targets, N, &opts)?;
        Ok((
            Self {
                stepper,
                gp,
                prior,
                rotation,
                project: C > 0,
            },
            report,
        ))
    }

    /// Switch the projection off (eq. 7 alone), e.g. to measure what it buys.
    pub fn without_projection(mut self) -> Self {
        self.project = false;
        self
    }

    /// The trained GP.
    pub fn gp(&self) -> &Gp {
        &self.gp
    }

    /// The nominal stepper.
    pub fn stepper(&self) -> &LieStepper<S, B, J, N, C> {
        &self.stepper
    }

    /// The rotation representation of the GP inputs.
    pub fn rotation(&self) -> Rotation {
        self.rotation
    }

    /// A GP workspace for [`Self::step_with`].
    pub fn workspace(&self) -> Workspace {
        self.gp.workspace()
    }

    /// The unprojected velocities ν_u = prior(z) + μ(z) (eq. 7).
    pub fn predict_velocity(
        &self,
        z: &SpatialState<B>,
        ws: &mut Workspace,
    ) -> Result<SVector<f64, N>, LearnSpatialError> {
        // the GP input on the stack (heap only above 128 dimensions, i.e.
        // more than 7 links with rotation matrices)
        let d = self.rotation.input_dim(B);
        let mut stack = [0.0f64; 128];
        let mut heap;
        let input: &mut [f64] = if d <= stack.len() {
            &mut stack[..d]
        } else {
            heap = vec![0.0; d];
            &mut heap
        };
        self.rotation.encode(z, input);
        let mut mean = SVector::<f64, N>::zeros();
        self.gp.predict_mean_into(input, mean.as_mut_slice(), ws)?;
        let prior: SVector<f64, N> = match self.prior {
            Prior::Nominal => {
                let z1 = self.stepper.step(z)?;
                pack(&z1.v, &z1.w)
            }
            Prior::Constant => SVector::zeros(),
        };
        let nu = prior + mean;
        if !nu.iter().all(|x| x.is_finite()) {
            return Err(LearnSpatialError::Step(
                vigp_core::StepError::NonFiniteState,
            ));
        }
        Ok(nu)
    }

    /// One learned step: configuration k+1 exactly, velocities predicted
    /// and projected so that configuration k+2 is consistent. No
    /// allocation (GP inputs of up to 128 dimensions).
    pub fn step_with(
        &self,
        z: &SpatialState<B>,
        ws: &mut Workspace,
    ) -> Result<SpatialState<B>, LearnSpatialError> {
        if !z.is_finite() {
            return Err(vigp_core::StepError::NonFiniteState.into());
        }
        let (x1, q1) = z.advanced(self.stepper.dt());
        let nu = self.predict_velocity(z, ws)?;
        let nu = if self.project && C > 0 {
            self.stepper.project_velocity(&x1, &q1, &nu)?
        } else {
            nu
        };
        let (v, w) = unpack(&nu);
        Ok(SpatialState { x: x1, q: q1, v, w })
    }
}

impl<S: Spatial<B, J>, const B: usize, const J: usize, const N: usize, const C: usize>
    SpatialIntegrator<B> for LearnedSpatial<S, B, J, N, C>
{
    fn dt(&self) -> f64 {
        self.stepper.dt()
    }

    /// One step; allocates a GP workspace per call (use
    /// [`LearnedSpatial::step_with`] in loops).
    fn step(&self, z: &SpatialState<B>) -> Result<SpatialState<B>, SpatialError> {
        let mut ws = self.gp.workspace();
        Ok(self.step_with(z, &mut ws)?)
    }

    /// Steps with one workspace.
    fn rollout(
        &self,
        z0: &SpatialState<B>,
        steps: usize,
    ) -> Result<Vec<SpatialState<B>>, SpatialError> {
        let mut ws = self.gp.workspace();
        let mut out = Vec::with_capacity(steps + 1);
        out.push(*z0);
        let mut z = *z0;
        for k in 0..steps {
            z = self.step_with(&z, &mut ws).map_err(|e| match e {
                LearnSpatialError::Step(error) => {
                    SpatialError::Rollout(vigp_core::RolloutError { step: k, error })
                }
                other => SpatialError::Learn(Box::new(other)),
            })?;
            out.push(z);
        }
        Ok(out)
    }
}
