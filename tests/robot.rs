//! Robots at run time (`vigp::Robot`, the linear-time tree engine) against
//! independent references: the generated `mechanism!` spatial code of the
//! same arm (M, p, ∂L/∂q, the DEL residual and step-by-step rollouts),
//! Pinocchio on the Panda and the UR5 (fixtures by
//! scripts/robot_pin_fixtures.py), energy behaviour, the self-subdividing
//! step, and typed errors for bad URDF.

use vigp::SVector;
use vigp::embedded::tree::{BodyScratch, EngineError, EngineOptions};
use vigp::prelude::*;
use vigp::robot::{Robot, RobotError, RobotState};
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

/// Deterministic pseudo-random numbers in [lo, hi) (xorshift).
struct Rng(u64);
impl Rng {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        lo + (hi - lo) * ((self.0 >> 11) as f64 / (1u64 << 53) as f64)
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
    let vi = Variational::new(sys.minimal(), dt);
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

fn read_json(path: &str) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn floats(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

#[test]
fn urdf_robots_match_pinocchio() {
    let pin = read_json(&fixture("pin.json"));
    for (name, file) in [("panda", "panda.urdf"), ("ur5", "ur5.urdf")] {
        let robot = Robot::from_urdf(fixture(file)).unwrap();
        let r = &pin[name];
        let names: Vec<&str> = r["joints"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_str().unwrap())
            .collect();
        let n = robot.dof();
        assert_eq!(names.len(), n, "{name}: coordinates");
        // perm[k]: our coordinate of Pinocchio's k-th joint
        let perm: Vec<usize> = names
            .iter()
            .map(|j| robot.joint_names().iter().position(|x| x == j).unwrap())
            .collect();
        for case in r["cases"].as_array().unwrap() {
            let (qp, vp) = (floats(&case["q"]), floats(&case["v"]));
            let mut q = vec![0.0; n];
            let mut v = vec![0.0; n];
            for k in 0..n {
                q[perm[k]] = qp[k];
                v[perm[k]] = vp[k];
            }
            let m = robot.mass_matrix(&q).unwrap();
            let m_pin: Vec<Vec<f64>> = case["mass"]
                .as_array()
                .unwrap()
                .iter()
                .map(floats)
                .collect();
            let scale = m_pin.iter().flatten().fold(0.0f64, |a, x| a.max(x.abs()));
            // relative to the largest entry: two O(N) recursions in double
            // precision, in other frames and orders
            for a in 0..n {
                for b in 0..n {
                    let e = (m[perm[a] * n + perm[b]] - m_pin[a][b]).abs();
                    assert!(e < 1e-10 * scale, "{name} M[{a},{b}]: {e:e}");
                }
            }
            let bias = robot.bias_forces(&q, &v).unwrap();
            let (p, _, dv) = robot.terms(&q, &v).unwrap();
            let (nle, grav) = (floats(&case["nle"]), floats(&case["gravity"]));
            let bscale = nle.iter().fold(1.0f64, |a, x| a.max(x.abs()));
            for k in 0..n {
                assert!(
                    (bias[perm[k]] - nle[k]).abs() < 1e-10 * bscale,
                    "{name} nle[{k}]: {} vs {}",
                    bias[perm[k]],
                    nle[k]
                );
                assert!(
                    (dv[perm[k]] - grav[k]).abs() < 1e-10 * bscale,
                    "{name} g[{k}]"
                );
            }
            let ke: f64 = 0.5 * p.iter().zip(&v).map(|(a, b)| a * b).sum::<f64>();
            let e = robot
                .energy(&RobotState::new(q.clone(), v.clone()))
                .unwrap();
            let (ke_pin, pe_pin) = (
                case["kinetic"].as_f64().unwrap(),
                case["potential"].as_f64().unwrap(),
            );
            let escale = 1.0 + ke_pin.abs() + pe_pin.abs();
            assert!((ke - ke_pin).abs() < 1e-10 * escale, "{name} kinetic");
            assert!(
                (e - (ke_pin + pe_pin)).abs() < 1e-10 * escale,
                "{name} energy"
            );
        }
    }
}

#[test]
fn long_rollouts_keep_their_energy() {
    // A first-order VI's energy error is O(Δt) and bounded (no drift): over
    // 10^4 steps of 1 ms it stays within 1% of the energy scale Σ m·|g|·1 m
    // (the UR5 has no damping; the Panda's 0.003 N·m·s/rad dissipates less
    // than 0.1 J over these 10 s).
    for (file, q) in [
        ("ur5.urdf", vec![0.3, -1.2, 1.0, -0.5, 0.8, 0.2]),
        ("panda.urdf", vec![0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8]),
    ] {
        let robot = Robot::from_urdf(fixture(file)).unwrap();
        let n = robot.dof();
        let z0 = RobotState::new(q, vec![0.5; n]);
        let run = robot.rollout(&z0, 1e-3, 10_000).unwrap();
        let e0 = robot.energy(&z0).unwrap();
        let err: Vec<f64> = run
            .states
            .iter()
            .map(|z| (robot.energy(z).unwrap() - e0).abs())
            .collect();
        let scale = robot.tree().bodies.iter().map(|b| b.mass).sum::<f64>() * 9.81;
        let worst = err.iter().fold(0.0f64, |a, &x| a.max(x));
        let first = err[..1000].iter().fold(0.0f64, |a, &x| a.max(x));
        let last = err[9000..].iter().fold(0.0f64, |a, &x| a.max(x));
        println!(
            "{file} 10^4 steps of 1 ms: energy error max {worst:.3e} J (first 1000 steps {first:.3e}, \
             last 1000 {last:.3e}), scale {scale:.1} J, {:.2} iterations/step, {} subdivided",
            run.report.iterations as f64 / run.report.steps as f64,
            run.report.subdivided
        );
        assert!(worst < 1e-2 * scale, "{file}: {worst}");
    }
}

/// A planar chain of n rods (m = 1, l = 0.5, thin-rod inertia) hanging in
/// the x–z plane, revolute about y, as URDF.
fn chain_urdf(n: usize) -> String {
    let mut s = String::from("<robot name=\"chain\"><link name=\"l0\"/>");
    let (m, l) = (1.0, 0.5);
    let i = m * l * l / 12.0;
    for k in 1..=n {
        let z = if k == 1 { 0.0 } else { -l };
        s += &format!(
            "<link name=\"l{k}\"><inertial><origin xyz=\"0 0 {}\"/><mass value=\"{m}\"/>\
             <inertia ixx=\"{i}\" ixy=\"0\" ixz=\"0\" iyy=\"{i}\" iyz=\"0\" izz=\"1e-6\"/></inertial></link>\
             <joint name=\"j{k}\" type=\"continuous\"><parent link=\"l{}\"/><child link=\"l{k}\"/>\
             <origin xyz=\"0 0 {z}\"/><axis xyz=\"0 1 0\"/></joint>",
            -l / 2.0,
            k - 1
        );
    }
    s + "</robot>"
}

#[test]
fn chains_subdivide_where_the_full_step_fails() {
    // The case: released from q = (1, −0.5, 0, …) at rest, dt = 10
    // and 5 ms, 10^4 steps with default options. Energy scale: Σ m|g||c_i|
    // hanging straight (c_i at depth l/2 + (i−1)l). A first-order VI's energy
    // error is bounded and O(Δt): within 5% of that scale at these steps.
    for n in [8, 12, 16] {
        let robot = Robot::from_urdf_str(&chain_urdf(n)).unwrap();
        let scale: f64 = (0..n).map(|i| 9.81 * (0.25 + 0.5 * i as f64)).sum();
        let mut q = vec![0.0; n];
        q[0] = 1.0;
        q[1] = -0.5;
        let z0 = RobotState::new(q, vec![0.0; n]);
        let e0 = robot.energy(&z0).unwrap();
        for dt in [0.01, 0.005] {
            let run = robot.rollout(&z0, dt, 10_000).unwrap();
            let worst = run
                .states
                .iter()
                .map(|z| (robot.energy(z).unwrap() - e0).abs())
                .fold(0.0f64, f64::max);
            println!(
                "chain {n}, dt {} ms, 10^4 steps: {} subdivided (deepest {}), {:.2} iterations/step, \
                 max |ΔE| {worst:.3e} J of scale {scale:.0} J",
                dt * 1e3,
                run.report.subdivided,
                run.report.deepest,
                run.report.iterations as f64 / run.report.steps as f64,
            );
            assert!(worst < 0.05 * scale, "chain {n} dt {dt}: {worst}");
            if run.report.subdivided > 0 {
                // without subdivision the same rollout fails, with a typed error
                let fixed = robot
                    .clone()
                    .with_options(EngineOptions {
                        max_depth: 0,
                        ..EngineOptions::default()
                    })
                    .unwrap();
                match fixed.rollout(&z0, dt, 10_000) {
                    Err(RobotError::Rollout { source, .. }) => assert!(
                        matches!(
                            *source,
                            RobotError::Engine(
                                EngineError::NotConverged { depth: 0, .. }
                                    | EngineError::EnergyJump { depth: 0, .. }
                            )
                        ),
                        "{source}"
                    ),
                    other => panic!("expected a failure without subdivision, got {other:?}"),
                }
            }
        }
    }
}

fn err(urdf: &str) -> String {
    Robot::from_urdf_str(urdf).unwrap_err().to_string()
}

#[test]
fn bad_urdf_is_a_typed_error_naming_the_element() {
    let good = std::fs::read_to_string(fixture("arm3.urdf")).unwrap();
    // malformed XML
    let e = Robot::from_urdf_str(&good.replace("</robot>", "")).unwrap_err();
    assert!(matches!(e, RobotError::Parse(_)), "{e}");
    // NaN in a joint origin, ∞ in an inertia
    let e = err(&good.replace("xyz=\"0.3 0 0\"", "xyz=\"0.3 NaN 0\""));
    assert!(e.contains("joint `j3` <origin>"), "{e}");
    let e = err(&good.replace("izz=\"0.005\"", "izz=\"inf\""));
    assert!(e.contains("link `link1` <inertial> <inertia>"), "{e}");
    // a mimic joint
    let e = Robot::from_urdf_str(&good.replace(
        "<dynamics damping=\"0.1\"/>",
        "<mimic joint=\"j1\" multiplier=\"2\"/>",
    ))
    .unwrap_err();
    assert!(
        matches!(&e, RobotError::Mimic { joint, mimics } if joint == "j2" && mimics == "j1"),
        "{e}"
    );
    // floating and planar joints
    let e = err(&good.replace("type=\"prismatic\"", "type=\"floating\""));
    assert!(e.contains("joint `j3`") && e.contains("floating"), "{e}");
    let e = err(&good.replace("type=\"prismatic\"", "type=\"planar\""));
    assert!(e.contains("joint `j3`") && e.contains("planar"), "{e}");
    // an unknown link, a zero axis, a negative mass
    let e = err(&good.replace("<child link=\"link3\"/>", "<child link=\"link9\"/>"));
    assert!(e.contains("joint `j3`") && e.contains("link9"), "{e}");
    let e = err(&good.replace("<axis xyz=\"1 0 0\"/>", "<axis xyz=\"0 0 0\"/>"));
    assert!(e.contains("joint `j3` <axis>"), "{e}");
    let e = err(&good.replace("<mass value=\"0.5\"/>", "<mass value=\"-0.5\"/>"));
    assert!(e.contains("link `link3`"), "{e}");
    // a moving subtree without inertia
    let e = Robot::from_urdf_str(
        &good
            .replace("<mass value=\"0.5\"/>", "<mass value=\"0\"/>")
            .replace("<mass value=\"0.2\"/>", "<mass value=\"0\"/>")
            .replace(
                "ixx=\"0.0005\" ixy=\"0\" ixz=\"0\" iyy=\"0.002\" iyz=\"0\" izz=\"0.002\"",
                "ixx=\"0\" ixy=\"0\" ixz=\"0\" iyy=\"0\" iyz=\"0\" izz=\"0\"",
            )
            .replace(
                "ixx=\"0.0001\" ixy=\"0\" ixz=\"0\" iyy=\"0.0001\" iyz=\"0\" izz=\"0.0001\"",
                "ixx=\"0\" ixy=\"0\" ixz=\"0\" iyy=\"0\" iyz=\"0\" izz=\"0\"",
            ),
    )
    .unwrap_err();
    assert!(
        matches!(&e, RobotError::SingularMass { joint } if joint == "j3"),
        "{e}"
    );
    // unknown actuated joint; a missing file
    let e = Robot::from_urdf_str(&good)
        .unwrap()
        .with_actuated(&["j1", "tool_weld"])
        .unwrap_err();
    assert!(
        matches!(&e, RobotError::UnknownJoint { name, .. } if name == "tool_weld"),
        "{e}"
    );
    assert!(matches!(
        Robot::from_urdf(fixture("missing.urdf")),
        Err(RobotError::Io { .. })
    ));
    // NaN in the state, the inputs; wrong lengths
    let robot = Robot::from_urdf_str(&good)
        .unwrap()
        .with_actuated(&["j2"])
        .unwrap();
    let z = RobotState::new(vec![0.0, f64::NAN, 0.0], vec![0.0; 3]);
    assert!(robot.step(&z, &[0.0], 0.01).is_err());
    let z = RobotState::new(vec![0.0; 3], vec![0.0; 3]);
    assert!(matches!(
        robot.step(&z, &[f64::INFINITY], 0.01),
        Err(RobotError::Engine(EngineError::NonFiniteInput))
    ));
    assert!(matches!(
        robot.step(&z, &[], 0.01),
        Err(RobotError::WrongLength { .. })
    ));
}

#[test]
fn an_input_is_a_generalized_force_on_its_joint() {
    // u on j3 (prismatic) against the same step with that force as the
    // engine's generalized force: a constant force on the slide raises the
    // slide's momentum by u·Δt over an unforced step, to first order
    let robot = Robot::from_urdf(fixture("arm3.urdf"))
        .unwrap()
        .with_actuated(&["j3"])
        .unwrap();
    let z = RobotState::new(vec![0.1, 0.2, 0.0], vec![0.0; 3]);
    let dt = 1e-3;
    let (a, _) = robot.step(&z, &[0.0], dt).unwrap();
    let (b, _) = robot.step(&z, &[2.0], dt).unwrap();
    let pa = robot.momentum(&a).unwrap();
    let pb = robot.momentum(&b).unwrap();
    // p1 − p1' = Δt·u on the actuated coordinate, exactly for the DEL at
    // the same q1 but for the O(Δt·Δv) change of ∂T/∂q and D·v
    assert!(
        (pb[2] - pa[2] - 2.0 * dt).abs() < 1e-6,
        "{} {}",
        pb[2] - pa[2],
        2.0 * dt
    );
    assert!((pb[0] - pa[0]).abs() < 1e-6);
}
