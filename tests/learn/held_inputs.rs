//! Learning under zero-order-held inputs from truths other than vigp's own
//! first-order variational integrator.
//!
//! Under a held input the next discrete velocity v_{k+1} depends on the
//! state z_k = (x_k, v_k), the input held over the new interval (u) and the
//! input that produced v_k (u_prev): for a continuous system, x_k, x_{k+1}
//! and u_prev fix the true velocity at t_{k+1}. A forced learned model's
//! GP therefore takes (enc(z_k), u_prev, u) (`vigp::learned`, "Under
//! inputs"). Here three actuated mechanisms (a torque pendulum, an acrobot,
//! a cart-pole pushed along its rail) are logged from two truths that carry
//! the previous input — the midpoint VI, whose momentum keeps the input's
//! share of the last interval, and RK4 on the continuous equations at
//! Δt/20 sampled every Δt — with inputs held for segments of 1 to 20
//! steps; and from two peers (`rk45_truth`, `mujoco_truth`): SciPy's RK45
//! on MuJoCo's dynamics and MuJoCo's `implicitfast` integrator, logged by
//! scripts/held_inputs_truths.py. A model learned on these logs (the nominal prior is the
//! first-order VI of the same mechanism, without any parameter error: all
//! there is to learn is the truth's integration) must predict 20 steps
//! more accurately than the nominal model at every switch length.
//!
//! The learned step's exact derivatives A = ∂z₁/∂z₀, B = ∂z₁/∂u and
//! B_prev = ∂z₁/∂u_prev are checked against five-point central
//! differences.

use crate::common;
use common::{Rng, a_stencil_errors, stencil};
use nalgebra::SVector;
use vigp::gp::TrainOptions;
use vigp::learned::{Encoding, ForcedTransition, Learned, Prior, forced_transitions};
use vigp::{Integrator, Mechanism, Rk4, State, Variational};

vigp::mechanism! {
    /// A damped pendulum driven by a torque at its pivot.
    pub HeldPendulum {
        gravity: [0.0, -9.81],
        links {
            rod: { mass: 1.0, length: 1.0 },
        }
        joints {
            pivot: revolute(world, rod.start) { damping: 0.5, actuated },
        }
    }
}

vigp::mechanism! {
    /// An acrobot: a double pendulum driven at the elbow.
    pub HeldAcrobot {
        gravity: [0.0, -9.81],
        links {
            upper: { mass: 1.0, length: 1.0 },
            lower: { mass: 1.0, length: 1.0 },
        }
        joints {
            shoulder: revolute(world, upper.start) { damping: 0.1 },
            elbow: revolute(upper.end, lower.start) { damping: 0.1, actuated },
        }
    }
}

drive_cartpole! {
    /// A cart-pole pushed along its rail.
    HeldCartpole {
        gravity: [0.0, -9.81],
        rail: [damping: 0.3],
        hinge: [damping: 0.05],
    }
}

const DT: f64 = 0.01;
/// RK4 sub-steps per Δt: RK4's error at Δt/20 = 5e-4 s is orders below
/// the first-order VI's at Δt, so the RK4 log is the continuous motion
/// for this comparison.
const SUBSTEPS: usize = 20;
/// Prediction horizon (steps).
const HORIZON: usize = 20;
/// Start samples of the test windows of each switch length: 1..=STARTS
/// covers every phase of a segment of up to 20 steps.
const STARTS: usize = 20;

#[derive(Clone, Copy, Debug)]
enum Truth {
    Midpoint,
    Rk4,
}

/// Inputs logged with each of `samples` samples, held until the next:
/// u_0 = 0 (the log starts at rest), then segments of `length(rng)` steps,
/// each a uniform draw in ±`scale`.
fn held_inputs<const U: usize>(
    rng: &mut Rng,
    samples: usize,
    scale: f64,
    mut length: impl FnMut(&mut Rng) -> usize,
) -> Vec<SVector<f64, U>> {
    let mut out = vec![SVector::zeros()];
    while out.len() < samples {
        let u = SVector::from_fn(|_, _| rng.uniform(-scale, scale));
        for _ in 0..length(rng) {
            out.push(u);
        }
    }
    out.truncate(samples);
    out
}

