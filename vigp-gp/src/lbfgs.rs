//! L-BFGS-B (Byrd, Lu, Nocedal & Zhu 1995; version 3.0 of Morales &
//! Nocedal 2011, as in scipy) with a Moré–Thuente line search, for
//! box-constrained minimisation.
//!
//! Why hand-written: `argmin` 0.11 has L-BFGS without bounds, and the pure-Rust
//! L-BFGS-B ports on crates.io are young single-author 0.1 releases. GP
//! hyperparameter problems have d + 2 ≤ a few dozen variables: up to
//! [`DENSE_MAX`] variables the limited-memory matrix is formed densely
//! (n × n); above it (a sparse GP's inducing points, M·d of them) it is
//! applied through the compact representation of Byrd, Nocedal & Schnabel
//! (1994), B = θI − W·M·Wᵀ with W = [Y θS] (n × 2m), in O(n·m) per product,
//! and the subspace step solves its reduced system by the
//! Sherman–Morrison–Woodbury formula in O(n·m² + m³). Both give the same
//! matrix (the tests compare them); the iteration is scipy's:
//!
//! * **model**: B = θI updated by the last `memory` pairs (s, y), θ = yᵀy/sᵀy
//!   of the newest pair (1 with an empty memory); pairs with
//!   sᵀy ≤ ε·(−gᵀs) are skipped, so B stays positive definite;
//! * **generalized Cauchy point** x_c: the first minimiser of the quadratic
//!   model along the projected steepest-descent path P(x − t·g), segment by
//!   segment between the breakpoints where variables reach their bounds, so
//!   several variables can become active in one iteration; variables at a
//!   bound whose gradient pushes outwards stay there;
//! * **subspace minimisation** (skipped with an empty memory): the model's
//!   minimiser over the variables free at x_c, the others held, projected
//!   into the box, or, if that projection makes it an ascent direction, the
//!   step from x_c truncated at the first bound; this gives x̄;
//! * **line search** along d = x̄ − x: the Moré–Thuente search (Moré &
//!   Thuente 1994, MINPACK-2 `dcsrch` / `dcstep`, as scipy's `lnsrlb` calls
//!   it) with the same constants: sufficient decrease 1e-3, curvature 0.9
//!   (strong Wolfe), interval tolerance 0.1, at most 20 trials, over steps
//!   t ∈ (0, t_max] with t_max the largest step in the box (≥ 1, as x̄ is in
//!   the box); the first trial is t = 1 (x̄ itself); on the very first
//!   iteration t_max = 1, and the first trial is min(1/‖d‖₂, 1) unless every
//!   bound is finite;
//! * a search that fails (no descent direction, a model that is not
//!   positive definite, or 20 trials without a decrease) clears the memory
//!   and retries, as scipy does; with an empty memory the run stops;
//! * stop (scipy's tests) when ‖P(x − g) − x‖∞ ≤ `pgtol`, or the relative
//!   decrease (f_k − f_{k+1})/max(|f_k|, |f_{k+1}|, 1) ≤ `ftol`, or after
//!   `max_iters` iterations.
//!
//! Departures from scipy:
//!
//! * **`unit_start`** (set by GP training): with an empty memory scipy
//!   models f by B = I, so its first trial is x̄ = P(x − g) however large g
//!   is. In log-hyperparameter space the LML's gradient grows with N, and
//!   for a badly scaled start that trial is a corner of the box; the
//!   projection has then thrown away the gradient's proportions, and a
//!   corner with the length scales at their lower bound is a plateau (the
//!   GP sees white noise; the gradient vanishes) where the run stops. With
//!   `unit_start`, when scipy's trial P(x − g) would clip *every*
//!   variable to a bound, the empty-memory model is B = max(1, ‖g‖₂)·I
//!   instead, so the Cauchy point is at most a unit steepest-descent step
//!   away, and the line search of that iteration may extend the step to
//!   the edge of the box. Otherwise (some variable stays inside the box,
//!   ‖g‖₂ ≤ 1, or no bounds) it is scipy's iteration;
//!
//! and, each saving evaluations:
//!
//! * a trial that repeats one of the last 16 evaluated points reuses it;
//! * a search that stops without meeting the Wolfe conditions returns its
//!   best trial if it decreased f (scipy takes the last trial, even a
//!   worse one, and then stops on the ftol test); without any decrease it
//!   ends the run at the current point, unless the memory is not empty
//!   and ½‖P(x − g) − x‖²∞ exceeds the negligible decrease a below: then,
//!   as scipy does after a failed search, it retries with an empty memory
//!   (on an ill-conditioned kernel matrix rounding can spoil a curvature
//!   pair and shrink the model's direction to nothing far from any
//!   optimum);
//! * **negligible decreases** are not paid for: with a = `ftol`·max(|f|, 1),
//!   the decrease below which the ftol test stops, (i) a search that has
//!   backtracked to steps t with t·|gᵀd| ≤ a stops, returning its best
//!   trial or, without a decrease, ending the run as above (near a minimum rounding
//!   noise in f defeats the sufficient-decrease test, and scipy spends up
//!   to 20 trials and a memory reset on it), and (ii) an iteration is not
//!   taken if the model predicted the previous step's decrease within 25 %
//!   and predicts this one's, the model's largest decrease along d
//!   (gᵀd)²/(2·dᵀBd), to be at most a/1.25: the step would end the run by
//!   the ftol test (a model that mispredicted, e.g. on a plateau, is not
//!   trusted with this);
//! * an evaluation that fails (e.g. a kernel matrix that is not positive
//!   definite) or is not finite shrinks the trial step towards the best
//!   point instead of stopping the run.

use std::collections::VecDeque;

use faer::Mat;

use crate::error::GpError;

/// Options of [`minimise`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct LbfgsOptions {
    /// Curvature pairs kept (m; scipy's `maxcor`).
    pub memory: usize,
    /// Most iterations (accepted steps).
    pub max_iters: usize,
    /// Stop when the projected gradient's ∞-norm is at most this.
    pub pgtol: f64,
    /// Stop when the relative decrease of an iteration is at most this.
    pub ftol: f64,
    /// With an empty memory, when scipy's first trial P(x − g) would put
    /// every variable on a bound (a corner of the box), model the
    /// objective by B = max(1, ‖g‖₂)·I instead of scipy's B = I, so the
    /// steepest-descent step to the Cauchy point is at most 1 long, and
    /// let that iteration's line search run to the edge of the box
    /// (scipy: up to x̄). See the module docs for why GP training sets it.
    pub unit_start: bool,
}

/// Outcome of [`minimise`].
#[derive(Clone, Debug)]
pub(crate) struct LbfgsResult {
    /// The best point reached.
    pub x: Vec<f64>,
    /// f there.
    pub f: f64,
    /// Iterations (accepted steps).
    pub iterations: usize,
    /// Evaluations of f and its gradient, the first included (repeated
    /// points served from the cache are not counted).
    pub evaluations: usize,
    /// A stopping test was met (not `max_iters`).
    pub converged: bool,
    /// scipy's first trial from the start, P(x₀ − g₀), clips every
    /// variable to a bound (a corner of the box): the case `unit_start`
    /// changes.
    pub corner_start: bool,
    /// The curvature pairs (s, y) held at the end, oldest first: a seed
    /// for [`minimise_seeded`] on a related objective.
    pub memory: Vec<(Vec<f64>, Vec<f64>)>,
}

/// Line-search constants of scipy's L-BFGS-B (`lnsrlb`).
const LS_FTOL: f64 = 1e-3;
const LS_GTOL: f64 = 0.9;
const LS_XTOL: f64 = 0.1;
const LS_MAX_EVALS: usize = 20;
/// Relative error within which the model must have predicted the last
/// step's decrease for its prediction to end a run (see the module docs).
const MODEL_TOL: f64 = 0.25;
/// Evaluations remembered for repeated trial points.
const RECENT: usize = 16;

