//! `mechanism! { Name { urdf: "…" } }`: a URDF file read when the macro
//! runs. Checked against independent references:
//!
//! * tests/fixtures/robots/wrist.urdf (rpy on joint and inertial origins,
//!   full inertia tensors, damping, a fixed joint to merge, a prismatic
//!   joint) against the same arm declared by hand in the spatial DSL with
//!   the fixed joint kept as a `fixed` joint (values by
//!   scripts/wrist_by_hand.py, numpy, not vigp's reader): M, ∂M/∂q, ∇V, D
//!   and the forced step of the minimal views;
//! * overrides (gravity, a joint's damping) against the closed forms they
//!   change;
//! * the Panda (tests/fixtures/robots/panda.urdf) against the run-time
//!   `vigp::Robot` of the same file (the tree engine: another algorithm
//!   on the same conversion) and against Pinocchio's mass matrix
//!   (tests/fixtures/robots/pin.json, scripts/robot_pin_fixtures.py);
//! * the Panda on a floating base against closed forms of a free body
//!   (the base translation's mass block and gravity gradient are the
//!   total mass of the file's links) and against the fixed-base arm.

use crate::common::XorShift as Rng;
use crate::common::json_floats;
use vigp::SVector;
use vigp::robot::{Robot, RobotState};
use vigp::spatial::minimal;
use vigp::{Mechanism, Variational};

const FIXTURES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/robots");

vigp::mechanism! {
    /// wrist.urdf, read by the macro; the shoulder and the slide driven.
    WristUrdf {
        urdf: "tests/fixtures/robots/wrist.urdf",
        joints {
            shoulder: { actuated },
            slide: { actuated },
        }
    }
}

vigp::mechanism! {
    /// wrist.urdf on the Moon, with a stiffer elbow damper.
    WristMoon {
        urdf: "tests/fixtures/robots/wrist.urdf",
        gravity: [0.0, 0.0, -1.62],
        joints { elbow: { damping: 0.5 } }
    }
}

// The same arm by hand (printed by scripts/wrist_by_hand.py): each link in
// its own frame, the hand welded to the forearm by a `fixed` joint.
vigp::mechanism! {
    WristByHand {
        gravity: [0.0, 0.0, -9.81],
        links {
            upper: { mass: 1.5, com: [0.1, 0.02, 0.05],
                inertia: [[0.02628, 0.0029599999999999987, -0.0026], [0.002959999999999998, 0.028720000000000002, 0.0018000000000000002], [-0.0026, 0.0018000000000000002, 0.012]],
                frame: [[1.0, 0.0, 0.0], [0.0, 0.8, 0.6], [0.0, -0.6, 0.8]] },
            fore: { mass: 0.8, com: [0.15, 0.01, -0.02],
                inertia: [[0.0024614198675286417, -0.0012299241700866057, -0.0015873331932787411], [-0.0012299241700866061, 0.010738011845555034, -7.954424345121308e-06], [-0.0015873331932787416, -7.954424345121897e-06, 0.010300568286916324]],
                frame: [[0.6000000000000001, 0.4799999999999999, -0.64], [0.0, 0.8, 0.6], [0.7999999999999999, -0.36000000000000004, 0.4800000000000001]] },
            hand: { mass: 0.3, com: [0.02, 0.01, 0.0],
                inertia: [[0.0004, 5e-05, 0.0], [5e-05, 0.0003, 0.0], [0.0, 0.0, 0.0003]],
                frame: [[0.4800000000000001, 0.864, -0.15200000000000002], [-0.36000000000000004, 0.35200000000000015, 0.864], [0.7999999999999999, -0.36000000000000004, 0.4800000000000001]] },
            finger: { mass: 0.1, com: [0.01, 0.0, 0.005],
                inertia: [[2.3668534725962742e-05, 0.0, 5.6769005825391115e-06], [0.0, 4e-05, 0.0], [5.676900582539111e-06, 0.0, 2.633146527403726e-05]],
                frame: [[0.4800000000000001, 0.864, -0.15200000000000002], [-0.19388850338679808, 0.2734624763138952, 0.9421388020364622], [0.8555742213592152, -0.4227555724627086, 0.2987816555568632]] },
        }
        joints {
            shoulder: revolute(world @ [0.0, 0.0, 0.2], upper.start) { axis: [0.0, -0.6, 0.8], damping: 0.05, actuated },
            elbow: revolute(upper @ [0.3, 0.0, 0.0], fore.start) { axis: [0.0, 1.0, 0.0], damping: 0.02 },
            wrist_weld: fixed(fore @ [0.25, 0.0, 0.0], hand.start),
            slide: prismatic(hand @ [0.05, 0.0, 0.01], finger.start) { axis: [0.7071067811865475, 0.6930117232058353, 0.14048043101898117], actuated },
        }
    }
}