/// Positions x_0, …, x_{K−1} of `truth` from rest at `q0` under `logged`
/// (K inputs, `logged[k]` held over [t_k, t_{k+1}]).
fn log<M, const N: usize, const U: usize>(
    model: M,
    truth: Truth,
    q0: SVector<f64, N>,
    logged: &[SVector<f64, U>],
) -> Vec<SVector<f64, N>>
where
    M: Mechanism<N, 0> + Clone + vigp::Inputs<U>,
{
    match truth {
        Truth::Midpoint => {
            // the rollout carries the momentum (with the midpoint rule's
            // share of the last interval's input); step k runs under the
            // input over [t_{k+1}, t_{k+2}], and the first interval's
            // input is 0 (at rest, as `held_inputs` logs it)
            let vi = Variational::midpoint(model, DT).unwrap();
            let z0 = State {
                q: q0,
                v: SVector::zeros(),
            };
            let mut out = vec![z0; logged.len() - 1];
            vi.rollout_forced_into(&z0, &logged[1..], &mut out).unwrap();
            std::iter::once(q0).chain(out.iter().map(|z| z.q)).collect()
        }
        Truth::Rk4 => {
            let rk = Rk4::new(model, DT / SUBSTEPS as f64);
            let mut z = State {
                q: q0,
                v: SVector::zeros(),
            };
            let mut out = vec![q0];
            for u in &logged[..logged.len() - 1] {
                for _ in 0..SUBSTEPS {
                    z = rk.step_forced(&z, u).unwrap();
                }
                out.push(z.q);
            }
            out
        }
    }
}

/// RMS position error over all steps of all test windows, nominal and
/// learned, for one switch length.
struct Errors {
    nominal: f64,
    learned: f64,
}

/// One log: samples x_k and the inputs u_k held over [t_k, t_{k+1}];
/// `length` is the switch length of a test log (0 for a training log).
struct Log<const N: usize, const U: usize> {
    length: usize,
    inputs: Vec<SVector<f64, U>>,
    x: Vec<SVector<f64, N>>,
}

/// Trains a forced model on logs of `truth` with switch lengths drawn from
/// 1..=20 and measures nominal and learned 20-step errors for every switch
/// length 1..=20 (windows starting at samples 1..=20 of a fresh log each).
fn held_input_errors<M, const N: usize, const U: usize>(
    name: &str,
    model: M,
    truth: Truth,
    encoding: Encoding,
    scale: f64,
    q_range: [f64; N],
    seed: u64,
) -> Vec<Errors>
where
    M: Mechanism<N, 0> + Clone + vigp::Inputs<U> + vigp::Parameters,
{
    let mut rng = Rng(seed);
    let start =
        |rng: &mut Rng| SVector::<f64, N>::from_fn(|i, _| rng.uniform(-1.0, 1.0) * q_range[i]);
    let mut logs = Vec::new();
    for _ in 0..6 {
        let inputs = held_inputs::<U>(&mut rng, 72, scale, |r| 1 + (r.next_u64() % 20) as usize);
        let q0 = start(&mut rng);
        let x = log(model.clone(), truth, q0, &inputs);
        logs.push(Log {
            length: 0,
            inputs,
            x,
        });
    }
    for length in 1..=20 {
        let inputs = held_inputs::<U>(&mut rng, STARTS + HORIZON + 2, scale, |_| length);
        let q0 = start(&mut rng);
        let x = log(model.clone(), truth, q0, &inputs);
        logs.push(Log { length, inputs, x });
    }
    errors(&format!("{name} {truth:?}"), model, &logs, encoding, seed)
}

