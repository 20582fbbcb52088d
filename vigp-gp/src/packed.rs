//! Packed lower-triangular matrices stored **by rows** (row i holds
//! L_i0 … L_ii and starts at i(i+1)/2), and the solves and products
//! prediction and online updates need.
//!
//! Row storage makes appending a sample an O(N) push (the online updates),
//! and turns both the forward substitution and the product with a stored
//! inverse into independent dot products over contiguous rows, which
//! vectorise and need no store-to-load chain (the column-oriented forward
//! substitution updates the whole remaining right-hand side after each
//! entry).

use faer::Mat;

/// Offset of row `i` in the packed storage.
#[inline(always)]
pub(crate) fn row_start(i: usize) -> usize {
    i * (i + 1) / 2
}

/// Row `i` (length i + 1) of a packed lower triangle.
#[inline(always)]
pub(crate) fn row(l: &[f64], i: usize) -> &[f64] {
    &l[row_start(i)..row_start(i + 1)]
}

/// The lower triangle of a faer matrix, packed by rows.
pub(crate) fn pack_rows(l: &Mat<f64>) -> Vec<f64> {
    let n = l.nrows();
    let mut out = Vec::with_capacity(row_start(n));
    for i in 0..n {
        for j in 0..=i {
            out.push(l[(i, j)]);
        }
    }
    out
}

/// The packed rows as a dense faer matrix (upper triangle zero).
pub(crate) fn unpack(l: &[f64], n: usize) -> Mat<f64> {
    let mut m = Mat::zeros(n, n);
    for i in 0..n {
        for (j, v) in row(l, i).iter().enumerate() {
            m[(i, j)] = *v;
        }
    }
    m
}

/// L⁻¹ of a lower-triangular factor (the upper part of `l` is ignored),
/// packed by rows.
pub(crate) fn lower_inverse(l: &Mat<f64>) -> Vec<f64> {
    let n = l.nrows();
    let mut low = Mat::<f64>::zeros(n, n);
    for j in 0..n {
        for i in j..n {
            low[(i, j)] = l[(i, j)];
        }
    }
    let mut inv = Mat::<f64>::zeros(n, n);
    faer::linalg::triangular_inverse::invert_lower_triangular(
        inv.as_mut(),
        low.as_ref(),
        faer::Par::Seq,
    );
    pack_rows(&inv)
}

/// The lower triangle packed column by column (the layout of
/// `vigp_core::gp::ExportedGp::cholesky`).
pub(crate) fn to_column_packed(l: &[f64], n: usize) -> Vec<f64> {
    let mut out = Vec::with_capacity(row_start(n));
    for j in 0..n {
        for i in j..n {
            out.push(l[row_start(i) + j]);
        }
    }
    out
}

/// Σ a_i·b_i with eight interleaved partial sums (vectorises; fixed order).
#[inline(always)]
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0f64; 8];
    let mut ca = a.chunks_exact(8);
    let mut cb = b.chunks_exact(8);
    for (x, y) in (&mut ca).zip(&mut cb) {
        for l in 0..8 {
            acc[l] += x[l] * y[l];
        }
    }
    for (l, (x, y)) in ca.remainder().iter().zip(cb.remainder()).enumerate() {
        acc[l] += x * y;
    }
    ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]))
}

/// Four dot products of rows of equal length with one vector: the vector is
/// read once for all four (register blocking).
#[inline(always)]
fn dot4(r0: &[f64], r1: &[f64], r2: &[f64], r3: &[f64], v: &[f64]) -> [f64; 4] {
    let n = v.len();
    let (r0, r1, r2, r3) = (&r0[..n], &r1[..n], &r2[..n], &r3[..n]);
    let mut acc = [[0.0f64; 4]; 4];
    let chunks = n / 4;
    for c in 0..chunks {
        let b = 4 * c;
        for l in 0..4 {
            let x = v[b + l];
            acc[0][l] += r0[b + l] * x;
            acc[1][l] += r1[b + l] * x;
            acc[2][l] += r2[b + l] * x;
            acc[3][l] += r3[b + l] * x;
        }
    }
    for (l, i) in (4 * chunks..n).enumerate() {
        let x = v[i];
        acc[0][l] += r0[i] * x;
        acc[1][l] += r1[i] * x;
        acc[2][l] += r2[i] * x;
        acc[3][l] += r3[i] * x;
    }
    acc.map(|a| (a[0] + a[1]) + (a[2] + a[3]))
}

