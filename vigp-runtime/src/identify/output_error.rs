//! The second stage: refinement by output error.
//!
//! The regression of the first stage fits the DEL residual of logged
//! triples. Its rows hold second differences of the noisy positions, so
//! position noise enters the regressor itself (errors in variables); the
//! instrumental variables remove the bias, but the estimate stays noisy
//! where the noise is large. Output error instead compares *simulated*
//! positions with the logged ones: the noise then enters only the
//! comparison, and minimising the squared simulation error is the maximum
//! likelihood under independent Gaussian position noise.
//!
//! # The problem
//!
//! Every log is cut into segments of [`OutputError::segment`] samples
//! (multiple shooting: each segment starts afresh, so errors do not grow
//! over the whole log, and a segment of a chaotic or unstable mechanism
//! stays in the regime where a local fit is meaningful). Segment s has its
//! own initial positions θ_s = (x_0, x_1) ∈ ℝ²ᴺ, unknowns estimated with π
//! (starting a segment from the noisy logged samples would bias the fit);
//! continuity between segments is not imposed. A segment simulates
//! x_2, …, x_{L−1} by solving the regressor's own residual
//! r(x_{j−1}, x_j, x_{j+1}; π) = 0 for x_{j+1}, with the logged inputs
//! (so the simulation is exactly the rule the first stage regressed). The
//! estimate is the maximum a posteriori
//!
//! ```text
//! (π̂, θ̂) = argmin  Σ_s Σ_j |x_j(π, θ_s) − x̃_j|² / σ²  +  |S⁻¹(π − π₀)|²
//! ```
//!
//! with the prior of the first stage (centre π₀, scales S), and σ the
//! position noise (from the residuals of the start, re-estimated at the
//! solution; the problem is solved again if it moved by more than 20 %).
//!
//! # Exact sensitivities
//!
//! The residual is affine in π with ∂r/∂π = Y (the regressor rows) and
//! has exact Jacobians J₀, J₁, J₂ in x_{j−1}, x_j, x_{j+1}
//! ([`Regressor::position_jacobians`]). By the implicit function theorem,
//! the sensitivities D_j = ∂x_j/∂(π, θ_s) follow the recursion
//!
//! ```text
//! J₂ D_{j+1} = −(Y [I 0] + J₀ D_{j−1} + J₁ D_j),   D_0 = [0 I 0], D_1 = [0 0 I]
//! ```
//!
//! one LU of J₂ (already the Newton matrix of the step) per sample.
//!
//! # The solver
//!
//! Levenberg–Marquardt on the Gauss–Newton normal equations, with the
//! segments' initial states eliminated block by block (a Schur complement:
//! cost linear in the number of segments), Marquardt's diagonal scaling,
//! and a step that would leave the physically consistent parameters
//! projected onto them in the metric of the damped Gauss–Newton model
//! ([`super::consistency::project`]; the set is convex and the iterate
//! strictly inside it), so that the iteration can slide along the set's
//! boundary (a joint without friction, a thin link) instead of stopping
//! there. The objective is not convex: when the first stage's estimate
//! was projected onto the consistent set (an estimate far off, e.g. least
//! squares on noisy positions), the iteration starting on the boundary
//! can stall in a poorer minimum, so it runs from the declared values (the
//! prior's centre) as well and the lower objective wins. The covariance
//! of π
//! is the inverse of the reduced Gauss–Newton matrix at the solution (the
//! Laplace approximation of the posterior); the base parameters' intervals
//! follow as in the first stage.
//!
//! # Scope
//!
//! **Loops** are simulated with their multipliers: a step solves
//! r(x_{j−1}, x_j, x_{j+1}; π) = G(x_j)ᵀλ and g(x_{j+1}) = 0 for
//! (x_{j+1}, λ), r the residual before the first stage's projection onto
//! G's null space ([`Regressor::loop_constraints`]), and the sensitivities
//! come from the same KKT matrix,
//!
//! ```text
//! [ J₂         −G(x_j)ᵀ ] [ D_{j+1} ]     [ Y [I 0] + J₀ D_{j−1} + (J₁ − Σλ_i∇²g_i(x_j)) D_j ]
//! [ G(x_{j+1})  0       ] [ D_λ     ] = − [ 0                                                ]
//! ```
//!
//! (Y the unprojected rows). The multipliers are eliminated, not
//! estimated; a segment's two initial positions are free, so the fit
//! moves them onto the loop only as far as the data do. Unforced logs: the unforced
//! DEL residual is homogeneous in π, so the simulation does not change
//! when π is scaled; the data then fix every ratio and the prior the
//! overall scale. Output error is free of the regression's pull of the
//! scale towards zero, so use it on such logs.

