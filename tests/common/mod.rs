//! Shared helpers for the integration tests.
#![allow(dead_code)]

#[path = "rng.rs"]
mod rng;
#[allow(unused_imports)] // not every test binary draws random numbers
pub use rng::Rng;

use nalgebra::SVector;
use vigp::{Mechanism, Variational};

/// Training options with `restarts` restarts and seed `seed` (the rest
/// default).
pub fn train_options(restarts: usize, seed: u64) -> vigp::gp::TrainOptions {
    vigp::gp::TrainOptions {
        restarts,
        seed,
        ..vigp::gp::TrainOptions::default()
    }
}

/// Training options with `restarts` restarts (the rest default).
pub fn restarts(restarts: usize) -> vigp::gp::TrainOptions {
    vigp::gp::TrainOptions {
        restarts,
        ..vigp::gp::TrainOptions::default()
    }
}

/// Step options solving to 1e-14 (the rest default).
pub fn tight() -> vigp::StepOptions {
    vigp::StepOptions {
        tolerance: 1e-14,
        ..vigp::StepOptions::default()
    }
}

/// The state at sample `k` of positions `q` sampled every `dt`: q_k with
/// the velocity (q_{k+1} − q_k)/dt.
pub fn state_at<const N: usize>(q: &[SVector<f64, N>], k: usize, dt: f64) -> vigp::State<N> {
    vigp::State {
        q: q[k],
        v: (q[k + 1] - q[k]) / dt,
    }
}

/// The bound window of positions `p` sampled every `dt`: the state at the
/// first sample, then the positions after it.
pub fn window<const N: usize>(p: &[SVector<f64, N>], dt: f64) -> vigp::bound::Window<N> {
    vigp::bound::Window {
        start: state_at(p, 0, dt),
        positions: p[1..].to_vec(),
    }
}

/// The first transition of a bound window sampled every `dt`: its start
/// and the velocity of its first step.
pub fn first_transition<const N: usize>(
    w: &vigp::bound::Window<N>,
    dt: f64,
) -> vigp::learned::Transition<N> {
    vigp::learned::Transition {
        z: w.start,
        v_next: (w.positions[1] - w.positions[0]) / dt,
    }
}

/// `f` run in a fresh rayon pool of `threads` threads.
pub fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

/// Whether the two reference-step results agree: the engine's step and
/// the reference step (`name`, `alpha` name them in failures) give the
/// same positions and velocities within 1e-11; returns |Δv|.
pub fn reference_gap<const N: usize, T, E: std::fmt::Display, F: std::fmt::Display>(
    name: &str,
    alpha: f64,
    engine: Result<vigp::State<N>, E>,
    reference: Result<(vigp::State<N>, T), F>,
) -> f64 {
    let a = engine.unwrap_or_else(|e| panic!("{name} α={alpha}: {e}"));
    let (b, _) = reference.unwrap_or_else(|e| panic!("{name} α={alpha} reference: {e}"));
    assert_eq!(a.q, b.q);
    let d = (a.v - b.v).amax();
    assert!(d <= 1e-11, "{name} α={alpha}: |Δv| = {d:.2e}");
    d
}

/// The consistent state of `m` at rest near the positions `q`: `q`
/// projected onto the constraints, and the velocity zero projected at `dt`.
pub fn at_rest<M: Mechanism<N, C>, const N: usize, const C: usize>(
    m: &M,
    q: impl Into<SVector<f64, N>>,
    dt: f64,
) -> vigp::State<N> {
    vigp::projection::consistent_state(m, &q.into(), &SVector::zeros(), dt).unwrap()
}

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
    let q = at_rest(&m, q0, h).q;
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

/// `z` with `e` added to q_j (`in_q`) or to v_j.
pub fn nudged<const N: usize>(z: &vigp::State<N>, j: usize, in_q: bool, e: f64) -> vigp::State<N> {
    let mut zp = *z;
    if in_q {
        zp.q[j] += e;
    } else {
        zp.v[j] += e;
    }
    zp
}

