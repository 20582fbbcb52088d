//! How much precision the posterior variance needs: could the stored L⁻¹ of
//! the variance path be kept in `f32` (half the memory, so half the bytes
//! the learned step's bound streams from cache)?
//!
//! Run: `cargo run --release --example variance_precision` (trains the
//! double-pendulum model of `benches/learned.rs` at N = 512, about a
//! minute on 2 cores).
//!
//! For each output of the trained GP it forms L⁻¹ in `f64` from the
//! exported Cholesky factor, rounds it to `f32`, and at 840 states along 40
//! trajectories of the nominal model compares the variance
//! σ_f² − ‖L⁻¹k‖² with the one from the rounded inverse. It also prints the
//! width of the rigorous interval for ‖L⁻¹k‖² that the rounded inverse
//! gives (each entry is within 2⁻²⁴ of its `f64` value, so each
//! (L⁻¹k)_i is within 2⁻²⁴·Σ_j |L̃⁻¹_ij| k_j, accumulated in `f64`),
//! relative to the variance: a value above 1 means the rounded inverse
//! cannot even bound the variance from above usefully.
//!
//! The answer on this model (2026-11-25): the median variance at the query
//! states is about 10⁻⁷ σ_f² (σ_f² − ‖L⁻¹k‖² cancels seven digits), so
//! `f32` entries (seven digits) leave none: the rounded estimate is ≤ 0 at
//! 81–94 % of the states, its error is 10²× the variance (median), and the
//! rigorous interval 10⁴× it. The stored inverse stays `f64`.

use std::f64::consts::PI;

use nalgebra::{DMatrix, SVector};
use vigp::learned::{Encoding, Prior};
use vigp::prelude::*;
use vigp::systems::{DoublePendulum, DoublePendulumMinimal};

#[path = "../benches/learned/data.rs"]
mod data;

use data::{DT, Rng, train};

/// The median of `v` (sorted in place).
fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n = 512;
    let model = train(n, Prior::Constant)?;
    // the query states: 40 nominal trajectories of 1 s from rest, every
    // fifth state
    let nominal = Variational::new(DoublePendulum::default().minimal(), DT)?;
    let mut rng = Rng(99);
    let mut queries = Vec::new();
    for _ in 0..40 {
        let q = SVector::from([rng.uniform(-PI, PI), rng.uniform(-PI, PI)]);
        let traj = nominal.rollout(
            &State {
                q,
                v: SVector::zeros(),
            },
            100,
        )?;
        for z in traj.iter().step_by(5) {
            let mut x = [0.0; 6];
            Encoding::SinCos.encode(&DoublePendulumMinimal::KINDS, z, &mut x);
            queries.push(x);
        }
    }
    // 2⁻²⁴ (f32 rounding to nearest) plus the f64 accumulation, generously
    let unit = f64::from(f32::EPSILON) / 2.0 * (1.0 + 1e-6) + (n as f64 + 2.0) * f64::EPSILON;
    println!(
        "N = {n}, {} query states; L⁻¹ per output: {} KB as f64, {} KB as f32",
        queries.len(),
        n * (n + 1) / 2 * 8 / 1024,
        n * (n + 1) / 2 * 4 / 1024
    );
    println!(
        "output | median var/σ_f² | smallest | f32 estimate ≤ 0 | median |f32 − f64|/var | median interval/var"
    );
    for j in 0..2 {
        let a = model.gp().export_output(j, true)?;
        let packed = a.cholesky.as_ref().ok_or("no Cholesky factor")?;
        // L packed by columns (column c holds L_cc … L_{N−1,c}), then L⁻¹
        // by nalgebra's triangular solve against the identity
        let mut l = DMatrix::<f64>::zeros(n, n);
        let mut at = 0;
        for c in 0..n {
            for i in c..n {
                l[(i, c)] = packed[at + i - c];
            }
            at += n - c;
        }
        let inv = l
            .solve_lower_triangular(&DMatrix::identity(n, n))
            .ok_or("singular Cholesky factor")?
            .transpose(); // row-major below: inv[i * n + c] = (L⁻¹)_ic
        let inv = inv.as_slice();
        let inv32: Vec<f32> = inv.iter().map(|x| *x as f32).collect();
        let sf2 = a.signal_variance;
        let (mut rel, mut err, mut width) = (Vec::new(), Vec::new(), Vec::new());
        let mut non_positive = 0;
        for x in &queries {
            let q: Vec<f64> = (0..a.input_dim)
                .map(|m| ((x[m] - a.input_shift[m]) / a.input_scale[m]) / a.length_scales[m])
                .collect();
            let mut k = vec![0.0; n];
            vigp_core::gp::kernel_row(&a.inputs, n, &q, sf2, &mut k)?;
            let (mut q64, mut q32, mut lo, mut hi) = (0.0, 0.0, 0.0, 0.0);
            for i in 0..n {
                let (mut e, mut f, mut s) = (0.0, 0.0, 0.0);
                for c in 0..=i {
                    e += inv[i * n + c] * k[c];
                    let w = f64::from(inv32[i * n + c]);
                    f += w * k[c];
                    s += w.abs() * k[c].abs();
                }
                q64 += e * e;
                q32 += f * f;
                let (a_lo, a_hi) = ((f.abs() - unit * s).max(0.0), f.abs() + unit * s);
                lo += a_lo * a_lo;
                hi += a_hi * a_hi;
            }
            let var = sf2 - q64;
            rel.push(var / sf2);
            err.push(((sf2 - q32) - var).abs() / var);
            width.push((hi - lo) / var);
            if sf2 - q32 <= 0.0 {
                non_positive += 1;
            }
        }
        let smallest = rel.iter().copied().fold(f64::INFINITY, f64::min);
        println!(
            "{j:>6} | {:>15.2e} | {smallest:>8.2e} | {non_positive:>5} of {:<5} | {:>21.2e} | {:>19.2e}",
            median(&mut rel),
            queries.len(),
            median(&mut err),
            median(&mut width),
        );
    }
    Ok(())
}