/// Solves L·w = v in place (forward substitution by rows). Blocked by four
/// rows: the part of each row left of the block is a dot product with the
/// solved entries, done for the four rows together; the 4×4 diagonal block
/// is then solved directly.
pub(crate) fn forward_rows(l: &[f64], v: &mut [f64]) {
    let n = v.len();
    let mut i = 0;
    while i + 4 <= n {
        let s = dot4(
            row(l, i),
            row(l, i + 1),
            row(l, i + 2),
            row(l, i + 3),
            &v[..i],
        );
        for k in 0..4 {
            let r = row(l, i + k);
            let mut t = v[i + k] - s[k];
            for j in 0..k {
                t -= r[i + j] * v[i + j];
            }
            v[i + k] = t / r[i + k];
        }
        i += 4;
    }
    while i < n {
        let r = row(l, i);
        v[i] = (v[i] - dot(&r[..i], &v[..i])) / r[i];
        i += 1;
    }
}

/// Solves Lᵀ·x = v in place (backward substitution; row i of L is column i
/// of Lᵀ, applied as an axpy once x_i is known).
pub(crate) fn backward_rows(l: &[f64], v: &mut [f64]) {
    let n = v.len();
    for i in (0..n).rev() {
        let r = row(l, i);
        let xi = v[i] / r[i];
        v[i] = xi;
        if xi != 0.0 {
            for (vj, lij) in v[..i].iter_mut().zip(&r[..i]) {
                *vj -= lij * xi;
            }
        }
    }
}

/// out = L⁻¹·v with L⁻¹ given (packed rows): out_i = Σ_{j≤i} (L⁻¹)_ij v_j,
/// four rows at a time; in AVX2 registers where the CPU has them (detected
/// at run time), with the bits of the portable [`lower_matvec_impl`].
/// With `reverse` the rows are visited last to first: the same blocks of
/// four rows and the same arithmetic per row, so the same bits.
/// Alternating the direction between calls finds the part of L⁻¹ the
/// previous call read last still in the core's cache (L⁻¹ of N = 512 is
/// 1 MB, a core's L2 here 512 KB).
pub(crate) fn lower_matvec_dir(linv: &[f64], v: &[f64], out: &mut [f64], reverse: bool) {
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = pulp::x86::V3::try_new() {
        return simd.vectorize(|| lower_matvec_avx2(simd, linv, v, out, reverse));
    }
    lower_matvec_impl(linv, v, out, reverse);
}

/// [`lower_matvec_dir`]'s traversal: `block(i, out)` for the blocks of
/// four rows starting at i (in reverse order when `reverse`), and the rows
/// past the last full block one by one, after the blocks (before them when
/// reversed).
#[inline(always)]
fn traverse(
    linv: &[f64],
    v: &[f64],
    out: &mut [f64],
    reverse: bool,
    mut block: impl FnMut(usize, &mut [f64]),
) {
    let n = v.len();
    let full = n / 4;
    let single = |out: &mut [f64]| {
        for i in 4 * full..n {
            out[i] = dot(row(linv, i), &v[..=i]);
        }
    };
    if reverse {
        single(out);
    }
    for b in 0..full {
        block(4 * if reverse { full - 1 - b } else { b }, out);
    }
    if !reverse {
        single(out);
    }
}

/// The portable [`lower_matvec_dir`].
#[inline(always)]
fn lower_matvec_impl(linv: &[f64], v: &[f64], out: &mut [f64], reverse: bool) {
    traverse(linv, v, out, reverse, |i, out| {
        matvec_block(linv, i, v, out)
    });
}

