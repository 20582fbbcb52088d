//! A learned robot on fixed-size data: the tree's bodies, the prior, the
//! encoding and one exported GP per joint ([`LearnedTree`], normally a
//! `static` written by `vigp export` from a model of `vigp fit --urdf`),
//! stepped without allocation by [`LearnedTreeStepper`].
//!
//! The step is the std runtime's learned robot step (its mean):
//! q₁ = q + Δt·v and v₁ = v̄(z, u) + μ(enc(z), u_prev, u), where v̄ is
//! the tree engine's step from the momentum of z under the inputs held
//! over the step (zero under [`Prior::Constant`]) and μ the GP means.

use super::derivatives::{DerivativeBuffers, derivative_scratch_len};
use super::spatial::V3;
use super::{Body, BodyScratch, Engine, EngineOptions, JointKind, TreeRef};
use crate::error::StepError;
use crate::forced::{InputJacobian, RolloutDerivativeBuffers, StateJacobian, StepDerivatives};
use crate::gp::ExportedGp;
use crate::learned::{Encoding, LearnedError, Prior, VelocityDerivatives, buffer_length};
use crate::state::{CoordinateKind, State};
use nalgebra::SVector;

/// A learned robot as data: `N` joints, `D` GP inputs (the encoded state,
/// then the previous and the current input).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LearnedTree<'a, const N: usize, const D: usize> {
    /// The robot's name.
    pub robot: &'a str,
    /// The joints with a coordinate, in the tree's (depth-first) order.
    pub joints: [&'a str; N],
    /// The bodies (parents first): the prior's model, with identified
    /// parameters where the model was trained on them.
    pub bodies: &'a [Body; N],
    /// Gravity in world coordinates (m/s²).
    pub gravity: V3,
    /// The actuated joints, in input order (names from `joints`).
    pub inputs: &'a [&'a str],
    /// Time step Δt (s).
    pub dt: f64,
    /// GP input encoding of the state.
    pub encoding: Encoding,
    /// Prior of the velocity map.
    pub prior: Prior,
    /// Options of the engine's step.
    pub options: EngineOptions,
    /// One GP per joint velocity.
    pub gps: &'a [ExportedGp<'a, D>; N],
}

/// The exact derivatives of one learned robot step
/// ([`LearnedTreeStepper::step_derivatives`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LearnedTreeDerivatives<const N: usize, const U: usize> {
    /// The state after the step (that of [`LearnedTreeStepper::step`], to
    /// the solver's tolerance).
    pub state: State<N>,
    /// A = ∂z₁/∂z₀.
    pub a: StateJacobian<N>,
    /// B = ∂z₁/∂u (the input held over this step).
    pub b: InputJacobian<N, U>,
    /// ∂z₁/∂u_prev (the GP reads the previous input).
    pub b_prev: InputJacobian<N, U>,
}

/// Number of N × N blocks in a [`TreeDerivativeScratch`]: the prior's A
/// (4) and B (2, U ≤ N), and the engine's derivative scratch
/// (12N² + 2N·U + 2N ≤ 16N²).
const DERIVATIVE_BLOCKS: usize = 22;

/// The scratch of [`LearnedTreeStepper::step_derivatives`]: 22 N × N
/// blocks of `f64` (for the Panda, N = 7: 8.6 KB), on the stack or in a
/// `static`.
#[derive(Clone, Debug)]
pub struct TreeDerivativeScratch<const N: usize> {
    blocks: [[[f64; N]; N]; DERIVATIVE_BLOCKS],
}

impl<const N: usize> TreeDerivativeScratch<N> {
    /// Zeroed scratch.
    pub const fn new() -> Self {
        Self {
            blocks: [[[0.0; N]; N]; DERIVATIVE_BLOCKS],
        }
    }
}

impl<const N: usize> Default for TreeDerivativeScratch<N> {
    fn default() -> Self {
        Self::new()
    }
}

