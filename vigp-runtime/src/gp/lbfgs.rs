//! Projected L-BFGS with a Moré–Thuente line search for box-constrained
//! minimisation.
//!
//! Why hand-written: `argmin` 0.11 has L-BFGS without bounds, and the pure-Rust
//! L-BFGS-B ports on crates.io are young single-author 0.1 releases. GP
//! hyperparameter problems have d + 2 ≤ a few dozen variables, where an
//! active-set quasi-Newton method (Bertsekas 1982; Kim, Sra & Dhillon 2010)
//! with the line search of scipy's L-BFGS-B is simple, deterministic and
//! spends as few evaluations:
//!
//! * the active set holds the variables at a bound whose gradient pushes
//!   outwards; the L-BFGS two-loop direction is computed on the free
//!   variables (steepest descent if that is not a descent direction);
//! * the step runs along the straight line x + t·d, t ∈ (0, t_max], with t_max
//!   the largest step that stays in the box (a variable that reaches its
//!   bound becomes active in the next iteration); t is found by the
//!   Moré–Thuente line search (Moré & Thuente 1994, MINPACK-2 `dcsrch` /
//!   `dcstep`, the search scipy's L-BFGS-B uses) with the same constants:
//!   sufficient decrease 1e-3, curvature 0.9 (strong Wolfe), interval
//!   tolerance 0.1, at most 20 evaluations; the first trial step is 1, or
//!   min(1/‖d‖₂, t_max) with an empty memory;
//! * an evaluation that fails (e.g. a kernel matrix that is not positive
//!   definite) or is not finite shrinks the trial step towards the best point;
//! * a line search that fails clears the memory and retries once along the
//!   steepest-descent direction; curvature pairs with sᵀy ≤ ε·‖s‖‖y‖ are
//!   skipped, so the inverse-Hessian approximation stays positive definite;
//! * stop (scipy's tests) when ‖P(x − g) − x‖∞ ≤ `pgtol`, or the relative
//!   decrease (f_k − f_{k+1})/max(|f_k|, |f_{k+1}|, 1) ≤ `ftol`, or after
//!   `max_iters` iterations.

use std::collections::VecDeque;

use super::error::GpError;

/// Options of [`minimise`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct LbfgsOptions {
    pub memory: usize,
    pub max_iters: usize,
    pub pgtol: f64,
    pub ftol: f64,
}

/// Outcome of [`minimise`].
#[derive(Clone, Debug)]
pub(crate) struct LbfgsResult {
    pub x: Vec<f64>,
    pub f: f64,
    pub iterations: usize,
    pub evaluations: usize,
    pub converged: bool,
}

/// Line-search constants of scipy's L-BFGS-B (`lnsrlb`).
const LS_FTOL: f64 = 1e-3;
const LS_GTOL: f64 = 0.9;
const LS_XTOL: f64 = 0.1;
const LS_MAX_EVALS: usize = 20;
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
        let s = theta.abs().max(dx.abs()).max(dp.abs());
        let mut gamma = s * ((theta / s).powi(2) - (*dx / s) * (dp / s)).max(0.0).sqrt();
        if *stp < *stx {
            gamma = -gamma;
        }
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
        let s = theta.abs().max(dx.abs()).max(dp.abs());
        let mut gamma = s * ((theta / s).powi(2) - (*dx / s) * (dp / s)).max(0.0).sqrt();
        if *stp > *stx {
            gamma = -gamma;
        }
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
        let s = theta.abs().max(dx.abs()).max(dp.abs());
        let mut gamma = s * ((theta / s).powi(2) - (*dx / s) * (dp / s)).max(0.0).sqrt();
        if *stp > *stx {
            gamma = -gamma;
        }
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
            let s = theta.abs().max(dy.abs()).max(dp.abs());
            let mut gamma = s * ((theta / s).powi(2) - (*dy / s) * (dp / s)).max(0.0).sqrt();
            if *stp > *sty {
                gamma = -gamma;
            }
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

