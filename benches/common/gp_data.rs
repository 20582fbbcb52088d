//! The deterministic GP data set shared by `benches/gp.rs` and
//! `examples/gp_train.rs` (included with `#[path]`), built as
//! scripts/gp_sklearn_bench.py builds it for the scikit-learn comparison.

/// Fractional parts of √p for the first primes: Weyl-sequence directions.
pub const DIRS: [f64; 8] = [
    0.414_213_562_373_095_1,
    0.732_050_807_568_877_2,
    0.236_067_977_499_789_7,
    0.645_751_311_064_590_6,
    0.316_624_790_355_399_85,
    0.605_551_275_463_989_3,
    0.123_105_625_617_660_55,
    0.358_898_943_540_673_6,
];

/// x_ij = 4·frac((i+1)·dir_j) − 2; y = sin(3x₀) + cos(2x₁) + 0.5·x₂x₃ + small
/// deterministic noise. Same formula as scripts/gp_sklearn_bench.py.
pub fn bench_data(n: usize, d: usize) -> (Vec<f64>, Vec<f64>) {
    let mut x = vec![0.0; n * d];
    let mut y = vec![0.0; n];
    for i in 0..n {
        let r = &mut x[i * d..(i + 1) * d];
        for (j, v) in r.iter_mut().enumerate() {
            *v = 4.0 * (((i + 1) as f64) * DIRS[j]).fract() - 2.0;
        }
        let mut t = (3.0 * r[0]).sin() + (2.0 * r[1]).cos();
        if d >= 4 {
            t += 0.5 * r[2] * r[3];
        }
        t += 0.01 * ((((i + 1) as f64) * 0.754_877_666_246_692_8).fract() - 0.5);
        y[i] = t;
    }
    (x, y)
}
