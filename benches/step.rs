//! Cost of one integrator step on the paper's systems, minimal and maximal
//! coordinates, first-order and midpoint VI, and the classical integrators
//! (group `step`, the std dual-number runtime), and the fixed-size `no_std`
//! first-order VI (group `embedded`: one step from a state, and one step
//! inside a rollout, which carries the momentum).
//! Run: `cargo bench --bench step`. Speed against error is printed by
//! `cargo run --release --example speed_vs_error`.

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::SVector;
use std::hint::black_box;
use vigp::embedded::Stepper;
use vigp::prelude::*;
use vigp::projection::consistent_state;
use vigp::systems::{Cartpole, DoublePendulum, Fourbar, Pendulum};

/// One step of `integrator` from `z`, any integrator and any state (the
/// one `Integrator` trait).
fn bench_step<I: Integrator>(
    g: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    name: &str,
    integrator: &I,
    z: &I::State,
) {
    g.bench_function(name, |b| b.iter(|| integrator.step(black_box(z)).unwrap()));
}

/// The first-order VI step of a planar mechanism from the minimal state
/// `z`, in its minimal coordinates (`<name>/minimal/vi`) and in its maximal
/// ones (`<name>/maximal/vi`, from `z` taken there).
fn bench_views<Mn, Mx, const N: usize, const C: usize, const NM: usize, const CM: usize>(
    g: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    name: &str,
    minimal: Mn,
    maximal: Mx,
    z: &State<N>,
    dt: f64,
) where
    Mn: Mechanism<N, C> + Coordinates<N, NM> + Clone,
    Mx: Mechanism<NM, CM> + Clone,
{
    let zm = minimal.to_maximal(z, dt);
    let vi = Variational::new(minimal, dt).unwrap();
    bench_step(g, &format!("{name}/minimal/vi"), &vi, z);
    let vim = Variational::new(maximal, dt).unwrap();
    bench_step(g, &format!("{name}/maximal/vi"), &vim, &zm);
}

/// The four-bar's benchmark state: q = [0.9, −1.3, −0.4, 1.3] and
/// v = [0.5, 0, 0, 0] made consistent with its loop constraints.
fn fourbar_state(fb: &Fourbar, dt: f64) -> State<4> {
    consistent_state(
        &fb.minimal(),
        &SVector::from([0.9, -1.3, -0.4, 1.3]),
        &SVector::from([0.5, 0.0, 0.0, 0.0]),
        dt,
    )
    .unwrap()
}

fn bench_steps(c: &mut Criterion) {
    let dt = 0.01;
    let mut g = c.benchmark_group("step");

    let p = Pendulum::default();
    let z = State::new([1.0], [0.5]);
    bench_views(&mut g, "pendulum", p.minimal(), p.maximal(), &z, dt);

    let cp = Cartpole::default();
    let z = State::new([0.2, 2.0], [0.3, 0.5]);
    bench_views(&mut g, "cartpole", cp.minimal(), cp.maximal(), &z, dt);

    let dp = DoublePendulum::default();
    let z = State::new([1.0, -0.5], [0.5, 1.0]);
    let vi = Variational::new(dp.minimal(), dt).unwrap();
    bench_step(&mut g, "double_pendulum/minimal/vi", &vi, &z);
    let vi2 = Variational::midpoint(dp.minimal(), dt).unwrap();
    bench_step(&mut g, "double_pendulum/minimal/midpoint", &vi2, &z);
    bench_step(
        &mut g,
        "double_pendulum/minimal/rk4",
        &Rk4::new(dp.minimal(), dt),
        &z,
    );
    let vim = Variational::new(dp.maximal(), dt).unwrap();
    bench_step(
        &mut g,
        "double_pendulum/maximal/vi",
        &vim,
        &dp.minimal().to_maximal(&z, dt),
    );

    let fb = Fourbar::default();
    let z = fourbar_state(&fb, dt);
    let vi = Variational::new(fb.minimal(), dt).unwrap();
    bench_step(&mut g, "fourbar/minimal/vi", &vi, &z);
    let zm = fb.minimal().to_maximal(&z, dt);
    let vim = Variational::new(fb.maximal(), dt).unwrap();
    bench_step(&mut g, "fourbar/maximal/vi", &vim, &zm);
    // the same step in a kept workspace (no 24 KB of zeros per call)
    let mut ws = vigp::embedded::StepWorkspace::new();
    g.bench_function("fourbar/maximal/vi_in", |b| {
        b.iter(|| vim.step_in(black_box(&zm), &mut ws).unwrap())
    });
    g.finish();
}