use super::regressor::{Regressor, Transition};
use super::{Identification, IdentifyError, Log, check_length, consistency, covariance};
use nalgebra::{DMatrix, DVector};

/// Options of the output-error refinement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutputError {
    /// Samples per segment (at least 3; default 50). Longer segments
    /// inform the parameters more but grow the region where the
    /// simulation must stay close to the log.
    pub segment: usize,
    /// Largest number of Levenberg–Marquardt iterations (default 50).
    pub max_iterations: usize,
    /// Stop when an accepted step lowers the objective by less than this
    /// fraction of it (default 1e-10).
    pub tolerance: f64,
}

impl Default for OutputError {
    fn default() -> Self {
        OutputError {
            segment: 50,
            max_iterations: 50,
            tolerance: 1e-10,
        }
    }
}

/// What the refinement did.
#[derive(Clone, Debug, PartialEq)]
pub struct Refinement {
    /// Segments simulated.
    pub segments: usize,
    /// Logged samples compared (all segments).
    pub samples: usize,
    /// Levenberg–Marquardt iterations (all passes).
    pub iterations: usize,
    /// Root-mean-square simulation error at the start: the first stage's
    /// estimate, each segment started from its logged samples.
    pub rms_start: f64,
    /// Root-mean-square simulation error at the solution.
    pub rms: f64,
    /// Position noise σ estimated at the solution (the residuals' sum of
    /// squares over their degrees of freedom).
    pub position_sigma: f64,
    /// Whether the relative decrease fell below the tolerance before the
    /// iteration limit.
    pub converged: bool,
    /// Whether the logs were homogeneous in π (no input acts), so that
    /// the refinement started from the declared values, not from the
    /// regression's estimate ([`super::Options::output_error`]).
    pub homogeneous: bool,
}

/// One segment of one log: samples `start .. start + len` of log `log`.
#[derive(Clone, Copy, Debug)]
struct Segment {
    log: usize,
    start: usize,
    len: usize,
}

/// A simulated segment of a log ([`simulate`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Simulation {
    /// The simulated positions x_0, …, x_{L−1} (x_0, x_1 the initial ones).
    pub positions: Vec<Vec<f64>>,
    /// The errors x_j − x̃_j against the log, stacked (L·N).
    pub error: DVector<f64>,
    /// ∂x/∂π, stacked as `error` (L·N × P); empty unless requested.
    pub wrt_pi: DMatrix<f64>,
    /// ∂x/∂(x_0, x_1) (L·N × 2N); empty unless requested.
    pub wrt_start: DMatrix<f64>,
}

/// Simulate samples `start .. start + len` of `log` (len ≥ 3) with
/// parameters π from the initial positions `initial` = (x_0, x_1) (2N
/// entries) under the log's inputs, by solving the regressor's residual
/// for every next sample; with `derivatives`, also the exact sensitivities
/// to π and to the initial positions (module docs).
pub fn simulate<R: Regressor>(
    regressor: &R,
    log: &Log,
    start: usize,
    len: usize,
    pi: &[f64],
    initial: &[f64],
    derivatives: bool,
) -> Result<Simulation, IdentifyError> {
    let n = regressor.coordinates();
    if len < 3 || start + len > log.positions.len() {
        return Err(IdentifyError::Options {
            message: format!(
                "samples {start}..{} of a log of {}: at least 3, inside the log",
                start + len,
                log.positions.len()
            ),
        });
    }
    for (what, v, expected) in [
        ("initial positions", initial.len(), 2 * n),
        ("parameters", pi.len(), regressor.structure().len()),
    ] {
        check_length(what, expected, v)?;
    }
    log.check_input_count()?;
    let seg = Segment { log: 0, start, len };
    simulate_segment(
        regressor,
        log,
        seg,
        pi,
        &DVector::from_column_slice(initial),
        derivatives,
    )
    .map_err(|e| match e {
        SimFailure::Error(e) => e,
        SimFailure::Diverged => IdentifyError::Simulation {
            message: format!("the step after sample {start} did not converge"),
        },
    })
}

/// Why a simulation stopped (the solver then shortens its step).
#[derive(Debug)]
enum SimFailure {
    /// Newton did not converge, or a value went non-finite.
    Diverged,
    /// A typed error from the regressor (dimensions, loops).
    Error(IdentifyError),
}

impl From<IdentifyError> for SimFailure {
    fn from(e: IdentifyError) -> Self {
        match e {
            IdentifyError::NonFinite { .. } | IdentifyError::NoDslForm { .. } => {
                SimFailure::Diverged
            }
            e => SimFailure::Error(e),
        }
    }
}

