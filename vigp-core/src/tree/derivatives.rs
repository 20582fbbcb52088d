//! The exact derivatives of the engine's step, A = ∂z₁/∂z₀ and
//! B = ∂z₁/∂u, by the implicit function theorem on the recursive residual,
//! without allocation: [`Engine::step_derivatives`] on caller-owned slices.
//!
//! Each converged sub-step of h solves
//! r = P(q₀, v₀) − P(q₁, v₁) + h·(∂T/∂q(q₁, v₁) − ∇V(q₁) − D·v₁ + S·u) = 0
//! with q₁ = q₀ + h·v₀, P(q, v) = M(q)v and S the input selection. With
//! J = ∂r/∂v₁ and K = ∂r/∂q₁ (at fixed q₀, v₀):
//!
//! ```text
//! ∂q₁/∂q₀ = 1,  ∂q₁/∂v₀ = h,
//! ∂v₁/∂q₀ = −J⁻¹(∂P/∂q(q₀, v₀) + K),  ∂v₁/∂v₀ = −J⁻¹(M(q₀) + h·K),
//! ∂v₁/∂u = −h·J⁻¹S.
//! ```
//!
//! A subdivided step chains its sub-steps' derivatives (A = A_s⋯A_1,
//! B = Σ A_s⋯A_{k+1} B_k). The terms' derivatives are the engine's closed
//! forms ([`Engine::term_derivatives`], O(N·depth) per sub-step); J has the
//! tree's pattern (an entry for each pair of bodies on one path from the
//! root) and is factored in it where the tree branches, leaves first,
//! without fill (O(Σ depth²)), else (chains, or a tiny pivot) by dense
//! Gaussian elimination with partial pivoting.

// Row-major matrices indexed as the equations write them.
#![allow(clippy::needless_range_loop)]

use super::engine::{
    BodyScratch, Engine, EngineError, EngineOptions, EngineReport, TermDerivatives, check_len,
    check_time_step,
};
use super::model::{Tree, ancestors};

/// Length (f64 entries) of the scratch of [`Engine::step_derivatives`]
/// for `n` bodies and `inputs` inputs: 12n² + 2n·inputs + 2n.
pub const fn derivative_scratch_len(n: usize, inputs: usize) -> usize {
    12 * n * n + 2 * n * inputs + 2 * n
}

/// The outputs and scratch of [`Engine::step_derivatives`].
#[derive(Debug)]
pub struct DerivativeBuffers<'a> {
    /// A = ∂z₁/∂z₀, z = (q, v): row-major 2N × 2N (4N² entries).
    pub a: &'a mut [f64],
    /// B = ∂z₁/∂u: row-major 2N × U (2N·U entries; U = the inputs).
    pub b: &'a mut [f64],
    /// At least [`derivative_scratch_len`]`(N, U)` numbers. Its first 2N²
    /// hold ∂P/∂q and M at the state on return: the next step of a
    /// rollout reuses them with `start_known`.
    pub scratch: &'a mut [f64],
    /// Whether `p` and the scratch's first 2N² entries already hold the
    /// momentum and its Jacobians at (q, v) (from the step before); else
    /// they are computed.
    pub start_known: bool,
}

/// Whether every entry is finite (a branch-free reduction, which the
/// compiler vectorizes).
fn all_finite(xs: &[f64]) -> bool {
    xs.iter().fold(true, |ok, x| ok & x.is_finite())
}

/// Factors in place, without pivoting, the row-major n × n matrix `jac`
/// whose entry (i, j) is zero unless body i is body j, an ancestor or a
/// descendant of it (the pattern of the mass matrix, and of the Newton
/// matrix −M + h·∂(∂T/∂q)/∂v − h·D): bodies are eliminated leaves first,
/// each against its ancestors only, which creates no entry outside the
/// pattern (Featherstone's LTL order). Afterwards (i, k), i an ancestor of
/// k, holds the multiplier J_ik/J_kk, and (k, j), j an ancestor of k or k
/// itself, the row that solves for x_k. O(Σ depth²) instead of O(N³).
/// `false` when a pivot is not finite or below 1e-10 of the largest
/// diagonal entry (then the dense, pivoting elimination is used).
fn tree_factor<T: Tree>(jac: &mut [f64], tree: &T) -> bool {
    let n = tree.len();
    let big = (0..n).fold(0.0f64, |m, i| m.max(jac[i * n + i].abs()));
    for k in (0..n).rev() {
        let pivot = jac[k * n + k];
        if !(pivot.is_finite() && pivot.abs() > 1e-10 * big) {
            return false;
        }
        for i in ancestors(tree, k) {
            let l = jac[i * n + k] / pivot;
            jac[i * n + k] = l;
            if l != 0.0 {
                for j in ancestors(tree, k) {
                    jac[i * n + j] -= l * jac[k * n + j];
                }
            }
        }
    }
    true
}