/// Minimises `f` (returning value and gradient) over the box [lo, hi] from x0.
pub(crate) fn minimise<F>(
    mut f: F,
    x0: &[f64],
    lo: &[f64],
    hi: &[f64],
    opt: LbfgsOptions,
) -> Result<LbfgsResult, GpError>
where
    F: FnMut(&[f64]) -> Result<(f64, Vec<f64>), GpError>,
{
    let n = x0.len();
    let mut x = x0.to_vec();
    project(&mut x, lo, hi);
    let (mut fx, mut g) = f(&x)?;
    if !fx.is_finite() || g.iter().any(|v| !v.is_finite()) {
        return Err(GpError::OptimiserFailed {
            output: 0,
            reason: "objective not finite at the starting point".into(),
        });
    }
    let mut evaluations = 1;
    // The last evaluated points with their values and gradients.
    let mut recent: VecDeque<(Vec<f64>, f64, Vec<f64>)> = VecDeque::with_capacity(RECENT);
    recent.push_back((x.clone(), fx, g.clone()));
    let mut mem: VecDeque<(Vec<f64>, Vec<f64>, f64)> = VecDeque::new();
    let mut converged = false;
    let mut iterations = 0;
    let mut trial = vec![0.0; n];
    while iterations < opt.max_iters {
        if projected_gradient_norm(&x, &g, lo, hi) <= opt.pgtol {
            converged = true;
            break;
        }
        iterations += 1;
        let active: Vec<bool> = (0..n)
            .map(|i| (x[i] <= lo[i] && g[i] > 0.0) || (x[i] >= hi[i] && g[i] < 0.0))
            .collect();
        let mut accepted = None;
        for attempt in 0..2 {
            if attempt == 1 {
                if mem.is_empty() {
                    break;
                }
                mem.clear();
            }
            let mut d = direction(&g, &active, &mem);
            if dot(&g, &d) >= 0.0 {
                d = (0..n)
                    .map(|i| if active[i] { 0.0 } else { -g[i] })
                    .collect();
            }
            // Free variables already at a bound that d would cross cannot move.
            for i in 0..n {
                if (x[i] <= lo[i] && d[i] < 0.0) || (x[i] >= hi[i] && d[i] > 0.0) {
                    d[i] = 0.0;
                }
            }
            let slope = dot(&g, &d);
            if slope >= 0.0 || d.iter().all(|v| *v == 0.0) {
                continue;
            }
            // Largest step that stays in the box.
            let mut tmax = f64::INFINITY;
            for i in 0..n {
                if d[i] > 0.0 {
                    tmax = tmax.min((hi[i] - x[i]) / d[i]);
                } else if d[i] < 0.0 {
                    tmax = tmax.min((lo[i] - x[i]) / d[i]);
                }
            }
            let dnorm = dot(&d, &d).sqrt();
            let mut stp = if mem.is_empty() { 1.0 / dnorm } else { 1.0 };
            stp = stp.min(tmax);
            if stp.is_nan() || stp <= 0.0 {
                continue;
            }
            let mut ls = MoreThuente::new(fx, slope, stp, 0.0, tmax);
            // The best (lowest f) trial of this search: returned if the
            // search stops without meeting the Wolfe conditions.
            let mut best: Option<(f64, f64, Vec<f64>, Vec<f64>)> = None;
            let mut done = false;
            for _ in 0..LS_MAX_EVALS {
                for i in 0..n {
                    trial[i] = x[i] + stp * d[i];
                }
                // Land exactly on the bound at t_max (rounding can overshoot).
                project(&mut trial, lo, hi);
                // A trial that repeats a recent point (a search that falls
                // back to its start or its best step, with steps below the
                // resolution of x, as rounding noise in f causes) reuses
                // that evaluation: the same path, without paying twice.
                let r = match recent.iter().find(|(p, _, _)| *p == trial) {
                    Some((_, v, gr)) => Some((*v, gr.clone())),
                    None => {
                        evaluations += 1;
                        let r = f(&trial)
                            .ok()
                            .filter(|(v, gr)| v.is_finite() && gr.iter().all(|q| q.is_finite()));
                        if let Some((v, gr)) = &r {
                            if recent.len() == RECENT {
                                recent.pop_front();
                            }
                            recent.push_back((trial.clone(), *v, gr.clone()));
                        }
                        r
                    }
                };
                let Some((ft, gt)) = r else {
                    stp = ls.failed(stp);
                    if stp.is_nan() || stp <= 1e-20 * ls.stpmax.max(1e-300) {
                        break;
                    }
                    continue;
                };
                if ft < fx && best.as_ref().is_none_or(|b| ft < b.1) {
                    best = Some((stp, ft, trial.clone(), gt.clone()));
                }
                match ls.next(stp, ft, dot(&gt, &d)) {
                    Search::Converged => {
                        best = Some((stp, ft, trial.clone(), gt));
                        done = true;
                        break;
                    }
                    Search::Stop => break,
                    Search::Evaluate(s) => {
                        if s == ls.best() && best.as_ref().is_some_and(|b| b.0 == s) {
                            // The search falls back to its best point, already evaluated.
                            break;
                        }
                        stp = s;
                    }
                }
            }
            let _ = done;
            if let Some((_, ft, xt, gt)) = best {
                accepted = Some((ft, xt, gt));
                break;
            }
        }
        let Some((fn_, xn, gn)) = accepted else {
            // No decrease along any direction: a (numerical) stationary point.
            converged = true;
            break;
        };
        let s: Vec<f64> = xn.iter().zip(&x).map(|(a, b)| a - b).collect();

        let y: Vec<f64> = gn.iter().zip(&g).map(|(a, b)| a - b).collect();
        let sy = dot(&s, &y);
        if sy > f64::EPSILON * dot(&y, &y).sqrt() * dot(&s, &s).sqrt() && sy > 0.0 {
            if mem.len() == opt.memory {
                mem.pop_front();
            }
            mem.push_back((s, y, 1.0 / sy));
        }
        let f_old = fx;
        x = xn;
        fx = fn_;
        g = gn;
        if (f_old - fx) <= opt.ftol * f_old.abs().max(fx.abs()).max(1.0) {
            converged = true;
            break;
        }
    }
    Ok(LbfgsResult {
        x,
        f: fx,
        iterations,
        evaluations,
        converged,
    })
}