fn segments(logs: &[Log], len: usize) -> Vec<Segment> {
    let mut out = Vec::new();
    for (li, log) in logs.iter().enumerate() {
        let k = log.positions.len();
        let mut start = 0;
        while start + 3 <= k {
            // a remainder shorter than half a segment joins the last one
            let rest = k - start;
            let take = if rest < len + len / 2 { rest } else { len };
            out.push(Segment {
                log: li,
                start,
                len: take,
            });
            start += take;
        }
    }
    out
}

/// Simulate a segment from θ = (x_0, x_1) with parameters π.
fn simulate_segment<R: Regressor>(
    regressor: &R,
    log: &Log,
    seg: Segment,
    pi: &[f64],
    start: &DVector<f64>,
    derivatives: bool,
) -> Result<Simulation, SimFailure> {
    let n = regressor.coordinates();
    let p = pi.len();
    let zeros = vec![0.0; regressor.inputs()];
    let input = |k: usize| -> &[f64] {
        if log.inputs.is_empty() {
            &zeros
        } else {
            &log.inputs[k]
        }
    };
    let mut xs: Vec<Vec<f64>> = vec![
        start.rows(0, n).iter().cloned().collect(),
        start.rows(n, n).iter().cloned().collect(),
    ];
    let cols = p + 2 * n;
    let mut d: Vec<DMatrix<f64>> = Vec::new();
    if derivatives {
        let mut d0 = DMatrix::zeros(n, cols);
        let mut d1 = DMatrix::zeros(n, cols);
        for i in 0..n {
            d0[(i, p + i)] = 1.0;
            d1[(i, p + n + i)] = 1.0;
        }
        d.push(d0);
        d.push(d1);
    }
    // loops: the multipliers of the step, carried as the next step's guess
    let c = n - regressor.rows();
    let mut lambda = DVector::<f64>::zeros(c);
    for j in 1..seg.len - 1 {
        let k = seg.start + j;
        let inputs = [input(k - 1), input(k)];
        // Newton on x_{j+1} from the linear extrapolation
        let mut next: Vec<f64> = (0..n).map(|i| 2.0 * xs[j][i] - xs[j - 1][i]).collect();
        if c > 0 {
            let dn = loop_step(
                regressor,
                [&xs[j - 1], &xs[j]],
                &mut next,
                &mut lambda,
                inputs,
                pi,
                &d,
                p,
                derivatives,
            )?;
            if let Some(dn) = dn {
                d.push(dn);
            }
            xs.push(next);
            continue;
        }
        let mut converged = false;
        for _ in 0..30 {
            let t = Transition {
                positions: [&xs[j - 1], &xs[j], &next],
                inputs,
            };
            let (r, js) = regressor.position_jacobians(&t, pi)?;
            let dx = js[2].clone().lu().solve(&r).ok_or(SimFailure::Diverged)?;
            let scale = 1.0 + next.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
            for (x, e) in next.iter_mut().zip(dx.iter()) {
                *x -= e;
            }
            if !next.iter().all(|v| v.is_finite()) {
                return Err(SimFailure::Diverged);
            }
            if dx.amax() <= 1e-13 * scale {
                converged = true;
                break;
            }
        }
        if !converged {
            return Err(SimFailure::Diverged);
        }
        if derivatives {
            // the Jacobians at the converged x_{j+1} (the last Newton
            // update was below rounding)
            let t = Transition {
                positions: [&xs[j - 1], &xs[j], &next],
                inputs,
            };
            let js = regressor.position_jacobians(&t, pi)?.1;
            let (y, _) = regressor.transition(&t)?;
            let mut rhs = &js[0] * &d[j - 1] + &js[1] * &d[j];
            let mut left = rhs.columns_mut(0, p);
            left += &y;
            rhs.neg_mut();
            let dn = js[2].clone().lu().solve(&rhs).ok_or(SimFailure::Diverged)?;
            d.push(dn);
        }
        xs.push(next);
    }
    let rows = seg.len * n;
    let mut error = DVector::zeros(rows);
    for (j, x) in xs.iter().enumerate() {
        let logged = &log.positions[seg.start + j];
        for i in 0..n {
            error[j * n + i] = x[i] - logged[i];
        }
    }
    let (mut wrt_pi, mut wrt_start) = (DMatrix::zeros(0, 0), DMatrix::zeros(0, 0));
    if derivatives {
        wrt_pi = DMatrix::zeros(rows, p);
        wrt_start = DMatrix::zeros(rows, 2 * n);
        for (j, dj) in d.iter().enumerate() {
            wrt_pi.rows_mut(j * n, n).copy_from(&dj.columns(0, p));
            wrt_start
                .rows_mut(j * n, n)
                .copy_from(&dj.columns(p, 2 * n));
        }
    }
    Ok(Simulation {
        positions: xs,
        error,
        wrt_pi,
        wrt_start,
    })
}

