//! The spatial examples against MuJoCo (an independent implementation in
//! generalized coordinates): `scripts/spatial_mujoco.py` writes the same
//! models as MJCF, simulates them with RK4 at Δt = 1e-4 s for 2 s from fixed
//! initial states and stores the link poses every 0.05 s in
//! `tests/fixtures/spatial_mujoco.json`. Here the maximal-coordinate
//! Lie-group VI starts from the same states (made consistent) and must
//! converge to MuJoCo's trajectories at first order.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde_json::Value;
use vigp::spatial::{LieStepper, Maximal, Spatial, SpatialState};
use vigp::systems::spatial::{DoublePendulum3d, Furuta, SpatialSliderCrank, SphericalPendulum};

fn fixture() -> Value {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/spatial_mujoco.json"
    ))
    .unwrap();
    serde_json::from_str(&text).unwrap()
}

fn vec3(v: &Value) -> Vector3<f64> {
    Vector3::new(
        v[0].as_f64().unwrap(),
        v[1].as_f64().unwrap(),
        v[2].as_f64().unwrap(),
    )
}

fn quat(v: &Value) -> UnitQuaternion<f64> {
    let f = |i: usize| v[i].as_f64().unwrap();
    UnitQuaternion::new_normalize(Quaternion::new(f(0), f(1), f(2), f(3)))
}

/// Largest distance between our centres of mass (and orientation angle, in
/// radians, times 1 m) and MuJoCo's at the fixture's sample times, for a
/// run at `dt`; also checks the reference pose.
fn run<S, const B: usize, const J: usize, const N: usize, const C: usize, const NM: usize>(
    name: &str,
    sys: S,
    view: Maximal<S, B, J, N, C>,
    dt: f64,
) -> f64
where
    S: Spatial<B, J> + Copy,
{
    let all = fixture();
    let m = &all["models"][name];
    // the reference configuration (all joint coordinates zero) is MuJoCo's
    // qpos0: the same frames, anchors and centres of mass
    let q_ref = vigp::spatial::views::reference::<S, B, J, NM>(&sys);
    let (x_ref, _) = vigp::spatial::views::configuration::<S, B, J, NM>(&sys, &q_ref);
    for (i, r) in m["reference_com"].as_array().unwrap().iter().enumerate() {
        assert!(
            (x_ref[i] - vec3(r)).norm() < 1e-12,
            "{name}: reference pose of link {i}"
        );
    }
    let init = m["initial"].as_array().unwrap();
    assert_eq!(init.len(), B);
    let z = SpatialState::<B> {
        x: std::array::from_fn(|i| vec3(&init[i]["com"])),
        q: std::array::from_fn(|i| quat(&init[i]["quat"])),
        v: std::array::from_fn(|i| vec3(&init[i]["v_com"])),
        w: std::array::from_fn(|i| vec3(&init[i]["w_body"])),
    };
    let stepper = LieStepper::new(view, dt).unwrap();
    // continuous velocities as the first discrete ones, projected so that
    // the first step's end is consistent (an O(Δt) change)
    let z0 = stepper.consistent_state(&z).unwrap();
    let samples = m["samples"].as_array().unwrap();
    let every = (0.05 / dt).round() as usize;
    assert!(
        (every as f64 * dt - 0.05).abs() < 1e-12,
        "Δt must divide the 0.05 s sampling"
    );
    let n = every * (samples.len() - 1);
    let mut traj = vec![z0; n + 1];
    stepper.rollout_into(&z0, &mut traj).unwrap();
    let mut err = 0.0f64;
    for (k, s) in samples.iter().enumerate() {
        let z = &traj[k * every];
        for i in 0..B {
            err = err.max((z.x[i] - vec3(&s["com"][i])).norm());
            err = err.max(z.q[i].angle_to(&quat(&s["quat"][i])));
        }
    }
    err
}

/// Prints the largest pose differences `e` to MuJoCo at Δt = 1, 0.5,
/// 0.25 ms and asserts first order (observed orders within [0.85, 1.2])
/// and e < 4e-3 at the smallest Δt.
fn check(name: &str, e: [f64; 3]) {
    let orders = [(e[0] / e[1]).log2(), (e[1] / e[2]).log2()];
    println!(
        "{name}: max pose difference to MuJoCo over 2 s: {:.3e}, {:.3e}, {:.3e} at Δt = 1, 0.5, 0.25 ms; orders {:.3}, {:.3}",
        e[0], e[1], e[2], orders[0], orders[1]
    );
    assert!(e[2] < 4e-3, "{name}: {e:?}");
    for p in orders {
        assert!((0.85..=1.2).contains(&p), "{name}: order {p}");
    }
}

/// Every example converges to MuJoCo's RK4 trajectory: over 2 s the
/// largest pose difference halves with Δt (observed order within
/// [0.85, 1.2] from Δt = 1 ms to 0.25 ms) and is below 4e-3 (m or rad) at
/// Δt = 0.25 ms (the fixture itself, RK4 at 0.1 ms, is accurate to ~1e-12). The reference poses agree to 1e-12.
#[test]
fn examples_converge_to_mujoco() {
    let dts = [1e-3, 5e-4, 2.5e-4];
    let sys = SphericalPendulum::default();
    check(
        "spherical pendulum",
        dts.map(|dt| run::<_, 1, 1, 6, 3, 4>("spherical_pendulum", sys, sys.maximal(), dt)),
    );
    let sys = Furuta::default();
    check(
        "furuta",
        dts.map(|dt| run::<_, 2, 2, 12, 10, 2>("furuta", sys, sys.maximal(), dt)),
    );
    let sys = DoublePendulum3d::default();
    check(
        "3-D double pendulum",
        dts.map(|dt| run::<_, 2, 2, 12, 10, 2>("double_pendulum_3d", sys, sys.maximal(), dt)),
    );
    let sys = SpatialSliderCrank::default();
    check(
        "spatial slider-crank",
        dts.map(|dt| run::<_, 3, 4, 18, 16, 6>("spatial_slider_crank", sys, sys.maximal(), dt)),
    );
}

/// The same with joint damping (MuJoCo's joint `damping`: on the hinge and
/// slide velocities and on each angular velocity component of a ball
/// joint, ours on the joint rates and |ω_rel|): the damped 3-D double
/// pendulum (0.3, 0.15 N·m·s/rad) and the slider-crank with damped
/// crankshaft, crank pin and rail (0.02, 0.01 N·m·s/rad, 0.5 N·s/m)
/// converge to MuJoCo at first order too.
#[test]
fn damped_examples_converge_to_mujoco() {
    let dts = [1e-3, 5e-4, 2.5e-4];
    let mut sys = DoublePendulum3d::default();
    sys.joints.shoulder.damping = 0.3;
    sys.joints.elbow.damping = 0.15;
    check(
        "damped 3-D double pendulum",
        dts.map(|dt| {
            run::<_, 2, 2, 12, 10, 2>("double_pendulum_3d_damped", sys, sys.maximal(), dt)
        }),
    );
    let mut sys = SpatialSliderCrank::default();
    sys.joints.crankshaft.damping = 0.02;
    sys.joints.crankpin.damping = 0.01;
    sys.joints.rail.damping = 0.5;
    check(
        "damped spatial slider-crank",
        dts.map(|dt| {
            run::<_, 3, 4, 18, 16, 6>("spatial_slider_crank_damped", sys, sys.maximal(), dt)
        }),
    );
}