fn project(x: &mut [f64], lo: &[f64], hi: &[f64]) {
    for ((v, l), h) in x.iter_mut().zip(lo).zip(hi) {
        *v = v.clamp(*l, *h);
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// ‖P(x − g) − x‖∞.
fn projected_gradient_norm(x: &[f64], g: &[f64], lo: &[f64], hi: &[f64]) -> f64 {
    (0..x.len())
        .map(|i| ((x[i] - g[i]).clamp(lo[i], hi[i]) - x[i]).abs())
        .fold(0.0, f64::max)
}

/// State of the Moré–Thuente search (MINPACK-2 `dcsrch`).
struct MoreThuente {
    brackt: bool,
    stage1: bool,
    finit: f64,
    ginit: f64,
    gtest: f64,
    width: f64,
    width1: f64,
    stx: f64,
    fx: f64,
    gx: f64,
    sty: f64,
    fy: f64,
    gy: f64,
    stmin: f64,
    stmax: f64,
    stpmin: f64,
    stpmax: f64,
}

/// What the search asks for after a trial.
enum Search {
    /// Evaluate at this step.
    Evaluate(f64),
    /// The strong Wolfe conditions hold at the last trial.
    Converged,
    /// No further progress (interval below tolerance, rounding, or a bound
    /// of the step reached): the last trial is the best the search can do.
    Stop,
}

impl MoreThuente {
    /// Starts a search from f(0) = `f0`, f'(0) = `g0` < 0, first trial `stp`.
    fn new(f0: f64, g0: f64, stp: f64, stpmin: f64, stpmax: f64) -> Self {
        let width = stpmax - stpmin;
        Self {
            brackt: false,
            stage1: true,
            finit: f0,
            ginit: g0,
            gtest: LS_FTOL * g0,
            width,
            width1: 2.0 * width,
            stx: 0.0,
            fx: f0,
            gx: g0,
            sty: 0.0,
            fy: f0,
            gy: g0,
            stmin: 0.0,
            stmax: stp + 4.0 * stp,
            stpmin,
            stpmax,
        }
    }

    /// Feeds f(stp), f'(stp) of the last trial; returns what to do next.
    fn next(&mut self, stp: f64, f: f64, g: f64) -> Search {
        let ftest = self.finit + stp * self.gtest;
        if self.stage1 && f <= ftest && g >= 0.0 {
            self.stage1 = false;
        }
        // Convergence first: the strong Wolfe conditions.
        if f <= ftest && g.abs() <= LS_GTOL * (-self.ginit) {
            return Search::Converged;
        }
        if (self.brackt
            && (stp <= self.stmin
                || stp >= self.stmax
                || self.stmax - self.stmin <= LS_XTOL * self.stmax))
            || (stp == self.stpmax && f <= ftest && g <= self.gtest)
            || (stp == self.stpmin && (f > ftest || g >= self.gtest))
        {
            return Search::Stop;
        }
        let mut stp = stp;
        if self.stage1 && f <= self.fx && f > ftest {
            // The modified function ψ(t) = f(t) − f(0) − t·gtest.
            let gt = self.gtest;
            let mut fxm = self.fx - self.stx * gt;
            let mut fym = self.fy - self.sty * gt;
            let mut gxm = self.gx - gt;
            let mut gym = self.gy - gt;
            let fm = f - stp * gt;
            let gm = g - gt;
            dcstep(
                &mut self.stx,
                &mut fxm,
                &mut gxm,
                &mut self.sty,
                &mut fym,
                &mut gym,
                &mut stp,
                fm,
                gm,
                &mut self.brackt,
                self.stmin,
                self.stmax,
            );
            self.fx = fxm + self.stx * gt;
            self.fy = fym + self.sty * gt;
            self.gx = gxm + gt;
            self.gy = gym + gt;
        } else {
            dcstep(
                &mut self.stx,
                &mut self.fx,
                &mut self.gx,
                &mut self.sty,
                &mut self.fy,
                &mut self.gy,
                &mut stp,
                f,
                g,
                &mut self.brackt,
                self.stmin,
                self.stmax,
            );
        }
        if self.brackt {
            if (self.sty - self.stx).abs() >= 0.66 * self.width1 {
                stp = self.stx + 0.5 * (self.sty - self.stx);
            }
            self.width1 = self.width;
            self.width = (self.sty - self.stx).abs();
            self.stmin = self.stx.min(self.sty);
            self.stmax = self.stx.max(self.sty);
        } else {
            self.stmin = stp + 1.1 * (stp - self.stx);
            self.stmax = stp + 4.0 * (stp - self.stx);
        }
        stp = stp.clamp(self.stpmin, self.stpmax);
        if self.brackt
            && (stp <= self.stmin
                || stp >= self.stmax
                || self.stmax - self.stmin <= LS_XTOL * self.stmax)
        {
            stp = self.stx;
        }
        Search::Evaluate(stp)
    }

    /// A trial failed (evaluation error or non-finite value): the step is
    /// too long. Shrinks the upper end to `stp` and tries halfway from the
    /// best point.
    fn failed(&mut self, stp: f64) -> f64 {
        self.stpmax = stp.min(self.stpmax);
        if self.brackt {
            self.sty = self.sty.min(stp);
        }
        self.stmax = self.stmax.min(stp);
        self.stx + 0.5 * (stp - self.stx)
    }

    /// Step of the best point so far (the lowest f, or the modified ψ in stage 1).
    fn best(&self) -> f64 {
        self.stx
    }
}

/// γ of [`dcstep`]'s cubic interpolation with slope term `theta` between
/// an end of derivative `d` and the trial (derivative `dp`):
/// γ = s·√((θ/s)² − (d/s)(dp/s)) with s = max(|θ|, |d|, |dp|) against
/// overflow (the radicand clamped at 0), negated when `negate`.
fn cubic_gamma(theta: f64, d: f64, dp: f64, negate: bool) -> f64 {
    let s = theta.abs().max(d.abs()).max(dp.abs());
    let gamma = s * ((theta / s).powi(2) - (d / s) * (dp / s)).max(0.0).sqrt();
    if negate { -gamma } else { gamma }
}

/// One safeguarded step of Moré–Thuente (MINPACK-2 `dcstep`): updates the
/// interval [stx, sty] containing a step that satisfies the conditions and
/// computes the next trial `stp` from cubic and quadratic interpolation.
#[allow(clippy::too_many_arguments)]
fn dcstep(
    stx: &mut f64,
    fx: &mut f64,
    dx: &mut f64,
    sty: &mut f64,
    fy: &mut f64,
    dy: &mut f64,
    stp: &mut f64,
    fp: f64,
    dp: f64,
    brackt: &mut bool,
    stpmin: f64,
    stpmax: f64,
) {
    let sgnd = dp * (*dx / dx.abs());
    let stpf;
    if fp > *fx {
        // Case 1: higher function value; the minimum is bracketed.
        let theta = 3.0 * (*fx - fp) / (*stp - *stx) + *dx + dp;
        let gamma = cubic_gamma(theta, *dx, dp, *stp < *stx);
        let p = (gamma - *dx) + theta;
        let q = ((gamma - *dx) + gamma) + dp;
        let r = p / q;
        let stpc = *stx + r * (*stp - *stx);
        let stpq = *stx + ((*dx / ((*fx - fp) / (*stp - *stx) + *dx)) / 2.0) * (*stp - *stx);
        stpf = if (stpc - *stx).abs() < (stpq - *stx).abs() {
            stpc
        } else {
            stpc + (stpq - stpc) / 2.0
        };
        *brackt = true;
    } else if sgnd < 0.0 {
        // Case 2: lower value, derivatives of opposite sign: bracketed.
        let theta = 3.0 * (*fx - fp) / (*stp - *stx) + *dx + dp;
        let gamma = cubic_gamma(theta, *dx, dp, *stp > *stx);
        let p = (gamma - dp) + theta;
        let q = ((gamma - dp) + gamma) + *dx;
        let r = p / q;
        let stpc = *stp + r * (*stx - *stp);
        let stpq = *stp + (dp / (dp - *dx)) * (*stx - *stp);
        stpf = if (stpc - *stp).abs() > (stpq - *stp).abs() {
            stpc
        } else {
            stpq
        };
        *brackt = true;
    } else if dp.abs() < dx.abs() {
        // Case 3: lower value, same sign, derivative decreases in magnitude.
        let theta = 3.0 * (*fx - fp) / (*stp - *stx) + *dx + dp;
        let gamma = cubic_gamma(theta, *dx, dp, *stp > *stx);
        let p = (gamma - dp) + theta;
        let q = (gamma + (*dx - dp)) + gamma;
        let r = p / q;
        let stpc = if r < 0.0 && gamma != 0.0 {
            *stp + r * (*stx - *stp)
        } else if *stp > *stx {
            stpmax
        } else {
            stpmin
        };
        let stpq = *stp + (dp / (dp - *dx)) * (*stx - *stp);
        if *brackt {
            let mut f = if (stpc - *stp).abs() < (stpq - *stp).abs() {
                stpc
            } else {
                stpq
            };
            f = if *stp > *stx {
                f.min(*stp + 0.66 * (*sty - *stp))
            } else {
                f.max(*stp + 0.66 * (*sty - *stp))
            };
            stpf = f;
        } else {
            let f = if (stpc - *stp).abs() > (stpq - *stp).abs() {
                stpc
            } else {
                stpq
            };
            stpf = f.min(stpmax).max(stpmin);
        }
    } else {
        // Case 4: lower value, same sign, derivative does not decrease.
        stpf = if *brackt {
            let theta = 3.0 * (fp - *fy) / (*sty - *stp) + *dy + dp;
            let gamma = cubic_gamma(theta, *dy, dp, *stp > *sty);
            let p = (gamma - dp) + theta;
            let q = ((gamma - dp) + gamma) + *dy;
            let r = p / q;
            *stp + r * (*sty - *stp)
        } else if *stp > *stx {
            stpmax
        } else {
            stpmin
        };
    }
    if fp > *fx {
        *sty = *stp;
        *fy = fp;
        *dy = dp;
    } else {
        if sgnd < 0.0 {
            *sty = *stx;
            *fy = *fx;
            *dy = *dx;
        }
        *stx = *stp;
        *fx = fp;
        *dx = dp;
    }
    *stp = stpf;
}

/// A point with its value and gradient.
struct Point {
    x: Vec<f64>,
    f: f64,
    g: Vec<f64>,
}

/// The objective with a cache of its last [`RECENT`] evaluations.
struct Objective<F> {
    f: F,
    evaluations: usize,
    recent: VecDeque<(Vec<f64>, f64, Vec<f64>)>,
}

impl<F> Objective<F>
where
    F: FnMut(&[f64]) -> Result<(f64, Vec<f64>), GpError>,
{
    fn remember(&mut self, x: &[f64], v: f64, g: &[f64]) {
        if self.recent.len() == RECENT {
            self.recent.pop_front();
        }
        self.recent.push_back((x.to_vec(), v, g.to_vec()));
    }

    /// f(x) and ∇f(x), or `None` if the evaluation fails or is not finite. A
    /// point that repeats a recent one (a search that falls back to its
    /// start or its best step, with steps below the resolution of x, as
    /// rounding noise in f causes) reuses that evaluation: the same path,
    /// without paying twice.
    fn eval(&mut self, x: &[f64]) -> Option<(f64, Vec<f64>)> {
        if let Some((_, v, g)) = self.recent.iter().find(|(p, _, _)| p == x) {
            return Some((*v, g.clone()));
        }
        self.evaluations += 1;
        let r = (self.f)(x)
            .ok()
            .filter(|(v, g)| v.is_finite() && g.iter().all(|q| q.is_finite()));
        if let Some((v, g)) = &r {
            self.remember(x, *v, g);
        }
        r
    }
}

/// The limited-memory BFGS matrix: B = θI updated by the stored pairs
/// (s, y), oldest first, with θ = yᵀy/sᵀy of the newest pair (1 when
/// empty). This is the matrix of L-BFGS-B's compact representation
/// θI − W·M·Wᵀ; the problems here are small, so it is formed densely.
struct Memory {
    cap: usize,
    pairs: VecDeque<(Vec<f64>, Vec<f64>, f64)>,
    theta: f64,
}

impl Memory {
    fn new(cap: usize) -> Self {
        Self {
            cap,
            pairs: VecDeque::with_capacity(cap),
            theta: 1.0,
        }
    }

    fn is_empty(&self) -> bool {
        self.pairs.is_empty()
    }

    fn clear(&mut self) {
        self.pairs.clear();
        self.theta = 1.0;
    }

    /// Adds the pair (s, y) with sᵀy = `sy` > 0, dropping the oldest if full.
    fn push(&mut self, s: Vec<f64>, y: Vec<f64>, sy: f64) {
        if self.cap == 0 {
            return;
        }
        if self.pairs.len() == self.cap {
            self.pairs.pop_front();
        }
        self.theta = dot(&y, &y) / sy;
        self.pairs.push_back((s, y, sy));
    }

    /// B as a dense row-major n × n matrix, or `None` if rounding made an
    /// update lose positive curvature (sᵀBs ≤ 0).
    fn dense(&self, n: usize) -> Option<Vec<f64>> {
        let mut b = vec![0.0; n * n];
        for i in 0..n {
            b[i * n + i] = self.theta;
        }
        for (s, y, sy) in &self.pairs {
            let bs = matvec(&b, s);
            let sbs = dot(s, &bs);
            if sbs.is_nan() || sbs <= 0.0 {
                return None;
            }
            for i in 0..n {
                for j in 0..n {
                    b[i * n + j] += y[i] * y[j] / sy - bs[i] * bs[j] / sbs;
                }
            }
        }
        Some(b)
    }
}

/// Above this many variables the model matrix is applied in compact form
/// ([`Model::Compact`]) instead of being formed (n × n; forming it costs
/// O(m·n²) per iteration and the subspace step's Cholesky O(n³)).
pub(crate) const DENSE_MAX: usize = 64;

impl Memory {
    /// The model matrix B for `n` variables: dense when `dense`, else in
    /// compact form; `None` if rounding spoiled positive curvature.
    fn model(&self, n: usize, dense: bool) -> Option<Model> {
        if dense {
            return self.dense(n).map(|b| Model::Dense { n, b });
        }
        // B = θI − W·M·Wᵀ, W = [Y θS], M⁻¹ = [[−D, Lᵀ], [L, θSᵀS]] with
        // D = diag(sᵢᵀyᵢ) and L_ij = sᵢᵀy_j for i > j (pairs oldest first).
        let k = self.pairs.len();
        let theta = self.theta;
        let mut w: Vec<Vec<f64>> = self.pairs.iter().map(|(_, y, _)| y.clone()).collect();
        w.extend(
            self.pairs
                .iter()
                .map(|(s, _, _)| s.iter().map(|v| theta * v).collect::<Vec<f64>>()),
        );
        let pair = |i: usize| &self.pairs[i];
        let minv = Mat::<f64>::from_fn(2 * k, 2 * k, |i, j| match (i < k, j < k) {
            (true, true) if i == j => -pair(i).2,
            (true, true) => 0.0,
            // block (1, 0) = L: s_{i−k}ᵀy_j below the diagonal
            (false, true) if i - k > j => dot(&pair(i - k).0, &pair(j).1),
            // block (0, 1) = Lᵀ
            (true, false) if j - k > i => dot(&pair(j - k).0, &pair(i).1),
            (false, true) | (true, false) => 0.0,
            (false, false) => theta * dot(&pair(i - k).0, &pair(j - k).0),
        });
        let finite = (0..2 * k).all(|j| (0..2 * k).all(|i| minv[(i, j)].is_finite()));
        if !(finite && theta.is_finite() && theta > 0.0) {
            return None;
        }
        let lu = minv.partial_piv_lu();
        Some(Model::Compact { theta, w, minv, lu })
    }
}

/// The model matrix B of one iteration.
enum Model {
    /// Formed: row-major n × n.
    Dense { n: usize, b: Vec<f64> },
    /// B = θI − W·M·Wᵀ: `w` the 2k columns of W = [Y θS], `minv` = M⁻¹
    /// (2k × 2k) and its LU factors.
    Compact {
        theta: f64,
        w: Vec<Vec<f64>>,
        minv: Mat<f64>,
        lu: faer::linalg::solvers::PartialPivLu<f64>,
    },
}

impl Model {
    /// With an empty memory: B = `scale`·I.
    fn set_scaled_identity(&mut self, scale: f64) {
        match self {
            Model::Dense { n, b } => {
                b.iter_mut().for_each(|v| *v = 0.0);
                for i in 0..*n {
                    b[i * *n + i] = scale;
                }
            }
            Model::Compact { theta, w, .. } => {
                debug_assert!(w.is_empty());
                *theta = scale;
            }
        }
    }

    /// B·v.
    fn apply(&self, v: &[f64]) -> Vec<f64> {
        match self {
            Model::Dense { b, .. } => matvec(b, v),
            Model::Compact { theta, w, lu, .. } => {
                use faer::linalg::solvers::Solve;
                let mut out: Vec<f64> = v.iter().map(|x| theta * x).collect();
                if !w.is_empty() {
                    let wv = Mat::<f64>::from_fn(w.len(), 1, |i, _| dot(&w[i], v));
                    let c = lu.solve(&wv);
                    for (i, col) in w.iter().enumerate() {
                        let ci = c[(i, 0)];
                        for (o, wi) in out.iter_mut().zip(col) {
                            *o -= ci * wi;
                        }
                    }
                }
                out
            }
        }
    }

    /// Solves B_FF·u = r on the variables `idx`; `None` if B_FF is not
    /// numerically positive definite (dense: its Cholesky fails; compact:
    /// rᵀu ≤ 0 for r ≠ 0, or a u that is not finite).
    fn reduced_solve(&self, idx: &[usize], r: &[f64]) -> Option<Vec<f64>> {
        match self {
            Model::Dense { n, b } => {
                let reduced: Vec<f64> = idx
                    .iter()
                    .flat_map(|&i| idx.iter().map(move |&j| b[i * n + j]))
                    .collect();
                cholesky_solve(reduced, r)
            }
            Model::Compact { theta, w, minv, .. } => {
                use faer::linalg::solvers::Solve;
                // Woodbury: B_FF⁻¹ = I/θ + W_F (M⁻¹ − W_FᵀW_F/θ)⁻¹ W_Fᵀ / θ².
                let mut u: Vec<f64> = r.iter().map(|x| x / theta).collect();
                if !w.is_empty() {
                    let wf: Vec<Vec<f64>> = w
                        .iter()
                        .map(|c| idx.iter().map(|&i| c[i]).collect())
                        .collect();
                    let m2 = wf.len();
                    let k = Mat::<f64>::from_fn(m2, m2, |i, j| {
                        minv[(i, j)] - dot(&wf[i], &wf[j]) / theta
                    });
                    let wr = Mat::<f64>::from_fn(m2, 1, |i, _| dot(&wf[i], r));
                    let c = k.partial_piv_lu().solve(&wr);
                    for (i, col) in wf.iter().enumerate() {
                        let ci = c[(i, 0)] / (theta * theta);
                        for (o, wi) in u.iter_mut().zip(col) {
                            *o += ci * wi;
                        }
                    }
                }
                let ru = dot(r, &u);
                let ok =
                    u.iter().all(|v| v.is_finite()) && (ru > 0.0 || r.iter().all(|v| *v == 0.0));
                ok.then_some(u)
            }
        }
    }
}

/// A·v for a dense row-major square A.
fn matvec(a: &[f64], v: &[f64]) -> Vec<f64> {
    a.chunks_exact(v.len()).map(|row| dot(row, v)).collect()
}

/// Solves A·u = r for a symmetric positive definite row-major A (Cholesky);
/// `None` if A is not numerically positive definite.
fn cholesky_solve(mut a: Vec<f64>, r: &[f64]) -> Option<Vec<f64>> {
    let n = r.len();
    for j in 0..n {
        let mut djj = a[j * n + j];
        for k in 0..j {
            djj -= a[j * n + k] * a[j * n + k];
        }
        if djj.is_nan() || djj <= 0.0 {
            return None;
        }
        let ljj = djj.sqrt();
        a[j * n + j] = ljj;
        for i in j + 1..n {
            let mut v = a[i * n + j];
            for k in 0..j {
                v -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = v / ljj;
        }
    }
    let mut u = r.to_vec();
    for i in 0..n {
        for k in 0..i {
            u[i] -= a[i * n + k] * u[k];
        }
        u[i] /= a[i * n + i];
    }
    for i in (0..n).rev() {
        for k in i + 1..n {
            u[i] -= a[k * n + i] * u[k];
        }
        u[i] /= a[i * n + i];
    }
    u.iter().all(|v| v.is_finite()).then_some(u)
}

/// The generalized Cauchy point (L-BFGS-B's `cauchy`): the first local
/// minimiser of the model m(x + s) = gᵀs + ½sᵀBs along the projected
/// steepest-descent path P(x − t·g), t ≥ 0, found segment by segment
/// between the breakpoints where variables reach their bounds. Returns the
/// point and the variables free there: those neither held at a bound by
/// the gradient nor stopped at one along the path.
fn cauchy(x: &[f64], g: &[f64], lo: &[f64], hi: &[f64], b: &Model) -> (Vec<f64>, Vec<bool>) {
    let n = x.len();
    let mut d = vec![0.0; n];
    let mut free = vec![true; n];
    let mut breaks: Vec<(f64, usize)> = Vec::new();
    for i in 0..n {
        if lo[i] >= hi[i] || (x[i] <= lo[i] && g[i] >= 0.0) || (x[i] >= hi[i] && g[i] <= 0.0) {
            free[i] = false;
            continue;
        }
        d[i] = -g[i];
        if d[i] < 0.0 && lo[i].is_finite() {
            breaks.push(((x[i] - lo[i]) / -d[i], i));
        } else if d[i] > 0.0 && hi[i].is_finite() {
            breaks.push(((hi[i] - x[i]) / d[i], i));
        }
    }
    let mut xcp = x.to_vec();
    if d.iter().all(|v| *v == 0.0) {
        return (xcp, free);
    }
    breaks.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    // z = xcp − x at the start of the current segment, which starts at
    // t_start; along it the model's slope is f1 + f2·(t − t_start).
    let mut z = vec![0.0; n];
    let mut bd = b.apply(&d);
    let mut f1 = dot(g, &d);
    let f2_org = dot(&d, &bd);
    let mut f2 = f2_org;
    let mut dtm = -f1 / f2;
    let mut t_start = 0.0;
    for &(tb, i) in &breaks {
        let dt = tb - t_start;
        if dtm < dt {
            break;
        }
        // Pass the breakpoint: variable i stops at its bound.
        t_start = tb;
        for (zj, dj) in z.iter_mut().zip(&d) {
            *zj += dt * dj;
        }
        xcp[i] = if d[i] > 0.0 { hi[i] } else { lo[i] };
        z[i] = xcp[i] - x[i];
        d[i] = 0.0;
        free[i] = false;
        if d.iter().all(|v| *v == 0.0) {
            dtm = 0.0;
            break;
        }
        bd = b.apply(&d);
        f1 = dot(g, &d) + dot(&z, &bd);
        // scipy's safeguard against a curvature lost to rounding.
        f2 = dot(&d, &bd).max(f64::EPSILON * f2_org);
        dtm = -f1 / f2;
    }
    let t = t_start + dtm.max(0.0);
    for i in 0..n {
        if d[i] != 0.0 {
            xcp[i] = (x[i] + t * d[i]).clamp(lo[i], hi[i]);
        }
    }
    (xcp, free)
}

/// Subspace minimisation (L-BFGS-B's `subsm`, direct primal method): the
/// minimiser of the model over the variables free at the Cauchy point
/// `xcp`, the others held there, projected into the box; if the projection
/// makes x̄ − x an ascent direction, the step from `xcp` is instead
/// truncated at the first bound (Morales & Nocedal 2011, as in L-BFGS-B
/// 3.0). `None` if the reduced matrix is not numerically positive definite.
fn subspace(
    at: &Point,
    lo: &[f64],
    hi: &[f64],
    b: &Model,
    xcp: Vec<f64>,
    free: &[bool],
) -> Option<Vec<f64>> {
    let (x, g) = (&at.x, &at.g);
    let n = x.len();
    let idx: Vec<usize> = (0..n).filter(|&i| free[i]).collect();
    if idx.is_empty() {
        return Some(xcp);
    }
    // Reduced Newton step from xcp: (ZᵀBZ)·u = −Zᵀ(g + B(xcp − x)).
    let dx: Vec<f64> = xcp.iter().zip(x).map(|(a, b)| a - b).collect();
    let bdx = b.apply(&dx);
    let r: Vec<f64> = idx.iter().map(|&i| -(g[i] + bdx[i])).collect();
    let mut du = b.reduced_solve(&idx, &r)?;
    let mut z = xcp.clone();
    let mut at_bound = false;
    for (k, &i) in idx.iter().enumerate() {
        z[i] = (xcp[i] + du[k]).clamp(lo[i], hi[i]);
        at_bound |= z[i] == lo[i] || z[i] == hi[i];
    }
    if !at_bound || (0..n).map(|i| (z[i] - x[i]) * g[i]).sum::<f64>() <= 0.0 {
        return Some(z);
    }
    // The largest α ≤ 1 that keeps xcp + α·u in the box.
    let mut alpha = 1.0;
    let mut ibd = None;
    for (k, &i) in idx.iter().enumerate() {
        let t = if du[k] < 0.0 {
            let room = lo[i] - xcp[i];
            if room >= 0.0 { 0.0 } else { room / du[k] }
        } else if du[k] > 0.0 {
            let room = hi[i] - xcp[i];
            if room <= 0.0 { 0.0 } else { room / du[k] }
        } else {
            alpha
        };
        if t < alpha {
            alpha = t;
            ibd = Some(k);
        }
    }
    let mut z = xcp;
    if let Some(k) = ibd {
        let i = idx[k];
        z[i] = if du[k] > 0.0 { hi[i] } else { lo[i] };
        du[k] = 0.0;
    }
    for (k, &i) in idx.iter().enumerate() {
        z[i] += alpha * du[k];
    }
    Some(z)
}

/// scipy's trial from an empty memory, P(x − g), clips every variable to a
/// bound (a corner of the box).
fn corner_trial(x: &[f64], g: &[f64], lo: &[f64], hi: &[f64]) -> bool {
    (0..x.len()).all(|i| {
        let t = x[i] - g[i];
        t < lo[i] || t > hi[i]
    })
}

/// What stays fixed over a run: the box and the decrease too small to
/// matter.
struct Setting<'a> {
    lo: &'a [f64],
    hi: &'a [f64],
    /// Some bound is finite (else the Cauchy point is skipped when the
    /// memory is not empty, as in L-BFGS-B).
    constrained: bool,
    /// Every bound is finite.
    boxed: bool,
    /// `ftol` of [`LbfgsOptions`].
    ftol: f64,
    /// `unit_start` of [`LbfgsOptions`].
    unit_start: bool,
    /// Largest n for the dense model matrix ([`DENSE_MAX`]; the tests
    /// lower it to compare the two forms).
    dense_max: usize,
}

/// How one iteration's search ended.
enum Attempt {
    /// A point with a lower value, and the decrease the model predicted
    /// for the step to it.
    Step(Point, f64),
    /// No decrease worth resolving: the model, after predicting the last
    /// step well, predicts a relative decrease ≤ `ftol`, or the line
    /// search shrank its trial steps below that decrease (rounding noise)
    /// or stopped without any decrease.
    Stalled,
    /// No descent direction, a singular model, or a search that ran out of
    /// evaluations without a decrease: worth a retry with an empty memory.
    Failed,
}

/// One L-BFGS-B iteration from `at`: generalized Cauchy point, subspace
/// minimisation over the variables free there, Moré–Thuente line search
/// along d = x̄ − x. `first`: no iteration yet (scipy's iter = 0);
/// `model_ok`: the model predicted the last step's decrease well.
fn attempt<F>(
    obj: &mut Objective<F>,
    set: &Setting,
    at: &Point,
    mem: &Memory,
    first: bool,
    model_ok: bool,
) -> Attempt
where
    F: FnMut(&[f64]) -> Result<(f64, Vec<f64>), GpError>,
{
    let (x, fx, g, lo, hi) = (&at.x, at.f, &at.g, set.lo, set.hi);
    let n = x.len();
    let Some(mut b) = mem.model(n, n <= set.dense_max) else {
        return Attempt::Failed;
    };
    // `unit_start`: scipy's first trial P(x − g) would be a corner of the
    // box (every variable clipped), which keeps none of g's proportions.
    let scaled = mem.is_empty() && set.unit_start && corner_trial(x, g, lo, hi);
    if scaled {
        b.set_scaled_identity(dot(g, g).sqrt().max(1.0));
    }
    let (xcp, free) = if set.constrained || mem.is_empty() {
        cauchy(x, g, lo, hi, &b)
    } else {
        (x.to_vec(), vec![true; n])
    };
    let z = if mem.is_empty() {
        xcp
    } else {
        match subspace(at, lo, hi, &b, xcp, &free) {
            Some(z) => z,
            None => return Attempt::Failed,
        }
    };
    let d: Vec<f64> = z.iter().zip(x).map(|(a, b)| a - b).collect();
    let slope = dot(g, &d);
    if slope.is_nan() || slope >= 0.0 {
        return Attempt::Failed;
    }
    // The decrease below which the ftol test stops the run.
    let negligible = set.ftol * fx.abs().max(1.0);
    let curv = dot(&d, &b.apply(&d));
    // The model's decrease at step t along d.
    let predicted = |t: f64| -(t * slope + 0.5 * t * t * curv);
    // The model's largest decrease along d is slope²/(2·curv). If the model
    // predicted the last step's decrease within MODEL_TOL and predicts this
    // one's, with that margin, to be at most the negligible decrease, the
    // step would end the run by the ftol test: not worth an evaluation.
    if model_ok && curv > 0.0 && (1.0 + MODEL_TOL) * slope * slope / (2.0 * curv) <= negligible {
        return Attempt::Stalled;
    }
    // Largest step in the box; 1 on the first iteration of a bounded
    // problem (scipy's `lnsrlb`, where d = P(x − g) − x then).
    let mut tmax: f64 = 1e10;
    if first && set.constrained && !scaled {
        tmax = 1.0;
    } else {
        for i in 0..n {
            if d[i] < 0.0 && lo[i].is_finite() {
                tmax = tmax.min(((lo[i] - x[i]) / d[i]).max(0.0));
            } else if d[i] > 0.0 && hi[i].is_finite() {
                tmax = tmax.min(((hi[i] - x[i]) / d[i]).max(0.0));
            }
        }
    }
    let mut stp = if first && !set.boxed {
        (1.0 / dot(&d, &d).sqrt()).min(tmax)
    } else {
        tmax.min(1.0)
    };
    if stp.is_nan() || stp <= 0.0 {
        return Attempt::Failed;
    }
    let mut ls = MoreThuente::new(fx, slope, stp, 0.0, tmax);
    // The best (lowest f) trial of this search, with its step: returned if
    // the search stops without meeting the Wolfe conditions.
    let mut best: Option<(f64, Point)> = None;
    let found = |best: Option<(f64, Point)>, none: Attempt| match best {
        Some((t, p)) => Attempt::Step(p, predicted(t)),
        None => none,
    };
    // A search that ends without any decrease: the end of the run, unless
    // the memory is not empty and the projected gradient promises more than
    // a negligible decrease even at unit curvature (½‖P(x − g) − x‖²∞ >
    // the negligible decrease). Then the model's direction is the suspect
    // (a curvature pair spoiled by rounding on an ill-conditioned kernel
    // matrix can make it tiny), and scipy's remedy applies: retry with an
    // empty memory.
    let no_decrease = || {
        let pg = projected_gradient_norm(x, g, lo, hi);
        if !mem.is_empty() && 0.5 * pg * pg > negligible {
            Attempt::Failed
        } else {
            Attempt::Stalled
        }
    };
    let mut trial = vec![0.0; n];
    for k in 0..LS_MAX_EVALS {
        if k > 0 && stp * -slope <= negligible {
            // Backtracked to steps whose decrease could not matter (rounding
            // noise in f defeats the sufficient-decrease test near a minimum).
            return found(best, no_decrease());
        }
        if stp == 1.0 {
            trial.copy_from_slice(&z);
        } else {
            for i in 0..n {
                trial[i] = x[i] + stp * d[i];
            }
            // Land exactly on the bound at t_max (rounding can overshoot).
            project(&mut trial, lo, hi);
        }
        let Some((ft, gt)) = obj.eval(&trial) else {
            stp = ls.failed(stp);
            if stp.is_nan() || stp <= 1e-20 * ls.stpmax.max(1e-300) {
                break;
            }
            continue;
        };
        let dg = dot(&gt, &d);
        let point = Point {
            x: trial.clone(),
            f: ft,
            g: gt,
        };
        let search = ls.next(stp, ft, dg);
        if let Search::Converged = search {
            return Attempt::Step(point, predicted(stp));
        }
        if ft < fx && best.as_ref().is_none_or(|(_, b)| ft < b.f) {
            best = Some((stp, point));
        }
        match search {
            Search::Converged => unreachable!("returned above"),
            Search::Stop => return found(best, no_decrease()),
            Search::Evaluate(s) => {
                if s == ls.best() && best.as_ref().is_some_and(|(t, _)| *t == s) {
                    // The search falls back to its best point, already evaluated.
                    break;
                }
                stp = s;
            }
        }
    }
    found(best, Attempt::Failed)
}

/// Minimises `f` (returning value and gradient) over the box [lo, hi] from x0.
pub(crate) fn minimise<F>(
    f: F,
    x0: &[f64],
    lo: &[f64],
    hi: &[f64],
    opt: LbfgsOptions,
) -> Result<LbfgsResult, GpError>
where
    F: FnMut(&[f64]) -> Result<(f64, Vec<f64>), GpError>,
{
    minimise_with(f, x0, lo, hi, opt, DENSE_MAX, Seed::NONE)
}

/// Curvature pairs to start [`minimise_seeded`]'s model from.
#[derive(Clone, Copy)]
struct Seed<'a> {
    /// (s, y) pairs, oldest first.
    memory: &'a [(Vec<f64>, Vec<f64>)],
    /// Factor on every y.
    y_scale: f64,
}

impl Seed<'_> {
    const NONE: Seed<'static> = Seed {
        memory: &[],
        y_scale: 1.0,
    };
}