/// The embedded stepper: `step` (computes p₀ = M(x₀)v₀, then solves) from
/// one state and from 64 states along a trajectory, and the per-step cost of
/// a 100-step `rollout_into` (momentum carried).
fn bench_embedded<M, const N: usize, const C: usize>(
    g: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    name: &str,
    sys: M,
    z: State<N>,
) where
    M: vigp::embedded::Dynamics<N, C> + Copy,
{
    let s = Stepper::new(sys, 0.01).unwrap();
    g.bench_function(format!("{name}/step"), |b| {
        b.iter(|| s.step(black_box(&z)).unwrap())
    });
    let mut out = [z; 101];
    g.bench_function(format!("{name}/rollout_100"), |b| {
        b.iter(|| s.rollout_into(black_box(&z), &mut out).unwrap())
    });
    // One step from each of 64 states spread along a trajectory (every 50th
    // of 3 200 steps from z): the cost of a step from a state averaged over
    // the configurations a motion visits (Newton iterations and sincos range
    // reduction vary with the state; the single state above is one sample).
    // Time per 64 steps.
    let mut long = vec![z; 64 * 50 + 1];
    s.rollout_into(&z, &mut long).unwrap();
    let states: Vec<State<N>> = long.iter().step_by(50).take(64).copied().collect();
    g.bench_function(format!("{name}/step_64_states"), |b| {
        b.iter(|| {
            for z in &states {
                black_box(s.step(black_box(z)).unwrap());
            }
        })
    });
}

fn bench_embedded_steps(c: &mut Criterion) {
    let dt = 0.01;
    let mut g = c.benchmark_group("embedded");
    bench_embedded(
        &mut g,
        "pendulum",
        Pendulum::default(),
        State::new([1.0], [0.5]),
    );
    bench_embedded(
        &mut g,
        "cartpole",
        Cartpole::default(),
        State::new([0.2, 2.0], [0.3, 0.5]),
    );
    bench_embedded(
        &mut g,
        "double_pendulum",
        DoublePendulum::default(),
        State::new([1.0, -0.5], [0.5, 1.0]),
    );
    let fb = Fourbar::default();
    let z = fourbar_state(&fb, dt);
    bench_embedded(&mut g, "fourbar", fb, z);
    g.finish();
}

#[path = "common/driven_double_pendulum.rs"]
mod driven_double_pendulum;
use driven_double_pendulum::DrivenDoublePendulum;

/// The embedded double-pendulum step against the same step with its exact
/// derivatives A = ∂z₁/∂z₀ and B = ∂z₁/∂u (implicit function theorem), both
/// rules; the ratio is what the control docs quote (docs/control.md).
fn bench_derivatives(c: &mut Criterion) {
    let dt = 0.01;
    let mut g = c.benchmark_group("derivatives");
    let m = DrivenDoublePendulum::default();
    let z = State::new([1.0, -0.5], [0.5, 1.0]);
    let u = SVector::<f64, 2>::new(0.3, -0.2);
    for (rule, s) in [
        ("first_order", Stepper::new(m, dt).unwrap()),
        ("midpoint", Stepper::midpoint(m, dt).unwrap()),
    ] {
        g.bench_function(format!("double_pendulum/{rule}/step"), |b| {
            b.iter(|| s.step_forced(black_box(&z), black_box(&u)).unwrap())
        });
        g.bench_function(format!("double_pendulum/{rule}/step_with_a_b"), |b| {
            b.iter(|| {
                s.step_with_derivatives(black_box(&z), black_box(&u))
                    .unwrap()
            })
        });
    }
    // maximal coordinates (N = 6, C = 4): the embedded stepper zeroes the
    // solver's 4 KB scratch at every call, the std runtime keeps it per
    // thread (the same results, bit for bit)
    let (mx, zx) = (m.maximal(), m.minimal().to_maximal(&z, dt));
    let s = Stepper::new(mx, dt).unwrap();
    let vi = Variational::new(mx, dt).unwrap();
    g.bench_function("double_pendulum/maximal/step", |b| {
        b.iter(|| s.step_forced(black_box(&zx), black_box(&u)).unwrap())
    });
    g.bench_function("double_pendulum/maximal/vi_step", |b| {
        b.iter(|| vi.step_forced(black_box(&zx), black_box(&u)).unwrap())
    });
    g.bench_function("double_pendulum/maximal/step_with_a_b", |b| {
        b.iter(|| {
            s.step_with_derivatives(black_box(&zx), black_box(&u))
                .unwrap()
        })
    });
    g.bench_function("double_pendulum/maximal/vi_step_with_a_b", |b| {
        b.iter(|| vi.step_derivatives(black_box(&zx), black_box(&u)).unwrap())
    });
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30).measurement_time(std::time::Duration::from_secs(2)).warm_up_time(std::time::Duration::from_millis(500));
    targets = bench_steps, bench_embedded_steps, bench_derivatives
}
criterion_main!(benches);