vigp::mechanism! {
    /// The Panda arm with its hand (example-robot-data, fingers fixed).
    Panda { urdf: "tests/fixtures/robots/panda.urdf" }
}

vigp::mechanism! {
    /// The Panda on a floating base: `panda_link0` on a free joint.
    PandaFloating { urdf: "tests/fixtures/robots/panda.urdf", base: floating }
}

fn largest<const R: usize, const C: usize>(m: &nalgebra::SMatrix<f64, R, C>) -> f64 {
    m.iter().fold(0.0f64, |a, x| a.max(x.abs()))
}

#[test]
fn urdf_wrist_equals_the_hand_written_wrist() {
    let (u, h) = (WristUrdf::default(), WristByHand::default());
    let mut rng = Rng(0x2545_f491_4f6c_dd1d);
    for _ in 0..8 {
        let q = SVector::<f64, 3>::from_fn(|i, _| rng.uniform(-1.5, 1.5) * [1.0, 1.0, 0.02][i]);
        let tu = minimal::terms::<WristUrdf, 3, 3, 3>(&u, &q);
        let th = minimal::terms::<WristByHand, 4, 4, 3>(&h, &q);
        // to rounding: the same kinematics reached through other frames
        // (the weld merged before, or kept through, the kinematics) and
        // literals rounded to 17 digits; 1e-12 of the largest entry leaves
        // room for a few hundred roundings of O(1) products
        let close = |a: f64, b: f64, scale: f64, what: &str| {
            assert!((a - b).abs() <= 1e-12 * scale, "{what}: {a} vs {b}");
        };
        let sm = largest(&th.mass);
        for i in 0..3 {
            for j in 0..3 {
                close(tu.mass[(i, j)], th.mass[(i, j)], sm, "M");
                close(tu.damping[(i, j)], th.damping[(i, j)], 1.0, "D");
                for l in 0..3 {
                    let s = largest(&th.dmass[l]).max(sm);
                    close(tu.dmass[l][(i, j)], th.dmass[l][(i, j)], s, "dM/dq");
                }
            }
            close(
                tu.dpotential[i],
                th.dpotential[i],
                th.dpotential.amax(),
                "dV/dq",
            );
        }
    }
    // the forced steps of the minimal views from the same state
    let dt = 0.005;
    let (vu, vh) = (
        Variational::new(u.minimal(), dt).unwrap(),
        Variational::new(h.minimal(), dt).unwrap(),
    );
    let mut zu = u.minimal().state([0.4, -0.7, 0.01], [1.0, -0.5, 0.05]);
    let mut zh = h.minimal().state([0.4, -0.7, 0.01], [1.0, -0.5, 0.05]);
    let mut worst = 0.0f64;
    for k in 0..50 {
        let input = SVector::<f64, 2>::new(0.3 * (0.1 * k as f64).sin(), -0.2);
        zu = vu.step_forced(&zu, &input).unwrap();
        zh = vh.step_forced(&zh, &input).unwrap();
        worst = worst.max((zu.q - zh.q).amax()).max((zu.v - zh.v).amax());
    }
    println!("wrist: urdf vs by hand, 50 forced steps: largest |Δq|, |Δv| = {worst:.2e}");
    // both iterations solve the same DEL equations to the solver's
    // tolerance (a 1e-12 scaled residual, states of size O(1)); measured
    // 1.7e-14 over the 50 steps
    assert!(worst < 1e-12, "{worst}");
}