/// [`lower_matvec_impl`] with each row's four lane sums of [`dot4`] in one
/// AVX2 register (same order, so the same bits).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn lower_matvec_avx2(simd: pulp::x86::V3, linv: &[f64], v: &[f64], out: &mut [f64], reverse: bool) {
    use pulp::{Simd, x86::V3};
    traverse(linv, v, out, reverse, |i, out| {
        let m = i + 1;
        let chunks = m / 4;
        let (r, rc, rs) = block_rows_avx2(linv, i);
        let vc = &v[..m];
        let zero = simd.splat_f64s(0.0);
        let (mut a0, mut a1, mut a2, mut a3) = (zero, zero, zero, zero);
        for ((((x0, x1), x2), x3), y) in rs[0]
            .iter()
            .zip(rs[1])
            .zip(rs[2])
            .zip(rs[3])
            .zip(V3::as_simd_f64s(vc).0)
        {
            a0 = simd.add_f64s(a0, simd.mul_f64s(*x0, *y));
            a1 = simd.add_f64s(a1, simd.mul_f64s(*x1, *y));
            a2 = simd.add_f64s(a2, simd.mul_f64s(*x2, *y));
            a3 = simd.add_f64s(a3, simd.mul_f64s(*x3, *y));
        }
        let mut lanes = [a0, a1, a2, a3].map(|x| [x.0, x.1, x.2, x.3]);
        for (l, j) in (4 * chunks..m).enumerate() {
            for k in 0..4 {
                lanes[k][l] += rc[k][j] * vc[j];
            }
        }
        block_tail(&r, i, lanes.map(|a| (a[0] + a[1]) + (a[2] + a[3])), v, out);
    });
}

/// [`lower_matvec_dir`] for m vectors at once (`vs` and `outs` hold them one
/// after the other, each of length n), with the same arithmetic per vector,
/// so each result equals `lower_matvec_dir`'s bit for bit. Each block of four
/// rows of L⁻¹ is read from memory once for all m vectors: at N = 512 the
/// packed L⁻¹ (1 MB) does not fit a core's L2, so one vector at a time
/// streams all of it from L3 per vector; m vectors share that stream. Keep
/// m·n·8 bytes of vectors within L2 for the gain (the callers use chunks).
pub(crate) fn lower_matvec_many(linv: &[f64], n: usize, vs: &[f64], outs: &mut [f64]) {
    debug_assert_eq!(vs.len(), outs.len());
    // Once L⁻¹ is read once per chunk the products dominate: with AVX2
    // (detected at run time) each (row, vector) pair's four lane sums are
    // one 256-bit register, added in the same order as the portable code
    // (separate multiply and add, no fused multiply-add), so the same bits.
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = pulp::x86::V3::try_new() {
        return simd.vectorize(|| lower_matvec_many_avx2(simd, linv, n, vs, outs));
    }
    lower_matvec_many_impl(linv, n, vs, outs);
}

/// [`lower_matvec_many_impl`] with two vectors per block of four rows
/// (each row loaded once for both) and each (row, vector) pair's four lane
/// sums of [`dot4`] in one AVX2 register.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn lower_matvec_many_avx2(
    simd: pulp::x86::V3,
    linv: &[f64],
    n: usize,
    vs: &[f64],
    outs: &mut [f64],
) {
    use pulp::{Simd, x86::V3};
    let mut i = 0;
    while i + 4 <= n {
        let m = i + 1;
        let chunks = m / 4;
        let (r, rc, rs) = block_rows_avx2(linv, i);
        let mut pairs_v = vs.chunks_exact(2 * n);
        let mut pairs_o = outs.chunks_exact_mut(2 * n);
        for (v, out) in (&mut pairs_v).zip(&mut pairs_o) {
            let (v0, v1) = v.split_at(n);
            let vc = [&v0[..m], &v1[..m]];
            let (p0, p1) = (V3::as_simd_f64s(vc[0]).0, V3::as_simd_f64s(vc[1]).0);
            let zero = simd.splat_f64s(0.0);
            let (mut a00, mut a01, mut a02, mut a03) = (zero, zero, zero, zero);
            let (mut a10, mut a11, mut a12, mut a13) = (zero, zero, zero, zero);
            for (((((x0, x1), x2), x3), y0), y1) in rs[0]
                .iter()
                .zip(rs[1])
                .zip(rs[2])
                .zip(rs[3])
                .zip(p0)
                .zip(p1)
            {
                a00 = simd.add_f64s(a00, simd.mul_f64s(*x0, *y0));
                a01 = simd.add_f64s(a01, simd.mul_f64s(*x1, *y0));
                a02 = simd.add_f64s(a02, simd.mul_f64s(*x2, *y0));
                a03 = simd.add_f64s(a03, simd.mul_f64s(*x3, *y0));
                a10 = simd.add_f64s(a10, simd.mul_f64s(*x0, *y1));
                a11 = simd.add_f64s(a11, simd.mul_f64s(*x1, *y1));
                a12 = simd.add_f64s(a12, simd.mul_f64s(*x2, *y1));
                a13 = simd.add_f64s(a13, simd.mul_f64s(*x3, *y1));
            }
            let acc = [[a00, a01, a02, a03], [a10, a11, a12, a13]];
            let mut lanes = acc.map(|a| a.map(|x| [x.0, x.1, x.2, x.3]));
            for (l, j) in (4 * chunks..m).enumerate() {
                for h in 0..2 {
                    for k in 0..4 {
                        lanes[h][k][l] += rc[k][j] * vc[h][j];
                    }
                }
            }
            let (o0, o1) = out.split_at_mut(n);
            for ((a, v), out) in lanes.iter().zip([v0, v1]).zip([o0, o1]) {
                block_tail(&r, i, a.map(|a| (a[0] + a[1]) + (a[2] + a[3])), v, out);
            }
        }
        if let (Some(v), Some(out)) = (
            pairs_v.remainder().chunks_exact(n).next(),
            pairs_o.into_remainder().chunks_exact_mut(n).next(),
        ) {
            matvec_block(linv, i, v, out);
        }
        i += 4;
    }
    remainder_rows(linv, n, i, vs, outs);
}

