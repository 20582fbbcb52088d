//! A robot loaded from URDF at run time (`vigp::Robot`, the linear-time tree
//! engine) against the generated `mechanism!` spatial code of the same arm
//! declared by hand: M, p, ∂L/∂q, ∇V, the DEL residual and step-by-step
//! rollouts. Pinocchio, energy, subdivision and error tests of `Robot`:
//! vigp-runtime/tests/robot.rs.

use crate::common::XorShift as Rng;
use vigp::SVector;
use vigp::embedded::tree::BodyScratch;
use vigp::prelude::*;
use vigp::robot::{Robot, RobotState};
use vigp::spatial::minimal;

const FIXTURES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/robots");

fn fixture(name: &str) -> String {
    format!("{FIXTURES}/{name}")
}

// The arm of tests/fixtures/robots/arm3.urdf, declared by hand. Link frames
// are the URDF link frames: link2, link3 and tool are turned by the joint
// origin's yaw of π/2 (x along world y); anchors are the joint origins in
// the parent link frame; axes are in the parent frame (j2's URDF axis y of
// its joint frame is −x of link1's); inertias about the centre of mass in
// the link frame.
vigp::mechanism! {
    Arm3 {
        gravity: [0.0, 0.0, -9.81],
        links {
            link1: { mass: 2.0, com: [0.02, 0.0, 0.15],
                     inertia: [[0.02, 0.001, 0.0], [0.001, 0.021, 0.0], [0.0, 0.0, 0.005]] },
            link2: { mass: 1.2, com: [0.15, 0.0, 0.0], inertia: [0.001, 0.01, 0.01],
                     frame: [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]] },
            link3: { mass: 0.5, com: [0.05, 0.01, 0.0], inertia: [0.0005, 0.002, 0.002],
                     frame: [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]] },
            tool: { mass: 0.2, inertia: [0.0001, 0.0001, 0.0001],
                    frame: [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]] },
        }
        joints {
            j1: revolute(world @ [0.0, 0.0, 0.1], link1.start) { axis: [0.0, 0.0, 1.0], damping: 0.0 },
            j2: revolute(link1 @ [0.0, 0.05, 0.3], link2.start) { axis: [-1.0, 0.0, 0.0], damping: 0.1 },
            j3: prismatic(link2 @ [0.3, 0.0, 0.0], link3.start) { axis: [1.0, 0.0, 0.0], damping: 0.0 },
            tool_weld: fixed(link3 @ [0.1, 0.0, 0.0], tool.start),
        }
    }
}

#[test]
fn urdf_arm_matches_the_generated_spatial_code() {
    let robot = Robot::from_urdf(fixture("arm3.urdf")).unwrap();
    assert_eq!(robot.joint_names(), ["j1", "j2", "j3"]);
    assert_eq!(robot.link_names(), ["link1", "link2", "link3"]);
    // limits kept as written; the welded tool's mass merged into link3
    let l = robot.tree().bodies[0].limits;
    assert_eq!(
        (l.lower, l.upper, l.effort, l.velocity),
        (-2.9, 2.9, 50.0, 2.0)
    );
    assert_eq!(robot.tree().bodies[2].mass, 0.5 + 0.2);
    assert_eq!(robot.tree().bodies[1].damping, 0.1);
    let sys = Arm3::default();
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let dt = 0.01;
    for _ in 0..6 {
        let q: [f64; 3] = std::array::from_fn(|i| rng.uniform(-1.5, 1.5) * [1.0, 1.0, 0.1][i]);
        let v: [f64; 3] = std::array::from_fn(|_| rng.uniform(-2.0, 2.0));
        let t = minimal::terms::<Arm3, 4, 4, 3>(&sys, &SVector::from(q));
        // agreement to rounding: entries are O(1), both sides sum O(10)
        // products of O(1) numbers in another order
        let tol = 1e-13;
        let m = robot.mass_matrix(&q).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                assert!((m[i * 3 + j] - t.mass[(i, j)]).abs() < tol, "M[{i},{j}]");
            }
        }
        let (p, dtdq, dvdq) = robot.terms(&q, &v).unwrap();
        let vv = SVector::from(v);
        let p_ref = t.mass * vv;
        for i in 0..3 {
            let dt_ref = 0.5 * vv.dot(&(t.dmass[i] * vv));
            assert!((p[i] - p_ref[i]).abs() < tol, "p[{i}]");
            assert!(
                (dtdq[i] - dt_ref).abs() < tol,
                "dT/dq[{i}] {} vs {dt_ref}",
                dtdq[i]
            );
            assert!((dvdq[i] - t.dpotential[i]).abs() < 1e-12, "dV/dq[{i}]");
        }
        // the DEL residual at a trial v1, against the same formula on the
        // reference terms at q1 = q0 + dt·v0
        let v1: [f64; 3] = std::array::from_fn(|i| v[i] + rng.uniform(-0.3, 0.3));
        let q1: [f64; 3] = std::array::from_fn(|i| q[i] + dt * v[i]);
        let t1 = minimal::terms::<Arm3, 4, 4, 3>(&sys, &SVector::from(q1));
        let w1 = SVector::from(v1);
        let mut r = [0.0; 3];
        let mut ws = vec![BodyScratch::default(); 3];
        robot
            .engine()
            .residual(&q, &v, &p, &[0.0; 3], &v1, dt, &mut r, &mut ws)
            .unwrap();
        let f = SVector::<f64, 3>::from_fn(|i, _| 0.5 * w1.dot(&(t1.dmass[i] * w1)))
            - t1.dpotential
            - t1.damping * w1;
        let r_ref = p_ref - t1.mass * w1 + f * dt;
        for i in 0..3 {
            assert!(
                (r[i] - r_ref[i]).abs() < tol,
                "r[{i}] {} vs {}",
                r[i],
                r_ref[i]
            );
        }
    }
}

#[test]
fn urdf_arm_steps_as_the_generated_integrator() {
    let robot = Robot::from_urdf(fixture("arm3.urdf")).unwrap();
    let sys = Arm3::default();
    let dt = 0.005;
    let vi = Variational::new(sys.minimal(), dt).unwrap();
    let mut z = sys.minimal().state([0.4, -0.9, 0.05], [1.0, 0.5, -0.2]);
    let mut zr = RobotState::new(vec![0.4, -0.9, 0.05], vec![1.0, 0.5, -0.2]);
    let mut worst = 0.0f64;
    for _ in 0..400 {
        z = vi.step(&z).unwrap();
        zr = robot.step(&zr, &[], dt).unwrap().0;
        for i in 0..3 {
            worst = worst
                .max((z.q[i] - zr.q[i]).abs())
                .max((z.v[i] - zr.v[i]).abs());
        }
    }
    println!("arm3: largest |Δq|, |Δv| against mechanism! over 400 steps: {worst:.2e}");
    // both solve the same DEL equations to a 1e-12 scaled residual; the
    // difference is solver tolerance carried through 400 steps
    assert!(worst < 1e-9, "{worst}");
}