/// Row `i` of the row-major n × w matrix `x` minus `a` times its row `k`
/// (i ≠ k; nothing for a = 0).
#[inline(always)]
fn sub_row(x: &mut [f64], w: usize, i: usize, k: usize, a: f64) {
    if a == 0.0 {
        return;
    }
    let (dst, src) = if i > k {
        let (lo, hi) = x.split_at_mut(i * w);
        (&mut hi[..w], &lo[k * w..(k + 1) * w])
    } else {
        let (lo, hi) = x.split_at_mut(k * w);
        (&mut lo[i * w..(i + 1) * w], &hi[..w])
    };
    for (d, s) in dst.iter_mut().zip(src) {
        *d -= a * s;
    }
}

/// Row `k` of the row-major n × w matrix `x` divided by `d` (times 1/d).
#[inline(always)]
fn div_row(x: &mut [f64], w: usize, k: usize, d: f64) {
    let r = 1.0 / d;
    for v in &mut x[k * w..(k + 1) * w] {
        *v *= r;
    }
}

/// Solves J·X = R in place of the row-major n × w matrix `x` with the
/// factors of [`tree_factor`]: each column forward, leaves first
/// (r_i −= l_ik·r_k for the ancestors i of k), then backward, root first
/// (x_k from its row and its ancestors' x). O(Σ depth) per column.
fn tree_solve<T: Tree>(jac: &[f64], tree: &T, x: &mut [f64], w: usize) {
    let n = tree.len();
    for k in (0..n).rev() {
        for i in ancestors(tree, k) {
            sub_row(x, w, i, k, jac[i * n + k]);
        }
    }
    for k in 0..n {
        for j in ancestors(tree, k) {
            sub_row(x, w, k, j, jac[k * n + j]);
        }
        div_row(x, w, k, jac[k * n + k]);
    }
}

/// Solves J·X = R in place (J row-major n × n, destroyed; X row-major
/// n × w) by Gaussian elimination with partial pivoting: J = P·L·U in
/// place (the row swaps applied to X as they happen), then X by forward
/// and back substitution, a row of X at a time. `false` when a pivot is
/// zero or not finite.
pub(super) fn dense_solve(jac: &mut [f64], n: usize, x: &mut [f64], w: usize) -> bool {
    for k in 0..n {
        let (mut piv, mut best) = (k, jac[k * n + k].abs());
        for i in k + 1..n {
            let a = jac[i * n + k].abs();
            if a > best {
                (piv, best) = (i, a);
            }
        }
        if !(best.is_finite() && best > 0.0) {
            return false;
        }
        if piv != k {
            for j in 0..n {
                jac.swap(k * n + j, piv * n + j);
            }
            for c in 0..w {
                x.swap(k * w + c, piv * w + c);
            }
        }
        let r = 1.0 / jac[k * n + k];
        for i in k + 1..n {
            let l = jac[i * n + k] * r;
            jac[i * n + k] = l;
            if l != 0.0 {
                for j in k + 1..n {
                    jac[i * n + j] -= l * jac[k * n + j];
                }
            }
        }
    }
    substitute(jac, n, x, w);
    true
}

/// The row-major n × w matrix `x` replaced by U⁻¹L⁻¹x, L (unit lower)
/// and U the factors [`dense_solve`] left in `lu`, a whole row at a time:
/// row i minus l_ij times row j, j in order (each column sees the
/// operations of a column-by-column substitution, in the same order),
/// over rows contiguous in memory, which vectorizes.
fn substitute(lu: &[f64], n: usize, x: &mut [f64], w: usize) {
    for i in 1..n {
        let (done, rest) = x.split_at_mut(i * w);
        let xi = &mut rest[..w];
        for (j, xj) in done.chunks_exact(w).enumerate() {
            let f = lu[i * n + j];
            for (d, s) in xi.iter_mut().zip(xj) {
                *d -= f * s;
            }
        }
    }
    for i in (0..n).rev() {
        let (head, tail) = x.split_at_mut((i + 1) * w);
        let xi = &mut head[i * w..];
        for (j, xj) in tail.chunks_exact(w).enumerate() {
            let f = lu[i * n + i + 1 + j];
            for (d, s) in xi.iter_mut().zip(xj) {
                *d -= f * s;
            }
        }
        let r = 1.0 / lu[i * n + i];
        for d in xi.iter_mut() {
            *d *= r;
        }
    }
}