#[test]
fn overrides_change_gravity_and_damping_as_declared() {
    let (earth, moon) = (WristUrdf::default(), WristMoon::default());
    let q = SVector::<f64, 3>::new(0.3, -0.8, 0.02);
    let te = minimal::terms::<WristUrdf, 3, 3, 3>(&earth, &q);
    let tm = minimal::terms::<WristMoon, 3, 3, 3>(&moon, &q);
    // V is linear in g: ∇V scales by 1.62 / 9.81; M does not change
    for i in 0..3 {
        let want = te.dpotential[i] * 1.62 / 9.81;
        assert!((tm.dpotential[i] - want).abs() <= 1e-14 * te.dpotential.amax());
        for j in 0..3 {
            assert_eq!(tm.mass[(i, j)], te.mass[(i, j)]);
        }
    }
    // joint damping acts on each coordinate's rate: D = diag(c); the
    // override replaces the file's 0.02 of the elbow, the shoulder keeps 0.05
    // and the undamped slide 0
    for (i, c) in [0.05, 0.5, 0.0].into_iter().enumerate() {
        for j in 0..3 {
            let want = if i == j { c } else { 0.0 };
            assert!((tm.damping[(i, j)] - want).abs() < 1e-15, "D[{i},{j}]");
        }
    }
}

#[test]
fn urdf_panda_equals_the_run_time_robot_and_pinocchio() {
    let robot = Robot::from_urdf(format!("{FIXTURES}/panda.urdf")).unwrap();
    let sys = Panda::default();
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let mut worst_m = 0.0f64;
    for _ in 0..5 {
        let q: [f64; 7] = std::array::from_fn(|_| rng.uniform(-1.5, 1.5));
        let v: [f64; 7] = std::array::from_fn(|_| rng.uniform(-1.0, 1.0));
        let t = minimal::terms::<Panda, 7, 7, 7>(&sys, &SVector::from(q));
        let m = robot.mass_matrix(&q).unwrap();
        let (p, dtdq, dvdq) = robot.terms(&q, &v).unwrap();
        let vv = SVector::from(v);
        let p_ref = t.mass * vv;
        // two algorithms (jets through the generic kinematics, the O(N)
        // recursions) in double precision: 1e-10 of the largest entry
        let sm = largest(&t.mass);
        let sg = t.dpotential.amax();
        for i in 0..7 {
            let dt_ref = 0.5 * vv.dot(&(t.dmass[i] * vv));
            let mut errors = vec![
                (p[i] - p_ref[i]).abs() / sm,
                (dtdq[i] - dt_ref).abs() / sm,
                (dvdq[i] - t.dpotential[i]).abs() / sg,
            ];
            errors.extend((0..7).map(|j| (m[i * 7 + j] - t.mass[(i, j)]).abs() / sm));
            for e in errors {
                worst_m = worst_m.max(e);
                assert!(e < 1e-10, "row {i}: {e:e}");
            }
        }
    }
    // one step from the same state
    let dt = 0.002;
    let vi = Variational::new(sys.minimal(), dt).unwrap();
    let (q0, v0) = (
        [0.1, -0.4, 0.3, -1.8, 0.2, 1.4, 0.6],
        [0.5, -0.3, 0.2, 0.4, -0.6, 0.1, 0.3],
    );
    let z = vi.step(&sys.minimal().state(q0, v0)).unwrap();
    let (zr, _) = robot
        .step(&RobotState::new(q0.to_vec(), v0.to_vec()), &[], dt)
        .unwrap();
    let worst_step = (0..7).fold(0.0f64, |a, i| {
        a.max((z.q[i] - zr.q[i]).abs())
            .max((z.v[i] - zr.v[i]).abs())
    });
    // both converge to a 1e-12 scaled residual of the same equations
    assert!(worst_step < 1e-10, "{worst_step}");
    let mut worst_pin = 0.0f64;
    // Pinocchio's mass matrix at its configurations (its coordinate order
    // is the file's depth-first order, as ours)
    let pin: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(format!("{FIXTURES}/pin.json")).unwrap())
            .unwrap();
    let joints: Vec<&str> = pin["panda"]["joints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_str().unwrap())
        .collect();
    assert_eq!(joints, robot.joint_names());
    for case in pin["panda"]["cases"].as_array().unwrap() {
        let q: [f64; 7] = json_floats(&case["q"]).try_into().unwrap();
        let t = minimal::terms::<Panda, 7, 7, 7>(&sys, &SVector::from(q));
        let m_pin: Vec<Vec<f64>> = case["mass"]
            .as_array()
            .unwrap()
            .iter()
            .map(json_floats)
            .collect();
        let scale = largest(&t.mass);
        // Pinocchio's CRBA against our jets: two algorithms, 1e-10 relative
        // to the largest entry (as vigp-runtime/tests/robot.rs)
        for (i, row) in m_pin.iter().enumerate() {
            for (j, x) in row.iter().enumerate() {
                let e = (t.mass[(i, j)] - x).abs();
                worst_pin = worst_pin.max(e / scale);
                assert!(e < 1e-10 * scale, "M[{i},{j}] {e:e}");
            }
        }
    }
    println!(
        "panda: urdf: vs Robot, M, p, dT/dq, dV/dq {worst_m:.1e} (relative), one step {worst_step:.1e}; \
         vs Pinocchio, M {worst_pin:.1e} (relative)"
    );
}

