//! Projection onto the constraint manifold: consistent initial states for
//! mechanisms with loops ([`consistent_state`], [`consistent_state_holding`])
//! and the velocity projection of the
//! constrained learned integrator (paper eq. 8).

use crate::linalg::FullPivLu;
use crate::mechanism::{Mechanism, State};
use crate::newton::{StepError, StepOptions, StepReport};
use nalgebra::{SMatrix, SVector};
use vigp_core::CoordinateKind;
use vigp_core::state::discrete_velocity;

/// Project a configuration onto g(q) = 0 by Gauss–Newton minimum-norm
/// corrections q ← q − Gᵀ(GGᵀ)⁻¹g (the nearest consistent configuration to
/// first order). Returns the iteration count and final |g|.
///
/// Far from the manifold a full correction can overshoot by whole turns (a
/// loop's angles wind around), so each correction is shortened to at most
/// 0.5 rad per angle (0.5 length scales per length) and halved until |g|
/// decreases. On convergence every angle coordinate is moved by whole turns
/// to lie within π of its value in `q`, when the constraints still hold
/// there (they do for revolute joints and link orientations), so the result
/// is the configuration near the guess, not a copy of it several turns
/// away.
pub fn project_configuration<M: Mechanism<N, C>, const N: usize, const C: usize>(
    m: &M,
    q: &SVector<f64, N>,
    options: &StepOptions,
) -> Result<(SVector<f64, N>, StepReport), StepError> {
    options.validate()?;
    if q.iter().any(|x| !x.is_finite()) {
        return Err(StepError::NonFiniteState { step: None });
    }
    let k = m.constants()?;
    let scale = crate::mechanism::length_scale::<M, N, C>(q);
    gauss_newton(
        q,
        scale,
        &[],
        &correction_caps::<M, N, C>(scale, 1.0),
        Some(&M::KINDS),
        options,
        |x| m.constraints_and_jacobian(&k, x),
    )
}

/// The largest correction of one Gauss–Newton iteration: 0.5 rad per
/// angle (or quaternion component), 0.5 length scales per length, divided
/// by `per` (Δt for a velocity whose configuration is q + Δt·v).
fn correction_caps<M: Mechanism<N, C>, const N: usize, const C: usize>(
    scale: f64,
    per: f64,
) -> SVector<f64, N> {
    const MAX_CORRECTION: f64 = 0.5;
    SVector::from_fn(|i, _| match M::KINDS[i] {
        CoordinateKind::Length => MAX_CORRECTION * scale / per,
        CoordinateKind::Angle | CoordinateKind::Quaternion => MAX_CORRECTION / per,
    })
}

/// Gauss–Newton on the free coordinates of r(x) = 0: x ← x − α·Jᵀ(JJᵀ)⁺r
/// with the held columns of J zeroed (complete pivoting drops
/// rank-deficient directions), the correction shortened to `caps` and α
/// halved (down to 2⁻¹⁰) until |r| decreases. Converged when
/// |r|∞/`scale` ≤ the tolerance. With `angles`, the coordinates of kind
/// [`CoordinateKind::Angle`] are then moved by whole turns to within π of
/// `x0`'s, if r still converges there. `residual` returns r(x) and J(x).
fn gauss_newton<const N: usize, const C: usize>(
    x0: &SVector<f64, N>,
    scale: f64,
    hold: &[usize],
    caps: &SVector<f64, N>,
    angles: Option<&[CoordinateKind; N]>,
    options: &StepOptions,
    residual: impl Fn(&SVector<f64, N>) -> (SVector<f64, C>, SMatrix<f64, C, N>),
) -> Result<(SVector<f64, N>, StepReport), StepError> {
    let mut x = *x0;
    let (mut r, mut j) = residual(&x);
    for iter in 0..=options.max_iterations {
        let res = r.amax() / scale;
        if !res.is_finite() {
            return Err(StepError::NonFiniteResidual {
                iteration: iter,
                step: None,
            });
        }
        if res <= options.tolerance {
            if let Some(kinds) = angles {
                let turn = 2.0 * core::f64::consts::PI;
                let mut wound = x;
                for ((w, a), kind) in wound.iter_mut().zip(x0.iter()).zip(kinds) {
                    if *kind == CoordinateKind::Angle {
                        *w -= turn * ((*w - a) / turn).round();
                    }
                }
                if wound != x && residual(&wound).0.amax() / scale <= options.tolerance {
                    x = wound;
                }
            }
            let info = StepReport {
                iterations: iter,
                residual: res,
                ..StepReport::default()
            };
            return Ok((x, info));
        }
        if iter == options.max_iterations {
            return Err(StepError::NotConverged {
                iterations: iter,
                residual: res,
                tolerance: options.tolerance,
                step: None,
            });
        }
        for &i in hold {
            j.set_column(i, &SVector::<f64, C>::zeros());
        }
        let y = FullPivLu::new(j * j.transpose(), 1e-13).solve(&r);
        let mut dx = j.transpose() * y;
        let over = dx
            .iter()
            .zip(caps)
            .fold(0.0f64, |o, (d, c)| o.max(d.abs() / c));
        if over > 1.0 {
            dx /= over;
        }
        let r0 = r.norm();
        let mut alpha = 1.0;
        loop {
            let x_try = x - dx * alpha;
            let (r_try, j_try) = residual(&x_try);
            if r_try.norm() < r0 || alpha <= 1.0 / 1024.0 {
                (x, r, j) = (x_try, r_try, j_try);
                break;
            }
            alpha *= 0.5;
        }
    }
    unreachable!("the loop returns on its last iteration")
}