/// One step of a simulation with loops: x_{j+1} and the multipliers λ
/// solve r(x_{j−1}, x_j, x_{j+1}) = G(x_j)ᵀλ and g(x_{j+1}) = 0 by Newton
/// from `next` and `lambda` (updated in place); with `derivatives`, the
/// sensitivity D_{j+1} by the implicit function theorem on the same KKT
/// matrix:
///
/// ```text
/// [ J₂         −G(x_j)ᵀ ] [ D_{j+1} ]     [ Y [I 0] + J₀ D_{j−1} + (J₁ − Σλ_i∇²g_i(x_j)) D_j ]
/// [ G(x_{j+1})  0       ] [ D_λ     ] = − [ 0                                                ]
/// ```
#[allow(clippy::too_many_arguments)]
fn loop_step<R: Regressor>(
    regressor: &R,
    before: [&[f64]; 2],
    next: &mut [f64],
    lambda: &mut DVector<f64>,
    inputs: [&[f64]; 2],
    pi: &[f64],
    d: &[DMatrix<f64>],
    p: usize,
    derivatives: bool,
) -> Result<Option<DMatrix<f64>>, SimFailure> {
    let n = next.len();
    let c = lambda.len();
    let constraints = |x: &[f64]| -> Result<(DVector<f64>, DMatrix<f64>), SimFailure> {
        regressor.loop_constraints(x)?.ok_or_else(|| {
            SimFailure::Error(IdentifyError::Layout {
                message: "the regressor has fewer rows than coordinates but no loop constraints"
                    .into(),
            })
        })
    };
    let (_, gk) = constraints(before[1])?;
    let kkt = |j2: &DMatrix<f64>, g1: &DMatrix<f64>| {
        let mut a = DMatrix::zeros(n + c, n + c);
        a.view_mut((0, 0), (n, n)).copy_from(j2);
        a.view_mut((0, n), (n, c)).copy_from(&(-gk.transpose()));
        a.view_mut((n, 0), (c, n)).copy_from(g1);
        a
    };
    let mut converged = false;
    let mut last = f64::INFINITY;
    for _ in 0..30 {
        let t = Transition {
            positions: [before[0], before[1], next],
            inputs,
        };
        let (r, js) = regressor.position_jacobians(&t, pi)?;
        let (g1, gj1) = constraints(next)?;
        let mut f = DVector::zeros(n + c);
        f.rows_mut(0, n).copy_from(&(r - gk.transpose() * &*lambda));
        f.rows_mut(n, c).copy_from(&g1);
        let step = kkt(&js[2], &gj1)
            .lu()
            .solve(&f)
            .ok_or(SimFailure::Diverged)?;
        let scale = 1.0 + next.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
        for (x, e) in next.iter_mut().zip(step.rows(0, n).iter()) {
            *x -= e;
        }
        *lambda -= step.rows(n, c);
        if !(next.iter().all(|v| v.is_finite()) && lambda.iter().all(|v| v.is_finite())) {
            return Err(SimFailure::Diverged);
        }
        // converged; or at the rounding floor of an ill-conditioned KKT
        // matrix (near a loop's singular configuration), where the updates
        // stop shrinking at a size far below any motion
        let size = step.rows(0, n).amax();
        if size <= 1e-13 * scale || (size <= 1e-10 * scale && size >= 0.5 * last) {
            converged = true;
            break;
        }
        last = size;
    }
    if !converged {
        return Err(SimFailure::Diverged);
    }
    if !derivatives {
        return Ok(None);
    }
    let j = d.len() - 1;
    let t = Transition {
        positions: [before[0], before[1], next],
        inputs,
    };
    let js = regressor.position_jacobians(&t, pi)?.1;
    let (y, _) = regressor.unprojected_transition(&t)?;
    let (_, gj1) = constraints(next)?;
    let curvature = regressor.loop_curvature(before[1], lambda.as_slice())?;
    let cols = d[j].ncols();
    let mut top = &js[0] * &d[j - 1] + (&js[1] - curvature) * &d[j];
    let mut left = top.columns_mut(0, p);
    left += &y;
    let mut rhs = DMatrix::zeros(n + c, cols);
    rhs.rows_mut(0, n).copy_from(&top);
    rhs.neg_mut();
    let sol = kkt(&js[2], &gj1)
        .lu()
        .solve(&rhs)
        .ok_or(SimFailure::Diverged)?;
    Ok(Some(sol.rows(0, n).into_owned()))
}

