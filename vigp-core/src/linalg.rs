//! Small fixed-size dense solvers for the Newton steps.
//!
//! nalgebra's decompositions need `ToTypenum` bounds on const-generic sizes,
//! which generic runtime code cannot state on stable Rust; these solvers work
//! on `SMatrix<f64, M, M>` for any const `M`, without allocation.

use nalgebra::{SMatrix, SVector};

/// LU factorisation with complete (row and column) pivoting,
/// P·A·Q = L·U, rank-revealing.
///
/// Complexity O(M³) to factor, O(M²) per solve. Pivots below
/// `rel_tol · |largest entry|` are treated as zero: the numerical rank is
/// reported and the solution sets the corresponding free unknowns to zero (a
/// basic least-squares-compatible solution, exact when the system is
/// consistent).
#[derive(Clone, Copy, Debug)]
pub struct FullPivLu<const M: usize> {
    lu: SMatrix<f64, M, M>,
    rows: [usize; M],
    cols: [usize; M],
    rank: usize,
}

impl<const M: usize> FullPivLu<M> {
    /// Factor `a`; `rel_tol` is the relative pivot threshold (e.g. 1e-14).
    pub fn new(mut a: SMatrix<f64, M, M>, rel_tol: f64) -> Self {
        let mut rows = [0; M];
        let mut cols = [0; M];
        for i in 0..M {
            rows[i] = i;
            cols[i] = i;
        }
        let scale = a.amax();
        let mut rank = M;
        for k in 0..M {
            let (mut pi, mut pj, mut best) = (k, k, -1.0);
            for j in k..M {
                for i in k..M {
                    let v = a[(i, j)].abs();
                    if v > best {
                        (pi, pj, best) = (i, j, v);
                    }
                }
            }
            if best <= rel_tol * scale || best == 0.0 || best.is_nan() {
                rank = k;
                break;
            }
            a.swap_rows(k, pi);
            a.swap_columns(k, pj);
            rows.swap(k, pi);
            cols.swap(k, pj);
            let p = a[(k, k)];
            for i in k + 1..M {
                let f = a[(i, k)] / p;
                a[(i, k)] = f;
                for j in k + 1..M {
                    a[(i, j)] -= f * a[(k, j)];
                }
            }
        }
        Self {
            lu: a,
            rows,
            cols,
            rank,
        }
    }

    /// Numerical rank.
    pub fn rank(&self) -> usize {
        self.rank
    }

    /// Solve A x = b (free unknowns beyond the rank set to zero).
    pub fn solve(&self, b: &SVector<f64, M>) -> SVector<f64, M> {
        let mut y = SVector::<f64, M>::zeros();
        for i in 0..M {
            y[i] = b[self.rows[i]];
        }
        for i in 0..self.rank {
            let mut s = y[i];
            for j in 0..i {
                s -= self.lu[(i, j)] * y[j];
            }
            y[i] = s;
        }
        let mut z = SVector::<f64, M>::zeros();
        for i in (0..self.rank).rev() {
            let mut s = y[i];
            for j in i + 1..self.rank {
                s -= self.lu[(i, j)] * z[j];
            }
            z[i] = s / self.lu[(i, i)];
        }
        let mut x = SVector::<f64, M>::zeros();
        for i in 0..M {
            x[self.cols[i]] = z[i];
        }
        x
    }

    /// Solve A X = B column by column.
    pub fn solve_matrix<const K: usize>(&self, b: &SMatrix<f64, M, K>) -> SMatrix<f64, M, K> {
        solve_columns(b, |col| self.solve(col))
    }
}

/// X with column k = `solve(B column k)`: a factorisation's
/// `solve_matrix` from its vector solve.
#[inline]
fn solve_columns<const M: usize, const K: usize>(
    b: &SMatrix<f64, M, K>,
    solve: impl Fn(&SVector<f64, M>) -> SVector<f64, M>,
) -> SMatrix<f64, M, K> {
    let mut x = SMatrix::<f64, M, K>::zeros();
    for k in 0..K {
        x.set_column(k, &solve(&b.column(k).into_owned()));
    }
    x
}

/// LU factorisation with partial (row) pivoting, P·A = L·U, for
/// well-conditioned matrices such as Newton matrices that perturb −M
/// (O(M³/3) to factor, O(M²) per solve; cheaper than [`FullPivLu`]'s
/// complete pivoting, which searches the whole trailing block per column).
#[derive(Clone, Copy, Debug)]
pub struct PartialLu<const M: usize> {
    // row-major: plain arrays let the compiler drop the bounds checks that
    // nalgebra's (row, column) indexing keeps in these loops
    lu: [[f64; M]; M],
    perm: [usize; M],
}

impl<const M: usize> PartialLu<M> {
    /// Factor `a`; `None` when a pivot is below `rel_tol · |largest entry|`
    /// or not finite (singular or ill-conditioned for partial pivoting: use
    /// [`FullPivLu`]).
    pub fn new(a: SMatrix<f64, M, M>, rel_tol: f64) -> Option<Self> {
        let mut lu = [[0.0f64; M]; M];
        for (i, row) in lu.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                *x = a[(i, j)];
            }
        }
        Self::from_rows(lu, rel_tol)
    }

    /// [`PartialLu::new`] from the rows of A (`rows[i][j]` = A_ij).
    // inlined: out of line, the rows and the factors are copied in and out
    // (memcpy) at every call, which costs a tenth of a 10×10 factorisation
    #[inline(always)]
    pub fn from_rows(rows: [[f64; M]; M], rel_tol: f64) -> Option<Self> {
        let mut lu = Self {
            lu: rows,
            perm: [0; M],
        };
        lu.factor(rel_tol).then_some(lu)
    }

    /// Factor in place: `self.lu` holds the rows of A on entry, its factors
    /// on return; `false` where [`PartialLu::from_rows`] gives `None` (the
    /// factors are then partial). In place, a caller that keeps the factors
    /// (`SchurFactor`) forms A where they will stay instead of copying it
    /// there and the factors back.
    #[inline(always)]
    fn factor(&mut self, rel_tol: f64) -> bool {
        let Self { lu, perm } = self;
        // max |a_ij| by plain comparisons (which ignore NaN as `f64::max`
        // does, without its NaN bookkeeping); a NaN that reaches a pivot is
        // refused below
        let mut amax = 0.0f64;
        for row in lu.iter() {
            for x in row {
                let a = x.abs();
                if a > amax {
                    amax = a;
                }
            }
        }
        let tiny = rel_tol * amax;
        for (i, p) in perm.iter_mut().enumerate() {
            *p = i;
        }
        for k in 0..M {
            let mut p = k;
            for i in k + 1..M {
                if lu[i][k].abs() > lu[p][k].abs() {
                    p = i;
                }
            }
            let pivot = lu[p][k];
            if pivot.abs() <= tiny || !pivot.is_finite() {
                return false;
            }
            if p != k {
                lu.swap(k, p);
                perm.swap(k, p);
            }
            let inv = 1.0 / pivot;
            let pivot_row = lu[k];
            for row in lu.iter_mut().skip(k + 1) {
                // a zero below the pivot (Schur complements of mechanisms
                // are block-banded: constraints on different bodies do not
                // couple) needs no elimination: the row is unchanged, as
                // subtracting 0·pivot_row would leave it (up to the sign of
                // a zero; a NaN in the pivot row still reaches the solution
                // through back substitution, where callers test finiteness)
                if row[k] == 0.0 {
                    continue;
                }
                let f = row[k] * inv;
                row[k] = f;
                for j in k + 1..M {
                    row[j] -= f * pivot_row[j];
                }
            }
        }
        true
    }

    /// min |u_kk| / max |u_kk| over U's diagonal: a cheap indicator of
    /// ill-conditioning (a ratio of 1e-8 means that A⁻¹ may lose about
    /// eight digits). Not an estimate of 1/cond(A) with guarantees: partial
    /// pivoting can leave a nearly singular A with no small pivot, rarely.
    pub fn pivot_ratio(&self) -> f64 {
        let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
        for (k, row) in self.lu.iter().enumerate() {
            let u = row[k].abs();
            lo = lo.min(u);
            hi = hi.max(u);
        }
        if hi > 0.0 { lo / hi } else { 0.0 }
    }

    /// Solve A x = b.
    // forward and back substitution read as the textbook formulas
    #[allow(clippy::needless_range_loop)]
    pub fn solve(&self, b: &SVector<f64, M>) -> SVector<f64, M> {
        SVector::from(self.solve_array(b.as_slice()))
    }

    /// [`PartialLu::solve`] on plain arrays (`b` has length M).
    // forward and back substitution read as the textbook formulas
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    pub fn solve_array(&self, b: &[f64]) -> [f64; M] {
        let mut x = [0.0f64; M];
        for i in 0..M {
            x[i] = b[self.perm[i]];
        }
        for i in 0..M {
            let mut s = x[i];
            for j in 0..i {
                s -= self.lu[i][j] * x[j];
            }
            x[i] = s;
        }
        for i in (0..M).rev() {
            let mut s = x[i];
            for j in i + 1..M {
                s -= self.lu[i][j] * x[j];
            }
            x[i] = s / self.lu[i][i];
        }
        x
    }

    /// Solve A X = B column by column.
    pub fn solve_matrix<const K: usize>(&self, b: &SMatrix<f64, M, K>) -> SMatrix<f64, M, K> {
        solve_columns(b, |col| self.solve(col))
    }
}