/// J = h·∂(∂T/∂q)/∂v − M − h·D into `jac` (row-major n × n).
fn newton_matrix(
    jac: &mut [f64],
    t_v: &[f64],
    p_v: &[f64],
    bodies: impl Iterator<Item = f64>,
    n: usize,
    h: f64,
) {
    for ((j, t), p) in jac.iter_mut().zip(t_v).zip(p_v) {
        *j = h * t - p;
    }
    for (i, d) in bodies.enumerate() {
        jac[i * n + i] -= h * d;
    }
}

impl<T: Tree> Engine<T> {
    /// One step of Δt = `dt` from (q, v) under the generalized forces `tau`
    /// (as [`Engine::step`]: q, v and p become the new state and momentum,
    /// subdivided as the options allow), with its exact derivatives into
    /// `out.a` = ∂(q₁, v₁)/∂(q₀, v₀) and `out.b` = ∂(q₁, v₁)/∂u, input c
    /// being a generalized force on coordinate `inputs[c]` (module docs).
    /// No allocation: `out.scratch` holds
    /// [`derivative_scratch_len`]`(N, inputs.len())` numbers.
    ///
    /// The state is that of [`Engine::step`] started from v (to the
    /// solver's tolerance); a sub-step whose Newton matrix is singular is
    /// [`EngineError::SingularNewtonMatrix`]. On an error, q, v and p are
    /// unspecified.
    #[allow(clippy::too_many_arguments)]
    pub fn step_derivatives(
        &self,
        q: &mut [f64],
        v: &mut [f64],
        p: &mut [f64],
        tau: &[f64],
        inputs: &[usize],
        dt: f64,
        out: DerivativeBuffers<'_>,
        ws: &mut [BodyScratch],
    ) -> Result<EngineReport, EngineError> {
        self.step_derivatives_guessed(q, v, p, tau, inputs, dt, None, out, ws)
    }

    /// [`Engine::step_derivatives`] with the iteration of the full step
    /// started at `guess` instead of v, as [`Engine::step_guessed`] starts
    /// it (a rollout passes an extrapolation of the last velocities; the
    /// state and its derivatives are the same to the solver's tolerance).
    /// A non-finite guess is ignored.
    #[allow(clippy::too_many_arguments)]
    pub fn step_derivatives_guessed(
        &self,
        q: &mut [f64],
        v: &mut [f64],
        p: &mut [f64],
        tau: &[f64],
        inputs: &[usize],
        dt: f64,
        guess: Option<&[f64]>,
        out: DerivativeBuffers<'_>,
        ws: &mut [BodyScratch],
    ) -> Result<EngineReport, EngineError> {
        check_time_step(dt)?;
        let n = self.dof();
        let u = inputs.len();
        for (what, got) in [
            ("q", q.len()),
            ("v", v.len()),
            ("p", p.len()),
            ("tau", tau.len()),
        ] {
            check_len(what, got, n)?;
        }
        check_len("a", out.a.len(), 4 * n * n)?;
        check_len("b", out.b.len(), 2 * n * u)?;
        if out.scratch.len() < derivative_scratch_len(n, u) {
            return Err(EngineError::WrongLength {
                what: "scratch",
                expected: derivative_scratch_len(n, u),
                got: out.scratch.len(),
            });
        }
        if inputs.iter().any(|&i| i >= n) {
            return Err(EngineError::InvalidOptions(
                "an input acts on no coordinate",
            ));
        }
        let (start, rest) = out.scratch.split_at_mut(2 * n * n);
        if !out.start_known {
            let (sp_q, sp_v) = start.split_at_mut(n * n);
            self.momentum_derivatives(q, v, p, sp_q, sp_v, ws)?;
        }
        let (terms, rest) = rest.split_at_mut(5 * n * n);
        let (jac, rest) = rest.split_at_mut(n * n);
        let w = 2 * n + u;
        let (x, rest) = rest.split_at_mut(n * w);
        let (tmp, rest) = rest.split_at_mut(n * w);
        let (q0, rest) = rest.split_at_mut(n);
        let v0 = &mut rest[..n];
        let options = *self.options();
        // one sub-step at a time: the engine's own step without subdivision
        let single = self.with_options_borrowed(EngineOptions {
            max_depth: 0,
            ..options
        })?;
        let branches = self.branched;
        let mut report = EngineReport::default();
        let (mut depth, mut done, mut total, mut first) = (0u32, 0usize, 1usize, true);
        while done < total {
            let h = dt / total as f64;
            q0.copy_from_slice(q);
            v0.copy_from_slice(v);
            let first_guess = if total == 1 { guess } else { None };
            let failed = match single.step_guessed(q, v, p, tau, h, first_guess, ws) {
                Ok(r) => {
                    report.iterations += r.iterations;
                    report.substeps += 1;
                    report.residual = report.residual.max(r.residual);
                    done += 1;
                    self.substep_derivatives(h, inputs, start, terms, jac, x, branches, ws)?;
                    chain(out.a, out.b, x, tmp, n, u, h, first);
                    first = false;
                    continue;
                }
                Err(EngineError::NotConverged {
                    iterations,
                    residual,
                    ..
                }) => {
                    report.iterations += iterations;
                    EngineError::NotConverged {
                        depth,
                        substep_dt: h,
                        iterations,
                        residual,
                    }
                }
                Err(EngineError::EnergyJump { jump, .. }) => EngineError::EnergyJump {
                    depth,
                    substep_dt: h,
                    jump,
                },
                Err(e) => return Err(e),
            };
            if depth >= options.max_depth || !(h * 0.5 * h * 0.5).is_normal() {
                return Err(failed);
            }
            // a failed sub-step leaves p as it was
            q.copy_from_slice(q0);
            v.copy_from_slice(v0);
            depth += 1;
            done *= 2;
            total *= 2;
        }
        report.depth = depth;
        if !(all_finite(out.a) && all_finite(out.b)) {
            return Err(EngineError::SingularNewtonMatrix);
        }
        Ok(report)
    }