/// Two-loop recursion on the free variables: d = −H·g with active entries zeroed.
fn direction(g: &[f64], active: &[bool], mem: &VecDeque<(Vec<f64>, Vec<f64>, f64)>) -> Vec<f64> {
    let mut q: Vec<f64> = g
        .iter()
        .zip(active)
        .map(|(v, a)| if *a { 0.0 } else { *v })
        .collect();
    let mut alphas = Vec::with_capacity(mem.len());
    for (s, y, rho) in mem.iter().rev() {
        let a = rho * dot(s, &q);
        for (qi, yi) in q.iter_mut().zip(y) {
            *qi -= a * yi;
        }
        alphas.push(a);
    }
    if let Some((s, y, _)) = mem.back() {
        let gamma = dot(s, y) / dot(y, y);
        q.iter_mut().for_each(|v| *v *= gamma);
    }
    for ((s, y, rho), a) in mem.iter().zip(alphas.iter().rev()) {
        let b = rho * dot(y, &q);
        for (qi, si) in q.iter_mut().zip(s) {
            *qi += (a - b) * si;
        }
    }
    q.iter()
        .zip(active)
        .map(|(v, a)| if *a { 0.0 } else { -v })
        .collect()
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
        }
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

    #[test]
    fn rosenbrock_unconstrained_interior() {
        let r = minimise(rosenbrock, &[-1.2, 1.0], &[-5.0, -5.0], &[5.0, 5.0], opts()).unwrap();
        assert!(r.converged);
        // Minimiser (1, 1); pgtol 1e-9 on a well-conditioned-near-optimum problem
        // gives ~1e-8 accuracy in x.
        assert!(
            (r.x[0] - 1.0).abs() < 1e-6 && (r.x[1] - 1.0).abs() < 1e-6,
            "{:?}",
            r.x
        );
        // scipy 1.17.1's L-BFGS-B on the same problem (box [−5, 5]², pgtol
        // 1e-9, ftol 0, memory 10) takes 51 evaluations in 36 iterations.
        println!("{} evaluations, {} iterations", r.evaluations, r.iterations);
        assert!(r.evaluations <= 51, "{} evaluations", r.evaluations);
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
}