/// Solve A x = b by Gaussian elimination with partial (row) pivoting, for
/// well-conditioned systems such as the Newton matrix of a tree step (a
/// perturbation of −M). O(M³), no allocation. `None` when a pivot is
/// below `1e-14 · |largest entry|` or not finite.
///
/// For `M ≤ 2` the solution is in closed form (one division; Cramer's rule
/// is forward stable for 2×2 systems, Higham, *Accuracy and Stability of
/// Numerical Algorithms*, 2nd ed., §1.10.1) unless the determinant is below
/// `1e-14 · |largest entry|²`, where elimination decides as for larger `M`.
#[inline(always)]
pub fn solve_partial<const M: usize>(
    a: &SMatrix<f64, M, M>,
    b: &SVector<f64, M>,
) -> Option<SVector<f64, M>> {
    // max |a_ij| (nalgebra's amax goes through generic SIMD comparisons
    // that cost more than the 2×2 solve itself). `f64::max` drops NaN; a
    // NaN or ∞ entry makes the determinant or a pivot non-finite, which the
    // checks below refuse.
    let mut amax = 0.0f64;
    for x in a.iter() {
        amax = amax.max(x.abs());
    }

    let tiny = 1e-14 * amax;
    if M == 1 {
        let d = a[(0, 0)];
        return (d.abs() > tiny && d.is_finite()).then(|| b / d);
    }
    if M == 2 {
        let (a00, a01, a10, a11) = (a[(0, 0)], a[(0, 1)], a[(1, 0)], a[(1, 1)]);
        let det = a00 * a11 - a01 * a10;
        if det.abs() > tiny * amax && det.is_finite() {
            let r = 1.0 / det;
            let mut x = *b;
            x[0] = (b[0] * a11 - a01 * b[1]) * r;
            x[1] = (a00 * b[1] - a10 * b[0]) * r;
            return Some(x);
        }
    }
    // NaN or ±∞ somewhere (x·0 is NaN exactly then): the closed forms above
    // caught it through the determinant
    if a.iter().fold(0.0, |s, x| s + x * 0.0) != 0.0 {
        return None;
    }
    let (mut a, mut x) = (*a, *b);
    for k in 0..M {
        let mut p = k;
        for i in k + 1..M {
            if a[(i, k)].abs() > a[(p, k)].abs() {
                p = i;
            }
        }
        let pivot = a[(p, k)];
        if pivot.abs() <= tiny || !pivot.is_finite() {
            return None;
        }
        if p != k {
            a.swap_rows(k, p);
            x.swap_rows(k, p);
        }
        for i in k + 1..M {
            let f = a[(i, k)] / pivot;
            for j in k + 1..M {
                a[(i, j)] -= f * a[(k, j)];
            }
            x[i] -= f * x[k];
        }
    }
    for k in (0..M).rev() {
        let mut s = x[k];
        for j in k + 1..M {
            s -= a[(k, j)] * x[j];
        }
        x[k] = s / a[(k, k)];
    }
    Some(x)
}

/// The solution (x, y) of a KKT system.
pub type KktSolution<const N: usize, const C: usize> = (SVector<f64, N>, SVector<f64, C>);

/// Solve the saddle-point (KKT) system
///
/// ```text
/// [ J   B ] [x]   [r]
/// [ A   0 ] [y] = [c]
/// ```
///
/// with J (N×N) invertible, by the Schur complement S = A J⁻¹ B (C×C).
/// S is assembled from the nonzero entries of A only and factored by
/// partial pivoting; a rank-deficient S (a constraint Jacobian losing rank,
/// e.g. a folded four-bar) meets a tiny pivot there and is handled by
/// complete pivoting: the multiplier component in the deficient direction is
/// set to zero. Returns `None` when J is singular.
///
/// Through J⁻¹ the solution loses digits when J is ill-conditioned even if
/// the whole KKT matrix is not (in quaternion coordinates M is singular
/// along each quaternion, whose norm constraint fixes that direction: a
/// Newton matrix −M + O(Δt) can have cond(J) ≈ 1e13 while the KKT matrix
/// has 1e4). [`solve_kkt_regularised`] checks for that.
pub fn solve_kkt<const N: usize, const C: usize>(
    j: &SMatrix<f64, N, N>,
    b: &SMatrix<f64, N, C>,
    a: &SMatrix<f64, C, N>,
    r: &SVector<f64, N>,
    c: &SVector<f64, C>,
) -> Option<(SVector<f64, N>, SVector<f64, C>)> {
    solve_kkt_rated(j, b, a, r, c).map(|(sol, _)| sol)
}

/// [`solve_kkt`] and whether J looked ill-conditioned: a pivot ratio
/// ([`PartialLu::pivot_ratio`]) below [`KKT_SUSPECT_PIVOT_RATIO`], or a
/// J that needed complete pivoting.
fn solve_kkt_rated<const N: usize, const C: usize>(
    j: &SMatrix<f64, N, N>,
    b: &SMatrix<f64, N, C>,
    a: &SMatrix<f64, C, N>,
    r: &SVector<f64, N>,
    c: &SVector<f64, C>,
) -> Option<(KktSolution<N, C>, bool)> {
    // J: partial pivoting (Newton matrices perturb −M, or I), complete
    // pivoting when that meets a tiny pivot (rank-revealing: a singular J
    // is reported, and the caller may regularise)
    let (jr, jb, suspect) = match PartialLu::new(*j, 1e-12) {
        Some(lu) => (
            lu.solve(r),
            lu.solve_matrix(b),
            lu.pivot_ratio() < KKT_SUSPECT_PIVOT_RATIO,
        ),
        None => {
            let lu = FullPivLu::new(*j, 1e-14);
            if lu.rank() < N {
                return None;
            }
            (lu.solve(r), lu.solve_matrix(b), true)
        }
    };
    if C == 0 {
        return Some(((jr, SVector::zeros()), suspect));
    }
    let (x, y) = solve_with_rows(a, &rows_of(&jb), jr.into(), c);
    Some(((x, SVector::from(y)), suspect))
}

/// The pivot ratio of J ([`PartialLu::pivot_ratio`]) below which
/// [`solve_kkt_regularised`] checks the residual of the solution through
/// J⁻¹. The ratio is a loose indicator: on the spatial slider-crank in
/// quaternion coordinates a J with cond(J) = 4e12 had a pivot ratio of
/// 1.9e-8, and its Schur complement lost a multiplier. 1e-4 keeps the
/// check off well-conditioned Newton matrices (the planar fourbar's is at
/// least 2.7e-2 over 200 configurations).
pub const KKT_SUSPECT_PIVOT_RATIO: f64 = 1e-4;