#[test]
fn floating_base_carries_the_whole_robot() {
    // the total mass, summed from the file's `<mass value="…">` elements
    // (not through vigp's reader)
    let text = std::fs::read_to_string(format!("{FIXTURES}/panda.urdf")).unwrap();
    let total: f64 = text
        .split("<mass value=\"")
        .skip(1)
        .map(|s| s[..s.find('"').unwrap()].parse::<f64>().unwrap())
        .sum();
    let (free, fixed) = (PandaFloating::default(), Panda::default());
    let mut rng = Rng(0x1234_5678_9abc_def1);
    for _ in 0..3 {
        let joints: [f64; 7] = std::array::from_fn(|_| rng.uniform(-1.5, 1.5));
        let quat = nalgebra::UnitQuaternion::from_euler_angles(
            rng.uniform(-1.0, 1.0),
            rng.uniform(-1.0, 1.0),
            rng.uniform(-1.0, 1.0),
        );
        // position, unit quaternion (w, x, y, z), then the arm's joints
        let mut q = SVector::<f64, 14>::zeros();
        q.fixed_rows_mut::<3>(0).copy_from_slice(&[0.3, -0.2, 0.5]);
        q.fixed_rows_mut::<4>(3)
            .copy_from_slice(&[quat.w, quat.i, quat.j, quat.k]);
        q.fixed_rows_mut::<7>(7).copy_from_slice(&joints);
        let t = minimal::terms::<PandaFloating, 8, 8, 14>(&free, &q);
        // T = ½ m |ṗ|² + ṗ·(…): the translation block is m·I whatever the
        // pose, and V = m g z_com gives ∂V/∂p = (0, 0, 9.81 m); rounding of
        // sums of 10 link masses
        let scale = total * 9.81;
        for i in 0..3 {
            for j in 0..3 {
                let want = if i == j { total } else { 0.0 };
                assert!((t.mass[(i, j)] - want).abs() < 1e-13 * total, "M[{i},{j}]");
            }
            let want = if i == 2 { scale } else { 0.0 };
            assert!((t.dpotential[i] - want).abs() < 1e-12 * scale, "dV/dp[{i}]");
        }
        // with the base at the identity pose, the joints' block is the
        // fixed-base arm's mass matrix
        q.fixed_rows_mut::<4>(3)
            .copy_from_slice(&[1.0, 0.0, 0.0, 0.0]);
        let t = minimal::terms::<PandaFloating, 8, 8, 14>(&free, &q);
        let tf = minimal::terms::<Panda, 7, 7, 7>(&fixed, &SVector::from(joints));
        let sm = largest(&tf.mass);
        for i in 0..7 {
            for j in 0..7 {
                let e = (t.mass[(7 + i, 7 + j)] - tf.mass[(i, j)]).abs();
                assert!(e < 1e-12 * sm, "M[{i},{j}] {e:e}");
            }
        }
    }
}

