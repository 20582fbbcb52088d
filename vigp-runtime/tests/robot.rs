//! Robots loaded from URDF at run time (`Robot`, the linear-time tree
//! engine) against independent references: Pinocchio on the Panda, the
//! UR5, the Solo-12 legs and the 29-joint G1 humanoid, both on a fixed base
//! (fixtures by scripts/robot_pin_fixtures.py: mass matrix, nonlinear
//! effects, gravity, energies), energy behaviour of long rollouts, the
//! self-subdividing step on fast chains, inputs, and typed errors for bad
//! URDF. The same engine against the generated `mechanism!` code of an
//! arm: tests/step/robot.rs of the `vigp` package.

use vigp_core::tree::{EngineError, EngineOptions};
use vigp_runtime::robot::{Robot, RobotError, RobotState, UrdfError};

mod common;

const FIXTURES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/fixtures/robots");

/// The path of the fixture `name`.
fn fixture(name: &str) -> String {
    format!("{FIXTURES}/{name}")
}

/// The robot of the URDF fixture `file`, the joints `joints` driven.
fn driven(file: &str, joints: &[&str]) -> Robot {
    Robot::from_urdf(fixture(file))
        .unwrap()
        .with_actuated(joints)
        .unwrap()
}

/// The largest |exact[(i, j)] − (f(j, ε) − f(j, −ε))/2ε| over the `cols`
/// columns j of `exact`: `f(j, e)` is the state (q then v) reached with
/// the j-th variable moved by e.
fn worst_columns(
    exact: &nalgebra::DMatrix<f64>,
    cols: usize,
    eps: f64,
    f: impl Fn(usize, f64) -> Vec<f64>,
) -> f64 {
    let mut worst = 0.0f64;
    for j in 0..cols {
        let (sp, sm) = (f(j, eps), f(j, -eps));
        for i in 0..exact.nrows() {
            worst = worst.max((exact[(i, j)] - (sp[i] - sm[i]) / (2.0 * eps)).abs());
        }
    }
    worst
}

/// `z` with its state entry `j` (q then v) moved by `e`.
fn nudged(z: &RobotState, j: usize, e: f64) -> RobotState {
    let mut z = z.clone();
    let n = z.q.len();
    if j < n {
        z.q[j] += e;
    } else {
        z.v[j - n] += e;
    }
    z
}

