//! The LML and its fused analytic gradient at N large enough for several
//! blocks of the blocked Cholesky / triangular inverse (block size 64), at
//! hyperparameters that put the kernel, the factor and its inverse deep into
//! underflow (short length scales), where the implementation zeroes entries
//! below 1e-100 of their scale to keep subnormals out: the value must agree
//! with a plain dense computation without any cut-off, and the gradient with
//! central differences.

use vigp::gp::log_marginal_likelihood;

const N: usize = 300; // 4 full blocks of 64 and a partial one
const D: usize = 3;

fn data() -> (Vec<f64>, Vec<f64>) {
    let dirs = [0.569_8, 0.754_8, 0.819_1];
    let x: Vec<f64> = (0..N)
        .flat_map(|i| dirs.map(|k| 4.0 * ((i + 1) as f64 * k).fract() - 2.0))
        .collect();
    let y = x
        .chunks(D)
        .map(|r| (2.0 * r[0]).sin() + 0.3 * r[1] * r[2])
        .collect();
    (x, y)
}

/// Textbook LML: dense K with libm exp (no cut-off), unblocked Cholesky.
fn reference_lml(x: &[f64], y: &[f64], theta: &[f64]) -> f64 {
    let ls: Vec<f64> = theta[..D].iter().map(|t| t.exp()).collect();
    let (sf2, sn2) = (theta[D].exp(), theta[D + 1].exp());
    let mut a = vec![0.0; N * N];
    for i in 0..N {
        for j in 0..=i {
            let r2: f64 = (0..D)
                .map(|k| ((x[i * D + k] - x[j * D + k]) / ls[k]).powi(2))
                .sum();
            a[i * N + j] = sf2 * (-0.5 * r2).exp() + if i == j { sn2 } else { 0.0 };
        }
    }
    for j in 0..N {
        let s: f64 = (0..j).map(|k| a[j * N + k] * a[j * N + k]).sum();
        a[j * N + j] = (a[j * N + j] - s).sqrt();
        for i in j + 1..N {
            let s: f64 = (0..j).map(|k| a[i * N + k] * a[j * N + k]).sum();
            a[i * N + j] = (a[i * N + j] - s) / a[j * N + j];
        }
    }
    let mut v = y.to_vec();
    for i in 0..N {
        let s: f64 = (0..i).map(|k| a[i * N + k] * v[k]).sum();
        v[i] = (v[i] - s) / a[i * N + i];
    }
    let fit: f64 = v.iter().map(|t| t * t).sum();
    let logdet: f64 = (0..N).map(|i| 2.0 * a[i * N + i].ln()).sum();
    -0.5 * fit - 0.5 * logdet - 0.5 * N as f64 * (2.0 * std::f64::consts::PI).ln()
}

#[test]
fn blocked_lml_and_fused_gradient_match_references() {
    let (x, y) = data();
    // (ln ℓ_1..3, ln σ_f², ln σ_n²): benign, short (underflowing kernel and
    // inverse), mixed ARD with one length scale far beyond the data.
    let thetas = [
        [0.1f64, -0.3, 0.4, 0.2, -4.0],
        [0.05f64.ln(), 0.07f64.ln(), 0.1f64.ln(), 0.0, -3.0],
        [0.08f64.ln(), 0.3f64.ln(), 5.0, 1.0, -5.0],
    ];
    for theta in thetas {
        let (v, g) = log_marginal_likelihood(&x, D, &y, &theta, false).unwrap();
        let r = reference_lml(&x, &y, &theta);
        assert!(
            (v - r).abs() < 1e-10 * r.abs().max(1.0),
            "θ {theta:?}: LML {v} vs reference {r}"
        );
        for k in 0..theta.len() {
            let h = 1e-5;
            let (mut tp, mut tm) = (theta, theta);
            tp[k] += h;
            tm[k] -= h;
            let fp = log_marginal_likelihood(&x, D, &y, &tp, false).unwrap().0;
            let fm = log_marginal_likelihood(&x, D, &y, &tm, false).unwrap().0;
            let fd = (fp - fm) / (2.0 * h);
            // Truncation O(h²) and round-off ε·|f|/h ≈ 1e-8 for |f| ~ 1e3.
            assert!(
                (fd - g[k]).abs() < 1e-6 * g[k].abs().max(1.0),
                "θ {theta:?}, component {k}: central difference {fd} vs analytic {}",
                g[k]
            );
        }
        // faer's parallel kernels inside the same blocked algorithm agree to round-off.
        let (vp, gp) = log_marginal_likelihood(&x, D, &y, &theta, true).unwrap();
        assert!((v - vp).abs() < 1e-10 * v.abs().max(1.0));
        for (a, b) in g.iter().zip(&gp) {
            assert!((a - b).abs() < 1e-8 * a.abs().max(1.0));
        }
    }
}