/// The largest deviation of the columns of an exact A (`a`) from
/// five-point differences ([`stencil`], step `eps`) of `step` at `z`
/// perturbed in each coordinate of q and v, and the largest entry of
/// those differences: (error, scale).
pub fn a_stencil_errors<const N: usize>(
    z: &vigp::State<N>,
    a: &vigp::embedded::StateJacobian<N>,
    eps: f64,
    mut step: impl FnMut(&vigp::State<N>) -> vigp::State<N>,
) -> (f64, f64) {
    let (mut err, mut scale) = (0.0f64, 0.0f64);
    for j in 0..N {
        for pos in [true, false] {
            let (dq, dv) = stencil(eps, |e| step(&nudged(z, j, pos, e)));
            let (aq, av) = if pos {
                (a.q_q.column(j), a.v_q.column(j))
            } else {
                (a.q_v.column(j), a.v_v.column(j))
            };
            err = err.max((aq - dq).amax()).max((av - dv).amax());
            scale = scale.max(dq.amax()).max(dv.amax());
        }
    }
    (err, scale)
}

/// The largest entry in magnitude of the four blocks of a state Jacobian.
pub fn jacobian_amax<const N: usize>(a: &vigp::embedded::StateJacobian<N>) -> f64 {
    a.q_q
        .amax()
        .max(a.q_v.amax())
        .max(a.v_q.amax())
        .max(a.v_v.amax())
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
            let (dq, dv) = stencil(eps, |e| step(&nudged(z, j, base, e), u));
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

/// The bits of a state's coordinates, q then v.
pub fn state_bits<const N: usize>(z: &vigp::State<N>) -> Vec<u64> {
    z.q.iter().chain(z.v.iter()).map(|x| x.to_bits()).collect()
}

/// Whether two states are equal bit for bit.
pub fn same_bits<const N: usize>(a: &vigp::State<N>, b: &vigp::State<N>) -> bool {
    state_bits(a) == state_bits(b)
}

/// The bits of a spatial state, link by link: x, q, v, ω.
pub fn spatial_bits<const B: usize>(z: &vigp::spatial::SpatialState<B>) -> Vec<u64> {
    (0..B)
        .flat_map(|i| {
            z.x[i]
                .iter()
                .chain(z.q[i].quaternion().coords.iter())
                .chain(z.v[i].iter())
                .chain(z.w[i].iter())
                .map(|x| x.to_bits())
                .collect::<Vec<_>>()
        })
        .collect()
}

/// Whether two spatial states are equal bit for bit.
pub fn same_spatial_bits<const B: usize>(
    a: &vigp::spatial::SpatialState<B>,
    b: &vigp::spatial::SpatialState<B>,
) -> bool {
    spatial_bits(a) == spatial_bits(b)
}

/// The default Furuta pendulum's consistent maximal state at `dt` from
/// minimal coordinates (0.3, 2.5) and rates (2.0, 0.5).
pub fn furuta_start(dt: f64) -> vigp::spatial::SpatialState<2> {
    let sys = vigp::systems::spatial::Furuta::default();
    let zmin = vigp::projection::consistent_state(
        &sys.minimal(),
        &SVector::from([0.3, 2.5]),
        &SVector::from([2.0, 0.5]),
        dt,
    )
    .unwrap();
    sys.minimal().to_maximal(&zmin, dt)
}

/// The numbers of a JSON array (of a test fixture).
pub fn json_floats(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

/// Deterministic pseudo-random numbers in [lo, hi) (xorshift).
pub struct XorShift(pub u64);

impl XorShift {
    /// Uniform in [lo, hi) with 53 random bits.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        lo + (hi - lo) * ((self.0 >> 11) as f64 / (1u64 << 53) as f64)
    }
}