/// The four rows of block i, their parts left of column i + 1, and those
/// parts as AVX2 vectors (without their last (i + 1) mod 4 values).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
#[allow(clippy::type_complexity)]
fn block_rows_avx2(linv: &[f64], i: usize) -> ([&[f64]; 4], [&[f64]; 4], [&[pulp::f64x4]; 4]) {
    let r = [
        row(linv, i),
        row(linv, i + 1),
        row(linv, i + 2),
        row(linv, i + 3),
    ];
    let rc = r.map(|x| &x[..=i]);
    let rs = rc.map(|x| <pulp::x86::V3 as pulp::Simd>::as_simd_f64s(x).0);
    (r, rc, rs)
}

/// Rows `from`..n of every out = L⁻¹·v (the rows after the last block of
/// four), one dot product each.
#[inline(always)]
fn remainder_rows(linv: &[f64], n: usize, from: usize, vs: &[f64], outs: &mut [f64]) {
    for i in from..n {
        let r = row(linv, i);
        for (v, out) in vs.chunks_exact(n).zip(outs.chunks_exact_mut(n)) {
            out[i] = dot(r, &v[..=i]);
        }
    }
}

/// Rows i..i+4 of out = L⁻¹·v from `s`, each row's product left of
/// column i + 1, and the entries right of column i.
#[inline(always)]
fn block_tail(r: &[&[f64]; 4], i: usize, s: [f64; 4], v: &[f64], out: &mut [f64]) {
    out[i] = s[0];
    out[i + 1] = s[1] + r[1][i + 1] * v[i + 1];
    out[i + 2] = s[2] + r[2][i + 1] * v[i + 1] + r[2][i + 2] * v[i + 2];
    out[i + 3] = s[3] + r[3][i + 1] * v[i + 1] + r[3][i + 2] * v[i + 2] + r[3][i + 3] * v[i + 3];
}

/// The portable [`lower_matvec_many`]: per block of four rows, every
/// vector in turn (the rows stay in L1 between them).
#[inline(always)]
fn lower_matvec_many_impl(linv: &[f64], n: usize, vs: &[f64], outs: &mut [f64]) {
    let mut i = 0;
    while i + 4 <= n {
        for (v, out) in vs.chunks_exact(n).zip(outs.chunks_exact_mut(n)) {
            matvec_block(linv, i, v, out);
        }
        i += 4;
    }
    remainder_rows(linv, n, i, vs, outs);
}

/// Rows i..i+4 of out = L⁻¹·v (i + 4 ≤ n).
#[inline(always)]
fn matvec_block(linv: &[f64], i: usize, v: &[f64], out: &mut [f64]) {
    let r = [
        row(linv, i),
        row(linv, i + 1),
        row(linv, i + 2),
        row(linv, i + 3),
    ];
    let s = dot4(r[0], r[1], r[2], r[3], &v[..=i]);
    block_tail(&r, i, s, v, out);
}

/// Squared norm with eight partial sums.
#[inline]
pub(crate) fn norm2(v: &[f64]) -> f64 {
    dot(v, v)
}