/// The JSON file at `path`, parsed.
fn read_json(path: &str) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The numbers of a JSON array.
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
    for (name, file) in [
        ("panda", "panda.urdf"),
        ("ur5", "ur5.urdf"),
        ("solo12", "solo12.urdf"),
        ("g1", "g1.urdf"),
    ] {
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
        // perm[k]: our coordinate of Pinocchio's k-th joint; the order is
        // Pinocchio's (depth first, children in file order), so the
        // identity
        let perm: Vec<usize> = names
            .iter()
            .map(|j| robot.joint_names().iter().position(|x| x == j).unwrap())
            .collect();
        assert!(
            perm.iter().enumerate().all(|(k, &p)| k == p),
            "{name}: coordinates {:?}, Pinocchio's {names:?}",
            robot.joint_names()
        );
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
    // A first-order VI's energy error is bounded (no drift) and O(Δt·ω)
    // relative to the energy scale, ω the fastest joint rate: over 10^4
    // steps of 1 ms, |E − E0| ≤ Δt·max|v|·(Σ m·|g|·1 m + max T). The UR5 has
    // no damping. The Panda's joints are damped (0.003 N·m·s/rad) and its
    // wrist spins up to ~70 rad/s while the arm falls, so it loses tens of
    // joules: there the bound holds for the energy gained above the start
    // (a flow that gained more would break the energy balance
    // dE/dt = −Σ d_i v_i²), and the energy ends lower.
    for (file, q) in [
        ("ur5.urdf", vec![0.3, -1.2, 1.0, -0.5, 0.8, 0.2]),
        ("panda.urdf", vec![0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8]),
        ("solo12.urdf", vec![0.0; 12]),
        ("g1.urdf", vec![0.0; 29]),
    ] {
        let robot = Robot::from_urdf(fixture(file)).unwrap();
        let damped = robot.tree().bodies.iter().any(|b| b.damping > 0.0);
        let n = robot.dof();
        let z0 = RobotState::new(q, vec![0.5; n]);
        let run = robot.rollout(&z0, 1e-3, 10_000).unwrap();
        let e0 = robot.energy(&z0).unwrap();
        let de: Vec<f64> = run
            .states
            .iter()
            .map(|z| robot.energy(z).unwrap() - e0)
            .collect();
        let kinetic = run
            .states
            .iter()
            .map(|z| {
                let p = robot.momentum(z).unwrap();
                0.5 * p.iter().zip(&z.v).map(|(a, b)| a * b).sum::<f64>()
            })
            .fold(0.0f64, f64::max);
        let scale = robot.tree().bodies.iter().map(|b| b.mass).sum::<f64>() * 9.81 + kinetic;
        let vmax = run
            .states
            .iter()
            .flat_map(|z| z.v.iter())
            .fold(0.0f64, |a, x| a.max(x.abs()));
        let bound = 1e-3 * vmax * scale;
        let gain = de.iter().fold(f64::NEG_INFINITY, |a, &x| a.max(x));
        let worst = de.iter().fold(0.0f64, |a, &x| a.max(x.abs()));
        println!(
            "{file} 10^4 steps of 1 ms: largest |E − E0| {worst:.3e} J, largest gain {gain:.3e} J, \
             final {:.3e} J, scale {scale:.1} J, max |v| {vmax:.1}, bound {bound:.3e} J, {:.2} iterations/step, {} subdivided",
            de.last().unwrap(),
            run.report.iterations as f64 / run.report.steps as f64,
            run.report.subdivided
        );
        if damped {
            assert!(gain < bound, "{file}: gain {gain}");
            assert!(*de.last().unwrap() < 0.0, "{file}: no dissipation");
        } else {
            assert!(worst < bound, "{file}: {worst}");
        }
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
    assert!(matches!(e, RobotError::Urdf(UrdfError::Parse(_))), "{e}");
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
        matches!(&e, RobotError::Urdf(UrdfError::Mimic { joint, mimics }) if joint == "j2" && mimics == "j1"),
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
    let robot = driven("arm3.urdf", &["j3"]);
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

/// max |A − A_fd| and max |B − B_fd| relative to the largest entry of A
/// and of B, with A_fd, B_fd central differences of `Robot::step` at
/// ε = 1e-5 on a robot whose solver tolerance is 1e-13 (the solver's noise
/// is then ~1e-13/ε = 1e-8 of the entries, the truncation error ~ε² =
/// 1e-10): a wrong or missing term (damping, an input, the momentum's
/// configuration derivative) shows at 1e-3 or more.
fn against_differences(robot: &Robot, z: &RobotState, u: &[f64], dt: f64) -> (f64, f64) {
    let d = robot.step_derivatives(z, u, dt).unwrap();
    let n = robot.dof();
    let fine = robot
        .clone()
        .with_options(EngineOptions {
            tolerance: 1e-13,
            ..*robot.engine().options()
        })
        .unwrap();
    // the differences must see the same sub-steps as the derivatives
    let (_, fine_report) = fine.step(z, u, dt).unwrap();
    assert_eq!(
        (fine_report.substeps, fine_report.depth),
        (d.report.substeps, d.report.depth),
        "the finer tolerance changed the sub-steps: the differences would not be of the same map"
    );
    let eps = 1e-5;
    let state = |z: &RobotState, u: &[f64]| {
        let (z1, _) = fine.step(z, u, dt).unwrap();
        [z1.q, z1.v].concat()
    };
    let worst_a = worst_columns(&d.a, 2 * n, eps, |j, e| state(&nudged(z, j, e), u));
    let worst_b = worst_columns(&d.b, u.len(), eps, |k, e| {
        let mut u = u.to_vec();
        u[k] += e;
        state(z, &u)
    });
    let scale_b = d.b.amax().max(f64::MIN_POSITIVE);
    (worst_a / d.a.amax(), worst_b / scale_b)
}

#[test]
fn step_derivatives_match_central_differences() {
    // the damped Panda, two joints driven, from a moving state; the arm3
    // (a prismatic joint, a yawed frame, a welded tool) driven on its slide
    let panda = driven("panda.urdf", &["panda_joint2", "panda_joint6"]);
    let z = RobotState::new(
        vec![0.1, -0.4, 0.3, -1.8, 0.2, 1.4, 0.6],
        vec![0.5, -0.3, 0.2, 0.4, -0.6, 0.1, 0.3],
    );
    let arm = driven("arm3.urdf", &["j1", "j3"]);
    let za = RobotState::new(vec![0.3, -0.7, 0.05], vec![1.2, -0.8, 0.3]);
    // a branching tree (four legs from a fixed base): the Newton matrix is
    // factored in the tree's pattern
    let solo = Robot::from_urdf(fixture("solo12.urdf")).unwrap();
    let joints = solo.joint_names().to_vec();
    let solo = solo
        .with_actuated(&[&joints[1], &joints[5], &joints[10]])
        .unwrap();
    let zs = RobotState::new(
        (0..12).map(|i| 0.4 * (1.3 * i as f64).sin()).collect(),
        (0..12).map(|i| 0.8 * (0.7 * i as f64).cos()).collect(),
    );
    for (name, robot, z, u, dt) in [
        ("panda", &panda, &z, vec![2.0, -1.0], 0.002),
        ("panda", &panda, &z, vec![2.0, -1.0], 0.02),
        ("arm3", &arm, &za, vec![0.4, 1.5], 0.005),
        ("solo12", &solo, &zs, vec![0.3, -0.2, 0.5], 0.002),
    ] {
        let d = robot.step_derivatives(z, &u, dt).unwrap();
        let (z1, report) = robot.step(z, &u, dt).unwrap();
        // the same sub-steps as the step itself, bit for bit
        assert_eq!(d.state, z1);
        assert_eq!(
            (d.report.substeps, d.report.depth),
            (report.substeps, report.depth)
        );
        let (ea, eb) = against_differences(robot, z, &u, dt);
        println!(
            "{name}, dt {} ms: A {ea:.1e}, B {eb:.1e} (vs central differences, of the largest entry)",
            dt * 1e3
        );
        assert!(ea < 1e-6 && eb < 1e-6, "{name}: A {ea:e}, B {eb:e}");
    }
}

#[test]
fn step_derivatives_chain_the_sub_steps_of_a_subdivided_step() {
    // the 8-rod chain at dt = 10 ms: the first step along its rollout that
    // subdivides itself; its A is the product of the sub-steps' and must
    // match differences of the whole (subdivided) step
    let robot = Robot::from_urdf_str(&chain_urdf(8))
        .unwrap()
        .with_actuated(&["j1"])
        .unwrap();
    let mut q = vec![0.0; 8];
    q[0] = 1.0;
    q[1] = -0.5;
    let mut z = RobotState::new(q, vec![0.0; 8]);
    let dt = 0.01;
    let mut found = None;
    for _ in 0..2000 {
        let (z1, report) = robot.step(&z, &[0.0], dt).unwrap();
        if report.depth > 0 {
            found = Some((z.clone(), report));
            break;
        }
        z = z1;
    }
    let (z, report) = found.expect("no step of the 8-rod chain subdivided in 2000 steps");
    let d = robot.step_derivatives(&z, &[0.0], dt).unwrap();
    assert_eq!(d.state, robot.step(&z, &[0.0], dt).unwrap().0);
    assert_eq!(
        (d.report.substeps, d.report.depth),
        (report.substeps, report.depth)
    );
    let (ea, eb) = against_differences(&robot, &z, &[0.0], dt);
    println!(
        "chain 8, dt 10 ms, {} sub-steps (depth {}): A {ea:.1e}, B {eb:.1e}",
        report.substeps, report.depth
    );
    assert!(ea < 1e-6 && eb < 1e-6, "A {ea:e}, B {eb:e}");
}

/// The engine's trajectories converge to MuJoCo's at the integrator's
/// order: MuJoCo 4.0 (its own URDF importer) with RK4 at dt = 1e-5 s over
/// T = 0.5 s is the reference (scripts/robot_mujoco.py writes
/// tests/fixtures/robots/mujoco_rk4.json); the engine's first-order rule
/// at dt = 4, 2, 1, 0.5 ms must approach it with a fitted order of
/// log(error) against log(dt) within 1 ± 0.15 (the error halving with dt),
/// and the Richardson extrapolation 2q(dt/2) − q(dt) of the two finest
/// runs ten times closer to MuJoCo than the finest run (so the limit is
/// MuJoCo's trajectory, not merely some trajectory). Panda (damped,
/// falling under gravity through 3 rad) and the Solo-12 legs.
#[test]
fn trajectories_converge_to_mujoco_rk4_at_first_order() {
    let reference = read_json(&fixture("mujoco_rk4.json"));
    for (name, file) in [("panda", "panda.urdf"), ("solo12", "solo12.urdf")] {
        let r = &reference[name];
        let robot = Robot::from_urdf(fixture(file)).unwrap();
        let joints: Vec<String> = r["joints"]
            .as_array()
            .unwrap()
            .iter()
            .map(|j| j.as_str().unwrap().to_string())
            .collect();
        assert_eq!(joints, robot.joint_names(), "{name}: coordinate order");
        let z0 = RobotState::new(floats(&r["q0"]), floats(&r["v0"]));
        let (t, q_ref) = (r["t"].as_f64().unwrap(), floats(&r["q"]));
        let gap = |a: &[f64], b: &[f64]| {
            a.iter()
                .zip(b)
                .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        };
        let (mut points, mut finals) = (Vec::new(), Vec::new());
        for dt in [0.004, 0.002, 0.001, 0.0005] {
            let steps = (t / dt).round() as usize;
            let run = robot.rollout(&z0, dt, steps).unwrap();
            let q = run.states.last().unwrap().q.clone();
            let e = gap(&q, &q_ref);
            finals.push(q);
            println!(
                "{name}: dt {:.1} ms, max |q(T) − q_MuJoCo RK4(T)| = {e:.3e}",
                dt * 1e3
            );
            points.push((dt, e));
        }
        let n = points.len() as f64;
        let (lx, ly): (Vec<f64>, Vec<f64>) = points.iter().map(|(x, y)| (x.ln(), y.ln())).unzip();
        let (mx, my) = (lx.iter().sum::<f64>() / n, ly.iter().sum::<f64>() / n);
        let order = lx
            .iter()
            .zip(&ly)
            .map(|(x, y)| (x - mx) * (y - my))
            .sum::<f64>()
            / lx.iter().map(|x| (x - mx) * (x - mx)).sum::<f64>();
        let extrapolated: Vec<f64> = finals[3]
            .iter()
            .zip(&finals[2])
            .map(|(fine, coarse)| 2.0 * fine - coarse)
            .collect();
        let richardson = gap(&extrapolated, &q_ref);
        println!("{name}: fitted order {order:.3}, Richardson extrapolation {richardson:.3e}");
        assert!((order - 1.0).abs() < 0.15, "{name}: order {order}");
        assert!(richardson < 0.1 * points[3].1, "{name}: {richardson:e}");
    }
}

#[test]
fn rollout_derivatives_chain_to_the_differences_of_the_whole_rollout() {
    // arm3 driven on two joints, 6 steps of 5 ms: the products of the
    // per-step A_k, B_k against central differences of the final state
    // (ε = 1e-5, solver tolerance 1e-13: 1e-6 of the largest entry, as
    // for one step)
    let robot = driven("arm3.urdf", &["j1", "j3"]);
    let fine = robot
        .clone()
        .with_options(EngineOptions {
            tolerance: 1e-13,
            ..EngineOptions::default()
        })
        .unwrap();
    let (n, dt) = (robot.dof(), 0.005);
    let z0 = RobotState::new(vec![0.3, -0.7, 0.05], vec![1.2, -0.8, 0.3]);
    let inputs: Vec<Vec<f64>> = (0..6)
        .map(|k| vec![0.5 * (k as f64).sin(), 1.0 - 0.2 * k as f64])
        .collect();
    let steps = robot.rollout_derivatives(&z0, &inputs, dt).unwrap();
    assert_eq!(steps.len(), 6);
    // ∂z_6/∂z_0 and ∂z_6/∂u_2
    let mut a = nalgebra::DMatrix::<f64>::identity(2 * n, 2 * n);
    for d in &steps {
        a = &d.a * a;
    }
    let mut b2 = steps[2].b.clone();
    for d in &steps[3..] {
        b2 = &d.a * b2;
    }
    let last = |z: &RobotState, us: &[Vec<f64>]| {
        let mut z = z.clone();
        for u in us {
            z = fine.step(&z, u, dt).unwrap().0;
        }
        [z.q, z.v].concat()
    };
    let eps = 1e-5;
    let worst_a = worst_columns(&a, 2 * n, eps, |j, e| last(&nudged(&z0, j, e), &inputs));
    let worst_b = worst_columns(&b2, 2, eps, |k, e| {
        let mut us = inputs.clone();
        us[2][k] += e;
        last(&z0, &us)
    });
    let (ea, eb) = (worst_a / a.amax(), worst_b / b2.amax());
    println!("arm3, 6 steps of 5 ms: dz6/dz0 {ea:.1e}, dz6/du2 {eb:.1e} (of the largest entry)");
    assert!(ea < 1e-6 && eb < 1e-6, "{ea:e} {eb:e}");
    // the states are the rollout's, to the solver's tolerance
    let run = robot
        .rollout_with(&z0, dt, 6, |k, _| inputs[k].clone())
        .unwrap();
    let gap = steps
        .iter()
        .zip(&run.states[1..])
        .flat_map(|(d, z)| d.state.q.iter().zip(&z.q).map(|(x, y)| (x - y).abs()))
        .fold(0.0f64, f64::max);
    assert!(gap < 1e-10, "{gap:e}");
    // into a caller's vector: the same entries, bit for bit, and on the
    // next call of the same length the same matrices (no new allocation)
    let mut reused = Vec::new();
    robot
        .rollout_derivatives_into(&z0, &inputs, dt, &mut reused)
        .unwrap();
    assert_eq!(reused, steps);
    let where_a: Vec<_> = reused.iter().map(|d| d.a.as_ptr()).collect();
    let z1 = RobotState::new(vec![-0.2, 0.4, 0.0], vec![0.5, 0.1, -0.2]);
    robot
        .rollout_derivatives_into(&z1, &inputs, dt, &mut reused)
        .unwrap();
    assert_eq!(reused, robot.rollout_derivatives(&z1, &inputs, dt).unwrap());
    let again: Vec<_> = reused.iter().map(|d| d.a.as_ptr()).collect();
    assert_eq!(again, where_a);
    // a shorter horizon drops the entries past it
    robot
        .rollout_derivatives_into(&z0, &inputs[..2], dt, &mut reused)
        .unwrap();
    assert_eq!(reused[..], steps[..2]);
    // one step at a time with a kept workspace: the rollout's entries, bit
    // for bit, in the same matrices on every call
    let mut ws = robot.workspace();
    let mut one = steps[0].clone();
    let kept_a = one.a.as_ptr();
    let mut z = z0.clone();
    for (u, want) in inputs.iter().zip(&steps) {
        robot
            .step_derivatives_in(&z, u, dt, &mut ws, &mut one)
            .unwrap();
        assert_eq!(&one, want);
        assert_eq!(one.a.as_ptr(), kept_a);
        z = one.state.clone();
    }
    // after a plain step the next one recomputes its start terms: the
    // single call's derivatives to the solver's tolerance
    let mut p = robot.momentum(&z).unwrap();
    robot
        .step_in(&mut z, &mut p, &inputs[0], dt, &mut ws)
        .unwrap();
    robot
        .step_derivatives_in(&z, &inputs[1], dt, &mut ws, &mut one)
        .unwrap();
    let single = robot.step_derivatives(&z, &inputs[1], dt).unwrap();
    let gap = (&one.a - &single.a).amax() + (&one.b - &single.b).amax();
    assert!(gap < 1e-8 * single.a.amax(), "{gap:e}");
}

#[test]
fn step_derivatives_refuse_bad_input_with_typed_errors() {
    let robot = driven("arm3.urdf", &["j3"]);
    let z = RobotState::new(vec![0.1, 0.2, 0.0], vec![0.0; 3]);
    let nan = RobotState::new(vec![0.1, f64::NAN, 0.0], vec![0.0; 3]);
    let short = RobotState::new(vec![0.1, 0.2], vec![0.0; 2]);
    assert!(matches!(
        robot.step_derivatives(&nan, &[0.0], 1e-3),
        Err(RobotError::Engine(EngineError::NonFiniteState))
    ));
    assert!(matches!(
        robot.step_derivatives(&short, &[0.0], 1e-3),
        Err(RobotError::WrongLength { what: "q", .. })
    ));
    assert!(matches!(
        robot.step_derivatives(&z, &[0.0, 1.0], 1e-3),
        Err(RobotError::WrongLength { what: "inputs", .. })
    ));
    assert!(matches!(
        robot.step_derivatives(&z, &[f64::INFINITY], 1e-3),
        Err(RobotError::Engine(EngineError::NonFiniteInput))
    ));
    for dt in [0.0, -1e-3, f64::NAN, f64::INFINITY] {
        assert!(
            matches!(
                robot.step_derivatives(&z, &[0.0], dt),
                Err(RobotError::Engine(EngineError::InvalidTimeStep { .. }))
            ),
            "dt {dt}"
        );
    }
    // a failing step inside a rollout names the step
    let inputs = vec![vec![0.0], vec![f64::NAN], vec![0.0]];
    match robot.rollout_derivatives(&z, &inputs, 1e-3) {
        Err(RobotError::Rollout { step: 1, .. }) => {}
        other => panic!("expected a failure at step 1, got {other:?}"),
    }
    // … and leaves the steps before it in a caller's vector
    let mut out = Vec::new();
    assert!(matches!(
        robot.rollout_derivatives_into(&z, &inputs, 1e-3, &mut out),
        Err(RobotError::Rollout { step: 1, .. })
    ));
    assert_eq!(out.len(), 1);
}

/// The regressor of a robot loaded at run time (`RobotRegressor`, the
/// tree engine's DEL residual with the parameters pulled out), on the
/// Panda with every joint driven: (1) its rows equal the residual at
/// parameters far from the declared ones (every body's block scaled, the
/// dampings changed), to 1e-9 of the cancelling terms (the columns are
/// differences of residuals, exact up to rounding);
/// (2) on a log that the truth's own rollouts wrote, every base parameter
/// is recovered to 1e-8 relative, as for the declared mechanisms, and the
/// dampings are identified.
#[test]
fn robot_regressor_recovers_its_own_log() {
    use vigp_runtime::identify::{Log, Options, Regressor, RobotRegressor, Status, identify};
    let dt = 0.002;
    let base = Robot::from_urdf(fixture("panda.urdf")).unwrap();
    let joints: Vec<String> = base.joint_names().to_vec();
    let names: Vec<&str> = joints.iter().map(String::as_str).collect();
    let declared = base.clone().with_actuated(&names).unwrap();
    let r = RobotRegressor::new(&declared, dt).unwrap();
    // the truth: each body's (m, m·c, I_O) scaled by its own factor (a
    // realisable body stays realisable), the dampings 0.2 + 0.05·i
    let mut truth_pi = r.standard();
    let offsets = r.structure().body_offsets();
    for (b, o) in offsets.iter().enumerate() {
        let f = 1.0 + 0.15 * ((b as f64) * 1.7).sin();
        for x in &mut truth_pi[*o..*o + 10] {
            *x *= f;
        }
    }
    let first_joint = offsets.last().unwrap() + 10;
    for (i, x) in truth_pi[first_joint..].iter_mut().enumerate() {
        *x = 0.2 + 0.05 * i as f64;
    }
    let truth = Robot::from_tree(
        "truth",
        r.tree_with(&truth_pi).unwrap(),
        joints.clone(),
        base.link_names().to_vec(),
    )
    .unwrap()
    .with_actuated(&names)
    .unwrap()
    // the log's own residual is the solver's: tighter than the default
    // 1e-12, for the weakest base parameters
    .with_options(EngineOptions {
        tolerance: 1e-15,
        max_iterations: 200,
        ..EngineOptions::default()
    })
    .unwrap();
    let n = truth.dof();
    let drive = |k: usize| -> Vec<f64> {
        let t = k as f64 * dt;
        (0..n)
            .map(|j| {
                3.0 * 0.6f64.powi(j as i32) * (1.1 * t * (1.0 + 0.3 * j as f64) + j as f64).sin()
            })
            .collect()
    };
    let z0 = RobotState::new(vec![0.1, -0.4, 0.3, -1.8, 0.2, 1.4, 0.6], vec![0.0; n]);
    let roll = truth.rollout_with(&z0, dt, 600, |k, _| drive(k)).unwrap();
    assert_eq!(roll.report.subdivided, 0, "the log is one DEL per step");
    let mut positions: Vec<Vec<f64>> = roll.states.iter().map(|z| z.q.clone()).collect();
    let last = roll.states.last().unwrap();
    positions.push((0..n).map(|i| last.q[i] + dt * last.v[i]).collect());
    let mut inputs = vec![vec![0.0; n]];
    inputs.extend((0..600).map(drive));
    inputs.push(vec![0.0; n]);
    let log = Log { positions, inputs };

    // (1) rows against the residual, and the truth's residual on its log
    let mut worst_affine = 0.0f64;
    let mut worst_truth = 0.0f64;
    for k in [1, 150, 300, 450, 599] {
        let t = common::transition_at(&log, k);
        let (y, b) = r.transition(&t).unwrap();
        for (pi, worst) in [(&truth_pi, &mut worst_truth), (&r.standard(), &mut 0.0)] {
            let res = r.residual(&t, pi).unwrap();
            for i in 0..n {
                let lin: f64 = (0..y.ncols()).map(|j| y[(i, j)] * pi[j]).sum::<f64>() - b[i];
                let size: f64 = (0..y.ncols())
                    .map(|j| (y[(i, j)] * pi[j]).abs())
                    .sum::<f64>()
                    + b[i].abs();
                worst_affine = worst_affine.max((res[i] - lin).abs() / size);
                *worst = worst.max(res[i].abs() / size);
            }
        }
    }
    // (2) identification
    let id = identify(&r, &[log], &Options::default()).unwrap();
    let k = &id.base.k;
    let worst_base = (0..k.nrows()).fold(0.0f64, |a, i| {
        let err: f64 = (0..k.ncols())
            .map(|j| k[(i, j)] * (id.estimate[j] - truth_pi[j]))
            .sum();
        let size: f64 = (0..k.ncols())
            .map(|j| (k[(i, j)] * truth_pi[j]).abs())
            .sum();
        a.max(err.abs() / size)
    });
    let report = id.report();
    let damped: Vec<_> = report
        .dsl
        .iter()
        .filter(|row| row.parameter.ends_with(".damping"))
        .collect();
    println!(
        "panda regressor: affine {worst_affine:.1e}, truth's residual {worst_truth:.1e}; \
         {} base parameters of {}, max relative error {worst_base:.1e}; projected links {:?}; dampings {:?}",
        id.base.rank(),
        id.structure.len(),
        id.projected,
        damped
            .iter()
            .map(|row| (row.identified, row.status))
            .collect::<Vec<_>>()
    );
    assert!(worst_affine < 1e-9, "{worst_affine:e}");
    assert!(worst_truth < 1e-9, "{worst_truth:e}");
    assert!(worst_base < 1e-8, "{worst_base:e}");
    assert_eq!(damped.len(), n);
    for (i, row) in damped.iter().enumerate() {
        assert_eq!(row.status, Status::Identified, "{}", row.parameter);
        let want = 0.2 + 0.05 * i as f64;
        assert!((row.identified - want).abs() < 1e-8 * want, "{row:?}");
    }
}

/// `Robot::step_in` in a loop is `Robot::rollout_with` bit for bit (both
/// start each step after the first from 2v_k − v_{k−1}); and a step that
/// reuses the poses its workspace kept from the previous step (the start
/// energy's) starts from the same energy as from a fresh workspace, bit
/// for bit, and not from another tree's poses.
#[test]
fn step_in_is_the_rollout_and_kept_poses_change_nothing() {
    use vigp_core::tree::{BodyScratch, Engine};
    let robot = driven("panda.urdf", &["panda_joint2", "panda_joint6"]);
    let z0 = RobotState::new(vec![0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8], vec![0.0; 7]);
    let (dt, steps) = (0.002, 400);
    let input = |k: usize| vec![3.0 * (0.01 * k as f64).sin(), -0.5];
    let run = robot.rollout_with(&z0, dt, steps, |k, _| input(k)).unwrap();
    let mut ws = robot.workspace();
    let mut z = z0.clone();
    let mut p = robot.momentum(&z).unwrap();
    for k in 0..steps {
        robot
            .step_in(&mut z, &mut p, &input(k), dt, &mut ws)
            .unwrap();
        assert_eq!(z, run.states[k + 1], "step {k}");
    }

    // The kept poses only enter the start energy, which is seen in the
    // jump of a step refused by an energy tolerance nothing meets (no
    // subdivision): from the state a default step committed, the same
    // step with the kept poses and with a fresh workspace must report the
    // same jump, also for a heavier copy of the arm (whose poses are not
    // the kept ones).
    let mut heavy = robot.tree().clone();
    heavy.bodies[3].mass *= 1.5;
    let strict = EngineOptions {
        max_depth: 0,
        energy_tolerance: f64::MIN_POSITIVE,
        ..EngineOptions::default()
    };
    let n = robot.dof();
    let tau = vec![0.0; n];
    let (mut q, mut v) = (z.q.clone(), z.v.clone());
    let mut p = vec![0.0; n];
    let mut warm = vec![BodyScratch::default(); n];
    let light = Engine::new(robot.tree()).unwrap();
    light.momentum_of(&q, &v, &mut p, &mut warm).unwrap();
    light
        .step(&mut q, &mut v, &mut p, &tau, dt, &mut warm)
        .unwrap();
    let mut jumps = Vec::new();
    for tree in [robot.tree(), &heavy] {
        let e = Engine::with_options(tree, strict).unwrap();
        let jump = |ws: &mut [BodyScratch]| {
            let (mut q, mut v, mut p) = (q.clone(), v.clone(), p.clone());
            match e.step(&mut q, &mut v, &mut p, &tau, dt, ws) {
                Err(EngineError::EnergyJump { jump, .. }) => jump,
                other => panic!("expected an energy jump, got {other:?}"),
            }
        };
        let kept = jump(&mut warm.clone());
        let fresh = jump(&mut vec![BodyScratch::default(); n]);
        assert_eq!(kept.to_bits(), fresh.to_bits(), "{kept:e} vs {fresh:e}");
        jumps.push(fresh);
    }
    // the heavier arm's start energy is another one
    assert_ne!(jumps[0], jumps[1]);
}
