//! Speed against error: every integrator on the double pendulum at several
//! time steps — time per step including one energy evaluation (median of 5
//! batches; run on a quiet machine for absolute numbers), position error at
//! t = 2 s against a reference, and the energy error over the run.
//!
//! Run: `cargo run --release --example speed_vs_error`

use std::time::Instant;
use vigp::prelude::*;
use vigp::systems::DoublePendulum;

const T: f64 = 2.0;

/// Final state, median µs per step, max |ΔE|.
type Run = Result<(State<2>, f64, f64), StepError>;

fn run<I: Integrator<State = State<2>, Error = StepError>>(
    i: &I,
    z0: &State<2>,
    energy: impl Fn(&State<2>) -> f64,
) -> Run {
    let steps = (T / i.dt()).round() as usize;
    let e0 = energy(z0);
    let mut best = Vec::new();
    let mut end = *z0;
    let mut de = 0.0f64;
    for _ in 0..5 {
        let mut z = *z0;
        let start = Instant::now();
        for _ in 0..steps {
            z = i.step(&z)?;
            de = de.max((energy(&z) - e0).abs());
        }
        best.push(start.elapsed().as_secs_f64() * 1e6 / steps as f64);
        end = z;
    }
    best.sort_by(f64::total_cmp);
    Ok((end, best[2], de))
}

fn main() -> Result<(), StepError> {
    let mut sys = DoublePendulum::default();
    sys.joints.shoulder.damping = 0.0;
    let m = sys.minimal();
    let q0 = [1.0, 0.5];
    // reference: the midpoint VI at 1e-5 s (second order, error ~1e-9 here)
    let h = 1e-5;
    let zr = State::new(q0, [0.0; 2]);
    let v = vigp::dynamics::discrete_velocity(&m, &zr.q, &zr.v, h)?;
    let reference =
        Variational::midpoint(m, h)?.rollout(&State { q: zr.q, v }, (T / h).round() as usize)?;
    let q_ref = reference.last().map(|z| z.q).unwrap_or(zr.q);
    println!(
        "double pendulum from q = {q0:?} at rest, t = {T} s; reference: midpoint VI at dt = 1e-5"
    );
    println!(
        "{:<18} {:>8} {:>12} {:>14} {:>14}",
        "integrator", "dt", "µs/step", "|q(T) − ref|", "max |ΔE| (J)"
    );
    for dt in [0.02, 0.01, 0.005, 0.0025] {
        let z0 = State::new(q0, [0.0; 2]);
        let vd = vigp::dynamics::discrete_velocity(&m, &z0.q, &z0.v, dt)?;
        let zd = State { q: z0.q, v: vd };
        let energy = |z: &State<2>| m.energy(z);
        let vi = Variational::new(m, dt)?;
        let mid = Variational::midpoint(m, dt)?;
        let rows: [(&str, Run); 5] = [
            (
                "explicit Euler",
                run(&ExplicitEuler::new(m, dt), &z0, energy),
            ),
            (
                "symplectic Euler",
                run(&SymplecticEuler::new(m, dt), &z0, energy),
            ),
            ("RK4", run(&Rk4::new(m, dt), &z0, energy)),
            ("VI (paper, 1st)", run(&vi, &zd, energy)),
            ("VI (midpoint)", run(&mid, &zd, |z| mid.energy(z))),
        ];
        for (name, r) in rows {
            match r {
                Ok((end, us, de)) => println!(
                    "{name:<18} {dt:>8} {us:>12.2} {:>14.3e} {de:>14.3e}",
                    (end.q - q_ref).amax()
                ),
                Err(e) => println!("{name:<18} {dt:>8} failed: {e}"),
            }
        }
    }
    Ok(())
}