/// Trains a forced model on the training logs (`length` 0) and measures
/// nominal and learned 20-step errors on each test log (windows starting
/// at samples 1..=20).
fn errors<M, const N: usize, const U: usize>(
    name: &str,
    model: M,
    logs: &[Log<N, U>],
    encoding: Encoding,
    seed: u64,
) -> Vec<Errors>
where
    M: Mechanism<N, 0> + Clone + vigp::Inputs<U> + vigp::Parameters,
{
    let mut data: Vec<ForcedTransition<N, U>> = Vec::new();
    for l in logs.iter().filter(|l| l.length == 0) {
        data.extend(forced_transitions(&l.x, &l.inputs, DT));
    }
    let options = TrainOptions {
        restarts: 1,
        seed,
        ..TrainOptions::default()
    };
    let (learned, _) =
        Learned::train_forced(model.clone(), DT, &data, encoding, Prior::Nominal, &options)
            .unwrap();
    assert!(learned.takes_previous_input());
    let nominal = Variational::new(model.clone(), DT).unwrap();
    let mut out = Vec::new();
    for l in logs.iter().filter(|l| l.length > 0) {
        let (length, logged, x) = (l.length, &l.inputs, &l.x);
        let (mut e_nom, mut e_lrn, mut n) = (0.0, 0.0, 0usize);
        for s in 1..=STARTS {
            let z0 = common::state_at(x, s, DT);
            // step k from sample s + k under the input of row s + k + 1,
            // after row s + k's: the start's velocity was produced by row s's
            let us = &logged[s + 1..=s + HORIZON];
            let mut pn = vec![z0; HORIZON];
            nominal.rollout_forced_into(&z0, us, &mut pn).unwrap();
            let mut pl = vec![z0; HORIZON];
            learned
                .rollout_mean_forced_into(&z0, &logged[s], us, &mut pl)
                .unwrap();
            for k in 0..HORIZON {
                let truth = x[s + k + 1];
                e_nom += (pn[k].q - truth).norm_squared();
                e_lrn += (pl[k].q - truth).norm_squared();
                n += 1;
            }
        }
        let e = Errors {
            nominal: (e_nom / n as f64).sqrt(),
            learned: (e_lrn / n as f64).sqrt(),
        };
        println!(
            "{name} switch every {length:2} steps: nominal {:.2e}, learned {:.2e}, \
             learned/nominal {:.3}",
            e.nominal,
            e.learned,
            e.learned / e.nominal
        );
        out.push(e);
    }
    out
}

/// At every switch length 1..=20 the learned model's RMS position error
/// over 20-step predictions is below the nominal model's.
fn assert_learned_wins(errors: &[Errors]) {
    let worst = errors
        .iter()
        .map(|e| e.learned / e.nominal)
        .fold(0.0, f64::max);
    println!("worst learned/nominal ratio over switch lengths 1..=20: {worst:.3}");
    for (i, e) in errors.iter().enumerate() {
        assert!(
            e.learned < e.nominal,
            "switch length {}: learned {:e} >= nominal {:e}",
            i + 1,
            e.learned,
            e.nominal
        );
    }
}

/// [`assert_learned_wins`] on [`held_input_errors`] of `model` (one
/// input, sin/cos-encoded angles) against `truth`.
fn learned_wins_on_held_inputs<M, const N: usize>(
    name: &str,
    model: M,
    truth: Truth,
    scale: f64,
    q_range: [f64; N],
    seed: u64,
) where
    M: Mechanism<N, 0> + Clone + vigp::Inputs<1> + vigp::Parameters,
{
    let e =
        held_input_errors::<_, N, 1>(name, model, truth, Encoding::SinCos, scale, q_range, seed);
    assert_learned_wins(&e);
}

#[test]
fn pendulum_midpoint_truth() {
    let m = HeldPendulum::default().minimal();
    learned_wins_on_held_inputs("pendulum", m, Truth::Midpoint, 4.0, [1.5], 1);
}

#[test]
fn pendulum_rk4_truth() {
    let m = HeldPendulum::default().minimal();
    learned_wins_on_held_inputs("pendulum", m, Truth::Rk4, 4.0, [1.5], 2);
}

#[test]
fn acrobot_midpoint_truth() {
    let m = HeldAcrobot::default().minimal();
    learned_wins_on_held_inputs("acrobot", m, Truth::Midpoint, 4.0, [0.8, 0.8], 3);
}

#[test]
fn acrobot_rk4_truth() {
    let m = HeldAcrobot::default().minimal();
    learned_wins_on_held_inputs("acrobot", m, Truth::Rk4, 4.0, [0.8, 0.8], 4);
}

#[test]
fn cartpole_midpoint_truth() {
    let m = HeldCartpole::default().minimal();
    learned_wins_on_held_inputs("cart-pole", m, Truth::Midpoint, 5.0, [0.3, 0.8], 5);
}