/// The configuration `x` moved onto the loop constraints g = 0 by
/// Gauss–Newton minimum-norm corrections x ← x − Gᵀ(GGᵀ)⁻¹g (a logged
/// sample is off them by its noise); `x` itself without loops, or where
/// the correction does not converge in 20 iterations.
fn onto_loops<R: Regressor>(regressor: &R, x: &[f64]) -> Result<Vec<f64>, IdentifyError> {
    let mut q = x.to_vec();
    for _ in 0..20 {
        let Some((g, gj)) = regressor.loop_constraints(&q)? else {
            return Ok(q);
        };
        let scale = 1.0 + q.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
        if g.amax() <= 1e-13 * scale {
            return Ok(q);
        }
        let Some(y) = (&gj * gj.transpose()).lu().solve(&g) else {
            break;
        };
        let dq = gj.transpose() * y;
        for (qi, d) in q.iter_mut().zip(dq.iter()) {
            *qi -= d;
        }
        if !q.iter().all(|v| v.is_finite()) {
            break;
        }
    }
    Ok(x.to_vec())
}

/// The state of the optimisation: π and every segment's initial positions.
#[derive(Clone)]
struct Point {
    pi: DVector<f64>,
    starts: Vec<DVector<f64>>,
}

/// The sum of squared simulation errors at a point, or `None` where a
/// segment's simulation fails.
fn sum_squares<R: Regressor>(
    regressor: &R,
    logs: &[Log],
    segs: &[Segment],
    at: &Point,
) -> Result<Option<f64>, IdentifyError> {
    let mut sum = 0.0;
    for (seg, start) in segs.iter().zip(&at.starts) {
        match simulate_segment(
            regressor,
            &logs[seg.log],
            *seg,
            at.pi.as_slice(),
            start,
            false,
        ) {
            Ok(s) => sum += s.error.norm_squared(),
            Err(SimFailure::Diverged) => return Ok(None),
            Err(SimFailure::Error(e)) => return Err(e),
        }
    }
    Ok(Some(sum))
}

/// The Gauss–Newton system at a point, with the initial states
/// eliminated: returns the reduced matrix and gradient in π, and per
/// segment what back-substitution needs.
struct Normal {
    /// Σ_s A_sᵀA_s/σ² (P × P), before the prior.
    h_pp: DMatrix<f64>,
    /// Σ_s A_sᵀe_s/σ².
    g_p: DVector<f64>,
    /// Per segment: H_ss = B_sᵀB_s/σ², H_sp = B_sᵀA_s/σ², g_s = B_sᵀe_s/σ².
    blocks: Vec<(DMatrix<f64>, DMatrix<f64>, DVector<f64>)>,
    /// Σ_s |e_s|² (unscaled).
    sum: f64,
}

fn normal<R: Regressor>(
    regressor: &R,
    logs: &[Log],
    segs: &[Segment],
    at: &Point,
    sigma2: f64,
) -> Result<Normal, IdentifyError> {
    let p = at.pi.len();
    let mut out = Normal {
        h_pp: DMatrix::zeros(p, p),
        g_p: DVector::zeros(p),
        blocks: Vec::with_capacity(segs.len()),
        sum: 0.0,
    };
    for (seg, start) in segs.iter().zip(&at.starts) {
        let s = simulate_segment(
            regressor,
            &logs[seg.log],
            *seg,
            at.pi.as_slice(),
            start,
            true,
        )
        .map_err(|e| match e {
            SimFailure::Error(e) => e,
            SimFailure::Diverged => IdentifyError::Simulation {
                message: format!(
                    "segment at sample {} of log {} does not simulate at the current \
                     parameters; shorten the segments",
                    seg.start, seg.log
                ),
            },
        })?;
        let (a, b, e) = (&s.wrt_pi, &s.wrt_start, &s.error);
        out.h_pp += a.tr_mul(a) / sigma2;
        out.g_p += a.tr_mul(e) / sigma2;
        out.blocks.push((
            b.tr_mul(b) / sigma2,
            b.tr_mul(a) / sigma2,
            b.tr_mul(e) / sigma2,
        ));
        out.sum += e.norm_squared();
    }
    Ok(out)
}

/// Solve the damped system; `None` if a block is singular.
/// A damped Gauss–Newton step with the initial states eliminated: the
/// step in π, the reduced (damped) matrix in π, and per segment the pair
/// (x, y) that gives its initial states' step for any step δπ as
/// −(y + x·δπ).
struct Step {
    dp: DVector<f64>,
    reduced: DMatrix<f64>,
    states: Vec<(DMatrix<f64>, DVector<f64>)>,
}