/// The stepper of a [`LearnedTree`]: its engine over the bodies
/// (validated once), the coordinate kinds and the input map.
#[derive(Clone, Copy, Debug)]
pub struct LearnedTreeStepper<'a, const N: usize, const D: usize> {
    learned: &'a LearnedTree<'a, N, D>,
    engine: Engine<TreeRef<'a>>,
    kinds: [CoordinateKind; N],
    /// The joint of input i, for i < `inputs`.
    actuated: [usize; N],
    inputs: usize,
    /// The encoded state's dimension (the GP input's first entries).
    encoded: usize,
}

impl<'a, const N: usize, const D: usize> LearnedTreeStepper<'a, N, D> {
    /// Checks the model: the bodies (the engine validates them), the
    /// inputs (distinct joints of the robot), the GP input dimension
    /// (encoding plus twice the inputs) and every GP's data.
    pub fn new(learned: &'a LearnedTree<'a, N, D>) -> Result<Self, LearnedError> {
        let tree = TreeRef {
            bodies: &learned.bodies[..],
            gravity: learned.gravity,
        };
        let engine = Engine::with_options(tree, learned.options).map_err(LearnedError::Engine)?;
        super::engine::check_time_step(learned.dt).map_err(LearnedError::Engine)?;
        let kinds = core::array::from_fn(|i| match learned.bodies[i].joint {
            JointKind::Revolute => CoordinateKind::Angle,
            JointKind::Prismatic => CoordinateKind::Length,
        });
        if learned.inputs.len() > N {
            return Err(LearnedError::InputCount {
                expected: N,
                got: learned.inputs.len(),
            });
        }
        let mut actuated = [0usize; N];
        for (i, name) in learned.inputs.iter().enumerate() {
            match learned.joints.iter().position(|j| j == name) {
                Some(j) if !actuated[..i].contains(&j) => actuated[i] = j,
                _ => return Err(LearnedError::UnknownInput(i)),
            }
        }
        let e = learned.encoding.dim(&kinds);
        let m = learned.inputs.len();
        if D != e + 2 * m {
            return Err(LearnedError::InputDimension {
                expected: e + 2 * m,
                got: D,
            });
        }
        for gp in learned.gps {
            gp.validate()?;
        }
        Ok(Self {
            learned,
            engine,
            kinds,
            actuated,
            inputs: m,
            encoded: e,
        })
    }