/// Appends to the packed L⁻¹ (size n) the row of the extended inverse when
/// L gains the row (cᵀ, δ): the new row is (−cᵀL⁻¹/δ, 1/δ). O(n²/2). The
/// reference for [`matvec_and_inverse_row`], which the online update uses.
#[cfg(test)]
pub(crate) fn extend_inverse(linv: &mut Vec<f64>, n: usize, c: &[f64], delta: f64) {
    let start = linv.len();
    linv.resize(start + n + 1, 0.0);
    let (old, new) = linv.split_at_mut(start);
    // new[j] = −Σ_{i≥j} c_i (L⁻¹)_ij / δ: accumulate row by row (axpy).
    for (i, ci) in c.iter().enumerate() {
        if *ci != 0.0 {
            for (nj, lij) in new[..=i].iter_mut().zip(row(old, i)) {
                *nj -= ci * lij;
            }
        }
    }
    for v in new[..n].iter_mut() {
        *v /= delta;
    }
    new[n] = 1.0 / delta;
}

/// One pass over the packed L⁻¹ (size n) for appending a sample: returns
/// c = L⁻¹·b in `c` and appends to `linv` the row w = −cᵀL⁻¹ (the new row
/// of the extended inverse before its scaling by 1/δ, which
/// [`finish_inverse_row`] applies once δ is known). Each row of L⁻¹ is read
/// from memory once, for its dot product with b and, while in cache, for
/// its share of w: half the memory traffic of [`lower_matvec_dir`] followed by
/// [`extend_inverse`]. Four rows at a time.
pub(crate) fn matvec_and_inverse_row(linv: &mut Vec<f64>, b: &[f64], c: &mut [f64]) {
    let n = b.len();
    let start = linv.len();
    debug_assert_eq!(start, row_start(n));
    linv.resize(start + n + 1, 0.0);
    let (old, new) = linv.split_at_mut(start);
    let mut i = 0;
    while i + 4 <= n {
        let (r0, r1, r2, r3) = (
            row(old, i),
            row(old, i + 1),
            row(old, i + 2),
            row(old, i + 3),
        );
        let s = dot4(r0, r1, r2, r3, &b[..=i]);
        let c0 = s[0];
        let c1 = s[1] + r1[i + 1] * b[i + 1];
        let c2 = s[2] + r2[i + 1] * b[i + 1] + r2[i + 2] * b[i + 2];
        let c3 = s[3] + r3[i + 1] * b[i + 1] + r3[i + 2] * b[i + 2] + r3[i + 3] * b[i + 3];
        c[i..i + 4].copy_from_slice(&[c0, c1, c2, c3]);
        // w_j −= Σ_k c_k (L⁻¹)_kj over the four rows (all have column ≤ i).
        for (j, w) in new[..=i].iter_mut().enumerate() {
            *w -= (c0 * r0[j] + c1 * r1[j]) + (c2 * r2[j] + c3 * r3[j]);
        }
        new[i + 1] -= c1 * r1[i + 1] + c2 * r2[i + 1] + c3 * r3[i + 1];
        new[i + 2] -= c2 * r2[i + 2] + c3 * r3[i + 2];
        new[i + 3] -= c3 * r3[i + 3];
        i += 4;
    }
    while i < n {
        let r = row(old, i);
        let ci = dot(r, &b[..=i]);
        c[i] = ci;
        for (w, l) in new[..=i].iter_mut().zip(r) {
            *w -= ci * l;
        }
        i += 1;
    }
}