impl Step {
    /// The initial states' steps that go with the step `dp` in π.
    fn states_for(&self, dp: &DVector<f64>) -> Vec<DVector<f64>> {
        self.states.iter().map(|(x, y)| -(y + x * dp)).collect()
    }

    /// The feasible π nearest to `at` + the step in the metric of the
    /// reduced matrix: the minimiser of the damped quadratic model over
    /// the consistent set (a projected Gauss–Newton step), from `at`
    /// (strictly feasible).
    fn projected(&self, structure: &super::Structure, at: &DVector<f64>) -> Option<DVector<f64>> {
        let l = self.reduced.clone().cholesky()?.l();
        let f = l.transpose();
        let rhs = &f * (at + &self.dp);
        let metric = consistency::Metric { f, rhs };
        let (pi, _) = consistency::project(structure, &metric, at.as_slice()).ok()?;
        Some(DVector::from_vec(pi))
    }
}

fn solve_step(
    sys: &Normal,
    prior_precision: &DVector<f64>,
    prior_gradient: &DVector<f64>,
    mu: f64,
) -> Option<Step> {
    let damp = |m: &mut DMatrix<f64>| {
        for i in 0..m.nrows() {
            let d = m[(i, i)];
            m[(i, i)] = d + mu * d.max(1e-300);
        }
    };
    let mut h = sys.h_pp.clone();
    for i in 0..h.nrows() {
        h[(i, i)] += prior_precision[i];
    }
    damp(&mut h);
    let mut g = &sys.g_p + prior_gradient;
    let mut inverses = Vec::with_capacity(sys.blocks.len());
    for (h_ss, h_sp, g_s) in &sys.blocks {
        let mut hs = h_ss.clone();
        damp(&mut hs);
        let chol = hs.cholesky()?;
        let x = chol.solve(h_sp);
        let y = chol.solve(g_s);
        h -= h_sp.tr_mul(&x);
        g -= h_sp.tr_mul(&y);
        inverses.push((x, y));
    }
    let dp = -h.clone().cholesky()?.solve(&g);
    Some(Step {
        dp,
        reduced: h,
        states: inverses,
    })
}

/// The reduced (undamped) Gauss–Newton matrix in π, prior included: the
/// inverse of the posterior covariance.
fn reduced_precision(sys: &Normal, prior_precision: &DVector<f64>) -> DMatrix<f64> {
    let mut h = sys.h_pp.clone();
    for i in 0..h.nrows() {
        h[(i, i)] += prior_precision[i];
    }
    for (h_ss, h_sp, _) in &sys.blocks {
        if let Some(chol) = h_ss.clone().cholesky() {
            h -= h_sp.tr_mul(&chol.solve(h_sp));
        }
    }
    h
}

/// What every descent of one refinement shares.
struct Problem<'a, R> {
    regressor: &'a R,
    logs: &'a [Log],
    segs: &'a [Segment],
    first: &'a Identification,
    options: &'a OutputError,
    consistent: bool,
    prior_precision: &'a DVector<f64>,
    declared: &'a DVector<f64>,
    residual_count: f64,
    dof: f64,
}

/// Where a descent ended.
struct Descent {
    at: Point,
    /// The simulation error's sum of squares there.
    sum: f64,
    sigma2: f64,
    iterations: usize,
    /// RMS simulation error at its start.
    rms_start: f64,
    converged: bool,
}

