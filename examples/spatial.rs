//! The spatial examples: spherical pendulum, Furuta pendulum, 3-D double
//! pendulum with non-parallel axes, spatial slider-crank (a loop), and a
//! free body tumbling about its intermediate axis. Each runs in maximal
//! coordinates (the Lie-group variational integrator, unit quaternions)
//! and in minimal coordinates (`Variational` on the generated
//! `Mechanism`), and prints the energy error (maximum, first and last
//! tenth), the largest constraint violation |g|, the largest quaternion
//! norm error |‖q‖ − 1|, the cost per step and (maximal view) the mean
//! number of Newton iterations.
//!
//! The initial states are MuJoCo's (`tests/fixtures/spatial_mujoco.json`,
//! written by `scripts/spatial_mujoco.py`), made consistent, so that
//! `python3 scripts/spatial_mujoco.py bench` prints MuJoCo's energy error
//! and cost from the same states.
//!
//! ```text
//! cargo run --release --example spatial              # 10⁵ steps of 10 ms each
//! cargo run --release --example spatial -- 20000     # fewer steps
//! cargo run --release --example spatial -- 20000 --maximal-only
//! ```

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde_json::Value;
use std::time::Instant;
use vigp::prelude::*;
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
        "{:<22} {:<8} {:>11} {:>11} {:>11} {:>9} {:>9} {:>11} {:>10} {:>7}",
        "system",
        "view",
        "max|ΔE| J",
        "1st tenth",
        "last tenth",
        "max|g|",
        "|‖q‖−1|",
        "E0 J",
        "µs/step",
        "Newton/KKT"
    );
    let fixture: Value = serde_json::from_str(&std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/fixtures/spatial_mujoco.json"
    ))?)?;
    let models = &fixture["models"];

    let sys = SphericalPendulum::default();
    let m = &models["spherical_pendulum"];
    run(
        "spherical pendulum",
        sys,
        sys.minimal(),
        sys.maximal(),
        m,
        steps,
    )?;
    let sys = Furuta::default();
    run(
        "furuta",
        sys,
        sys.minimal(),
        sys.maximal(),
        &models["furuta"],
        steps,
    )?;
    let sys = DoublePendulum3d::default();
    let m = &models["double_pendulum_3d"];
    run(
        "3-D double pendulum",
        sys,
        sys.minimal(),
        sys.maximal(),
        m,
        steps,
    )?;
    let sys = SpatialSliderCrank::default();
    let m = &models["spatial_slider_crank"];
    run(
        "spatial slider-crank",
        sys,
        sys.minimal(),
        sys.maximal(),
        m,
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
    let traj = vigp::Integrator::rollout(&stepper, &z0, steps)?;
    let cost = t.elapsed().as_secs_f64() / steps as f64 * 1e6;
    let s = summarize(&stepper, &traj);
    row(
        "tumbler",
        "maximal",
        &s,
        stepper.energy(&z0),
        cost,
        newton(&stepper, &z0),
    );
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

fn row(
    name: &str,
    view: &str,
    s: &vigp::spatial::SpatialSummary,
    e0: f64,
    us: f64,
    newton: (f64, f64),
) {
    let newton = if newton.0.is_nan() {
        String::new()
    } else {
        format!("{:.2}/{:.2}", newton.0, newton.1)
    };
    println!(
        "{name:<22} {view:<8} {:>11.3e} {:>11.3e} {:>11.3e} {:>9.1e} {:>9.1e} {:>11.4} {:>10.2} {newton:>7}",
        s.max_energy_error, s.first_tenth, s.last_tenth, s.max_violation, s.max_norm_error, e0, us
    );
}

/// Mean Newton iterations and KKT factorizations per step over 1000 steps.
fn newton<S: Spatial<B, J>, const B: usize, const J: usize, const N: usize, const C: usize>(
    stepper: &LieStepper<S, B, J, N, C>,
    z0: &SpatialState<B>,
) -> (f64, f64) {
    let mut z = *z0;
    let (mut total, mut factored) = (0, 0);
    for _ in 0..1000 {
        let (next, report) = stepper.step_with_report(&z).expect("step");
        total += report.iterations;
        factored += report.factorizations;
        z = next;
    }
    (total as f64 / 1000.0, factored as f64 / 1000.0)
}

fn vec3(v: &Value) -> Vector3<f64> {
    Vector3::new(
        v[0].as_f64().unwrap_or(f64::NAN),
        v[1].as_f64().unwrap_or(f64::NAN),
        v[2].as_f64().unwrap_or(f64::NAN),
    )
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
    fixture: &Value,
    steps: usize,
) -> Result<(), Box<dyn std::error::Error>>
where
    S: Spatial<B, J> + Copy,
    M: Mechanism<NM, CM> + Copy,
{
    // MuJoCo's initial state (centres of mass, orientations, continuous
    // velocities), made consistent: the discrete velocities projected so
    // that the first step ends on the joints
    let init = fixture["initial"].as_array().ok_or("fixture: initial")?;
    let q = |i: usize| {
        let c = |k: usize| init[i]["quat"][k].as_f64().unwrap_or(f64::NAN);
        UnitQuaternion::new_normalize(Quaternion::new(c(0), c(1), c(2), c(3)))
    };
    let guess = SpatialState::<B> {
        x: std::array::from_fn(|i| vec3(&init[i]["com"])),
        q: std::array::from_fn(q),
        v: std::array::from_fn(|i| vec3(&init[i]["v_com"])),
        w: std::array::from_fn(|i| vec3(&init[i]["w_body"])),
    };
    let stepper = LieStepper::new(view, DT)?;
    let z0 = stepper.consistent_state(&guess)?;
    let zmin = vigp::spatial::views::to_minimal::<S, B, J, NM>(&sys, &z0, DT);

    // maximal coordinates
    let mut traj = vec![z0; steps + 1];
    let t = Instant::now();
    stepper.rollout_into(&z0, &mut traj)?;
    let cost = t.elapsed().as_secs_f64() / steps as f64 * 1e6;
    let iterations = newton(&stepper, &z0);
    let summary = summarize(&stepper, &traj);
    row(
        name,
        "maximal",
        &summary,
        stepper.energy(&z0),
        cost,
        iterations,
    );

    // minimal coordinates
    if std::env::args().any(|a| a == "--maximal-only") {
        return Ok(());
    }
    let vi = Variational::new(minimal, DT)?;
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
    row(name, "minimal", &s, e0, cost, (f64::NAN, f64::NAN));
    Ok(())
}
