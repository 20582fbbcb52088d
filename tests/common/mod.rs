//! Shared helpers for the integration tests.
#![allow(dead_code)]

#[path = "rng.rs"]
mod rng;
#[allow(unused_imports)] // not every test binary draws random numbers
pub use rng::Rng;

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
    let vi = Variational::midpoint(m, h).unwrap();
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

/// The five-point central difference of a step's result in one direction,
/// [8(f(ε) − f(−ε)) − (f(2ε) − f(−2ε))]/(12ε): truncation O(ε⁴).
pub fn stencil<const N: usize>(
    eps: f64,
    mut f: impl FnMut(f64) -> vigp::State<N>,
) -> (nalgebra::SVector<f64, N>, nalgebra::SVector<f64, N>) {
    let (p1, m1, p2, m2) = (f(eps), f(-eps), f(2.0 * eps), f(-2.0 * eps));
    let d = |a: nalgebra::SVector<f64, N>,
             b: nalgebra::SVector<f64, N>,
             c: nalgebra::SVector<f64, N>,
             e: nalgebra::SVector<f64, N>| ((a - b) * 8.0 - (c - e)) / (12.0 * eps);
    (d(p1.q, m1.q, p2.q, m2.q), d(p1.v, m1.v, p2.v, m2.v))
}

/// The relative errors (max |A − A_fd| / max |A_fd|, the same for B) of the
/// exact one-step derivatives `d` of the forced step `step` at (`z`, `u`)
/// against five-point central differences ([`stencil`]) with steps `fd`
/// relative to each entry (at least 1). Relative to the whole of A (B):
/// blocks such as ∂q₁/∂q₀ = I are exact, others can be near zero. With
/// U = 0 the B error is 0.
pub fn ab_errors<const N: usize, const U: usize>(
    z: &vigp::State<N>,
    u: &nalgebra::SVector<f64, U>,
    d: &vigp::embedded::StepDerivatives<N, U>,
    fd: f64,
    step: impl Fn(&vigp::State<N>, &nalgebra::SVector<f64, U>) -> vigp::State<N>,
) -> (f64, f64) {
    use nalgebra::SMatrix;
    let mut a_fd = [SMatrix::<f64, N, N>::zeros(); 4];
    for j in 0..N {
        for (which, base) in [(0usize, true), (1, false)] {
            let x = if base { z.q[j] } else { z.v[j] };
            let eps = fd * x.abs().max(1.0);
            let (dq, dv) = stencil(eps, |e| {
                let mut zp = *z;
                if base {
                    zp.q[j] += e;
                } else {
                    zp.v[j] += e;
                }
                step(&zp, u)
            });
            a_fd[which].set_column(j, &dq);
            a_fd[2 + which].set_column(j, &dv);
        }
    }
    let mut b_fd = [SMatrix::<f64, N, U>::zeros(); 2];
    for i in 0..U {
        let eps = fd * u[i].abs().max(1.0);
        let (dq, dv) = stencil(eps, |e| {
            let mut up = *u;
            up[i] += e;
            step(z, &up)
        });
        b_fd[0].set_column(i, &dq);
        b_fd[1].set_column(i, &dv);
    }
    let a_scale = a_fd.iter().map(|b| b.amax()).fold(0.0, f64::max);
    let e_a = [
        (d.a.q_q - a_fd[0]).amax(),
        (d.a.q_v - a_fd[1]).amax(),
        (d.a.v_q - a_fd[2]).amax(),
        (d.a.v_v - a_fd[3]).amax(),
    ]
    .iter()
    .fold(0.0f64, |a, b| a.max(*b))
        / a_scale;
    let e_b = if U > 0 {
        let b_scale = b_fd[0].amax().max(b_fd[1].amax());
        (d.b.q_u - b_fd[0]).amax().max((d.b.v_u - b_fd[1]).amax()) / b_scale
    } else {
        0.0
    };
    (e_a, e_b)
}
