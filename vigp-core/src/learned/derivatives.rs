//! The exact derivatives of a learned step, shared by the std runtime's
//! `Learned::step_derivatives_forced` and the embedded
//! [`LearnedStepper::step_derivatives`](super::LearnedStepper::step_derivatives).
//!
//! A learned step is x₁ = x₀ + Δt·v₀ and v₁ = P(x₁, v_u) with
//! v_u = v̄(z₀, u) + μ(enc(z₀), u_prev, u): the nominal step's velocity
//! (or 0), the GP means, and for loops the projection P onto the
//! constraints. [`VelocityDerivatives`] holds ∂v/∂(q₀, v₀, u, u_prev) as
//! it is built up term by term: the prior's rows of A and B, then the GP
//! means' gradient through the encoding
//! ([`VelocityDerivatives::add_gp_gradient`]), then the projection,
//! differentiated through its KKT conditions
//! ([`VelocityDerivatives::project`]).

use super::{Encoding, LearnedError};
use crate::dynamics::Dynamics;
use crate::error::StepError;
use crate::forced::{InputJacobian, RolloutDerivativeBuffers, StateJacobian, StepDerivatives};
use crate::linalg::{solve_kkt, solve_partial};
use crate::state::{CoordinateKind, State};
use nalgebra::{SMatrix, SVector};

/// ∂v/∂q₀, ∂v/∂v₀, ∂v/∂u and ∂v/∂u_prev of a learned step's velocity
/// (module docs), N × N and N × U blocks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VelocityDerivatives<const N: usize, const U: usize> {
    /// ∂v/∂q₀.
    pub q: SMatrix<f64, N, N>,
    /// ∂v/∂v₀.
    pub v: SMatrix<f64, N, N>,
    /// ∂v/∂u.
    pub u: SMatrix<f64, N, U>,
    /// ∂v/∂u_prev.
    pub u_prev: SMatrix<f64, N, U>,
}

impl<const N: usize, const U: usize> VelocityDerivatives<N, U> {
    /// All blocks zero (a constant prior).
    pub fn zeros() -> Self {
        Self {
            q: SMatrix::zeros(),
            v: SMatrix::zeros(),
            u: SMatrix::zeros(),
            u_prev: SMatrix::zeros(),
        }
    }

    /// The velocity rows of a nominal step's derivatives (the prior
    /// v̄(z₀, u); it does not read u_prev).
    pub fn of_step(d: &StepDerivatives<N, U>) -> Self {
        Self {
            q: d.a.v_q,
            v: d.a.v_v,
            u: d.b.v_u,
            u_prev: SMatrix::zeros(),
        }
    }