#[test]
fn cartpole_rk4_truth() {
    let m = HeldCartpole::default().minimal();
    learned_wins_on_held_inputs("cart-pole", m, Truth::Rk4, 5.0, [0.3, 0.8], 6);
}

/// The logs of `tests/fixtures/held_inputs/{system}_{truth}.csv`, written
/// by `scripts/held_inputs_truths.py` (columns `run,length,u…,q…`; runs
/// with `length` 0 are training logs, the others test logs with inputs
/// switching every `length` steps).
fn peer_logs<const N: usize, const U: usize>(system: &str, truth: &str) -> Vec<Log<N, U>> {
    let path = format!(
        "{}/tests/fixtures/held_inputs/{system}_{truth}.csv",
        env!("CARGO_MANIFEST_DIR")
    );
    let text = std::fs::read_to_string(&path).unwrap();
    let mut logs: Vec<Log<N, U>> = Vec::new();
    let mut current = usize::MAX;
    for line in text.lines().skip(1) {
        let cols: Vec<&str> = line.split(',').collect();
        assert_eq!(cols.len(), 2 + U + N, "{path}: {line}");
        let run: usize = cols[0].parse().unwrap();
        let length: usize = cols[1].parse().unwrap();
        let num = |i: usize| cols[i].parse::<f64>().unwrap();
        if run != current {
            current = run;
            logs.push(Log {
                length,
                inputs: Vec::new(),
                x: Vec::new(),
            });
        }
        let l = logs.last_mut().unwrap();
        l.inputs.push(SVector::from_fn(|i, _| num(2 + i)));
        l.x.push(SVector::from_fn(|i, _| num(2 + U + i)));
    }
    assert_eq!(logs.len(), 26, "{path}");
    logs
}

/// The peers simulate the same mechanism as vigp: vigp's RK4 at Δt/20 from
/// each RK45 log's start under its inputs reproduces the log. Tolerance
/// 1e-8 rad or m: RK4's global error at h = 5e-4 s over 0.7 s is ~1e-11 for
/// these motions, SciPy's RK45 runs at rtol 1e-11; a wrong mass, length,
/// inertia, damping or sign shows at 1e-4 or more within a few steps.
fn assert_same_mechanism<M, const N: usize, const U: usize>(model: M, logs: &[Log<N, U>])
where
    M: Mechanism<N, 0> + Clone + vigp::Inputs<U>,
{
    let mut worst = 0.0f64;
    for l in logs {
        let x = log(model.clone(), Truth::Rk4, l.x[0], &l.inputs);
        for (a, b) in x.iter().zip(&l.x) {
            worst = worst.max((a - b).amax());
        }
    }
    println!("vigp RK4 vs SciPy RK45 on MuJoCo's dynamics: worst {worst:.1e}");
    assert!(worst < 1e-8, "{worst:e}");
}

/// Truths from peers: SciPy's RK45 on MuJoCo's continuous dynamics, and
/// MuJoCo's `implicitfast` integrator at 1 ms, on the same three
/// mechanisms (scripts/held_inputs_truths.py). The learned model beats the
/// nominal one at every switch length 1..=20.
#[test]
fn rk45_truth() {
    peer_truth("rk45");
}

/// See [`rk45_truth`].
#[test]
fn mujoco_truth() {
    peer_truth("mujoco");
}

fn peer_truth(truth: &str) {
    let p = HeldPendulum::default().minimal();
    let a = HeldAcrobot::default().minimal();
    let c = HeldCartpole::default().minimal();
    peer_learned_wins::<_, 1>("pendulum", "pendulum", p, truth, 1);
    peer_learned_wins::<_, 2>("acrobot", "acrobot", a, truth, 3);
    peer_learned_wins::<_, 2>("cartpole", "cart-pole", c, truth, 5);
}

/// The peer logs of `truth` for `system` (`name` in messages): on the
/// RK45 logs, vigp simulates the same mechanism
/// ([`assert_same_mechanism`]); the learned model wins at every switch
/// length ([`assert_learned_wins`], seed `seed`).
fn peer_learned_wins<M, const N: usize>(system: &str, name: &str, model: M, truth: &str, seed: u64)
where
    M: Mechanism<N, 0> + Clone + vigp::Inputs<1> + vigp::Parameters,
{
    let logs = peer_logs::<N, 1>(system, truth);
    if truth == "rk45" {
        assert_same_mechanism(model.clone(), &logs);
    }
    let name = format!("{name} {truth}");
    assert_learned_wins(&errors(&name, model, &logs, Encoding::SinCos, seed));
}