/// `true` when (x, y) solves the KKT system of [`solve_kkt`] to a relative
/// residual of 1e-8 in both block rows (each measured against the sizes of
/// its terms, |J||x| + |B||y| + |r| and |A||x| + |c|, max-norms), and is
/// finite. With a KKT matrix of condition κ the solution is then accurate
/// to about κ·1e-8: enough for a Newton direction. O(N² + NC).
pub fn kkt_solution_is_accurate<const N: usize, const C: usize>(
    j: &SMatrix<f64, N, N>,
    b: &SMatrix<f64, N, C>,
    a: &SMatrix<f64, C, N>,
    r: &SVector<f64, N>,
    c: &SVector<f64, C>,
    x: &SVector<f64, N>,
    y: &SVector<f64, C>,
) -> bool {
    let e1 = (j * x + b * y - r).amax();
    let e2 = (a * x - c).amax();
    let s1 = j.amax() * x.amax() + b.amax() * y.amax() + r.amax();
    let s2 = a.amax() * x.amax() + c.amax();
    let ok = e1 <= 1e-8 * s1.max(f64::MIN_POSITIVE) && e2 <= 1e-8 * s2.max(f64::MIN_POSITIVE);
    ok && x.iter().chain(y.iter()).all(|v| v.is_finite())
}

/// The rows of an N × C matrix (nalgebra stores it by columns), for the
/// row-wise loops of the Schur complement.
#[inline(always)]
fn rows_of<const N: usize, const C: usize>(m: &SMatrix<f64, N, C>) -> [[f64; C]; N] {
    let mut rows = [[0.0f64; C]; N];
    for (col, xs) in m.as_slice().chunks_exact(N).enumerate() {
        for (k, x) in xs.iter().enumerate() {
            rows[k][col] = *x;
        }
    }
    rows
}

/// The KKT solution from the rows of J⁻¹B and J⁻¹r: y from the Schur
/// complement ([`schur_sparse`], [`solve_schur`]), x = J⁻¹r − (J⁻¹B)·y.
#[inline(always)]
fn solve_with_rows<const N: usize, const C: usize>(
    a: &SMatrix<f64, C, N>,
    jb_rows: &[[f64; C]; N],
    jr: [f64; N],
    c: &SVector<f64, C>,
) -> (SVector<f64, N>, [f64; C]) {
    let mut s = [[0.0f64; C]; C];
    let rhs = schur_sparse(
        a,
        &ConstraintColumns::DENSE,
        jb_rows,
        &[1.0; N],
        &jr,
        c,
        &mut s,
    );
    let y = solve_schur(s, &rhs);
    (minus_rows_times(jr, jb_rows, &y), y)
}

/// x = J⁻¹r − (J⁻¹B)·y from J⁻¹r and the rows of J⁻¹B.
#[inline(always)]
fn minus_rows_times<const N: usize, const C: usize>(
    jr: [f64; N],
    jb_rows: &[[f64; C]; N],
    y: &[f64; C],
) -> SVector<f64, N> {
    let mut x = jr;
    for (xk, row) in x.iter_mut().zip(jb_rows.iter()) {
        *xk -= dot(row, y);
    }
    SVector::from(x)
}

/// `Some((x, y))` when every entry is finite.
#[inline(always)]
fn finite_solution<const N: usize, const C: usize>(
    x: SVector<f64, N>,
    y: [f64; C],
) -> Option<KktSolution<N, C>> {
    // on the slices, AND-ed without a branch per entry (nalgebra's element
    // iterator and `all`'s early exit each cost more than the test)
    let finite = x
        .as_slice()
        .iter()
        .chain(y.iter())
        .fold(true, |ok, v| ok & v.is_finite());
    finite.then(|| (x, SVector::from(y)))
}

/// Σ_j a_j b_j.
#[inline(always)]
fn dot<const C: usize>(a: &[f64; C], b: &[f64; C]) -> f64 {
    let mut s = 0.0;
    for (x, y) in a.iter().zip(b.iter()) {
        s += x * y;
    }
    s
}

/// The columns of each row of a C × N constraint Jacobian that may be
/// nonzero: [`Dynamics::CONSTRAINT_PATTERN`](crate::Dynamics::CONSTRAINT_PATTERN)
/// as index lists, built at compile time from the pattern
/// (`const { &ConstraintColumns::new(&M::CONSTRAINT_PATTERN) }`), so that
/// the Schur complement's loops visit only the entries that may be nonzero
/// (for a planar four-bar in maximal coordinates 32 of G's 120).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConstraintColumns<const N: usize, const C: usize> {
    cols: [[usize; N]; C],
    len: [usize; C],
    // every entry may be nonzero: test each for zero at run time instead
    dense: bool,
}

impl<const N: usize, const C: usize> ConstraintColumns<N, C> {
    /// No structural zeros known: every entry is tested for zero at run
    /// time (the default pattern of a hand-written model).
    pub const DENSE: Self = Self::new(&[[true; N]; C]);

    /// The index lists of `pattern` (`pattern[i][k]` is `false` where
    /// entry (i, k) is identically zero).
    pub const fn new(pattern: &[[bool; N]; C]) -> Self {
        let mut cols = [[0usize; N]; C];
        let mut len = [0usize; C];
        let mut dense = true;
        let mut i = 0;
        while i < C {
            let mut k = 0;
            while k < N {
                if pattern[i][k] {
                    cols[i][len[i]] = k;
                    len[i] += 1;
                } else {
                    dense = false;
                }
                k += 1;
            }
            i += 1;
        }
        Self { cols, len, dense }
    }

    /// Whether every entry may be nonzero (no structural zero known).
    pub const fn is_dense(&self) -> bool {
        self.dense
    }

    /// The columns of row `i` that may be nonzero, in increasing order.
    /// Panics when `i ≥ C`.
    #[inline(always)]
    pub fn row(&self, i: usize) -> &[usize] {
        &self.cols[i][..self.len[i]]
    }
}

/// One term a_ik of row i of [`schur_sparse`]: `acc` += a_ik·jr_k, `row`
/// += a_ik·w_k·R_k.
#[inline(always)]
fn add_schur_term<const C: usize>(
    aik: f64,
    jr_k: f64,
    w_k: f64,
    rows_k: &[f64; C],
    acc: &mut f64,
    row: &mut [f64; C],
) {
    *acc += aik * jr_k;
    let f = aik * w_k;
    for (sij, x) in row.iter_mut().zip(rows_k.iter()) {
        *sij += f * x;
    }
}

/// The Schur complement S = A·W·R (C×C, into `s`) and the right-hand side
/// A·(J⁻¹r) − c (returned), for W = diag(`w`) and R given by its rows
/// (R = J⁻¹B with W = I; R = B with W = J⁻¹ for a diagonal J), visiting
/// only the nonzero entries of A: a joint's constraint rows touch the
/// coordinates of two bodies, so most of A is zero in maximal coordinates
/// (O(nnz(A)·C) instead of O(C²N)). Skipping a zero a_ik leaves the sums
/// exactly as adding 0·x would (up to the sign of a zero).
#[inline(always)]
fn schur_sparse<const N: usize, const C: usize>(
    a: &SMatrix<f64, C, N>,
    cols: &ConstraintColumns<N, C>,
    rows: &[[f64; C]; N],
    w: &[f64; N],
    jr: &[f64],
    c: &SVector<f64, C>,
    s: &mut [[f64; C]; C],
) -> [f64; C] {
    // A is stored by columns: A_ik = a[k·C + i]
    let a_s = a.as_slice();
    let mut rhs = [0.0f64; C];
    if !cols.dense {
        // A's structural zeros known: the entries that may be nonzero
        // only, with no test (a runtime zero among them adds 0·x)
        for (i, (srow, rh)) in s.iter_mut().zip(rhs.iter_mut()).enumerate() {
            let mut row = [0.0f64; C];
            let mut acc = -c[i];
            for &k in cols.row(i) {
                add_schur_term(a_s[k * C + i], jr[k], w[k], &rows[k], &mut acc, &mut row);
            }
            *srow = row;
            *rh = acc;
        }
        return rhs;
    }
    for (i, (srow, rh)) in s.iter_mut().zip(rhs.iter_mut()).enumerate() {
        // the row accumulates in a local (registers), stored once: through
        // `s` every update would be stored
        let mut row = [0.0f64; C];
        let mut acc = -c[i];
        for k in 0..N {
            let aik = a_s[k * C + i];
            if aik != 0.0 {
                add_schur_term(aik, jr[k], w[k], &rows[k], &mut acc, &mut row);
            }
        }
        *srow = row;
        *rh = acc;
    }
    rhs
}