/// [`minimise`] with the limited-memory model seeded by the curvature
/// pairs `memory` (oldest first) of a run on a related objective, each y
/// multiplied by `y_scale` (e.g. N/m from a subset's likelihood to the full
/// one, whose curvature grows with the sample count). Pairs whose scaled
/// sᵀy is not positive are skipped. With a non-empty seed the first
/// iteration is an ordinary quasi-Newton one (trial step 1 at the model's
/// minimiser), not scipy's steepest-descent start.
pub(crate) fn minimise_seeded<F>(
    f: F,
    x0: &[f64],
    lo: &[f64],
    hi: &[f64],
    opt: LbfgsOptions,
    memory: &[(Vec<f64>, Vec<f64>)],
    y_scale: f64,
) -> Result<LbfgsResult, GpError>
where
    F: FnMut(&[f64]) -> Result<(f64, Vec<f64>), GpError>,
{
    minimise_with(f, x0, lo, hi, opt, DENSE_MAX, Seed { memory, y_scale })
}

/// [`minimise`] with the dense model matrix up to `dense_max` variables.
fn minimise_with<F>(
    f: F,
    x0: &[f64],
    lo: &[f64],
    hi: &[f64],
    opt: LbfgsOptions,
    dense_max: usize,
    seed: Seed,
) -> Result<LbfgsResult, GpError>
where
    F: FnMut(&[f64]) -> Result<(f64, Vec<f64>), GpError>,
{
    let mut x = x0.to_vec();
    project(&mut x, lo, hi);
    let mut obj = Objective {
        f,
        evaluations: 1,
        recent: VecDeque::with_capacity(RECENT),
    };
    let (fx, g) = (obj.f)(&x)?;
    if !fx.is_finite() || g.iter().any(|v| !v.is_finite()) {
        return Err(GpError::OptimiserFailed {
            output: 0,
            reason: "objective not finite at the starting point".into(),
        });
    }
    obj.remember(&x, fx, &g);
    let corner_start = corner_trial(&x, &g, lo, hi);
    let set = Setting {
        lo,
        hi,
        constrained: lo.iter().chain(hi).any(|v| v.is_finite()),
        boxed: lo.iter().chain(hi).all(|v| v.is_finite()),
        ftol: opt.ftol,
        unit_start: opt.unit_start,
        dense_max,
    };
    let mut at = Point { x, f: fx, g };
    let mut mem = Memory::new(opt.memory);
    for (s, y) in seed.memory {
        if s.len() != at.x.len() || y.len() != at.x.len() {
            continue;
        }
        let y: Vec<f64> = y.iter().map(|v| v * seed.y_scale).collect();
        let sy = dot(s, &y);
        if sy.is_finite() && sy > 0.0 {
            mem.push(s.clone(), y, sy);
        }
    }
    let seeded = !mem.is_empty();
    let mut converged = false;
    let mut iterations = 0;
    let mut model_ok = false;
    while iterations < opt.max_iters {
        if projected_gradient_norm(&at.x, &at.g, lo, hi) <= opt.pgtol {
            converged = true;
            break;
        }
        let step = loop {
            match attempt(
                &mut obj,
                &set,
                &at,
                &mem,
                iterations == 0 && !seeded,
                model_ok,
            ) {
                Attempt::Step(p, predicted) => break Some((p, predicted)),
                Attempt::Stalled => break None,
                Attempt::Failed if mem.is_empty() => break None,
                // scipy's remedy: restart from an empty memory.
                Attempt::Failed => mem.clear(),
            }
        };
        let Some((next, predicted)) = step else {
            // No decrease worth having along any direction: a (numerical)
            // stationary point.
            converged = true;
            break;
        };
        iterations += 1;
        // The model is trusted for the stopping test in `attempt` if it came
        // from curvature pairs and predicted this decrease within MODEL_TOL.
        let decrease = at.f - next.f;
        model_ok = !mem.is_empty() && (decrease - predicted).abs() <= MODEL_TOL * predicted;
        let s: Vec<f64> = next.x.iter().zip(&at.x).map(|(a, b)| a - b).collect();
        let y: Vec<f64> = next.g.iter().zip(&at.g).map(|(a, b)| a - b).collect();
        let sy = dot(&s, &y);
        // scipy's test: skip pairs with sᵀy ≤ ε·(−gᵀs), keeping B positive definite.
        if sy > 0.0 && sy > f64::EPSILON * -dot(&at.g, &s) {
            mem.push(s, y, sy);
        }
        let f_old = at.f;
        at = next;
        if (f_old - at.f) <= opt.ftol * f_old.abs().max(at.f.abs()).max(1.0) {
            converged = true;
            break;
        }
    }
    Ok(LbfgsResult {
        x: at.x,
        f: at.f,
        iterations,
        evaluations: obj.evaluations,
        converged,
        corner_start,
        memory: mem.pairs.into_iter().map(|(s, y, _)| (s, y)).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts() -> LbfgsOptions {
        LbfgsOptions {
            memory: 10,
            max_iters: 500,
            pgtol: 1e-9,
            ftol: 0.0,
            unit_start: false,
        }
    }

    /// Prints the run's evaluations and iterations and checks that it took
    /// at most `max` evaluations.
    fn assert_evaluations(r: &LbfgsResult, max: usize) {
        println!("{} evaluations, {} iterations", r.evaluations, r.iterations);
        assert!(r.evaluations <= max, "{} evaluations", r.evaluations);
    }

    fn rosenbrock(x: &[f64]) -> Result<(f64, Vec<f64>), GpError> {
        let (a, b) = (x[0], x[1]);
        let v = (1.0 - a).powi(2) + 100.0 * (b - a * a).powi(2);
        let g = vec![
            -2.0 * (1.0 - a) - 400.0 * a * (b - a * a),
            200.0 * (b - a * a),
        ];
        Ok((v, g))
    }

    /// Minimises `f` from Rosenbrock's start (−1.2, 1) in the box [−5, 5]²
    /// and checks that the run converged to within `tol` (per coordinate)
    /// of the minimiser (1, 1).
    fn rosenbrock_run(
        f: impl FnMut(&[f64]) -> Result<(f64, Vec<f64>), GpError>,
        o: LbfgsOptions,
        tol: [f64; 2],
    ) -> LbfgsResult {
        let r = minimise(f, &[-1.2, 1.0], &[-5.0, -5.0], &[5.0, 5.0], o).unwrap();
        assert!(r.converged);
        assert!(
            (r.x[0] - 1.0).abs() < tol[0] && (r.x[1] - 1.0).abs() < tol[1],
            "{:?}",
            r.x
        );
        r
    }

    /// The chained Rosenbrock function Σ (1 − x_i)² + 100(x_{i+1} − x_i²)².
    fn chained(x: &[f64]) -> Result<(f64, Vec<f64>), GpError> {
        let mut v = 0.0;
        let mut g = vec![0.0; x.len()];
        for i in 0..x.len() - 1 {
            let (a, b) = (x[i], x[i + 1]);
            v += (1.0 - a).powi(2) + 100.0 * (b - a * a).powi(2);
            g[i] += -2.0 * (1.0 - a) - 400.0 * a * (b - a * a);
            g[i + 1] += 200.0 * (b - a * a);
        }
        Ok((v, g))
    }

    /// The chained problem of the tests below: start (−1.2, 1, −1.2, …), box
    /// [−5, 5]ⁿ with x₃ ≤ 0.8 (active at the solution).
    fn chained_problem(n: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let x0 = (0..n)
            .map(|i| if i % 2 == 0 { -1.2 } else { 1.0 })
            .collect();
        let mut hi = vec![5.0; n];
        hi[3] = 0.8;
        (x0, vec![-5.0; n], hi)
    }

    /// scipy's defaults but gtol 1e-9.
    fn chained_opts() -> LbfgsOptions {
        LbfgsOptions {
            max_iters: 2000,
            ftol: 2.220446049250313e-9,
            ..opts()
        }
    }

    #[test]
    fn compact_and_dense_models_agree() {
        // Five curvature pairs of a convex quadratic (sᵀy > 0) in 12
        // variables: B·v and the reduced solve on 7 free variables from
        // the compact form against the formed matrix (relative 1e-10:
        // both are O(n·m) sums of O(1) terms; the Woodbury solve adds a
        // 10 × 10 LU, well conditioned here).
        let n = 12;
        let a = |i: usize, j: usize| {
            if i == j {
                2.0 + i as f64
            } else {
                0.3 / (1.0 + (i + j) as f64)
            }
        };
        let mut mem = Memory::new(10);
        for k in 0..5 {
            let s: Vec<f64> = (0..n)
                .map(|i| ((i * 7 + k * 3) as f64 * 0.37).sin())
                .collect();
            let y: Vec<f64> = (0..n)
                .map(|i| (0..n).map(|j| a(i, j) * s[j]).sum())
                .collect();
            let sy = dot(&s, &y);
            assert!(sy > 0.0);
            mem.push(s, y, sy);
        }
        let dense = mem.model(n, true).unwrap();
        let compact = mem.model(n, false).unwrap();
        let v: Vec<f64> = (0..n).map(|i| (i as f64 * 1.3).cos()).collect();
        let (bd, bc) = (dense.apply(&v), compact.apply(&v));
        let scale = bd.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for (p, q) in bd.iter().zip(&bc) {
            assert!((p - q).abs() <= 1e-10 * scale, "{p} vs {q}");
        }
        let idx = [0, 2, 3, 5, 8, 10, 11];
        let r: Vec<f64> = idx.iter().map(|&i| v[i]).collect();
        let (ud, uc) = (
            dense.reduced_solve(&idx, &r).unwrap(),
            compact.reduced_solve(&idx, &r).unwrap(),
        );
        let scale = ud.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for (p, q) in ud.iter().zip(&uc) {
            assert!((p - q).abs() <= 1e-10 * scale, "{p} vs {q}");
        }
    }

    #[test]
    fn compact_form_follows_the_dense_iteration() {
        // The same 20-variable bounded run with the formed and the compact
        // matrix: the same iteration up to rounding, so the same local
        // minimum, value and counts. scipy 1.17.1 (L-BFGS-B, maxcor 10,
        // gtol 1e-9, its default ftol 2.22e-9) on this problem:
        // f = 12.945063416168468 in 54 evaluations, 45 iterations.
        let (x0, lo, hi) = chained_problem(20);
        let o = chained_opts();
        let d = minimise_with(chained, &x0, &lo, &hi, o, usize::MAX, Seed::NONE).unwrap();
        let c = minimise_with(chained, &x0, &lo, &hi, o, 0, Seed::NONE).unwrap();
        println!(
            "dense: f {} in {} evaluations, {} iterations; compact: f {} in {}, {}",
            d.f, d.evaluations, d.iterations, c.f, c.evaluations, c.iterations
        );
        assert!(d.converged && c.converged);
        // the ftol test stops within 2.22e-9 relative of the minimum
        assert!((d.f - 12.945063416168468).abs() <= 1e-8 * 12.95, "{}", d.f);
        assert!((c.f - d.f).abs() <= 1e-12 * d.f, "{} vs {}", c.f, d.f);
        for (p, q) in c.x.iter().zip(&d.x) {
            assert!((p - q).abs() <= 1e-6, "{p} vs {q}");
        }
        assert_eq!(c.x[3], 0.8);
        assert!(c.evaluations.abs_diff(d.evaluations) <= 2);
    }

    #[test]
    fn compact_form_scales_to_hundreds_of_variables() {
        // 200 variables (above DENSE_MAX): scipy 1.17.1 with the settings
        // of the previous test reaches f = 191.12650077808004 in 51
        // evaluations, 41 iterations.
        let (x0, lo, hi) = chained_problem(200);
        let o = chained_opts();
        let r = minimise(chained, &x0, &lo, &hi, o).unwrap();
        println!(
            "f {} in {} evaluations, {} iterations",
            r.f, r.evaluations, r.iterations
        );
        assert!(r.converged);
        assert!((r.f - 191.12650077808004).abs() <= 1e-8 * 191.2, "{}", r.f);
        assert!(r.evaluations <= 51, "{}", r.evaluations);
    }

    #[test]
    fn rosenbrock_unconstrained_interior() {
        // Minimiser (1, 1); pgtol 1e-9 on a well-conditioned-near-optimum problem
        // gives ~1e-8 accuracy in x.
        let r = rosenbrock_run(rosenbrock, opts(), [1e-6, 1e-6]);
        // scipy 1.17.1's L-BFGS-B on the same problem (box [−5, 5]², pgtol
        // 1e-9, ftol 0, memory 10) takes 51 evaluations in 36 iterations.
        assert_evaluations(&r, 51);
    }

    #[test]
    fn quadratic_with_active_bound() {
        // min (x-3)² + (y+1)² on [0,2]×[0,2]: solution (2, 0), both bounds active.
        let f = |x: &[f64]| {
            Ok((
                (x[0] - 3.0).powi(2) + (x[1] + 1.0).powi(2),
                vec![2.0 * (x[0] - 3.0), 2.0 * (x[1] + 1.0)],
            ))
        };
        let r = minimise(f, &[1.0, 1.0], &[0.0, 0.0], &[2.0, 2.0], opts()).unwrap();
        assert!(r.converged);
        assert_eq!(r.x, vec![2.0, 0.0]);
    }

    #[test]
    fn strong_wolfe_conditions_hold_at_an_accepted_step() {
        // φ(t) = f(x + t·d) along d = −∇f at x = (−1.2, 1) on Rosenbrock.
        let x = [-1.2, 1.0];
        let (f0, g0) = rosenbrock(&x).unwrap();
        let d = [-g0[0], -g0[1]];
        let slope = dot(&g0, &d);
        let stp0 = 1.0 / dot(&d, &d).sqrt();
        let mut ls = MoreThuente::new(f0, slope, stp0, 0.0, 1e10);
        let mut stp = stp0;
        for _ in 0..LS_MAX_EVALS {
            let xt = [x[0] + stp * d[0], x[1] + stp * d[1]];
            let (ft, gt) = rosenbrock(&xt).unwrap();
            let dg = dot(&gt, &d);
            match ls.next(stp, ft, dg) {
                Search::Converged => {
                    assert!(ft <= f0 + LS_FTOL * stp * slope);
                    assert!(dg.abs() <= LS_GTOL * slope.abs());
                    return;
                }
                Search::Stop => panic!("stopped without convergence at {stp}"),
                Search::Evaluate(s) => stp = s,
            }
        }
        panic!("no convergence in {LS_MAX_EVALS} evaluations");
    }

    #[test]
    fn rounding_noise_does_not_cost_evaluations_at_the_same_point() {
        // A quadratic whose value carries deterministic noise of 1e-7 (a hash
        // of x's bits), as a sum of huge cancelling terms does: near the
        // minimiser the line searches cannot decrease f and shrink their
        // step to nothing. No point may be evaluated twice (a search that
        // falls back to its start has nothing new to evaluate).
        let seen = std::cell::RefCell::new(Vec::<Vec<f64>>::new());
        let f = |x: &[f64]| {
            seen.borrow_mut().push(x.to_vec());
            let h = x.iter().fold(0x9E37_79B9_7F4A_7C15u64, |h, v| {
                (h ^ v.to_bits()).wrapping_mul(0xBF58_476D_1CE4_E5B9)
            });
            let noise = 1e-7 * ((h >> 11) as f64 / (1u64 << 53) as f64 - 0.5);
            let v = (x[0] - 1.0).powi(2) + 10.0 * (x[1] + 0.5).powi(2) + noise;
            Ok((v, vec![2.0 * (x[0] - 1.0), 20.0 * (x[1] + 0.5)]))
        };
        let r = minimise(f, &[3.0, 2.0], &[-5.0, -5.0], &[5.0, 5.0], opts()).unwrap();
        assert!((r.x[0] - 1.0).abs() < 1e-3 && (r.x[1] + 0.5).abs() < 1e-3);
        let pts = seen.borrow();
        for (i, p) in pts.iter().enumerate() {
            assert!(
                pts[..i].iter().all(|q| q != p),
                "evaluation {i} repeats an earlier point {p:?} ({} evaluations)",
                pts.len()
            );
        }
    }

    #[test]
    fn failed_evaluations_shrink_the_step() {
        // f is undefined (an error) beyond x = 0.5: the minimiser of
        // (x − 0.4)² must still be found from 0.
        let f = |x: &[f64]| {
            if x[0] > 0.5 {
                Err(GpError::NotPositiveDefinite { jitter: 0.0 })
            } else {
                Ok(((x[0] - 0.4).powi(2), vec![2.0 * (x[0] - 0.4)]))
            }
        };
        let r = minimise(f, &[0.0], &[-10.0], &[10.0], opts()).unwrap();
        assert!((r.x[0] - 0.4).abs() < 1e-8, "{:?}", r.x);
    }

    /// ½(x − c)ᵀA(x − c) and its gradient, A = MᵀM + I with
    /// M_ij = (((i+1)(j+2) mod 7) − 3)/3 (5 × 5), c outside [−1, 1]⁵ in
    /// four coordinates.
    fn coupled_quadratic() -> (Vec<f64>, Vec<f64>) {
        let n = 5;
        let m = |i: usize, j: usize| ((((i + 1) * (j + 2)) % 7) as f64 - 3.0) / 3.0;
        let mut a = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                a[i * n + j] = (0..n).map(|k| m(k, i) * m(k, j)).sum::<f64>();
            }
            a[i * n + i] += 1.0;
        }
        (a, vec![3.0, -2.0, 0.3, 4.0, -5.0])
    }

    #[test]
    fn several_bounds_become_active_in_one_iteration() {
        let (a, c) = coupled_quadratic();
        let n = c.len();
        let grad = |x: &[f64]| {
            let r: Vec<f64> = x.iter().zip(&c).map(|(x, c)| x - c).collect();
            (matvec(&a, &r), r)
        };
        let seen = std::cell::RefCell::new(Vec::<Vec<f64>>::new());
        let f = |x: &[f64]| {
            seen.borrow_mut().push(x.to_vec());
            let (ar, r) = grad(x);
            Ok((0.5 * dot(&r, &ar), ar))
        };
        let r = minimise(f, &[0.0; 5], &[-1.0; 5], &[1.0; 5], opts()).unwrap();
        assert!(r.converged);
        // Closed form: x_1 = x_4 = −1 and x_2 = x_3 = 1 at their bounds, x_0
        // minimising over its own coordinate given those; the gradient
        // pushes every bound variable outwards (KKT: the minimiser, as the
        // problem is convex).
        let mut xs = vec![0.0, -1.0, 1.0, 1.0, -1.0];
        xs[0] = c[0] - (1..n).map(|j| a[j] * (xs[j] - c[j])).sum::<f64>() / a[0];
        let (gs, _) = grad(&xs);
        assert!(gs[0].abs() < 1e-12 && gs[1] > 0.0 && gs[2] < 0.0 && gs[3] < 0.0 && gs[4] > 0.0);
        assert_eq!(r.x[1..], xs[1..]);
        assert!((r.x[0] - xs[0]).abs() < 1e-10, "{:?} vs {xs:?}", r.x);
        // The first trial point (the Cauchy point along the projected
        // gradient path) already has all four variables at their bounds.
        assert_eq!(seen.borrow()[1][1..], xs[1..]);
        // scipy 1.17.1's L-BFGS-B (pgtol 1e-9, ftol 0, memory 10): 4
        // evaluations in 3 iterations.
        assert_evaluations(&r, 4);
    }

    #[test]
    fn rosenbrock_with_an_active_bound() {
        // On [−2, 0.5] × [−2, 2] the minimiser is (0.5, 0.25): x at its upper
        // bound (∂f/∂x = −1 there), y = x².
        let r = minimise(rosenbrock, &[-1.2, 1.0], &[-2.0, -2.0], &[0.5, 2.0], opts()).unwrap();
        assert!(r.converged);
        assert_eq!(r.x[0], 0.5);
        assert!((r.x[1] - 0.25).abs() < 1e-9, "{:?}", r.x);
        // scipy 1.17.1's L-BFGS-B (pgtol 1e-9, ftol 0, memory 10): 30
        // evaluations in 20 iterations.
        assert_evaluations(&r, 30);
    }

    #[test]
    fn a_negligible_predicted_decrease_ends_the_run() {
        // Σ w_i (exp(x_i − a_i) − (x_i − a_i)), minimum Σ w_i at x = a; only
        // the ftol test can stop (pgtol 0).
        let (w, a) = ([1.0, 10.0, 100.0], [0.5, -1.0, 2.0]);
        let f = |x: &[f64]| {
            let mut v = 0.0;
            let mut g = vec![0.0; 3];
            for i in 0..3 {
                let u = x[i] - a[i];
                v += w[i] * (u.exp() - u);
                g[i] = w[i] * (u.exp() - 1.0);
            }
            Ok((v, g))
        };
        let ftol = 2.220446049250313e-9;
        let o = LbfgsOptions {
            pgtol: 0.0,
            ftol,
            ..opts()
        };
        let r = minimise(f, &[0.8, -1.05, 2.005], &[-5.0; 3], &[5.0; 3], o).unwrap();
        assert!(r.converged);
        // Stopped no further from the minimum than the ftol test allows.
        let fmin: f64 = w.iter().sum();
        assert!(r.f - fmin <= ftol * fmin, "f − f* = {}", r.f - fmin);
        // scipy 1.17.1's L-BFGS-B (same options): 11 evaluations in 9
        // iterations, the last of which decreases f by less than ftol
        // (vigp without the rule: the same 11). The start is close enough
        // that the first trial is scipy's (no variable moves by more than
        // FIRST_REACH).
        assert_evaluations(&r, 10);
    }

    /// Minimises 50·‖x − c‖² in the box [−10, 10]³ from (0.5, 0.5, 0.5);
    /// checks that the run converges to c and returns the first trial point.
    fn steep_quadratic_first_trial(c: [f64; 3], unit_start: bool) -> Vec<f64> {
        let mut points: Vec<Vec<f64>> = Vec::new();
        let f = |x: &[f64]| {
            points.push(x.to_vec());
            let v = (0..3).map(|i| 50.0 * (x[i] - c[i]).powi(2)).sum();
            let g = (0..3).map(|i| 100.0 * (x[i] - c[i])).collect();
            Ok((v, g))
        };
        let o = LbfgsOptions {
            unit_start,
            ..opts()
        };
        let r = minimise(f, &[0.5; 3], &[-10.0; 3], &[10.0; 3], o).unwrap();
        assert!(r.converged);
        for (v, c) in r.x.iter().zip(c) {
            assert!((v - c).abs() < 1e-8, "{:?}", r.x);
        }
        points.swap_remove(1)
    }

    #[test]
    fn unit_start_first_trial_is_a_unit_steepest_descent_step() {
        // A steep start, g = 100·(x − c): scipy's first trial is P(x − g),
        // the corner (10, −10, 10) of the box, 9.5 or more away in every variable;
        // with `unit_start` it is x − g/‖g‖₂, and both runs converge.
        let c = [3.0, -2.0, 1.0];
        let x0 = [0.5; 3];
        for unit_start in [false, true] {
            let first = steep_quadratic_first_trial(c, unit_start);
            let g0: Vec<f64> = (0..3).map(|i| 100.0 * (x0[i] - c[i])).collect();
            let gn = dot(&g0, &g0).sqrt();
            let expected: Vec<f64> = if unit_start {
                (0..3).map(|i| x0[i] - g0[i] / gn).collect()
            } else {
                vec![10.0, -10.0, 10.0]
            };
            for (p, e) in first.iter().zip(&expected) {
                assert!((p - e).abs() < 1e-12, "first trial {first:?}");
            }
        }
    }

    /// Σᵢ −½·tanh(3xᵢ) − 2·exp(−8(xᵢ − ½)²) in the box [−1, 2]²: a deep
    /// minimum near xᵢ = 0.5 and, towards the corner (2, 2), a plateau
    /// (gradient ≈ −2e-5 per variable, pushing out of the box) lower than
    /// the start 0.
    fn plateau(x: &[f64]) -> Result<(f64, Vec<f64>), GpError> {
        let mut v = 0.0;
        let mut g = Vec::with_capacity(x.len());
        for &t in x {
            let (th, e) = ((3.0 * t).tanh(), (-8.0 * (t - 0.5) * (t - 0.5)).exp());
            v += -0.5 * th - 2.0 * e;
            g.push(-1.5 * (1.0 - th * th) + 32.0 * (t - 0.5) * e);
        }
        Ok((v, g))
    }

    #[test]
    fn unit_start_leaves_a_corner_plateau_to_the_minimum() {
        // From 0, g ≈ −3.66 per variable: scipy's first trial is the
        // corner (2, 2); it meets the strong Wolfe conditions and the
        // projected gradient vanishes there, so scipy's iteration stops on
        // the plateau (f ≈ −1) instead of the minimum (f ≈ −4.9). With
        // `unit_start` the first trial is a unit steepest-descent step.
        let run = |unit_start| {
            let mut points: Vec<Vec<f64>> = Vec::new();
            let f = |x: &[f64]| {
                points.push(x.to_vec());
                plateau(x)
            };
            let o = LbfgsOptions {
                unit_start,
                ..opts()
            };
            let r = minimise(f, &[0.0; 2], &[-1.0; 2], &[2.0; 2], o).unwrap();
            (r, points)
        };
        let (scipy, sp) = run(false);
        assert!(scipy.corner_start);
        assert_eq!(sp[1], vec![2.0, 2.0]);
        assert_eq!(scipy.x, vec![2.0, 2.0]);
        assert!((scipy.f + 1.0).abs() < 1e-4, "{}", scipy.f);
        let (guarded, gp) = run(true);
        let g0 = plateau(&[0.0; 2]).unwrap().1;
        let gn = dot(&g0, &g0).sqrt();
        for (p, g) in gp[1].iter().zip(&g0) {
            assert!((p + g / gn).abs() < 1e-12, "first trial {:?}", gp[1]);
        }
        assert!(guarded.converged);
        // minimum: 3(1 − tanh²(3x))/2 = 32(x − ½)e^{−8(x−½)²}, x ≈ 0.5
        let best = plateau(&guarded.x).unwrap();
        assert!(best.0 < -4.8, "{:?} at {:?}", best.0, guarded.x);
        assert!(best.1.iter().all(|g| g.abs() < 1e-5), "{:?}", best.1);
    }

    #[test]
    fn unit_start_keeps_scipys_first_trial_unless_it_is_a_corner() {
        // g = 100·(x − c) with c₃ = x₃ + 0.001: x − g clips the first two
        // variables but not the third, so with or without `unit_start` the
        // first trial is scipy's P(x − g) = (10, −10, 0.6).
        for unit_start in [false, true] {
            let first = steep_quadratic_first_trial([3.0, -2.0, 0.501], unit_start);
            for (p, e) in first.iter().zip([10.0, -10.0, 0.6]) {
                assert!((p - e).abs() < 1e-12, "first trial {first:?}");
            }
        }
    }

    #[test]
    fn backtracking_below_a_negligible_decrease_ends_the_run() {
        // Rosenbrock + 1 carrying deterministic noise of 1e-7 (a hash of x's
        // bits), with ftol 1e-9: once the noise defeats the
        // sufficient-decrease test, the search must stop when its steps could
        // only decrease f by ftol·|f|, rather than shrink them to nothing
        // and retry with a cleared memory.
        let f = |x: &[f64]| {
            let h = x.iter().fold(0x9E37_79B9_7F4A_7C15u64, |h, v| {
                (h ^ v.to_bits()).wrapping_mul(0xBF58_476D_1CE4_E5B9)
            });
            let noise = 1e-7 * ((h >> 11) as f64 / (1u64 << 53) as f64 - 0.5);
            let (v, g) = rosenbrock(x)?;
            Ok((1.0 + v + noise, g))
        };
        let o = LbfgsOptions {
            ftol: 1e-9,
            ..opts()
        };
        let r = rosenbrock_run(f, o, [1e-3, 2e-3]);
        // 49 evaluations in 33 iterations; 69 without the rule.
        assert_evaluations(&r, 55);
    }

    #[test]
    fn a_seeded_memory_starts_with_a_quasi_newton_step() {
        // f(x) = c·(½ xᵀAx − bᵀx) on a wide box, A symmetric positive
        // definite and badly scaled (diagonal 1 … 400). A run on c = 1
        // leaves curvature pairs; seeded with them (y scaled by c = 4) a run
        // on c = 4 from a point near its end must reach the same minimiser
        // A⁻¹b in fewer evaluations than the same run unseeded.
        let n = 6;
        let a = |i: usize, j: usize| {
            if i == j {
                [1.0, 4.0, 20.0, 60.0, 150.0, 400.0][i]
            } else {
                0.5 / (1.0 + (i + j) as f64)
            }
        };
        let b: Vec<f64> = (0..n).map(|i| 1.0 + i as f64).collect();
        let b = &b;
        let quad = |c: f64| {
            move |x: &[f64]| -> Result<(f64, Vec<f64>), GpError> {
                let ax: Vec<f64> = (0..n)
                    .map(|i| (0..n).map(|j| a(i, j) * x[j]).sum())
                    .collect();
                let v = 0.5 * dot(x, &ax) - dot(b, x);
                let g = ax.iter().zip(b).map(|(p, q)| c * (p - q)).collect();
                Ok((c * v, g))
            }
        };
        let (lo, hi) = (vec![-50.0; n], vec![50.0; n]);
        // scipy's stopping rules (the GP's)
        let o = LbfgsOptions {
            ftol: 2.220446049250313e-9,
            pgtol: 1e-5,
            ..opts()
        };
        // eight iterations: curvature pairs of useful length (a converged
        // run's last pairs are steps of rounding size)
        let short = LbfgsOptions { max_iters: 8, ..o };
        let first = minimise(quad(1.0), &vec![3.0; n], &lo, &hi, short).unwrap();
        assert_eq!(first.memory.len(), 8);
        let x0: Vec<f64> = first.x.iter().map(|v| v + 0.5).collect();
        let cold = minimise(quad(4.0), &x0, &lo, &hi, o).unwrap();
        let warm = minimise_seeded(quad(4.0), &x0, &lo, &hi, o, &first.memory, 4.0).unwrap();
        // pairs of another dimension are skipped, not an error
        let odd = [(vec![1.0], vec![1.0])];
        let other = minimise_seeded(quad(4.0), &x0, &lo, &hi, o, &odd, 4.0).unwrap();
        assert_eq!(other.evaluations, cold.evaluations);
        println!(
            "cold {} evaluations, seeded {}",
            cold.evaluations, warm.evaluations
        );
        assert!(cold.converged && warm.converged);
        assert!(warm.evaluations < cold.evaluations);
        // both at the minimiser: f within the ftol test's reach of each other
        assert!(
            (warm.f - cold.f).abs() <= 1e-8 * cold.f.abs(),
            "{} vs {}",
            warm.f,
            cold.f
        );
    }
}
