//! Cost of one learned step (paper eq. 7) on the double pendulum in minimal
//! coordinates, at N = 64 and N = 512 training points: mean only, and with
//! the posterior variance and the one-step error bound; the exported
//! (`no_std`) GP's mean; and the parts of a step (GP mean, nominal step).
//!
//! Run: `cargo bench --bench learned`. Setup trains four GPs (a few seconds
//! to a minute on 2 cores); the data is deterministic (seeded).
//!
//! Operation count of the GP mean per output: N·d subtract-multiply-adds
//! (the squared distances), N exponentials, N multiply-adds (k·α). The
//! paper's double-pendulum setting (constant prior, sin/cos encoding)
//! has d = 6 and p = 2 outputs, so one step at N = 512 costs 2·512 = 1024
//! exponentials and 2·512·6 = 6144 distance terms.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use vigp::bound::{BoundKind, Calibration};
use vigp::embedded::Stepper;
use vigp::gp::VarianceMode;
use vigp::learned::{Encoding, Prior};
use vigp::prelude::*;
use vigp::systems::{DoublePendulum, DoublePendulumMinimal};

#[path = "learned/data.rs"]
mod data;

use data::{DT, train};

fn bench_learned(c: &mut Criterion) {
    let z = State::new([1.0, -0.5], [0.5, 1.0]);
    let mut g = c.benchmark_group("learned");
    g.warm_up_time(Duration::from_secs(1));
    g.measurement_time(Duration::from_secs(4));
    for n in [64, 512] {
        let l = train(n, Prior::Constant).expect("training");
        let bound = l
            .error_bound(&BoundKind::theorem1(0.05), &Calibration::empty(0.01))
            .expect("bound");
        let mut ws = l.workspace();
        g.bench_function(format!("double_pendulum/N{n}/mean"), |b| {
            b.iter(|| l.step_mean_in(black_box(&z), &mut ws).unwrap())
        });
        g.bench_function(format!("double_pendulum/N{n}/bound"), |b| {
            b.iter(|| {
                let (next, info) = l.step_in(black_box(&z), &mut ws).unwrap();
                (next, bound.one_step(info.std_dev.as_slice()))
            })
        });
        // A 20-step horizon with the one-step bound at every step (MPC):
        // 20 `step_in` calls, against `rollout_with_info`, which steps on
        // the mean and batches the 20 variances (one pass over each L⁻¹).
        // Divide by 20 for the cost per step.
        g.bench_function(format!("double_pendulum/N{n}/horizon20_step_with"), |b| {
            b.iter(|| {
                let mut z = *black_box(&z);
                let mut s = 0.0;
                for _ in 0..20 {
                    let (next, info) = l.step_in(&z, &mut ws).unwrap();
                    s += bound.one_step(info.std_dev.as_slice()).unwrap();
                    z = next;
                }
                (z, s)
            })
        });
        g.bench_function(
            format!("double_pendulum/N{n}/horizon20_rollout_with_info"),
            |b| {
                b.iter(|| {
                    let steps = l.rollout_with_info(black_box(&z), 20, &mut ws).unwrap();
                    let s: f64 = steps
                        .iter()
                        .map(|(_, info)| bound.one_step(info.std_dev.as_slice()).unwrap())
                        .sum();
                    (steps.last().map(|(z, _)| *z), s)
                })
            },
        );
        // A bounded 20-step prediction (`Learned::predict`, Theorem 1):
        // the 20 steps with variances, and the position bound propagated
        // with the learned step's local Jacobian norms at every state.
        g.bench_function(format!("double_pendulum/N{n}/predict20_theorem1"), |b| {
            b.iter(|| l.predict(black_box(&z), 20, &bound).unwrap())
        });
        // Its share per state: the norms of the learned step's exact
        // Jacobian (mean step, GP mean gradient, two 2 × 2 SVDs).
        g.bench_function(format!("double_pendulum/N{n}/step_jacobian_norms"), |b| {
            b.iter(|| l.step_jacobian_norms(black_box(&z), &mut ws).unwrap())
        });
        // The same step with the two outputs' variances on two threads
        // (opt-in `set_parallel_variance`).
        let mut seq = l.clone();
        seq.set_parallel_variance(true);
        let mut seq_ws = seq.workspace();
        g.bench_function(
            format!("double_pendulum/N{n}/bound_parallel_variance"),
            |b| {
                b.iter(|| {
                    let (next, info) = seq.step_in(black_box(&z), &mut seq_ws).unwrap();
                    (next, bound.one_step(info.std_dev.as_slice()))
                })
            },
        );
        // The variance paths (issue 18, item 4): the default stored L⁻¹
        // (`VarianceMode::Inverse`, above) against the blocked forward
        // substitution (`Solve`) and the column-oriented substitution of the
        // previous code, which the exported GP still uses.
        let x = {
            let mut x = [0.0; 6];
            Encoding::SinCos.encode(&DoublePendulumMinimal::KINDS, &z, &mut x);
            x
        };
        let (mut mv, mut vv) = ([0.0; 2], [0.0; 2]);
        let mut gws = l.gp().workspace();
        g.bench_function(format!("gp/N{n}/mean_var_two_outputs/inverse"), |b| {
            b.iter(|| {
                l.gp()
                    .predict_into(black_box(&x), &mut mv, &mut vv, &mut gws)
            })
        });
        let mut solve_gp = l.gp().clone();
        solve_gp.set_variance_mode(VarianceMode::Solve);
        let mut sws = solve_gp.workspace();
        g.bench_function(format!("gp/N{n}/mean_var_two_outputs/blocked_solve"), |b| {
            b.iter(|| solve_gp.predict_into(black_box(&x), &mut mv, &mut vv, &mut sws))
        });
        let with_chol: Vec<_> = (0..2)
            .map(|j| l.gp().export_output(j, true).expect("export"))
            .collect();
        let views: Vec<_> = with_chol
            .iter()
            .map(|a| a.as_exported::<6>().expect("d = 6"))
            .collect();
        let mut scratch = vec![0.0; n];
        g.bench_function(
            format!("gp/N{n}/mean_var_two_outputs/column_solve_previous"),
            |b| {
                b.iter(|| {
                    let a = views[0].predict(black_box(&x), &mut scratch).unwrap();
                    let c = views[1].predict(black_box(&x), &mut scratch).unwrap();
                    (a, c)
                })
            },
        );
        // the exported no_std GP (output 0 of 2)
        let arrays = l.gp().export_output(0, false).expect("export");
        let e = arrays.as_exported::<6>().expect("d = 6");
        let mut x = [0.0; 6];
        Encoding::SinCos.encode(&DoublePendulumMinimal::KINDS, &z, &mut x);
        g.bench_function(format!("exported/N{n}/predict_mean_one_output"), |b| {
            b.iter(|| e.predict_mean(black_box(&x)).unwrap())
        });
        // the GP part of a step: both outputs' means
        let mut m = [0.0; 2];
        let mut gws = l.gp().workspace();
        g.bench_function(format!("gp/N{n}/predict_mean_into_two_outputs"), |b| {
            b.iter(|| l.gp().predict_mean_into(black_box(&x), &mut m, &mut gws))
        });
    }
    // with the nominal VI step as prior (paper eq. 7 for pendulum/cartpole)
    let l = train(512, Prior::Nominal).expect("training");
    let mut ws = l.workspace();
    g.bench_function("double_pendulum/N512/mean_nominal_prior", |b| {
        b.iter(|| l.step_mean_in(black_box(&z), &mut ws).unwrap())
    });
    // the two nominal steps a prior could use
    let vi = Variational::new(DoublePendulum::default().minimal(), DT).unwrap();
    g.bench_function("nominal/variational_std", |b| {
        b.iter(|| vi.step(black_box(&z)).unwrap())
    });
    let fast = Stepper::new(DoublePendulum::default(), DT).expect("stepper");
    g.bench_function("nominal/embedded_stepper", |b| {
        b.iter(|| fast.step(black_box(&z)).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench_learned);
criterion_main!(benches);