/// Solve S y = rhs for the Schur complement of a KKT system: partial
/// pivoting (O(C³/3), no search of the trailing block) when every pivot is
/// at least 1e-8 of the largest entry (S well conditioned), otherwise
/// complete pivoting with the rank threshold 1e-13. A singular or nearly
/// singular S (redundant constraints: a spatial slider-crank's loop has
/// pivots ≈ 1e-10 relative; a folded four-bar) thus takes the rank-revealing
/// path, where the multiplier component in the deficient direction is set
/// to zero, as before this fast path existed.
#[inline(always)]
fn solve_schur<const C: usize>(s: [[f64; C]; C], rhs: &[f64; C]) -> [f64; C] {
    match PartialLu::from_rows(s, SCHUR_PIVOT_TOL) {
        Some(lu) => lu.solve_array(rhs),
        None => full_piv_schur(&s).solve_array(rhs),
    }
}

/// Relative pivot threshold of the partial-pivoting Schur solve.
const SCHUR_PIVOT_TOL: f64 = 1e-8;

/// S's complete-pivoting factorisation (rank threshold 1e-13), where
/// partial pivoting met a pivot below [`SCHUR_PIVOT_TOL`].
fn full_piv_schur<const C: usize>(s: &[[f64; C]; C]) -> FullPivLu<C> {
    FullPivLu::new(SMatrix::<f64, C, C>::from_fn(|i, j| s[i][j]), 1e-13)
}

impl<const C: usize> FullPivLu<C> {
    /// [`FullPivLu::solve`] on plain arrays.
    fn solve_array(&self, rhs: &[f64; C]) -> [f64; C] {
        let y = self.solve(&SVector::from(*rhs));
        let mut out = [0.0; C];
        out.copy_from_slice(y.as_slice());
        out
    }
}

/// `Some(1/diag)` when `j` is diagonal (exact zeros off the diagonal) with
/// a finite, nonzero diagonal whose reciprocals are finite.
// inlined into its three callers (one per KKT entry point): out of line,
// the call costs more than the test for the small N of a tree
#[inline(always)]
fn invertible_diagonal<const N: usize>(j: &SMatrix<f64, N, N>) -> Option<[f64; N]> {
    // column-major storage: column k holds the diagonal entry at row k.
    // Branch-free test for a nonzero off the diagonal: OR the bits of every
    // off-diagonal entry without its sign (±0 give 0; NaN counts as nonzero)
    let mut off = 0u64;
    for (k, col) in j.as_slice().chunks_exact(N).enumerate() {
        for (i, x) in col.iter().enumerate() {
            off |= (x.to_bits() << 1) & if i == k { 0 } else { u64::MAX };
        }
    }
    if off != 0 {
        return None;
    }
    // x = 0 gives 1/x = ∞, x = ±∞ gives 0 (x NaN: NaN): x and 1/x both
    // finite is the test, AND-ed without a branch per entry
    // (the diagonal: every (N+1)-th entry of the storage)
    let mut inv = [0.0; N];
    let mut finite = true;
    for (d, x) in inv.iter_mut().zip(j.as_slice().iter().step_by(N + 1)) {
        *d = 1.0 / x;
        finite &= d.is_finite() & x.is_finite();
    }
    finite.then_some(inv)
}

/// The KKT system of [`solve_kkt`] for a diagonal J = diag(1/inv) (maximal
/// coordinates: a constant diagonal mass matrix): the Schur complement
/// S = A J⁻¹ B (C×C) is assembled from the nonzero entries of A only (a
/// joint's constraint rows touch the coordinates of two bodies, so most of
/// A is zero: O(nnz(A)·C) instead of O(C²N)) and solved as in
/// `solve_schur` (partial pivoting when well conditioned, complete pivoting
/// otherwise: redundant constraints make S singular); then
/// x = J⁻¹(r − B y). `None` when the solution is not finite.
#[inline]
fn solve_kkt_diagonal<const N: usize, const C: usize>(
    inv: &[f64; N],
    b: &SMatrix<f64, N, C>,
    a: &SMatrix<f64, C, N>,
    r: &SVector<f64, N>,
    c: &SVector<f64, C>,
) -> Option<KktSolution<N, C>> {
    let brow = rows_of(b);
    let mut jr = [0.0f64; N];
    for k in 0..N {
        jr[k] = r[k] * inv[k];
    }
    let mut s = [[0.0f64; C]; C];
    let rhs = schur_sparse(a, &ConstraintColumns::DENSE, &brow, inv, &jr, c, &mut s);
    let y = solve_schur(s, &rhs);
    let mut x = SVector::<f64, N>::zeros();
    for k in 0..N {
        x[k] = (r[k] - dot(&brow[k], &y)) * inv[k];
    }
    finite_solution(x, y)
}

/// Whether every entry is finite, without a branch per entry (`all` stops
/// at the first non-finite one, a test and a branch each; a flattening
/// iterator is not always inlined): x·0 is ±0 for finite x and NaN
/// otherwise, summed per column (independent chains that vectorise; one
/// multiply and one add per entry, where `is_finite` costs an absolute
/// value, a compare and an AND).
#[inline(always)]
fn all_finite<const N: usize, const C: usize>(rows: &[[f64; C]; N]) -> bool {
    let mut poison = [0.0f64; C];
    for row in rows {
        for (p, x) in poison.iter_mut().zip(row.iter()) {
            *p += x * 0.0;
        }
    }
    poison.iter().fold(0.0, |s, p| s + p) == 0.0
}

/// How [`KktFactors`] applies J⁻¹: a diagonal J by its reciprocals, any
/// other by partial-pivoting LU.
#[derive(Clone, Copy, Debug)]
enum JInverse<const N: usize> {
    Diagonal([f64; N]),
    Lu(PartialLu<N>),
}

/// The parts of the KKT system of [`solve_kkt`] that depend on J and B
/// only — J's factorisation and the rows of J⁻¹B — kept across Newton
/// iterations whose Newton matrix J and constraint-force matrix B do not
/// change. The step uses it for the first-order rule with a constant mass
/// matrix, whose J is −M − a·D at the fixed start configuration (a chord
/// iteration of the midpoint rule would qualify too; it does not use it).
/// Each [`KktFactors::solve`] then costs O(N²) for J⁻¹r,
/// O(nnz(A)·C) for the Schur complement and O(C³/3) for its solve, instead
/// of re-factoring J (O(N³/3)) and solving for C right-hand sides (O(N²C)).
#[derive(Clone, Copy, Debug)]
pub struct KktFactors<const N: usize, const C: usize> {
    j: JInverse<N>,
    jb_rows: [[f64; C]; N],
}

impl<const N: usize, const C: usize> Default for KktFactors<N, C> {
    /// The factors of J = I and B = 0 (a holder for
    /// [`KktFactors::factor_constraint_jacobian`]).
    fn default() -> Self {
        Self {
            j: JInverse::Diagonal([1.0; N]),
            jb_rows: [[0.0; C]; N],
        }
    }
}

impl<const N: usize, const C: usize> KktFactors<N, C> {
    /// Factor J (diagonal, or partial pivoting with the relative pivot
    /// threshold 1e-12 of [`solve_kkt`]) and form J⁻¹B. `None` when J is
    /// not diagonal and partial pivoting meets a tiny pivot, or when J⁻¹B
    /// is not finite: use [`solve_kkt_regularised`], which also handles a
    /// singular J.
    pub fn new(j: &SMatrix<f64, N, N>, b: &SMatrix<f64, N, C>) -> Option<Self> {
        let (j, jb_rows) = if let Some(inv) = invertible_diagonal(j) {
            // rows of J⁻¹B in one pass over B (stored by columns)
            let mut jb_rows = [[0.0f64; C]; N];
            for (col, xs) in b.as_slice().chunks_exact(N).enumerate() {
                for (k, x) in xs.iter().enumerate() {
                    jb_rows[k][col] = x * inv[k];
                }
            }
            (JInverse::Diagonal(inv), jb_rows)
        } else {
            return Self::from_lu(j, b);
        };
        Self::if_finite(j, jb_rows)
    }