/// The velocity projection of paper eq. (8):
/// v = argmin ‖v − v_u‖² subject to g(q₁ + Δt·v) = 0, by Newton on the KKT
/// system [I  Δt·Gᵀ; Δt·G  0] with a backtracking line search.
/// Returns the projected velocity and diagnostics; `|v − v_u|` is the size of
/// the correction.
///
/// **Far off the manifold** (a prediction that breaks the paper's Lipschitz
/// assumption, |v_u − v| ≫ 1/Δt), Newton from v_u can stall in a local
/// minimum of its merit function, since q₁ + Δt·v wraps around the loop's
/// configuration space. The remedy used then: restart Newton from the
/// feasible point v = (P(q₁ + Δt·v_u) − q₁)/Δt, with P the
/// [`project_configuration`] map (reported as [`StepReport::restarted`]). If
/// that fails too, the first run's error is returned.
pub fn project_velocity<M: Mechanism<N, C>, const N: usize, const C: usize>(
    m: &M,
    q1: &SVector<f64, N>,
    v_u: &SVector<f64, N>,
    dt: f64,
    options: &StepOptions,
) -> Result<(SVector<f64, N>, StepReport), StepError> {
    vigp_core::step::check_time_step(dt)?;
    options.validate()?;
    if q1.iter().chain(v_u.iter()).any(|x| !x.is_finite()) {
        return Err(StepError::NonFiniteState { step: None });
    }
    if C == 0 {
        return Ok((*v_u, StepReport::default()));
    }
    let k = m.constants()?;
    // Newton on the projection's KKT system from the initial guess `start`
    let newton =
        |start| vigp_core::projection::project_velocity_from(m, &k, q1, v_u, start, dt, options);
    let first = match newton(v_u) {
        Err(e @ (StepError::NotConverged { .. } | StepError::SingularJacobian { .. })) => e,
        done => return done,
    };
    let Ok((q2, _)) = project_configuration(m, &(q1 + v_u * dt), options) else {
        return Err(first);
    };
    let start = discrete_velocity(q1, &q2, dt);
    match newton(&start) {
        Ok((v, report)) => Ok((
            v,
            StepReport {
                restarted: true,
                ..report
            },
        )),
        Err(_) => Err(first),
    }
}

/// A consistent initial state from guesses: the configuration projected onto
/// g(q) = 0, then the discrete velocity projected so that g(q + Δt·v) = 0
/// (a velocity with only G(q)·v = 0 would leave the first step off the
/// manifold by O(Δt²)).
pub fn consistent_state<M: Mechanism<N, C>, const N: usize, const C: usize>(
    m: &M,
    q: &SVector<f64, N>,
    v: &SVector<f64, N>,
    dt: f64,
) -> Result<State<N>, StepError> {
    let options = StepOptions::default();
    let (q, _) = project_configuration(m, q, &options)?;
    let (v, _) = project_velocity(m, &q, v, dt, &options)?;
    Ok(State { q, v })
}

/// [`consistent_state`] holding the coordinates listed in `hold` at their
/// given values (positions and discrete velocities), e.g. a crank angle set
/// by the user while the rest of a linkage is solved: the configuration is
/// projected onto g(q) = 0 and the velocity onto g(q + Δt·v) = 0 by
/// Gauss–Newton minimum-norm corrections of the free coordinates only
/// (shortened far from the manifold, and the angles kept within π of the
/// guess, as in [`project_configuration`]).
///
/// Errors: an index in `hold` out of range ([`StepError::InvalidOptions`]);
/// [`StepError::NotConverged`] when the loop cannot close with the held
/// values (e.g. a crank angle the linkage cannot reach).
///
/// Example: a fourbar with its first top angle held at 0.7 rad while the
/// other three are solved (`tests/step/workflow.rs`):
/// `consistent_state_holding(&fourbar, &q_guess, &v_guess, dt, &[0])`.
pub fn consistent_state_holding<M: Mechanism<N, C>, const N: usize, const C: usize>(
    m: &M,
    q: &SVector<f64, N>,
    v: &SVector<f64, N>,
    dt: f64,
    hold: &[usize],
) -> Result<State<N>, StepError> {
    vigp_core::step::check_time_step(dt)?;
    if hold.iter().any(|&i| i >= N) {
        return Err(StepError::InvalidOptions(
            "consistent_state_holding: a held coordinate index is out of range",
        ));
    }
    if q.iter().chain(v.iter()).any(|x| !x.is_finite()) {
        return Err(StepError::NonFiniteState { step: None });
    }
    if C == 0 {
        return Ok(State { q: *q, v: *v });
    }
    if (0..N).all(|i| hold.contains(&i)) {
        return Err(StepError::InvalidOptions(
            "consistent_state_holding: every coordinate is held, none is free to close the loops",
        ));
    }
    let options = StepOptions::default();
    let scale = crate::mechanism::length_scale::<M, N, C>(q);
    let (q, _) = gauss_newton(
        q,
        scale,
        hold,
        &correction_caps::<M, N, C>(scale, 1.0),
        Some(&M::KINDS),
        &options,
        |x| (m.constraints(x), m.constraint_jacobian(x)),
    )?;
    let (v, _) = gauss_newton(
        v,
        scale,
        hold,
        &correction_caps::<M, N, C>(scale, dt),
        None,
        &options,
        |w| {
            let x2 = q + w * dt;
            (m.constraints(&x2), m.constraint_jacobian(&x2) * dt)
        },
    )?;
    Ok(State { q, v })
}