/// A = ∂z₁/∂z₀, B = ∂z₁/∂u and B_prev = ∂z₁/∂u_prev of the learned step
/// (an acrobot learned from the RK4 log, velocities with uniform noise of
/// σ = 1e-4) against five-point central differences with ε = 1e-3.
///
/// Tolerance 1e-6 relative to the largest entry of each matrix (the
/// tolerance of tests/step/control.rs for the same step): the five-point
/// stencil's truncation error is O(ε⁴) and its rounding error is the GP
/// mean's rounding (~1e-16·Σ|α_i k_i|) divided by ε; measured worst 3.9e-7
/// over the six states (A ≤ 3.2e-8, B ≤ 3.4e-7, B_prev ≤ 3.9e-7). The
/// noise on the targets keeps the GP's noise variance off its floor, as in
/// tests/step/control.rs (noise-free data drives α up and the mean's rounding
/// noise up to ~1e-7, which no stencil resolves to 1e-6).
#[test]
fn learned_step_derivatives_with_previous_input() {
    let model = HeldAcrobot::default().minimal();
    let mut rng = Rng(11);
    let mut data = Vec::new();
    for _ in 0..4 {
        let logged = held_inputs::<1>(&mut rng, 60, 4.0, |r| 1 + (r.next_u64() % 8) as usize);
        let q0 = SVector::<f64, 2>::new(rng.uniform(-0.8, 0.8), rng.uniform(-0.8, 0.8));
        let positions = log(model, Truth::Rk4, q0, &logged);
        data.extend(forced_transitions(&positions, &logged, DT));
    }
    let data: Vec<_> = data
        .into_iter()
        .step_by(2)
        .map(|mut t: ForcedTransition<2, 1>| {
            for x in t.v_next.iter_mut() {
                *x += rng.uniform(-1.7e-4, 1.7e-4);
            }
            t
        })
        .collect();
    let options = common::train_options(1, 5);
    let (l, _) =
        Learned::train_forced(model, DT, &data, Encoding::SinCos, Prior::Nominal, &options)
            .unwrap();
    let mut ws = l.workspace();
    let mut ws2 = l.workspace();
    let mut worst = 0.0f64;
    for t in data.iter().step_by(17).take(6) {
        let (z, up, u) = (t.z, t.u_prev, t.u);
        let (z1, d, dp) = l.step_derivatives_forced(&z, &up, &u, &mut ws).unwrap();
        assert_eq!(z1, l.step_mean_forced_in(&z, &up, &u, &mut ws).unwrap());
        let mut step = |z: State<2>, up: SVector<f64, 1>, u: SVector<f64, 1>| {
            l.step_mean_forced_in(&z, &up, &u, &mut ws2).unwrap()
        };
        let (err_a, scale_a) = a_stencil_errors(&z, &d.a, 1e-3, |zp| step(*zp, up, u));
        let one = SVector::<f64, 1>::new(1.0);
        let (bq, bv) = stencil(1e-3, |e| step(z, up, u + one * e));
        let err_b = (d.b.q_u.column(0) - bq)
            .amax()
            .max((d.b.v_u.column(0) - bv).amax());
        let (pq, pv) = stencil(1e-3, |e| step(z, up + one * e, u));
        let err_p = (dp.q_u.column(0) - pq)
            .amax()
            .max((dp.v_u.column(0) - pv).amax());
        // the previous input matters: its derivative is not negligible
        assert!(pv.amax() > 1e-4, "∂v₁/∂u_prev = {:e}", pv.amax());
        let rel = [err_a / scale_a, err_b / bv.amax(), err_p / pv.amax()];
        println!(
            "A err {:.1e}, B err {:.1e}, B_prev err {:.1e} (|∂v₁/∂u_prev| = {:.1e})",
            rel[0],
            rel[1],
            rel[2],
            pv.amax()
        );
        worst = rel.iter().fold(worst, |w, r| w.max(*r));
    }
    println!("learned step derivatives: worst relative error {worst:.1e}");
    assert!(worst <= 1e-6, "{worst:e}");
}