    /// [`KktFactors::new`] with B = −Gᵀ (the constraint forces of a step,
    /// G the constraint Jacobian at the step's start), read from G's
    /// storage: G is stored by columns, so column k of G is row k of B up
    /// to the sign and, for a diagonal J, row k of J⁻¹B is −(1/J_kk) times
    /// it — no transposed or negated copy of G is formed. The factors are
    /// those of `new(j, &-g.transpose())`, bit for bit.
    pub fn with_constraint_jacobian(
        j: &SMatrix<f64, N, N>,
        g: &SMatrix<f64, C, N>,
    ) -> Option<Self> {
        let mut f = Self::default();
        f.factor_constraint_jacobian(j, g).then_some(f)
    }

    /// [`KktFactors::with_constraint_jacobian`] in place: `self` becomes
    /// those factors, formed where they stay (returned in an `Option`, the
    /// factors — kilobytes — are copied on the way), and `true` is
    /// returned; `false` where `with_constraint_jacobian` gives `None`
    /// (`self` then holds unspecified factors).
    #[inline(always)]
    pub fn factor_constraint_jacobian(
        &mut self,
        j: &SMatrix<f64, N, N>,
        g: &SMatrix<f64, C, N>,
    ) -> bool {
        let Some(inv) = invertible_diagonal(j) else {
            return match Self::from_lu(j, &-g.transpose()) {
                Some(f) => {
                    *self = f;
                    true
                }
                None => false,
            };
        };
        for ((row, col), ik) in self
            .jb_rows
            .iter_mut()
            .zip(g.as_slice().chunks_exact(C))
            .zip(inv.iter())
        {
            for (x, gik) in row.iter_mut().zip(col.iter()) {
                *x = -gik * ik;
            }
        }
        self.j = JInverse::Diagonal(inv);
        all_finite(&self.jb_rows)
    }

    /// The factors of a J that is not diagonal: partial pivoting with the
    /// relative pivot threshold 1e-12 of [`solve_kkt`].
    fn from_lu(j: &SMatrix<f64, N, N>, b: &SMatrix<f64, N, C>) -> Option<Self> {
        let lu = PartialLu::new(*j, 1e-12)?;
        Self::if_finite(JInverse::Lu(lu), rows_of(&lu.solve_matrix(b)))
    }

    /// `Some` when every entry of J⁻¹B is finite.
    #[inline(always)]
    fn if_finite(j: JInverse<N>, jb_rows: [[f64; C]; N]) -> Option<Self> {
        if all_finite(&jb_rows) {
            Some(Self { j, jb_rows })
        } else {
            None
        }
    }

    /// J⁻¹r.
    #[inline(always)]
    fn j_solve(&self, r: &SVector<f64, N>) -> [f64; N] {
        match &self.j {
            JInverse::Diagonal(inv) => {
                let mut jr = [0.0f64; N];
                for ((x, rk), ik) in jr.iter_mut().zip(r.as_slice()).zip(inv.iter()) {
                    *x = rk * ik;
                }
                jr
            }
            JInverse::Lu(lu) => lu.solve_array(r.as_slice()),
        }
    }

    /// Solve the KKT system with this J and B and the given A, r and c (a
    /// singular Schur complement as in [`solve_kkt`]). `None` when the
    /// solution is not finite.
    #[inline]
    pub fn solve(
        &self,
        a: &SMatrix<f64, C, N>,
        r: &SVector<f64, N>,
        c: &SVector<f64, C>,
    ) -> Option<KktSolution<N, C>> {
        let (x, y) = solve_with_rows(a, &self.jb_rows, self.j_solve(r), c);
        finite_solution(x, y)
    }

    /// [`KktFactors::solve`], leaving the factored Schur complement
    /// S = A J⁻¹B in `schur` for [`KktFactors::solve_chord`] (not
    /// [`SchurFactor::is_formed`] when the solution is not finite). The
    /// caller keeps A for the chord steps (not copied here: the step keeps
    /// it where it was evaluated).
    ///
    /// `cols` lists the entries of A that may be nonzero (A's structural
    /// zeros, [`ConstraintColumns::new`]); [`ConstraintColumns::DENSE`]
    /// tests every entry for zero instead.
    #[inline(always)]
    pub fn solve_keeping(
        &self,
        a: &SMatrix<f64, C, N>,
        cols: &ConstraintColumns<N, C>,
        r: &SVector<f64, N>,
        c: &SVector<f64, C>,
        schur: &mut SchurFactor<N, C>,
    ) -> Option<KktSolution<N, C>> {
        let jr = self.j_solve(r);
        // S formed and factored where it stays: formed elsewhere and moved
        // there, S and its factors would be copied (memcpy) on the way
        let rhs = schur_sparse(a, cols, &self.jb_rows, &[1.0; N], &jr, c, &mut schur.lu.lu);
        schur.full = if schur.lu.factor(SCHUR_PIVOT_TOL) {
            None
        } else {
            // as `solve_schur`: S again (the attempt overwrote it)
            let mut s = [[0.0f64; C]; C];
            schur_sparse(a, cols, &self.jb_rows, &[1.0; N], &jr, c, &mut s);
            Some(full_piv_schur(&s))
        };
        let y = schur.solve(&rhs);
        let sol = finite_solution(minus_rows_times(jr, &self.jb_rows, &y), y);
        schur.formed = sol.is_some();
        sol
    }

    /// Solve the KKT system with this J and B, the S of `schur` and the A
    /// it was formed from (left by [`KktFactors::solve_keeping`] of these
    /// factors with this `a`) and the given r and c, without forming S: a
    /// chord step when the constraint rows have moved since (the
    /// caller evaluates the residuals exactly and keeps S only while the
    /// iteration contracts). O(N) (diagonal J) or O(N²) for J⁻¹r,
    /// O(NC) for A·J⁻¹r and for x, O(C²) for the solve with S.
    /// `None` when the solution is not finite.
    #[inline(always)]
    pub fn solve_chord(
        &self,
        schur: &SchurFactor<N, C>,
        a: &SMatrix<f64, C, N>,
        r: &SVector<f64, N>,
        c: &SVector<f64, C>,
    ) -> Option<KktSolution<N, C>> {
        let jr = self.j_solve(r);
        // A·(J⁻¹r) − c, column by column (A is stored by columns): with no
        // S to form, testing A's zeros costs more than multiplying them
        let mut rhs = [0.0f64; C];
        for (rh, ci) in rhs.iter_mut().zip(c.as_slice()) {
            *rh = -ci;
        }
        for (col, x) in a.as_slice().chunks_exact(C).zip(jr.iter()) {
            for (rh, aik) in rhs.iter_mut().zip(col.iter()) {
                *rh += aik * x;
            }
        }
        let y = schur.solve(&rhs);
        finite_solution(minus_rows_times(jr, &self.jb_rows, &y), y)
    }
}

/// The factored Schur complement S = A J⁻¹B of a [`KktFactors`] system
/// ([`KktFactors::solve_keeping`]), for chord steps
/// ([`KktFactors::solve_chord`], given the same A) with the same J and B.
/// [`SchurFactor::default`] holds none (not [`SchurFactor::is_formed`]).
#[derive(Clone, Copy, Debug)]
pub struct SchurFactor<const N: usize, const C: usize> {
    // (N: the KKT system's size, for the solves' signatures)
    _n: core::marker::PhantomData<[f64; N]>,
    // S by partial pivoting (as `solve_schur`), unless `full` holds its
    // complete-pivoting factors
    lu: PartialLu<C>,
    full: Option<FullPivLu<C>>,
    formed: bool,
}

impl<const N: usize, const C: usize> Default for SchurFactor<N, C> {
    fn default() -> Self {
        Self {
            _n: core::marker::PhantomData,
            lu: PartialLu {
                lu: [[0.0; C]; C],
                perm: [0; C],
            },
            full: None,
            formed: false,
        }
    }
}

impl<const N: usize, const C: usize> SchurFactor<N, C> {
    /// Forget the S held (not [`SchurFactor::is_formed`] until the next
    /// [`KktFactors::solve_keeping`]).
    pub fn clear(&mut self) {
        self.formed = false;
    }

    /// Whether it holds the S of a solve with a finite solution.
    pub fn is_formed(&self) -> bool {
        self.formed
    }