    /// −∂v₁/∂(q₀, v₀, u) of one sub-step of h, right after it converged
    /// (`ws` as it left it, at its end (q₁, v₁)), into `x` (row-major
    /// N × (2N + U)), from the momentum Jacobians `start` at its start;
    /// `start` then holds them at its end.
    #[allow(clippy::too_many_arguments)]
    fn substep_derivatives(
        &self,
        h: f64,
        inputs: &[usize],
        start: &mut [f64],
        terms: &mut [f64],
        jac: &mut [f64],
        x: &mut [f64],
        branches: bool,
        ws: &mut [BodyScratch],
    ) -> Result<(), EngineError> {
        let n = self.dof();
        let w = 2 * n + inputs.len();
        // the converged sub-step left in `ws` what the momentum pass at
        // (q₁, v₁) computes, bit for bit: the kinematics at q₁ = q₀ + h·v₀
        // (fixed through the iteration) and the twists and composite
        // momenta of the last iterate, v₁
        let mut blocks = TermDerivatives::split(terms, n);
        self.loaded_term_derivatives(&mut blocks, ws);
        let TermDerivatives {
            p_q,
            p_v,
            t_q,
            t_v,
            v_q,
        } = blocks;
        // K = ∂r/∂q₁ = h·(∂(∂T/∂q)/∂q − ∂(∇V)/∂q) − ∂P/∂q, in t_q
        for ((k, vq), pq) in t_q.iter_mut().zip(v_q.iter()).zip(p_q.iter()) {
            *k = h * (*k - vq) - pq;
        }
        // J·X = [∂P/∂q(q₀, v₀) + K | M(q₀) + h·K | h·S]
        let (s_q, s_v) = start.split_at(n * n);
        for i in 0..n {
            for j in 0..n {
                let k = t_q[i * n + j];
                x[i * w + j] = s_q[i * n + j] + k;
                x[i * w + n + j] = s_v[i * n + j] + h * k;
            }
            for c in 0..inputs.len() {
                x[i * w + 2 * n + c] = if inputs[c] == i { h } else { 0.0 };
            }
        }
        let tree = self.tree();
        let damping = || (0..n).map(|i| tree.body(i).damping);
        newton_matrix(jac, t_v, p_v, damping(), n, h);
        let mut solved = false;
        if branches {
            if tree_factor(jac, self.tree()) {
                tree_solve(jac, self.tree(), x, w);
                solved = true;
            } else {
                newton_matrix(jac, t_v, p_v, damping(), n, h);
            }
        }
        if !solved && !dense_solve(jac, n, x, w) {
            return Err(EngineError::SingularNewtonMatrix);
        }
        // the next sub-step starts here
        start[..n * n].copy_from_slice(p_q);
        start[n * n..2 * n * n].copy_from_slice(p_v);
        Ok(())
    }
}