/// max |A_robot − A_generated| over the four N × N blocks of the generated
/// `StateJacobian`, relative to the largest entry of the robot's A.
fn a_gap<const N: usize>(
    robot: &vigp::nalgebra::DMatrix<f64>,
    a: &vigp::embedded::StateJacobian<N>,
) -> f64 {
    let blocks = [(0, 0, a.q_q), (0, N, a.q_v), (N, 0, a.v_q), (N, N, a.v_v)];
    let scale = robot.amax();
    let mut worst = 0.0f64;
    for (r0, c0, block) in blocks {
        for i in 0..N {
            for j in 0..N {
                worst = worst.max((robot[(r0 + i, c0 + j)] - block[(i, j)]).abs() / scale);
            }
        }
    }
    worst
}

/// The exact A = ∂z₁/∂z₀ and B = ∂z₁/∂u of the generated code (jets
/// through the closed-form terms, `Variational::step_derivatives`) against
/// the run-time robot's (jets through the O(N) recursions,
/// `Robot::step_derivatives`): two implementations of the implicit
/// function theorem on the same DEL equations. Both steps converge to a
/// 1e-12 scaled residual, so the derivatives, taken at slightly different
/// roots, agree to about that: 1e-9 of the largest entry.
#[test]
fn urdf_step_derivatives_equal_the_run_time_robots() {
    let dt = 0.002;
    // the wrist, shoulder and slide driven
    let wrist = WristUrdf::default().minimal();
    let robot = Robot::from_urdf(format!("{FIXTURES}/wrist.urdf"))
        .unwrap()
        .with_actuated(&["shoulder", "slide"])
        .unwrap();
    let n = robot.dof();
    assert_eq!(n, 3);
    let (q0, v0, u) = ([0.3, -0.5, 0.02], [0.7, -0.4, 0.05], [1.5, -0.8]);
    let (z, d) = Variational::new(wrist, dt)
        .unwrap()
        .step_derivatives(&wrist.state(q0, v0), &SVector::from(u))
        .unwrap();
    let r = robot
        .step_derivatives(&RobotState::new(q0.to_vec(), v0.to_vec()), &u, dt)
        .unwrap();
    let worst_a = a_gap(&r.a, &d.a);
    let mut worst_b = 0.0f64;
    for i in 0..3 {
        for k in 0..2 {
            worst_b = worst_b
                .max((r.b[(i, k)] - d.b.q_u[(i, k)]).abs() / r.b.amax())
                .max((r.b[(3 + i, k)] - d.b.v_u[(i, k)]).abs() / r.b.amax());
        }
    }
    let worst_z = (0..3).fold(0.0f64, |a, i| {
        a.max((z.q[i] - r.state.q[i]).abs())
            .max((z.v[i] - r.state.v[i]).abs())
    });
    // the Panda, undriven, A only
    let panda = Panda::default().minimal();
    let arm = Robot::from_urdf(format!("{FIXTURES}/panda.urdf")).unwrap();
    let (q0, v0) = (
        [0.1, -0.4, 0.3, -1.8, 0.2, 1.4, 0.6],
        [0.5, -0.3, 0.2, 0.4, -0.6, 0.1, 0.3],
    );
    let (_, dp) = Variational::new(panda, dt)
        .unwrap()
        .step_derivatives(&panda.state(q0, v0), &SVector::<f64, 0>::zeros())
        .unwrap();
    let rp = arm
        .step_derivatives(&RobotState::new(q0.to_vec(), v0.to_vec()), &[], dt)
        .unwrap();
    let worst_panda = a_gap(&rp.a, &dp.a);
    println!(
        "step derivatives, generated vs Robot: wrist A {worst_a:.1e}, B {worst_b:.1e} (state {worst_z:.1e}); \
         Panda A {worst_panda:.1e} (of the largest entry)"
    );
    assert!(worst_z < 1e-10, "{worst_z:e}");
    assert!(
        worst_a < 1e-9 && worst_b < 1e-9,
        "A {worst_a:e} B {worst_b:e}"
    );
    assert!(worst_panda < 1e-9, "{worst_panda:e}");
}