    /// S⁻¹·rhs.
    #[inline(always)]
    fn solve(&self, rhs: &[f64; C]) -> [f64; C] {
        match &self.full {
            None => self.lu.solve_array(rhs),
            Some(full) => full.solve_array(rhs),
        }
    }
}

/// Solve the saddle-point (KKT) system of [`solve_kkt`]; when J is
/// singular but the whole KKT matrix is not (a link without rotational
/// inertia in maximal coordinates, whose orientation the constraints fix),
/// solve the equivalent augmented system
///
/// ```text
/// (J + ρ·B·A) x + B y = r + ρ·B·c,   A x = c
/// ```
///
/// which has the same solution (ρ·B times the second row added to the
/// first). ρ = ±‖J‖/‖B·A‖ (max-norms) with the sign of tr(J)·tr(B·A), so
/// that ρ·B·A adds to J with J's own sign. The augmented solution is
/// accepted only when it solves the original system to 1e-8 relative to
/// ‖J‖‖x‖ + ‖B‖‖y‖ + ‖r‖ (rows of J) and ‖A‖‖x‖ + ‖c‖ (rows of A)
/// ([`kkt_solution_is_accurate`]); otherwise, or when J is singular and
/// C = 0, `None`.
///
/// The same augmented solve replaces [`solve_kkt`]'s solution when J is
/// invertible but looks ill-conditioned (pivot ratio below
/// [`KKT_SUSPECT_PIVOT_RATIO`]) and that solution fails the same residual
/// test; when the augmented one fails it too, the plain solution is
/// returned (a singular Schur complement, whose rank-revealing solve
/// leaves the residual of the deficient constraint).
///
/// A diagonal J (maximal coordinates without damping) is inverted
/// directly: the Schur complement S = A J⁻¹ B costs O(nnz(A)·C) (only the
/// nonzero entries of A are visited), and S is solved by partial pivoting,
/// or by full pivoting when a pivot is tiny (a singular S: redundant
/// constraints).
///
/// Returns the solution and whether the regularisation was needed.
pub fn solve_kkt_regularised<const N: usize, const C: usize>(
    j: &SMatrix<f64, N, N>,
    b: &SMatrix<f64, N, C>,
    a: &SMatrix<f64, C, N>,
    r: &SVector<f64, N>,
    c: &SVector<f64, C>,
) -> Option<(KktSolution<N, C>, bool)> {
    if C > 0
        && let Some(inv) = invertible_diagonal(j)
        && let Some(sol) = solve_kkt_diagonal(&inv, b, a, r, c)
    {
        return Some((sol, false));
    }
    // through J⁻¹; when J looks ill-conditioned, kept only if accurate
    // (otherwise the augmented system, and this solution as the last
    // resort: a singular S, e.g. a folded four-bar, legitimately leaves a
    // constraint residual that no solution removes)
    let plain = solve_kkt_rated(j, b, a, r, c);
    if let Some(((x, y), suspect)) = plain
        && (!suspect || C == 0 || kkt_solution_is_accurate(j, b, a, r, c, &x, &y))
    {
        return Some(((x, y), false));
    }
    let plain = plain.map(|(sol, _)| (sol, false));
    if C == 0 {
        return plain;
    }
    let k = b * a;
    let (jn, kn) = (j.amax(), k.amax());
    if !(kn > 0.0 && kn.is_finite() && jn.is_finite()) {
        return plain;
    }
    let sign = if j.trace() * k.trace() >= 0.0 {
        1.0
    } else {
        -1.0
    };
    let rho = sign * if jn > 0.0 { jn / kn } else { 1.0 / kn };
    match solve_kkt(&(j + k * rho), b, a, &(r + b * c * rho), c) {
        Some((x, y)) if kkt_solution_is_accurate(j, b, a, r, c, &x, &y) => Some(((x, y), true)),
        _ => plain,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix3, Vector3};

    #[test]
    fn full_piv_lu_matches_nalgebra() {
        let a = Matrix3::new(2.0, -1.0, 0.5, 1.0, 3.0, -2.0, 0.25, 4.0, 1.0);
        let b = Vector3::new(1.0, -2.0, 0.5);
        let x = FullPivLu::new(a, 1e-14).solve(&b);
        let reference = a.lu().solve(&b).unwrap();
        assert!((x - reference).amax() < 1e-14);
    }

    /// The partial-pivoting factorisation against nalgebra's LU (a second
    /// implementation), with a zero leading entry forcing a swap; singular
    /// and non-finite matrices are refused.
    #[test]
    fn partial_lu_matches_nalgebra() {
        let a = Matrix3::new(0.0, -1.0, 0.5, 1.0, 3.0, -2.0, 0.25, 4.0, 1.0);
        let b = Vector3::new(1.0, -2.0, 0.5);
        let lu = PartialLu::new(a, 1e-14).unwrap();
        let reference = a.lu().solve(&b).unwrap();
        assert!((lu.solve(&b) - reference).amax() < 1e-14);
        let bm = nalgebra::Matrix3x2::new(1.0, 0.0, -2.0, 1.0, 0.5, 3.0);
        let xm = lu.solve_matrix(&bm);
        assert!((a * xm - bm).amax() < 1e-14);
        let singular = Matrix3::new(1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 0.0, 1.0, 1.0);
        assert!(PartialLu::new(singular, 1e-14).is_none());
        let nan = Matrix3::new(f64::NAN, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
        assert!(PartialLu::new(nan, 1e-14).is_none());
    }

    #[test]
    fn partial_pivoting_matches_nalgebra_and_detects_singularity() {
        // a zero leading entry forces a row swap
        let a = Matrix3::new(0.0, -1.0, 0.5, 1.0, 3.0, -2.0, 0.25, 4.0, 1.0);
        let b = Vector3::new(1.0, -2.0, 0.5);
        let x = solve_partial(&a, &b).unwrap();
        let reference = a.lu().solve(&b).unwrap();
        assert!((x - reference).amax() < 1e-14);
        let singular = Matrix3::new(1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 0.0, 1.0, 1.0);
        assert!(solve_partial(&singular, &b).is_none());
        let nan = Matrix3::new(f64::NAN, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
        assert!(solve_partial(&nan, &b).is_none());
    }

    /// The closed forms for 1×1 and 2×2 agree with nalgebra's LU (a second
    /// implementation) to a few ulps of the solution, including an
    /// ill-conditioned (κ ≈ 4e8) and a zero-leading-entry case; singular,
    /// near-singular and non-finite matrices give `None`.
    #[test]
    fn small_closed_forms_match_lu() {
        use nalgebra::{Matrix1, Matrix2, Vector1, Vector2};
        let b = Vector2::new(0.7, -1.9);
        for a in [
            Matrix2::new(-1.3, 0.2, 0.35, -0.9),
            Matrix2::new(0.0, 2.0, -3.0, 0.5),
            Matrix2::new(1.0, 1.0, 1.0, 1.0 + 1e-8),
        ] {
            let x = solve_partial(&a, &b).unwrap();
            let reference = a.lu().solve(&b).unwrap();
            // forward error of both ≲ κ·ε relative
            let kappa = a.norm() * a.try_inverse().unwrap().norm();
            let tol = 8.0 * kappa * f64::EPSILON * reference.amax();
            assert!((x - reference).amax() <= tol, "{a} {x} {reference}");
        }
        for bad in [
            Matrix2::new(1.0, 2.0, 2.0, 4.0),
            Matrix2::new(1.0, 1.0, 1.0, 1.0 + 1e-15),
            Matrix2::new(f64::NAN, 0.0, 0.0, 1.0),
            Matrix2::new(f64::INFINITY, 0.0, 0.0, 1.0),
        ] {
            assert!(solve_partial(&bad, &b).is_none(), "{bad}");
        }
        let one = Vector1::new(3.0);
        assert_eq!(
            solve_partial(&Matrix1::new(-2.0), &one),
            Some(Vector1::new(-1.5))
        );
        assert!(solve_partial(&Matrix1::new(0.0), &one).is_none());
        assert!(solve_partial(&Matrix1::new(f64::NAN), &one).is_none());
    }

    #[test]
    fn rank_deficient_consistent_system_is_solved() {
        // rows 1 and 2 are parallel; b in the range
        let a = Matrix3::new(1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 0.0, 1.0, 1.0);
        let b = Vector3::new(1.0, 2.0, 0.5);
        let lu = FullPivLu::new(a, 1e-14);
        assert_eq!(lu.rank(), 2);
        let x = lu.solve(&b);
        assert!((a * x - b).amax() < 1e-14);
    }

    #[test]
    fn kkt_matches_dense_solve() {
        let j = Matrix3::new(4.0, 1.0, 0.0, 1.0, 3.0, 0.5, 0.0, 0.5, 2.0);
        let b = nalgebra::Matrix3x1::new(1.0, 0.0, -1.0);
        let a = nalgebra::Matrix1x3::new(0.5, 1.0, 0.0);
        let r = Vector3::new(1.0, 2.0, 3.0);
        let c = nalgebra::Vector1::new(0.25);
        let (x, y) = solve_kkt(&j, &b, &a, &r, &c).unwrap();
        let mut k = nalgebra::Matrix4::zeros();
        k.fixed_view_mut::<3, 3>(0, 0).copy_from(&j);
        k.fixed_view_mut::<3, 1>(0, 3).copy_from(&b);
        k.fixed_view_mut::<1, 3>(3, 0).copy_from(&a);
        let rhs = nalgebra::Vector4::new(1.0, 2.0, 3.0, 0.25);
        let full = k.lu().solve(&rhs).unwrap();
        assert!((full.fixed_rows::<3>(0) - x).amax() < 1e-13);
        assert!((full[3] - y[0]).abs() < 1e-13);
    }

    /// A J that is nearly singular along a direction the constraint fixes
    /// (as −M along a quaternion, whose norm constraint holds it): cond(J)
    /// = 2e11 (pivot ratio above the 1e-12 that refuses J, below
    /// [`KKT_SUSPECT_PIVOT_RATIO`]), the KKT matrix well conditioned.
    /// [`solve_kkt_regularised`] against nalgebra's LU of the whole KKT
    /// matrix (a second implementation) to 1e-10 (it reached 2e-16); the
    /// plain solve through J⁻¹ misses by 2e-5, which the old code
    /// returned.
    #[test]
    fn ill_conditioned_j_is_solved_through_the_augmented_system() {
        use nalgebra::{Matrix4, Vector4};
        // J = Q·diag(−1, −2, −1e-14)·Qᵀ, Q a rotation; the third column of
        // Q (J's near-null direction) is what the constraint row sees
        let q = nalgebra::Rotation3::from_euler_angles(0.3, -0.7, 1.1).into_inner();
        let j = q * Matrix3::from_diagonal(&Vector3::new(-1.0, -2.0, -1e-11)) * q.transpose();
        let n = q.column(2).into_owned();
        let a = nalgebra::Matrix1x3::from_row_slice(&[n[0], n[1] + 0.2, n[2]]);
        let b = -a.transpose();
        let r = Vector3::new(0.3, -1.0, 0.7);
        let c = nalgebra::Vector1::new(0.2);
        let mut k = Matrix4::zeros();
        k.fixed_view_mut::<3, 3>(0, 0).copy_from(&j);
        k.fixed_view_mut::<3, 1>(0, 3).copy_from(&b);
        k.fixed_view_mut::<1, 3>(3, 0).copy_from(&a);
        let full = k.lu().solve(&Vector4::new(r[0], r[1], r[2], c[0])).unwrap();
        let kkt_cond = {
            let sv = k.svd(false, false).singular_values;
            sv.max() / sv.min()
        };
        assert!(kkt_cond < 1e3, "{kkt_cond:e}");
        let ((x, y), regularised) = solve_kkt_regularised(&j, &b, &a, &r, &c).unwrap();
        let err = (full.fixed_rows::<3>(0) - x)
            .amax()
            .max((full[3] - y[0]).abs());
        let (xp, yp) = solve_kkt(&j, &b, &a, &r, &c).unwrap();
        let plain = (full.fixed_rows::<3>(0) - xp)
            .amax()
            .max((full[3] - yp[0]).abs());
        assert!(regularised && err < 1e-10, "{err:e}");
        assert!(plain > 1e-6, "{plain:e}");
    }

    /// The diagonal-J Schur path against nalgebra's LU of the whole KKT
    /// matrix (a second implementation): sparse A (two-body rows, as a
    /// joint's constraint rows), B ≠ Aᵀ, and a redundant constraint (a row
    /// repeated, consistent right-hand side) that sends S to full pivoting.
    #[test]
    fn diagonal_kkt_matches_dense_solve() {
        use nalgebra::{SMatrix, SVector};
        const N: usize = 6;
        const C: usize = 4;
        let j = SMatrix::<f64, N, N>::from_diagonal(&SVector::from([
            -1.0, -1.0, -0.08, -2.0, -2.0, -0.3,
        ]));
        let mut a = SMatrix::<f64, C, N>::zeros();
        for (i, row) in [
            [1.0, 0.0, 0.4, 0.0, 0.0, 0.0],
            [0.0, 1.0, -0.7, 0.0, 0.0, 0.0],
            [1.0, 0.0, -0.3, -1.0, 0.0, 0.25],
            [0.0, 1.0, 0.6, 0.0, -1.0, -0.9],
        ]
        .iter()
        .enumerate()
        {
            for (k, x) in row.iter().enumerate() {
                a[(i, k)] = *x;
            }
        }
        let b =
            -(a + SMatrix::<f64, C, N>::from_fn(|i, k| 0.01 * (i as f64 - k as f64))).transpose();
        let r = SVector::<f64, N>::from_fn(|i, _| (i as f64 * 0.7).sin());
        let c = SVector::<f64, C>::from_fn(|i, _| 0.1 * i as f64 - 0.2);
        let ((x, y), reg) = solve_kkt_regularised(&j, &b, &a, &r, &c).unwrap();
        assert!(!reg);
        let mut k = SMatrix::<f64, 10, 10>::zeros();
        k.fixed_view_mut::<N, N>(0, 0).copy_from(&j);
        k.fixed_view_mut::<N, C>(0, N).copy_from(&b);
        k.fixed_view_mut::<C, N>(N, 0).copy_from(&a);
        let mut rhs = SVector::<f64, 10>::zeros();
        rhs.fixed_rows_mut::<N>(0).copy_from(&r);
        rhs.fixed_rows_mut::<C>(N).copy_from(&c);
        let full = k.lu().solve(&rhs).unwrap();
        // both backward stable on a matrix with condition ≈ 1e2
        assert!((full.fixed_rows::<N>(0) - x).amax() < 1e-13, "{x} {full}");
        assert!((full.fixed_rows::<C>(N) - y).amax() < 1e-13, "{y} {full}");

        // redundant: constraint row 3 repeated in place of row 2, with a
        // consistent right-hand side (the Schur complement is singular)
        let mut a2 = a;
        let row3 = a.row(3).into_owned();
        a2.set_row(2, &row3);
        let b2 = -a2.transpose();
        let mut c2 = c;
        c2[2] = c2[3];
        let ((x2, y2), _) = solve_kkt_regularised(&j, &b2, &a2, &r, &c2).unwrap();
        assert!((j * x2 + b2 * y2 - r).amax() < 1e-13);
        assert!((a2 * x2 - c2).amax() < 1e-13);
    }

    /// `invertible_diagonal` accepts a diagonal matrix (−0 off the diagonal
    /// included) and refuses a nonzero or NaN entry off the diagonal and a
    /// diagonal entry that is 0, ±∞, NaN or whose reciprocal overflows;
    /// `KktFactors::new` refuses a non-finite J⁻¹B.
    #[test]
    fn invertible_diagonal_refuses_what_it_cannot_invert() {
        let d = Matrix3::from_diagonal(&Vector3::new(-2.0, 0.5, -4.0));
        assert_eq!(invertible_diagonal(&d), Some([-0.5, 2.0, -0.25]));
        let mut neg_zero = d;
        neg_zero[(0, 2)] = -0.0;
        assert_eq!(invertible_diagonal(&neg_zero), Some([-0.5, 2.0, -0.25]));
        for (i, j, x) in [
            (0, 1, 1e-300),
            (2, 0, f64::NAN),
            (1, 1, 0.0),
            (1, 1, -0.0),
            (2, 2, f64::INFINITY),
            (0, 0, f64::NAN),
            (0, 0, 1e-310),
        ] {
            let mut m = d;
            m[(i, j)] = x;
            assert_eq!(invertible_diagonal(&m), None, "{m}");
        }
        let b = nalgebra::Matrix3x2::new(1.0, 0.0, f64::INFINITY, 1.0, 0.5, 3.0);
        assert!(KktFactors::new(&d, &b).is_none());
        assert!(KktFactors::new(&(d + Matrix3::repeat(0.1)), &b).is_none());
    }

    /// `KktFactors` (J factored once, reused for several A) and the general
    /// non-diagonal path of `solve_kkt` against nalgebra's LU of the whole
    /// KKT matrix (a second implementation), for a diagonal J and for a
    /// coupled one (joint damping in maximal coordinates), two different
    /// sparse A with the same factors, and a redundant constraint (singular
    /// Schur complement: complete pivoting, checked through the residuals).
    /// A Schur complement kept by `solve_keeping` (which solves as `solve`)
    /// serves `solve_chord`: the KKT system with the kept A in the
    /// constraint row (a chord step's), for new right-hand sides.
    #[test]
    fn kkt_factors_match_dense_solve() {
        use nalgebra::{SMatrix, SVector};
        const N: usize = 6;
        const C: usize = 4;
        let rows = [
            [1.0, 0.0, 0.4, 0.0, 0.0, 0.0],
            [0.0, 1.0, -0.7, 0.0, 0.0, 0.0],
            [1.0, 0.0, -0.3, -1.0, 0.0, 0.25],
            [0.0, 1.0, 0.6, 0.0, -1.0, -0.9],
        ];
        let a = SMatrix::<f64, C, N>::from_fn(|i, k| rows[i][k]);
        // the constraint Jacobian one Newton iteration later
        let a_next = a + SMatrix::<f64, C, N>::from_fn(|i, k| {
            if rows[i][k] != 0.0 {
                0.02 * (i + k) as f64
            } else {
                0.0
            }
        });
        let b =
            -(a + SMatrix::<f64, C, N>::from_fn(|i, k| 0.01 * (i as f64 - k as f64))).transpose();
        let r = SVector::<f64, N>::from_fn(|i, _| (i as f64 * 0.7).sin());
        let c = SVector::<f64, C>::from_fn(|i, _| 0.1 * i as f64 - 0.2);
        let diag = SMatrix::<f64, N, N>::from_diagonal(&SVector::from([
            -1.0, -1.0, -0.08, -2.0, -2.0, -0.3,
        ]));
        // damping couples the angle coordinates 2 and 5
        let mut coupled = diag;
        coupled[(2, 2)] -= 0.05;
        coupled[(5, 5)] -= 0.05;
        coupled[(2, 5)] += 0.05;
        coupled[(5, 2)] += 0.05;
        let dense = |j: &SMatrix<f64, N, N>,
                     a: &SMatrix<f64, C, N>,
                     r: &SVector<f64, N>,
                     c: &SVector<f64, C>| {
            let mut k = SMatrix::<f64, 10, 10>::zeros();
            k.fixed_view_mut::<N, N>(0, 0).copy_from(j);
            k.fixed_view_mut::<N, C>(0, N).copy_from(&b);
            k.fixed_view_mut::<C, N>(N, 0).copy_from(a);
            let mut rhs = SVector::<f64, 10>::zeros();
            rhs.fixed_rows_mut::<N>(0).copy_from(r);
            rhs.fixed_rows_mut::<C>(N).copy_from(c);
            k.lu().solve(&rhs).unwrap()
        };
        for j in [diag, coupled] {
            let f = KktFactors::new(&j, &b).unwrap();
            for a in [a, a_next] {
                let full = dense(&j, &a, &r, &c);
                // both backward stable on matrices with condition ≈ 1e2
                let (x, y) = f.solve(&a, &r, &c).unwrap();
                assert!((full.fixed_rows::<N>(0) - x).amax() < 1e-13, "{x} {full}");
                assert!((full.fixed_rows::<C>(N) - y).amax() < 1e-13, "{y} {full}");
                let (x, y) = solve_kkt(&j, &b, &a, &r, &c).unwrap();
                assert!((full.fixed_rows::<N>(0) - x).amax() < 1e-13, "{x} {full}");
                assert!((full.fixed_rows::<C>(N) - y).amax() < 1e-13, "{y} {full}");
            }
            // chord: S kept from A, then new right-hand sides (the
            // constraint row stays A, whatever the current Jacobian)
            let mut schur = SchurFactor::default();
            assert!(!schur.is_formed());
            assert_eq!(
                f.solve_keeping(&a, &ConstraintColumns::DENSE, &r, &c, &mut schur),
                f.solve(&a, &r, &c)
            );
            assert!(schur.is_formed());
            let (r2, c2) = (r.map(|x| 0.01 * x - 0.003), c.map(|x| 1e-3 * x + 2e-4));
            let full = dense(&j, &a, &r2, &c2);
            let (x, y) = f.solve_chord(&schur, &a, &r2, &c2).unwrap();
            assert!((full.fixed_rows::<N>(0) - x).amax() < 1e-15, "{x} {full}");
            assert!((full.fixed_rows::<C>(N) - y).amax() < 1e-15, "{y} {full}");
            // a non-finite solution keeps no S
            let nan = r.map(|_| f64::NAN);
            assert!(
                f.solve_keeping(&a_next, &ConstraintColumns::DENSE, &nan, &c, &mut schur)
                    .is_none()
            );
            assert!(!schur.is_formed());
            // redundant: row 3 repeated in place of row 2, consistent c
            let mut a2 = a;
            a2.set_row(2, &a.row(3).into_owned());
            let b2 = -a2.transpose();
            let mut c2 = c;
            c2[2] = c2[3];
            let f2 = KktFactors::new(&j, &b2).unwrap();
            let (x2, y2) = f2.solve(&a2, &r, &c2).unwrap();
            assert!((j * x2 + b2 * y2 - r).amax() < 1e-13);
            assert!((a2 * x2 - c2).amax() < 1e-13);
            // the kept S is singular (complete pivoting), consistent c
            let mut schur = SchurFactor::default();
            f2.solve_keeping(&a2, &ConstraintColumns::DENSE, &r, &c2, &mut schur)
                .unwrap();
            let (r3, mut c3) = (r * 0.5, c * 0.25);
            c3[2] = c3[3];
            let (x3, y3) = f2.solve_chord(&schur, &a2, &r3, &c3).unwrap();
            assert!((j * x3 + b2 * y3 - r3).amax() < 1e-13);
            assert!((a2 * x3 - c3).amax() < 1e-13);
        }
        // a singular J is left to the regularised solve
        let mut singular = diag;
        singular[(2, 2)] = 0.0;
        assert!(KktFactors::new(&singular, &b).is_none());
        // the factors from G (B = −Gᵀ, read from G's columns) are those of
        // `new` with the formed B, bit for bit, diagonal J or not
        let g = a + SMatrix::<f64, C, N>::from_fn(|i, k| 0.01 * (i as f64 - k as f64));
        for j in [diag, coupled] {
            let from_g = KktFactors::with_constraint_jacobian(&j, &g).unwrap();
            let from_b = KktFactors::new(&j, &-g.transpose()).unwrap();
            assert_eq!(from_g.jb_rows, from_b.jb_rows);
            assert_eq!(from_g.solve(&a, &r, &c), from_b.solve(&a, &r, &c));
            // in place, over factors of another J (diagonal or not)
            for mut held in [
                KktFactors::default(),
                from_b,
                KktFactors::new(&coupled, &b).unwrap(),
            ] {
                assert!(held.factor_constraint_jacobian(&j, &g));
                assert_eq!(held.jb_rows, from_b.jb_rows);
                assert_eq!(held.solve(&a, &r, &c), from_b.solve(&a, &r, &c));
            }
        }
        let mut inf = g;
        inf[(1, 3)] = f64::INFINITY;
        for (j, g) in [(singular, g), (diag, inf)] {
            assert!(KktFactors::with_constraint_jacobian(&j, &g).is_none());
            assert!(!KktFactors::default().factor_constraint_jacobian(&j, &g));
        }
    }
}