/// Scales the row appended by [`matvec_and_inverse_row`] by 1/δ and sets
/// its diagonal entry 1/δ: (−cᵀL⁻¹/δ, 1/δ).
pub(crate) fn finish_inverse_row(linv: &mut [f64], n: usize, delta: f64) {
    let new = &mut linv[row_start(n)..row_start(n + 1)];
    for v in new[..n].iter_mut() {
        *v /= delta;
    }
    new[n] = 1.0 / delta;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example(n: usize) -> Vec<f64> {
        // A well-conditioned lower triangle with a dominant diagonal.
        let mut l = Vec::new();
        for i in 0..n {
            for j in 0..=i {
                let v = if i == j {
                    2.0 + (i as f64 * 0.37).sin().abs()
                } else {
                    ((i * 7 + j * 3) as f64 * 0.61).sin() * 0.3
                };
                l.push(v);
            }
        }
        l
    }

    fn matvec(l: &[f64], x: &[f64]) -> Vec<f64> {
        (0..x.len()).map(|i| dot(row(l, i), &x[..=i])).collect()
    }

    /// The vectorised paths (AVX2 where this CPU has it) and the batched one
    /// give the portable single-vector product's bits: the lane sums keep
    /// their order and no multiply-add is fused.
    #[test]
    fn every_matvec_path_gives_the_portable_bits() {
        let bits = |x: &[f64]| x.iter().map(|a| a.to_bits()).collect::<Vec<_>>();
        for n in [1, 3, 4, 5, 9, 17, 64, 130] {
            let l = example(n);
            for m in [1, 2, 3, 7] {
                let vs: Vec<f64> = (0..m * n).map(|i| (i as f64 * 0.77).sin()).collect();
                let mut outs = vec![0.0; m * n];
                lower_matvec_many(&l, n, &vs, &mut outs);
                let mut portable = vec![0.0; m * n];
                lower_matvec_many_impl(&l, n, &vs, &mut portable);
                assert_eq!(bits(&portable), bits(&outs), "n = {n}, m = {m}");
                for (v, got) in vs.chunks_exact(n).zip(outs.chunks_exact(n)) {
                    let mut want = vec![0.0; n];
                    lower_matvec_impl(&l, v, &mut want, false);
                    assert_eq!(bits(got), bits(&want), "n = {n}, m = {m}");
                    // rows visited last to first: the same bits
                    for reverse in [false, true] {
                        let mut r = vec![f64::NAN; n];
                        lower_matvec_dir(&l, v, &mut r, reverse);
                        assert_eq!(bits(&r), bits(&want), "n = {n}, reverse");
                        let mut r = vec![f64::NAN; n];
                        lower_matvec_impl(&l, v, &mut r, reverse);
                        assert_eq!(bits(&r), bits(&want), "n = {n}, portable reverse");
                    }
                }
            }
        }
    }

    #[test]
    fn solves_and_inverse_agree_with_products() {
        for n in [1, 3, 4, 5, 9, 17] {
            let l = example(n);
            let x: Vec<f64> = (0..n).map(|i| (i as f64 * 1.3).cos()).collect();
            let b = matvec(&l, &x);
            let mut w = b.clone();
            forward_rows(&l, &mut w);
            for (a, e) in w.iter().zip(&x) {
                assert!((a - e).abs() < 1e-13, "n = {n}: {a} vs {e}");
            }
            // Lᵀ x = c with c computed directly
            let mut c = vec![0.0; n];
            for (i, xi) in x.iter().enumerate() {
                for (j, lij) in row(&l, i).iter().enumerate() {
                    c[j] += lij * xi;
                }
            }
            backward_rows(&l, &mut c);
            for (a, e) in c.iter().zip(&x) {
                assert!((a - e).abs() < 1e-13, "n = {n}: {a} vs {e}");
            }
            // the inverse, built row by row through extend_inverse
            let mut linv = Vec::new();
            for i in 0..n {
                // row i of L is (cᵀ, δ) of the extension
                let r = row(&l, i);
                extend_inverse(&mut linv, i, &r[..i], r[i]);
            }
            let mut out = vec![0.0; n];
            lower_matvec_dir(&linv, &b, &mut out, false);
            for (a, e) in out.iter().zip(&x) {
                assert!((a - e).abs() < 1e-13, "n = {n}: {a} vs {e}");
            }
            // the fused pass: the same c and the same appended row as
            // lower_matvec_dir + extend_inverse, up to the order of the sums
            let v: Vec<f64> = (0..n).map(|i| (i as f64 * 0.9).sin()).collect();
            let delta = 1.7;
            let (mut c1, mut c2) = (vec![0.0; n], vec![0.0; n]);
            lower_matvec_dir(&linv, &v, &mut c1, false);
            let mut a = linv.clone();
            extend_inverse(&mut a, n, &c1, delta);
            let mut f = linv.clone();
            matvec_and_inverse_row(&mut f, &v, &mut c2);
            finish_inverse_row(&mut f, n, delta);
            for (p, q) in c1.iter().zip(&c2).chain(a.iter().zip(&f)) {
                assert!(
                    (p - q).abs() < 1e-13 * (1.0 + q.abs()),
                    "n = {n}: {p} vs {q}"
                );
            }
        }
    }
}