/// The tree engine's constants of a `urdf:` mechanism (`Name::TREE_BODIES`,
/// `NameTree`) against the run-time `vigp::Robot` of the same file: the
/// same bodies, exactly (the file's numbers emitted as literals that
/// round-trip), with the block's overrides (the Moon's gravity, the
/// elbow's damping, the inputs in file order); and the engine stepping the
/// compile-time constants as it steps the robot's run-time tree, bit for
/// bit, over 300 falling Panda steps and 300 driven wrist steps (one
/// algorithm on the same numbers).
#[test]
fn urdf_tree_constants_equal_the_run_time_robot() {
    use vigp::embedded::tree::{Body, BodyScratch, Engine, Tree};
    let wrist = Robot::from_urdf(format!("{FIXTURES}/wrist.urdf"))
        .unwrap()
        .with_actuated(&["shoulder", "slide"])
        .unwrap();
    assert_eq!(
        WristUrdf::TREE_BODIES.as_slice(),
        wrist.tree().bodies.as_slice()
    );
    assert_eq!(WristUrdf::TREE_GRAVITY, wrist.tree().gravity);
    assert_eq!(WristUrdf::TREE_INPUTS, [0, 2]);
    assert_eq!(wrist.input_names(), ["shoulder", "slide"]);
    // the Moon's block: gravity and the elbow's damping replaced
    assert_eq!(WristMoon::TREE_GRAVITY, [0.0, 0.0, -1.62]);
    assert_eq!(WristMoon::TREE_INPUTS.len(), 0);
    for (k, (a, b)) in WristMoon::TREE_BODIES
        .iter()
        .zip(&wrist.tree().bodies)
        .enumerate()
    {
        let damping = if k == 1 { 0.5 } else { b.damping };
        assert_eq!(*a, Body { damping, ..*b }, "body {k}");
    }
    assert_eq!(WristUrdfTree.len(), 3);
    // the Panda: the same bodies; steps bit for bit
    let panda = Robot::from_urdf(format!("{FIXTURES}/panda.urdf")).unwrap();
    assert_eq!(
        Panda::TREE_BODIES.as_slice(),
        panda.tree().bodies.as_slice()
    );
    let folded = Engine::new(PandaTree).unwrap();
    let data = panda.engine();
    let mut ws = [BodyScratch::default(); 7];
    let mut ws2 = [BodyScratch::default(); 7];
    let (mut q, mut v, mut p) = ([0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8], [0.0; 7], [0.0; 7]);
    let (mut q2, mut v2, mut p2) = (q, v, p);
    folded.momentum_of(&q, &v, &mut p, &mut ws).unwrap();
    data.momentum_of(&q2, &v2, &mut p2, &mut ws2).unwrap();
    for _ in 0..300 {
        folded
            .step(&mut q, &mut v, &mut p, &[0.0; 7], 0.002, &mut ws)
            .unwrap();
        data.step(&mut q2, &mut v2, &mut p2, &[0.0; 7], 0.002, &mut ws2)
            .unwrap();
        assert_eq!((q, v, p), (q2, v2, p2));
    }
    assert!(v.iter().any(|x| x.abs() > 0.5), "the arm falls: {v:?}");
    // the wrist, driven through its inputs
    let folded = Engine::new(WristUrdfTree).unwrap();
    let data = wrist.engine();
    let mut ws = [BodyScratch::default(); 3];
    let mut ws2 = [BodyScratch::default(); 3];
    let (mut q, mut v, mut p) = ([0.3, -0.8, 0.02], [0.1, 0.2, -0.05], [0.0; 3]);
    let (mut q2, mut v2, mut p2) = (q, v, p);
    folded.momentum_of(&q, &v, &mut p, &mut ws).unwrap();
    data.momentum_of(&q2, &v2, &mut p2, &mut ws2).unwrap();
    for k in 0..300 {
        let mut tau = [0.0; 3];
        for (c, &i) in WristUrdf::TREE_INPUTS.iter().enumerate() {
            tau[i] = (0.01 * k as f64 + c as f64).sin();
        }
        folded
            .step(&mut q, &mut v, &mut p, &tau, 0.002, &mut ws)
            .unwrap();
        data.step(&mut q2, &mut v2, &mut p2, &tau, 0.002, &mut ws2)
            .unwrap();
        assert_eq!((q, v, p), (q2, v2, p2));
    }
}

