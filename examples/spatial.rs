//! The spatial examples: spherical pendulum, Furuta pendulum, 3-D double
//! pendulum with non-parallel axes, spatial slider-crank (a loop), and a
//! free body tumbling about its intermediate axis. Each runs in maximal
//! coordinates (the Lie-group variational integrator, unit quaternions)
//! and in minimal coordinates (`Variational` on the generated
//! `Mechanism`), and prints the energy error (maximum, first and last
//! tenth), the largest constraint violation |g|, the largest quaternion
//! norm error |‖q‖ − 1| and the cost per step.
//!
//! ```text
//! cargo run --release --example spatial              # 10⁵ steps of 10 ms each
//! cargo run --release --example spatial -- 20000     # fewer steps
//! ```

use nalgebra::{SVector, UnitQuaternion, Vector3};
use std::time::Instant;
use vigp::prelude::*;
use vigp::projection::consistent_state;
use vigp::spatial::{LieStepper, Maximal, Spatial, SpatialState, summarize};
use vigp::systems::spatial::{
    DoublePendulum3d, Furuta, SpatialSliderCrank, SphericalPendulum, Tumbler,
};

const DT: f64 = 0.01;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let steps: usize = std::env::args()
        .nth(1)
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(100_000);
    println!(
        "Δt = {DT} s, {steps} steps; load: {}",
        std::fs::read_to_string("/proc/loadavg")
            .unwrap_or_default()
            .trim()
    );
    println!(
        "{:<22} {:<8} {:>11} {:>11} {:>11} {:>9} {:>9} {:>11} {:>10}",
        "system",
        "view",
        "max|ΔE| J",
        "1st tenth",
        "last tenth",
        "max|g|",
        "|‖q‖−1|",
        "E0 J",
        "µs/step"
    );

    let sys = SphericalPendulum::default();
    run(
        "spherical pendulum",
        sys,
        sys.minimal(),
        sys.maximal(),
        [0.8, 0.1, 0.55, 0.2],
        [0.0, 0.5, 0.0, 1.5],
        steps,
    )?;
    let sys = Furuta::default();
    run(
        "furuta",
        sys,
        sys.minimal(),
        sys.maximal(),
        [0.0, 2.5],
        [3.0, 0.0],
        steps,
    )?;
    let sys = DoublePendulum3d::default();
    run(
        "3-D double pendulum",
        sys,
        sys.minimal(),
        sys.maximal(),
        [1.0, -0.8],
        [0.0, 0.0],
        steps,
    )?;
    let sys = SpatialSliderCrank::default();
    run(
        "spatial slider-crank",
        sys,
        sys.minimal(),
        sys.maximal(),
        [0.0, 0.99, 0.0, 0.0, 0.12, 0.03],
        [6.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        steps,
    )?;

    // the free body: maximal coordinates only (its minimal view has one
    // free joint, i.e. the same 6 DOF with a quaternion constraint)
    let stepper = LieStepper::new(Tumbler::default().maximal(), DT)?;
    let z0 = SpatialState::<1> {
        x: [Vector3::zeros()],
        q: [UnitQuaternion::identity()],
        v: [Vector3::zeros()],
        w: [Vector3::new(1e-4, 2.0, 1e-4)],
    };
    let t = Instant::now();
    let traj = vigp::spatial::SpatialIntegrator::rollout(&stepper, &z0, steps)?;
    let cost = t.elapsed().as_secs_f64() / steps as f64 * 1e6;
    let s = summarize(&stepper, &traj);
    row("tumbler", "maximal", &s, stepper.energy(&z0), cost);
    let l0 = stepper.momentum(&z0).1;
    let drift = traj
        .iter()
        .map(|z| (stepper.momentum(z).1 - l0).norm())
        .fold(0.0, f64::max);
    let flips = traj
        .windows(2)
        .filter(|w| w[0].w[0].y.signum() != w[1].w[0].y.signum())
        .count();
    println!(
        "tumbler: |L0| = {:.4}, max |L − L0| = {drift:.2e}; ω_y changed sign {flips} times (intermediate-axis flips)",
        l0.norm()
    );
    Ok(())
}

fn row(name: &str, view: &str, s: &vigp::spatial::SpatialSummary, e0: f64, us: f64) {
    println!(
        "{name:<22} {view:<8} {:>11.3e} {:>11.3e} {:>11.3e} {:>9.1e} {:>9.1e} {:>11.4} {:>10.2}",
        s.max_energy_error, s.first_tenth, s.last_tenth, s.max_violation, s.max_norm_error, e0, us
    );
}

#[allow(clippy::too_many_arguments)]
fn run<
    S,
    M,
    const B: usize,
    const J: usize,
    const N: usize,
    const C: usize,
    const NM: usize,
    const CM: usize,
>(
    name: &str,
    sys: S,
    minimal: M,
    view: Maximal<S, B, J, N, C>,
    q: [f64; NM],
    v: [f64; NM],
    steps: usize,
) -> Result<(), Box<dyn std::error::Error>>
where
    S: Spatial<B, J> + Copy,
    M: Mechanism<NM, CM> + Copy,
{
    let zmin = consistent_state(&minimal, &SVector::from(q), &SVector::from(v), DT)?;
    let z0 = vigp::spatial::views::to_maximal::<S, B, J, NM>(&sys, &zmin, DT);

    // maximal coordinates
    let stepper = LieStepper::new(view, DT)?;
    let mut traj = vec![z0; steps + 1];
    let t = Instant::now();
    stepper.rollout_into(&z0, &mut traj)?;
    let cost = t.elapsed().as_secs_f64() / steps as f64 * 1e6;
    row(
        name,
        "maximal",
        &summarize(&stepper, &traj),
        stepper.energy(&z0),
        cost,
    );

    // minimal coordinates
    let vi = Variational::new(minimal, DT);
    let mut out = vec![zmin; steps];
    let t = Instant::now();
    vi.rollout_into(&zmin, &mut out)?;
    let cost = t.elapsed().as_secs_f64() / steps as f64 * 1e6;
    let e0 = minimal.energy(&zmin);
    let n = steps;
    let tenth = (n / 10).max(1);
    let mut s = vigp::spatial::SpatialSummary {
        max_energy_error: 0.0,
        first_tenth: 0.0,
        last_tenth: 0.0,
        max_violation: 0.0,
        max_norm_error: 0.0,
    };
    for (k, z) in out.iter().enumerate() {
        let de = (minimal.energy(z) - e0).abs();
        s.max_energy_error = s.max_energy_error.max(de);
        if k < tenth {
            s.first_tenth = s.first_tenth.max(de);
        }
        if k + tenth >= n {
            s.last_tenth = s.last_tenth.max(de);
        }
        // loop rows and unit norms together (minimal coordinates)
        s.max_violation = s.max_violation.max(minimal.constraint_violation(z));
        // quaternion coordinates: |‖u‖ − 1|
        let mut i = 0;
        while i < NM {
            if M::KINDS[i] == vigp::CoordinateKind::Quaternion {
                let u = z.q.fixed_rows::<4>(i);
                s.max_norm_error = s.max_norm_error.max((u.norm() - 1.0).abs());
                i += 4;
            } else {
                i += 1;
            }
        }
    }
    row(name, "minimal", &s, e0, cost);
    Ok(())
}