    /// Adds the GP means' gradient: `gradient(j)` is the gradient of
    /// output j's mean in the GP input (enc(z₀), then u_prev at `at_prev`
    /// when the model takes it, then u at `at_u`), pulled back through
    /// `encoding` at the coordinates `q` of kinds `kinds`. Input columns
    /// past the GP input's end (U = 0 for a model with inputs) are skipped.
    #[allow(clippy::too_many_arguments)]
    pub fn add_gp_gradient<'g>(
        &mut self,
        encoding: Encoding,
        kinds: &[CoordinateKind; N],
        q: &SVector<f64, N>,
        at_prev: Option<usize>,
        at_u: usize,
        mut gradient: impl FnMut(usize) -> &'g [f64],
    ) {
        for j in 0..N {
            let g = gradient(j);
            encoding.pull_back(kinds, q.as_slice(), g, |i, x| {
                if i < N {
                    self.q[(j, i)] += x;
                } else {
                    self.v[(j, i - N)] += x;
                }
            });
            for i in 0..U {
                self.u[(j, i)] += g[at_u + i];
                if let Some(p) = at_prev {
                    self.u_prev[(j, i)] += g[p + i];
                }
            }
        }
    }

    /// Maps the derivatives of the unprojected velocity `v_u` to those of
    /// its projection `v_p` = argmin ½‖v − v_u‖² subject to
    /// g(x₁ + h·v) = 0, x₁ = q₀ + h·v₀. The KKT conditions
    /// F = [v − v_u + h·G(y)ᵀλ; g(y)] = 0, y = x₁ + h·v, differentiate
    /// (implicit function theorem) into
    ///
    /// ```text
    /// [I + h²H, h·Gᵀ; h·G, 0] [dv; dλ] = [dv_u − h·H·dx₁; −G·dx₁]
    /// ```
    ///
    /// with H = Σλ_i∇²g_i(y) and λ from the first row, h·Gᵀλ = v_u − v_p
    /// (least squares), for every direction of (q₀, v₀, u, u_prev).
    /// [`StepError::SingularJacobian`] when G(y) or the KKT matrix is
    /// singular.
    #[allow(clippy::too_many_arguments)]
    pub fn project<M: Dynamics<N, C>, const C: usize>(
        &mut self,
        model: &M,
        k: &M::Constants,
        x1: &SVector<f64, N>,
        v_u: &SVector<f64, N>,
        v_p: &SVector<f64, N>,
        h: f64,
    ) -> Result<(), StepError> {
        let singular = StepError::singular(0);
        let eye = SMatrix::<f64, N, N>::identity();
        let y = x1 + v_p * h;
        let (_, g) = model.constraints_and_jacobian(k, &y);
        let gg = g * g.transpose();
        let lambda = solve_partial(&gg, &(g * (v_u - v_p) / h)).ok_or(singular)?;
        let hess = model.constraint_hessian(k, &y, &lambda);
        let jm = eye + hess * (h * h);
        let bm = g.transpose() * h;
        let am = g * h;
        let solve = |dvu: SVector<f64, N>, dx1: SVector<f64, N>| {
            let r = dvu - hess * dx1 * h;
            let c = -(g * dx1);
            solve_kkt(&jm, &bm, &am, &r, &c)
                .map(|(dv, _)| dv)
                .ok_or(singular)
        };
        let mut out = *self;
        for i in 0..N {
            let e = eye.column(i).into_owned();
            out.q
                .set_column(i, &solve(self.q.column(i).into_owned(), e)?);
            out.v
                .set_column(i, &solve(self.v.column(i).into_owned(), e * h)?);
        }
        for i in 0..U {
            out.u
                .set_column(i, &solve(self.u.column(i).into_owned(), SVector::zeros())?);
            out.u_prev.set_column(
                i,
                &solve(self.u_prev.column(i).into_owned(), SVector::zeros())?,
            );
        }
        *self = out;
        Ok(())
    }

    /// The step z₁ = (q₀ + h·v₀, `v1`) with A, B and B_prev: the position
    /// rows are those of x₁ = q₀ + h·v₀, the velocity rows these blocks.
    pub fn into_step(
        self,
        z: &State<N>,
        v1: SVector<f64, N>,
        h: f64,
    ) -> (State<N>, StepDerivatives<N, U>, InputJacobian<N, U>) {
        let eye = SMatrix::<f64, N, N>::identity();
        (
            State {
                q: z.q + z.v * h,
                v: v1,
            },
            StepDerivatives {
                a: StateJacobian {
                    q_q: eye,
                    q_v: eye * h,
                    v_q: self.q,
                    v_v: self.v,
                },
                b: InputJacobian {
                    q_u: SMatrix::zeros(),
                    v_u: self.u,
                },
            },
            InputJacobian {
                q_u: SMatrix::zeros(),
                v_u: self.u_prev,
            },
        )
    }
}