/// `Name::tree()` and `Name::robot()` of a `urdf:` mechanism: the bodies
/// built from the run-time parameters (as for any declared 3-D tree)
/// against the file's constants (`TREE_BODIES`, the same conversion as
/// `Robot::from_urdf`). The two are built by different routes (the
/// lowered description through `links3`, the file's bodies directly), so
/// they are held to rounding: the mass matrices to 1e-12 of their largest
/// entry, 300 steps of 2 ms to 1e-10 (both engines converge to 1e-12; the
/// rollouts stay well conditioned over 0.6 s). A parameter changed at run
/// time reaches `tree()` and not the constants.
#[test]
fn urdf_tree_from_parameters_steps_as_the_constants() {
    use vigp::embedded::tree::{BodyScratch, Engine};
    assert_eq!(Panda::TREE_COORDINATES, [0, 1, 2, 3, 4, 5, 6]);
    assert_eq!(WristUrdf::TREE_COORDINATES, [0, 1, 2]);
    assert_eq!(WristUrdf::TREE_INPUTS, [0, 2]);
    assert_eq!(WristMoon::TREE_INPUTS.len(), 0);

    let (data, folded) = (
        Engine::new(Panda::default().tree()).unwrap(),
        Engine::new(PandaTree).unwrap(),
    );
    let mut ws = [BodyScratch::default(); 7];
    let (mut m1, mut m2) = ([0.0; 49], [0.0; 49]);
    let mut worst_m = 0.0f64;
    for q in [
        [0.0; 7],
        [0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8],
        [0.7, 0.4, -1.1, -1.5, 0.9, 1.2, -0.4],
    ] {
        data.mass_matrix(&q, &mut m1, &mut ws).unwrap();
        folded.mass_matrix(&q, &mut m2, &mut ws).unwrap();
        let scale = m2.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        let gap = m1
            .iter()
            .zip(&m2)
            .fold(0.0f64, |a, (x, y)| a.max((x - y).abs()));
        worst_m = worst_m.max(gap / scale);
    }
    assert!(
        worst_m < 1e-12,
        "Panda M: tree() vs TREE_BODIES {worst_m:.1e}"
    );

    let mut ws2 = [BodyScratch::default(); 7];
    let (mut q, mut v, mut p) = ([0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8], [0.0; 7], [0.0; 7]);
    let (mut q2, mut v2, mut p2) = (q, v, p);
    data.momentum_of(&q, &v, &mut p, &mut ws).unwrap();
    folded.momentum_of(&q2, &v2, &mut p2, &mut ws2).unwrap();
    let mut worst_step = 0.0f64;
    for _ in 0..300 {
        data.step(&mut q, &mut v, &mut p, &[0.0; 7], 0.002, &mut ws)
            .unwrap();
        folded
            .step(&mut q2, &mut v2, &mut p2, &[0.0; 7], 0.002, &mut ws2)
            .unwrap();
        for (a, b) in q.iter().chain(&v).zip(q2.iter().chain(&v2)) {
            worst_step = worst_step.max((a - b).abs());
        }
    }
    assert!(worst_step < 1e-10, "Panda 300 steps: {worst_step:.1e}");
    assert!(v.iter().any(|x| x.abs() > 0.5), "the arm falls: {v:?}");

    // the std robot of the block: names and inputs as declared, the same
    // driven steps as the file read at run time
    let robot = WristUrdf::default().robot().unwrap();
    let file = Robot::from_urdf(format!("{FIXTURES}/wrist.urdf"))
        .unwrap()
        .with_actuated(&["shoulder", "slide"])
        .unwrap();
    assert_eq!(robot.input_names(), file.input_names());
    assert_eq!(robot.dof(), 3);
    let (mut a, mut b) = (
        RobotState::new(vec![0.3, -0.8, 0.02], vec![0.1, 0.2, -0.05]),
        RobotState::new(vec![0.3, -0.8, 0.02], vec![0.1, 0.2, -0.05]),
    );
    let (mut pa, mut pb) = (robot.momentum(&a).unwrap(), file.momentum(&b).unwrap());
    let (mut wa, mut wb) = (robot.workspace(), file.workspace());
    let mut worst_driven = 0.0f64;
    for k in 0..300 {
        let u = [(0.01 * k as f64).sin(), (0.01 * k as f64 + 1.0).sin()];
        robot.step_in(&mut a, &mut pa, &u, 0.002, &mut wa).unwrap();
        file.step_in(&mut b, &mut pb, &u, 0.002, &mut wb).unwrap();
        for (x, y) in a.q.iter().chain(&a.v).zip(b.q.iter().chain(&b.v)) {
            worst_driven = worst_driven.max((x - y).abs());
        }
    }
    assert!(worst_driven < 1e-10, "wrist, driven: {worst_driven:.1e}");

    // a heavier forearm at run time: tree() changes, the constants do not
    let mut heavy = WristUrdf::default();
    heavy.links.fore.mass *= 2.0;
    let (light, heavy) = (
        Engine::new(WristUrdf::default().tree()).unwrap(),
        Engine::new(heavy.tree()).unwrap(),
    );
    let mut ws = [BodyScratch::default(); 3];
    let (mut ml, mut mh, mut mc) = ([0.0; 9], [0.0; 9], [0.0; 9]);
    let q = [0.3, -0.8, 0.02];
    light.mass_matrix(&q, &mut ml, &mut ws).unwrap();
    heavy.mass_matrix(&q, &mut mh, &mut ws).unwrap();
    Engine::new(WristUrdfTree)
        .unwrap()
        .mass_matrix(&q, &mut mc, &mut ws)
        .unwrap();
    assert!(mh[0] > ml[0] * 1.05, "M₀₀ {} against {}", mh[0], ml[0]);
    assert!((ml[0] - mc[0]).abs() < 1e-12 * mc[0]);
    println!(
        "urdf: tree() vs TREE_BODIES: Panda M {worst_m:.1e} (relative), 300 steps {worst_step:.1e}; \
         wrist robot() vs Robot::from_urdf, 300 driven steps {worst_driven:.1e}"
    );
}