/// A ← A_s·A and B ← A_s·B + B_s for the sub-step's A_s = [[I, h·I],
/// [−X_q, −X_v]] and B_s = [0; −X_u] (X from the sub-step's solve, row-major
/// N × (2N + U)); the first sub-step sets A = A_s and B = B_s. A is
/// row-major 2N × 2N, B 2N × U; `tmp` holds N × (2N + U).
#[allow(clippy::too_many_arguments)]
fn chain(
    a: &mut [f64],
    b: &mut [f64],
    x: &[f64],
    tmp: &mut [f64],
    n: usize,
    u: usize,
    h: f64,
    first: bool,
) {
    let w = 2 * n + u;
    let (n2, m) = (2 * n, n * 2 * n);
    if first {
        a.fill(0.0);
        b.fill(0.0);
        for i in 0..n {
            a[i * n2 + i] = 1.0;
            a[i * n2 + n + i] = h;
            for j in 0..n2 {
                a[m + i * n2 + j] = -x[i * w + j];
            }
            for c in 0..u {
                b[(n + i) * u + c] = -x[i * w + n2 + c];
            }
        }
        return;
    }
    // the new bottom rows: −X_q·A_top − X_v·A_bottom (and the same for B, − X_u)
    let (bt, bb) = tmp.split_at_mut(n * n2);
    for i in 0..n {
        for j in 0..n2 {
            let mut s = 0.0;
            for k in 0..n {
                s += x[i * w + k] * a[k * n2 + j] + x[i * w + n + k] * a[m + k * n2 + j];
            }
            bt[i * n2 + j] = -s;
        }
        for c in 0..u {
            let mut s = x[i * w + n2 + c];
            for k in 0..n {
                s += x[i * w + k] * b[k * u + c] + x[i * w + n + k] * b[(n + k) * u + c];
            }
            bb[i * u + c] = -s;
        }
    }
    // the new top rows: A_top + h·A_bottom (q₁ = q₀ + h·v₀)
    for i in 0..n {
        for j in 0..n2 {
            a[i * n2 + j] += h * a[m + i * n2 + j];
        }
        for c in 0..u {
            b[i * u + c] += h * b[(n + i) * u + c];
        }
    }
    a[m..].copy_from_slice(bt);
    b[n * u..].copy_from_slice(&bb[..n * u]);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The pivoting elimination against a hand-solved 3 × 3 system with a
    /// zero leading entry (so that it must pivot).
    #[test]
    fn dense_solve_pivots() {
        let mut j = [0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, 0.0, 1.0];
        // x = (1, 2, 3): J·x = (7, 3, 6)
        let mut x = [7.0, 3.0, 6.0];
        assert!(dense_solve(&mut j, 3, &mut x, 1));
        for (got, want) in x.iter().zip([1.0, 2.0, 3.0]) {
            assert!((got - want).abs() < 1e-14, "{x:?}");
        }
        // five right-hand sides: one block of four columns and one more;
        // X's columns are (1, 2, 3) scaled by c + 1, and (0, 0, 1) for the last
        let mut j = [0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, 0.0, 1.0];
        let mut x = [0.0; 15];
        for (i, r) in [7.0, 3.0, 6.0].iter().enumerate() {
            for c in 0..4 {
                x[i * 5 + c] = r * (c + 1) as f64;
            }
            x[i * 5 + 4] = [1.0, 0.0, 1.0][i];
        }
        assert!(dense_solve(&mut j, 3, &mut x, 5));
        for i in 0..3 {
            for c in 0..5 {
                let want = if c < 4 {
                    (i + 1) as f64 * (c + 1) as f64
                } else {
                    [0.0, 0.0, 1.0][i]
                };
                assert!((x[i * 5 + c] - want).abs() < 1e-14, "{x:?}");
            }
        }
        let mut singular = [1.0, 2.0, 2.0, 4.0];
        assert!(!dense_solve(&mut singular, 2, &mut [1.0, 1.0], 1));
    }
}
