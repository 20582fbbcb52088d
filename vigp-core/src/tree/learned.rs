//! A learned robot on fixed-size data: the tree's bodies, the prior, the
//! encoding and one exported GP per joint ([`LearnedTree`], normally a
//! `static` written by `vigp export` from a model of `vigp fit --urdf`),
//! stepped without allocation by [`LearnedTreeStepper`].
//!
//! The step is the std runtime's learned robot step (its mean):
//! q₁ = q + Δt·v and v₁ = v̄(z, u) + μ(enc(z), u_prev, u), where v̄ is
//! the tree engine's step from the momentum of z under the inputs held
//! over the step (zero under [`Prior::Constant`]) and μ the GP means.

use super::spatial::V3;
use super::{Body, BodyScratch, Engine, EngineError, EngineOptions, JointKind, TreeRef};
use crate::gp::ExportedGp;
use crate::learned::{Encoding, LearnedError, Prior};
use crate::state::{CoordinateKind, State};
use crate::step::StepError;
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
        if !(learned.dt.is_finite() && learned.dt > 0.0 && (learned.dt * learned.dt).is_normal()) {
            return Err(LearnedError::Engine(EngineError::InvalidTimeStep {
                dt: learned.dt,
            }));
        }
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
        let l = self.learned;
        let mut v1 = [0.0; N];
        if l.prior == Prior::Nominal {
            let mut q: [f64; N] = z.q.into();
            v1 = z.v.into();
            let mut p = [0.0; N];
            let mut tau = [0.0; N];
            for (k, &j) in self.actuated[..U].iter().enumerate() {
                tau[j] = u[k];
            }
            self.engine
                .momentum_of(&q, &v1, &mut p, ws)
                .map_err(LearnedError::Engine)?;
            self.engine
                .step(&mut q, &mut v1, &mut p, &tau, l.dt, ws)
                .map_err(LearnedError::Engine)?;
        }
        let mut x = [0.0; D];
        let e = self.encoded;
        l.encoding.encode(&self.kinds, z, &mut x[..e]);
        x[e..e + U].copy_from_slice(u_prev.as_slice());
        x[e + U..e + 2 * U].copy_from_slice(u.as_slice());
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
        if inputs.len() < out.len() {
            return Err((
                inputs.len(),
                StepError::NonFiniteInput { step: None }.into(),
            ));
        }
        let mut z = *z0;
        for (k, (slot, u)) in out.iter_mut().zip(inputs).enumerate() {
            let up = if k == 0 { u_prev } else { &inputs[k - 1] };
            z = self.step(&z, up, u, ws).map_err(|e| (k, e))?;
            *slot = z;
        }
        Ok(())
    }
}