    /// The model.
    pub fn learned(&self) -> &LearnedTree<'a, N, D> {
        self.learned
    }

    /// The engine of the prior.
    pub fn engine(&self) -> &Engine<TreeRef<'a>> {
        &self.engine
    }

    /// One learned step from `z` under inputs `u` (one per actuated joint,
    /// in [`LearnedTree::inputs`] order, held over the step) after
    /// `u_prev`, the input that produced z's velocity (module docs). `U`
    /// must be the model's number of inputs. `ws` is the engine's scratch,
    /// one per body. No allocation.
    pub fn step<const U: usize>(
        &self,
        z: &State<N>,
        u_prev: &SVector<f64, U>,
        u: &SVector<f64, U>,
        ws: &mut [BodyScratch; N],
    ) -> Result<State<N>, LearnedError> {
        self.check_step(z, u_prev, u)?;
        let l = self.learned;
        let mut v1 = [0.0; N];
        if l.prior.uses_nominal_step() {
            let mut q: [f64; N] = z.q.into();
            v1 = z.v.into();
            let mut p = [0.0; N];
            let tau = self.forces(u);
            self.engine
                .momentum_of(&q, &v1, &mut p, ws)
                .map_err(LearnedError::Engine)?;
            self.engine
                .step(&mut q, &mut v1, &mut p, &tau, l.dt, ws)
                .map_err(LearnedError::Engine)?;
        }
        let x = self.gp_input(z, u_prev, u);
        for (v, gp) in v1.iter_mut().zip(l.gps) {
            *v += gp.predict_mean(&x)?;
        }
        let v = SVector::from(v1);
        if !v.iter().all(|x| x.is_finite()) {
            return Err(StepError::NonFiniteState { step: None }.into());
        }
        Ok(State {
            q: z.q + z.v * l.dt,
            v,
        })
    }

    /// The checks of a step: the number of inputs, a finite state and
    /// finite inputs.
    fn check_step<const U: usize>(
        &self,
        z: &State<N>,
        u_prev: &SVector<f64, U>,
        u: &SVector<f64, U>,
    ) -> Result<(), LearnedError> {
        if U != self.inputs {
            return Err(LearnedError::InputCount {
                expected: self.inputs,
                got: U,
            });
        }
        if !z.is_finite() {
            return Err(StepError::NonFiniteState { step: None }.into());
        }
        if !(u.iter().chain(u_prev.iter()).all(|x| x.is_finite())) {
            return Err(StepError::NonFiniteInput { step: None }.into());
        }
        Ok(())
    }

    /// The generalized forces of the inputs `u` (each on its joint).
    fn forces<const U: usize>(&self, u: &SVector<f64, U>) -> [f64; N] {
        let mut tau = [0.0; N];
        for (k, &j) in self.actuated[..U].iter().enumerate() {
            tau[j] = u[k];
        }
        tau
    }

    /// The GP input: the encoded state, then `u_prev`, then `u`.
    fn gp_input<const U: usize>(
        &self,
        z: &State<N>,
        u_prev: &SVector<f64, U>,
        u: &SVector<f64, U>,
    ) -> [f64; D] {
        let mut x = [0.0; D];
        let e = self.encoded;
        self.learned.encoding.encode(&self.kinds, z, &mut x[..e]);
        x[e..e + U].copy_from_slice(u_prev.as_slice());
        x[e + U..e + 2 * U].copy_from_slice(u.as_slice());
        x
    }

    /// One learned step (as [`LearnedTreeStepper::step`]) with its exact
    /// derivatives, for MPC and iLQR on the learned model without
    /// allocation. q₁ = q + Δt·v gives A's top rows [I, Δt·I] and none of
    /// B; v₁ = v̄(z, u) + μ(enc(z), u_prev, u) differentiates into the
    /// tree engine's exact step derivatives
    /// ([`Engine::step_derivatives`], the implicit function theorem on its
    /// residual; none under [`Prior::Constant`]) plus each GP mean's
    /// gradient ([`ExportedGp::predict_mean_gradient`](crate::gp::ExportedGp::predict_mean_gradient))
    /// through the encoding. The same derivatives as the std runtime's
    /// learned robot, to rounding.
    pub fn step_derivatives<const U: usize>(
        &self,
        z: &State<N>,
        u_prev: &SVector<f64, U>,
        u: &SVector<f64, U>,
        scratch: &mut TreeDerivativeScratch<N>,
        ws: &mut [BodyScratch; N],
    ) -> Result<LearnedTreeDerivatives<N, U>, LearnedError> {
        self.check_step(z, u_prev, u)?;
        let l = self.learned;
        // ∂v₁/∂(q, v, u, u_prev): the robot's step's rows, then the GPs'
        let mut dv = VelocityDerivatives::<N, U>::zeros();
        let mut v1 = [0.0; N];
        if l.prior.uses_nominal_step() {
            let flat = scratch.blocks.as_flattened_mut().as_flattened_mut();
            let (pa, rest) = flat.split_at_mut(4 * N * N);
            let (pb, rest) = rest.split_at_mut(2 * N * U);
            let engine_scratch = &mut rest[..derivative_scratch_len(N, U)];
            let mut q: [f64; N] = z.q.into();
            v1 = z.v.into();
            let mut p = [0.0; N];
            let tau = self.forces(u);
            let buffers = DerivativeBuffers {
                a: pa,
                b: pb,
                scratch: engine_scratch,
                start_known: false,
            };
            self.engine
                .step_derivatives(
                    &mut q,
                    &mut v1,
                    &mut p,
                    &tau,
                    &self.actuated[..U],
                    l.dt,
                    buffers,
                    ws,
                )
                .map_err(LearnedError::Engine)?;
            for i in 0..N {
                let row = &pa[(N + i) * 2 * N..(N + i + 1) * 2 * N];
                for j in 0..N {
                    dv.q[(i, j)] = row[j];
                    dv.v[(i, j)] = row[N + j];
                }
                for c in 0..U {
                    dv.u[(i, c)] = pb[(N + i) * U + c];
                }
            }
        }
        let x = self.gp_input(z, u_prev, u);
        let e = self.encoded;
        let mut grads = [[0.0f64; D]; N];
        for ((v, gp), g) in v1.iter_mut().zip(l.gps.iter()).zip(&mut grads) {
            let (mean, grad) = gp.predict_mean_gradient(&x)?;
            *v += mean;
            *g = grad;
        }
        // the GP input is (enc(z), u_prev, u)
        dv.add_gp_gradient(l.encoding, &self.kinds, &z.q, Some(e), e + U, |j| {
            &grads[j][..]
        });
        let v = SVector::from(v1);
        if !v.iter().all(|x| x.is_finite()) {
            return Err(StepError::NonFiniteState { step: None }.into());
        }
        // q₁ = q + Δt·v: A's top rows [I, Δt·I], none of B
        let (state, d, b_prev) = dv.into_step(z, v, l.dt);
        Ok(LearnedTreeDerivatives {
            state,
            a: d.a,
            b: d.b,
            b_prev,
        })
    }

    /// The learned rollout of [`LearnedTreeStepper::rollout_into`] (step k
    /// under `inputs[k]` after `inputs[k − 1]`, the first after `u_prev`;
    /// K = `inputs.len()` steps) with the exact derivatives of every state
    /// with respect to z_0 and to every planned input, into caller-owned
    /// buffers. Each step is [`LearnedTreeStepper::step_derivatives`],
    /// chained by [`chain_step`](crate::learned::chain_step), as the
    /// declared mechanisms' learned rollouts are. Buffers of the wrong
    /// length are [`LearnedError::BufferLength`], before any step; a
    /// failing step returns its index with the error. No allocation.
    pub fn rollout_derivatives_into<const U: usize>(
        &self,
        z0: &State<N>,
        u_prev: &SVector<f64, U>,
        inputs: &[SVector<f64, U>],
        out: RolloutDerivativeBuffers<'_, N, U>,
        scratch: &mut TreeDerivativeScratch<N>,
        ws: &mut [BodyScratch; N],
    ) -> Result<(), (usize, LearnedError)> {
        let step = |z: &State<N>, up: &SVector<f64, U>, u: &SVector<f64, U>| {
            let d = self.step_derivatives(z, up, u, scratch, ws)?;
            Ok((d.state, StepDerivatives { a: d.a, b: d.b }, d.b_prev))
        };
        crate::learned::chain_rollout(z0, u_prev, inputs, out, step, buffer_length)
    }

    /// The states after 1, 2, …, `out.len()` steps from `z0`, step k under
    /// `inputs[k]` after `inputs[k − 1]` (the first after `u_prev`), into
    /// a caller-owned slice. `inputs` must be at least as long as `out`. On
    /// failure returns the index of the failing step with the error. No
    /// allocation.
    pub fn rollout_into<const U: usize>(
        &self,
        z0: &State<N>,
        u_prev: &SVector<f64, U>,
        inputs: &[SVector<f64, U>],
        out: &mut [State<N>],
        ws: &mut [BodyScratch; N],
    ) -> Result<(), (usize, LearnedError)> {
        let step =
            |z: &State<N>, up: &SVector<f64, U>, u: &SVector<f64, U>| self.step(z, up, u, ws);
        crate::learned::forced_rollout(z0, u_prev, inputs, out, step)
    }
}