impl<R: Regressor> Problem<'_, R> {
    /// The MAP objective: data misfit over σ² plus the prior's term.
    fn objective(&self, sum: f64, pi: &DVector<f64>, sigma2: f64) -> f64 {
        let prior: f64 = (pi - self.declared)
            .iter()
            .zip(self.prior_precision.iter())
            .map(|(d, w)| d * d * w)
            .sum();
        sum / sigma2 + prior
    }

    /// Levenberg–Marquardt from the parameters `start`, each segment from
    /// its logged samples (module docs; with loops, projected onto them),
    /// with σ² re-estimated at the solution and the problem solved again
    /// if it moved by more than 20 %.
    fn descend(&self, start: &[f64]) -> Result<Descent, IdentifyError> {
        let (regressor, logs, segs, first) = (self.regressor, self.logs, self.segs, self.first);
        let options = self.options;
        let n = regressor.coordinates();
        let mut starts = Vec::with_capacity(segs.len());
        for s in segs {
            let log = &logs[s.log];
            let mut x = DVector::zeros(2 * n);
            for (i, sample) in [s.start, s.start + 1].into_iter().enumerate() {
                let q = onto_loops(regressor, &log.positions[sample])?;
                x.rows_mut(i * n, n).copy_from_slice(&q);
            }
            starts.push(x);
        }
        let mut at = Point {
            pi: DVector::from_column_slice(start),
            starts,
        };
        if self.consistent && !consistency::feasible(&first.structure, start) {
            return Err(IdentifyError::Inconsistent {
                message: "output error starts from physically consistent parameters".into(),
            });
        }
        // σ² of the start weighs the prior in the first pass; the noisy
        // starting samples inflate it, so it is re-estimated at the solution.
        let mut sigma2 = {
            let sum = sum_squares(regressor, logs, segs, &at)?.ok_or_else(|| {
                IdentifyError::Simulation {
                    message: "a segment does not simulate at the refinement's start; \
                              shorten the segments"
                        .into(),
                }
            })?;
            (sum / self.residual_count).max(f64::MIN_POSITIVE)
        };
        let mut iterations = 0;
        let mut rms_start = None;
        let mut converged = false;
        let mut sys = normal(regressor, logs, segs, &at, sigma2)?;
        for pass in 0..3 {
            let mut mu = 1e-3;
            // (a later pass starts where the last ended, with σ² moved)
            if pass > 0 {
                sys = normal(regressor, logs, segs, &at, sigma2)?;
            }
            if rms_start.is_none() {
                rms_start = Some((sys.sum / self.residual_count).sqrt());
            }
            let mut f = self.objective(sys.sum, &at.pi, sigma2);
            converged = false;
            while iterations < options.max_iterations {
                iterations += 1;
                let prior_gradient = (&at.pi - self.declared).component_mul(self.prior_precision);
                let mut accepted = false;
                for _ in 0..20 {
                    let Some(step) = solve_step(&sys, self.prior_precision, &prior_gradient, mu)
                    else {
                        mu *= 10.0;
                        continue;
                    };
                    // an inconsistent step is projected onto the consistent
                    // set in the model's metric, so that the iteration
                    // slides along the set's boundary instead of stopping
                    // there
                    let mut trial = at.clone();
                    trial.pi = &at.pi + &step.dp;
                    let mut dp = step.dp.clone();
                    if self.consistent
                        && !consistency::feasible(&first.structure, trial.pi.as_slice())
                    {
                        match step.projected(&first.structure, &at.pi) {
                            Some(pi) if consistency::feasible(&first.structure, pi.as_slice()) => {
                                dp = &pi - &at.pi;
                                trial.pi = pi;
                            }
                            _ => {
                                mu *= 10.0;
                                continue;
                            }
                        }
                    }
                    let ds = step.states_for(&dp);
                    for ((t, s), d) in trial.starts.iter_mut().zip(&at.starts).zip(&ds) {
                        *t = s + d;
                    }
                    match sum_squares(regressor, logs, segs, &trial)? {
                        Some(sum) if self.objective(sum, &trial.pi, sigma2) < f => {
                            let f_new = self.objective(sum, &trial.pi, sigma2);
                            let decrease = (f - f_new) / f.max(f64::MIN_POSITIVE);
                            at = trial;
                            f = f_new;
                            mu = (mu * 0.3).max(1e-12);
                            accepted = true;
                            converged = decrease < options.tolerance;
                            break;
                        }
                        _ => mu *= 10.0,
                    }
                }
                if !accepted {
                    // no decrease at any damping: a minimum to rounding
                    converged = true;
                    break;
                }
                sys = normal(regressor, logs, segs, &at, sigma2)?;
                if converged {
                    break;
                }
            }
            let new_sigma2 = (sys.sum / self.dof).max(f64::MIN_POSITIVE);
            let moved = (new_sigma2 / sigma2 - 1.0).abs() > 0.44; // σ moved by > 20 %
            sigma2 = new_sigma2;
            if !moved || iterations >= options.max_iterations {
                break;
            }
        }
        Ok(Descent {
            sum: sys.sum,
            at,
            sigma2,
            iterations,
            rms_start: rms_start.unwrap_or(f64::NAN),
            converged,
        })
    }
}