/// One step of a rollout's chain rule, for steps that read the previous
/// input too (z_{k+1} = Φ(z_k, u_{k−1}, u_k), a learned step): from step
/// k's derivatives `d` (A_k, B_k) and `b_prev` (B_prev,k), the row
/// `row_k[j]` = ∂z_k/∂u_j and `initial_k` = ∂z_k/∂z_0, writes
/// `row_next[j]` = ∂z_{k+1}/∂u_j = A_k ∂z_k/∂u_j + [j = k] B_k +
/// [j = k − 1] B_prev,k for j ≤ k (later inputs do not reach z_{k+1}; their
/// entries are left as they are) and returns ∂z_{k+1}/∂z_0 = A_k ∂z_k/∂z_0.
/// `row_k` and `row_next` must hold at least k + 1 entries (fewer: only
/// those present are written).
pub fn chain_step<const N: usize, const U: usize>(
    d: &StepDerivatives<N, U>,
    b_prev: &InputJacobian<N, U>,
    k: usize,
    initial_k: &StateJacobian<N>,
    row_k: &[InputJacobian<N, U>],
    row_next: &mut [InputJacobian<N, U>],
) -> StateJacobian<N> {
    for (j, (next, now)) in row_next.iter_mut().zip(row_k).take(k + 1).enumerate() {
        *next = d.a.times_input(now);
        if j == k {
            next.q_u += d.b.q_u;
            next.v_u += d.b.v_u;
        } else if j + 1 == k {
            next.q_u += b_prev.q_u;
            next.v_u += b_prev.v_u;
        }
    }
    d.a.after(initial_k)
}

/// The derivatives of a K-step rollout of a step that reads the previous
/// input (K = `inputs.len()`), into `out`: step k is `step(z_k, u_{k−1},
/// u_k)` (`u_prev` before the first), returning z_{k+1}, A_k, B_k and
/// B_prev,k, chained by [`chain_step`]. What the learned rollouts'
/// derivatives run, std and embedded. Buffers of the wrong length are
/// `wrong(name, expected, got)` at step 0; a failing step returns its
/// index with the error.
#[allow(clippy::type_complexity)]
pub fn chain_rollout<const N: usize, const U: usize, E>(
    z0: &State<N>,
    u_prev: &SVector<f64, U>,
    inputs: &[SVector<f64, U>],
    out: RolloutDerivativeBuffers<'_, N, U>,
    mut step: impl FnMut(
        &State<N>,
        &SVector<f64, U>,
        &SVector<f64, U>,
    ) -> Result<(State<N>, StepDerivatives<N, U>, InputJacobian<N, U>), E>,
    wrong: impl FnOnce(&'static str, usize, usize) -> E,
) -> Result<(), (usize, E)> {
    let k_steps = inputs.len();
    let mut out = out;
    out.prepare(k_steps)
        .map_err(|(name, expected, got)| (0, wrong(name, expected, got)))?;
    let RolloutDerivativeBuffers {
        states,
        initial,
        inputs: wrt_u,
    } = out;
    let mut z = *z0;
    let mut start = StateJacobian::identity();
    // ∂z_0/∂u_j = 0: the row before the first step
    let zero_row = [InputJacobian::<N, U>::zeros(); 1];
    for (k, u) in inputs.iter().enumerate() {
        let up = if k == 0 { u_prev } else { &inputs[k - 1] };
        let (z1, d, d_prev) = step(&z, up, u).map_err(|e| (k, e))?;
        let (done, rest) = wrt_u.split_at_mut(k * k_steps);
        let row_k = if k == 0 {
            &zero_row[..]
        } else {
            &done[(k - 1) * k_steps..]
        };
        start = chain_step(&d, &d_prev, k, &start, row_k, &mut rest[..k_steps]);
        initial[k] = start;
        states[k] = z1;
        z = z1;
    }
    Ok(())
}

/// [`LearnedError::BufferLength`] for [`chain_rollout`].
pub(crate) fn buffer_length(name: &'static str, expected: usize, got: usize) -> LearnedError {
    LearnedError::BufferLength {
        name,
        expected,
        got,
    }
}
