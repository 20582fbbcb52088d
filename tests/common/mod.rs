//! Shared helpers for the integration tests.
#![allow(dead_code)]

/// SplitMix64: a tiny deterministic generator so tests need no RNG crate.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [lo, hi).
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * ((self.next_u64() >> 11) as f64 / (1u64 << 53) as f64)
    }
}

use nalgebra::SVector;
use vigp::{Mechanism, Variational};

/// Positions every `dt` for `samples` samples, integrated by the midpoint VI
/// at `dt / substeps` from a state at rest at `q0` (projected first when the
/// model has constraints).
pub fn positions<M: Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    m: M,
    q0: SVector<f64, N>,
    dt: f64,
    substeps: usize,
    samples: usize,
) -> Vec<SVector<f64, N>> {
    let h = dt / substeps as f64;
    let q = vigp::projection::consistent_state(&m, &q0, &SVector::zeros(), h)
        .unwrap()
        .q;
    let v = vigp::dynamics::discrete_velocity(&m, &q, &SVector::zeros(), h).unwrap();
    let z0 = vigp::State { q, v };
    let vi = Variational::midpoint(m, h);
    let mut z = z0;
    let mut out = vec![z.q];
    for _ in 1..samples {
        for _ in 0..substeps {
            z = vi.step(&z).unwrap();
        }
        out.push(z.q);
    }
    out
}

/// RK4 on the damped pendulum ODE I θ̈ = −m g l_c sin θ − c θ̇ with a tiny
/// step: an independent reference solution.
pub fn pendulum_reference(theta0: f64, omega0: f64, t: f64, inertia: f64, mgl: f64, c: f64) -> f64 {
    let f = |th: f64, om: f64| (om, (-mgl * th.sin() - c * om) / inertia);
    let n = 200_000;
    let h = t / n as f64;
    let (mut th, mut om) = (theta0, omega0);
    for _ in 0..n {
        let k1 = f(th, om);
        let k2 = f(th + 0.5 * h * k1.0, om + 0.5 * h * k1.1);
        let k3 = f(th + 0.5 * h * k2.0, om + 0.5 * h * k2.1);
        let k4 = f(th + h * k3.0, om + h * k3.1);
        th += h / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0);
        om += h / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1);
    }
    th
}