/// Refine the first stage's result `first` by output error (module
/// docs), starting from its estimate, or from the declared values when
/// the logs are `homogeneous` in π (no input acts: the regression's scale
/// cannot be trusted, [`super::Options::output_error`]). Returns the identification with the refined estimate, its
/// covariance and intervals, and [`Identification::refinement`] set.
pub fn refine<R: Regressor>(
    regressor: &R,
    logs: &[Log],
    first: &Identification,
    options: &OutputError,
    consistent: bool,
    homogeneous: bool,
) -> Result<Identification, IdentifyError> {
    if options.segment < 3
        || options.max_iterations == 0
        || !(options.tolerance > 0.0 && options.tolerance < 1.0)
    {
        return Err(IdentifyError::Options {
            message: format!(
                "output error: segment {} (≥ 3), iterations {} (≥ 1), tolerance {} (in (0, 1))",
                options.segment, options.max_iterations, options.tolerance
            ),
        });
    }
    let n = regressor.coordinates();
    let segs = segments(logs, options.segment);
    if segs.is_empty() {
        return Err(IdentifyError::TooFewTransitions { rows: 0, needed: 3 });
    }
    let prior_precision = DVector::from_iterator(
        first.prior_sd.len(),
        first.prior_sd.iter().map(|s| 1.0 / (s * s)),
    );
    let declared = DVector::from_column_slice(&first.declared);
    let samples: usize = segs.iter().map(|s| s.len).sum();
    let problem = Problem {
        regressor,
        logs,
        segs: &segs,
        first,
        options,
        consistent,
        prior_precision: &prior_precision,
        declared: &declared,
        residual_count: (samples * n) as f64,
        // degrees of freedom of the residuals: minus the initial states
        // and the base parameters
        dof: ((samples * n) as f64 - (segs.len() * 2 * n + first.base.rank()) as f64).max(1.0),
    };
    // From the regression's estimate; and when the consistency projection
    // moved that estimate onto the consistent set's boundary (a regression
    // far off: least squares on noisy positions), also from the declared
    // values. The objective is not convex, and from the boundary the
    // projected steps can stall in a poorer minimum. The lower objective
    // wins, compared with the smaller of the two noise estimates.
    // A regression far off may not simulate every segment; the declared
    // values then start the descent.
    let mut descent = match problem.descend(if homogeneous {
        &first.declared
    } else {
        &first.estimate
    }) {
        Err(IdentifyError::Simulation { .. }) if !homogeneous => {
            problem.descend(&first.declared)?
        }
        other => other?,
    };
    let on_boundary = !(first.projected.is_empty() && first.projected_joints.is_empty());
    if !homogeneous && on_boundary && first.estimate != first.declared {
        match problem.descend(&first.declared) {
            Ok(other) => {
                let sigma2 = descent.sigma2.min(other.sigma2);
                if problem.objective(other.sum, &other.at.pi, sigma2)
                    < problem.objective(descent.sum, &descent.at.pi, sigma2)
                {
                    let iterations = descent.iterations + other.iterations;
                    descent = Descent {
                        iterations,
                        rms_start: descent.rms_start,
                        ..other
                    };
                } else {
                    descent.iterations += other.iterations;
                }
            }
            // the declared values need not simulate every segment
            Err(IdentifyError::Simulation { .. }) => {}
            Err(e) => return Err(e),
        }
    }
    let Descent {
        at,
        sigma2,
        iterations,
        rms_start,
        converged,
        ..
    } = descent;
    let sys = normal(regressor, logs, &segs, &at, sigma2)?;
    let precision = reduced_precision(&sys, &prior_precision);
    let cov = match precision.clone().cholesky() {
        Some(c) => c.inverse(),
        None => {
            // A noise-free log weighs the data some 10²⁵ above the prior:
            // in the directions only the prior sees, the Schur complement
            // is then lost to rounding and may not be positive definite.
            // Their variance is at most the prior's: eigenvalues below the
            // smallest prior precision are raised to it.
            let floor = prior_precision.min();
            let sym = (&precision + precision.transpose()) * 0.5;
            let eig = sym.symmetric_eigen();
            let inv = eig.eigenvalues.map(|l| 1.0 / l.max(floor));
            &eig.eigenvectors * DMatrix::from_diagonal(&inv) * eig.eigenvectors.transpose()
        }
    };
    let k = &first.base.k;
    let base_covariance = k * &cov * k.transpose();
    let prior_cov = DMatrix::from_diagonal(&prior_precision.map(|w| 1.0 / w));
    let prior_base = k * prior_cov * k.transpose();
    let estimate: Vec<f64> = at.pi.iter().cloned().collect();
    let mut out = first.clone();
    out.base_estimate = (k * &at.pi).iter().cloned().collect();
    out.base_half_width = covariance::half_widths(&base_covariance);
    out.base_informed = (0..first.base.rank())
        .map(|i| base_covariance[(i, i)] < 0.5 * prior_base[(i, i)])
        .collect();
    out.unconstrained = estimate.clone();
    out.estimate = estimate;
    out.projected = Vec::new();
    out.projected_joints = Vec::new();
    out.covariance = cov;
    out.base_covariance = base_covariance;
    out.position_sigma = Some(sigma2.sqrt());
    out.refinement = Some(Refinement {
        segments: segs.len(),
        samples,
        iterations,
        rms_start,
        rms: (sys.sum / problem.residual_count).sqrt(),
        position_sigma: sigma2.sqrt(),
        converged,
        homogeneous,
    });
    Ok(out)
}
