//! Tree descriptions, planar and 3-D, on the linear-time tree engine
//! (`Name::tree()`, `Name::robot()`): their mass matrices, energies and
//! steps against the minimal views' terms and `Variational` steps of the
//! same descriptions (other derivations of the same equations: symbolic
//! closed forms in the plane, jets through the link kinematics in 3-D,
//! against recursive spatial-vector algorithms).

use vigp::embedded::tree::{BodyScratch, Engine, EngineOptions, Tree};
use vigp::prelude::*;
use vigp::systems::spatial::{DoublePendulum3d, Furuta};
use vigp::systems::{Cartpole, DoublePendulum, Pendulum};

vigp::mechanism! {
    /// A branched tree declared out of placement order: offset anchors,
    /// a slider on an oblique axis of a link, a centre of mass off the
    /// axis, damping, springs and two inputs.
    Branched {
        gravity: [0.3, -9.81],
        links {
            tip: { mass: 0.4, length: 0.3, com: [0.1, 0.02] },
            arm: { mass: 1.2, length: 0.8, inertia: 0.09 },
            slider: { mass: 0.5, length: 0.2 },
            side: { mass: 0.7, length: 0.5 },
        }
        joints {
            elbow: revolute(arm.end, tip @ [0.05, 0.01]) { damping: 0.2, actuated },
            shoulder: revolute(world @ [0.1, 0.2], arm.start) { stiffness: 3.0, rest: 0.4, actuated },
            rail: prismatic(arm.center, slider.center) { axis: [0.6, 0.8], damping: 0.1, stiffness: 5.0 },
            hip: revolute(arm @ [0.3, -0.1], side.start),
        }
    }
}

vigp::mechanism! {
    /// A cart on a tilted rail under the world, carrying a pendulum.
    TiltedCart {
        gravity: [0.0, -9.81],
        links {
            cart: { mass: 2.0, length: 0.4 },
            pole: { mass: 0.3, length: 0.6 },
        }
        joints {
            rail: prismatic(world @ [0.2, -0.1], cart.center) { axis: [0.8, -0.6], actuated },
            hinge: revolute(cart.center, pole.start),
        }
    }
}

vigp::mechanism! {
    /// A 3-D tree declared out of placement order: rotated link frames, a
    /// full inertia tensor, a slider on an oblique axis of a turned link,
    /// offset anchors, damping, springs and two inputs.
    Branched3 {
        gravity: [0.2, -0.1, -9.81],
        links {
            hand: { mass: 0.4, length: 0.3, inertia: [0.002, 0.004, 0.005], com: [0.1, 0.02, -0.01] },
            arm: {
                mass: 1.2,
                length: 0.8,
                inertia: [[0.01, 0.001, 0.0], [0.001, 0.06, 0.002], [0.0, 0.002, 0.065]],
                frame: [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]],
            },
            slider: { mass: 0.5, length: 0.2, inertia: [0.001, 0.002, 0.002] },
            side: { mass: 0.7, length: 0.5, inertia: [0.003, 0.015, 0.015], frame: [[0.6, 0.8, 0.0], [-0.8, 0.6, 0.0], [0.0, 0.0, 1.0]] },
        }
        joints {
            wrist: revolute(arm.end, hand @ [0.05, 0.01, 0.0]) { axis: [0.0, 0.6, 0.8], damping: 0.2, actuated },
            shoulder: revolute(world @ [0.1, 0.2, 0.3], arm.start) { axis: [0.0, 1.0, 0.0], stiffness: 3.0, rest: 0.4, actuated },
            rail: prismatic(arm.center, slider.center) { axis: [0.6, 0.0, 0.8], damping: 0.1, stiffness: 5.0 },
            hip: revolute(arm @ [0.3, -0.1, 0.05], side.start) { axis: [1.0, 0.0, 0.0] },
        }
    }
}

/// The engine's coordinates of a minimal state (body k is coordinate
/// `order[k]`).
fn to_bodies<const N: usize>(x: &SVector<f64, N>, order: &[usize; N]) -> [f64; N] {
    core::array::from_fn(|k| x[order[k]])
}

/// Largest |closed form − engine| over M(q) and E(q, v) at 20 states, and
/// over 100 forced steps of Δt = 5 ms from the first, relative to the
/// largest entry compared.
fn compare<M, const N: usize, const U: usize>(
    model: M,
    order: &[usize; N],
    inputs: &[usize; U],
    tree: vigp::embedded::tree::TreeArray<N>,
) -> (f64, f64, f64)
where
    M: Mechanism<N, 0> + vigp::embedded::Inputs<U> + Copy,
{
    // both solvers to 1e-14 of the momentum scale
    let options = EngineOptions {
        tolerance: 1e-14,
        ..EngineOptions::default()
    };
    let engine = Engine::with_options(tree, options).expect("a valid tree");
    assert_eq!(engine.tree().len(), N);
    let mut ws = [BodyScratch::zeroed(); N];
    let k = model.constants().expect("valid parameters");
    let (mut mass_err, mut energy_err) = (0.0f64, 0.0f64);
    let mut mm = vec![0.0; N * N];
    for s in 0..20 {
        let q = SVector::<f64, N>::from_fn(|i, _| (1.3 * (s * N + i) as f64).sin());
        let v = SVector::<f64, N>::from_fn(|i, _| 0.7 * (0.9 * (s * N + i) as f64).cos());
        let closed = model.mass(&k, &q);
        engine
            .mass_matrix(&to_bodies(&q, order), &mut mm, &mut ws)
            .unwrap();
        let scale = closed.amax();
        for a in 0..N {
            for b in 0..N {
                let e = (closed[(order[a], order[b])] - mm[a * N + b]).abs() / scale;
                mass_err = mass_err.max(e);
            }
        }
        let z = State { q, v };
        let e_closed = model.energy(&z);
        let e_engine = engine
            .energy(&to_bodies(&q, order), &to_bodies(&v, order), &mut ws)
            .unwrap();
        energy_err = energy_err.max((e_closed - e_engine).abs() / (1.0 + e_closed.abs()));
    }
    // steps under inputs that change every step
    let dt = 0.005;
    let vi = Variational::new(model, dt)
        .unwrap()
        .tolerance(1e-14)
        .unwrap();
    let mut z = State {
        q: SVector::from_fn(|i, _| 0.4 * (i as f64 + 1.0).sin()),
        v: SVector::from_fn(|i, _| 0.3 * (i as f64 + 0.5).cos()),
    };
    let (mut q, mut v) = (to_bodies(&z.q, order), to_bodies(&z.v, order));
    let mut p = [0.0; N];
    engine.momentum_of(&q, &v, &mut p, &mut ws).unwrap();
    let mut step_err = 0.0f64;
    for step in 0..100 {
        let u = SVector::<f64, U>::from_fn(|i, _| (0.1 * step as f64 + i as f64).sin());
        let mut tau = [0.0; N];
        for (i, &b) in inputs.iter().enumerate() {
            tau[b] += u[i];
        }
        z = vi.step_forced(&z, &u).unwrap();
        engine
            .step(&mut q, &mut v, &mut p, &tau, dt, &mut ws)
            .unwrap();
        for (a, b) in to_bodies(&z.q, order).iter().zip(&q) {
            step_err = step_err.max((a - b).abs());
        }
        for (a, b) in to_bodies(&z.v, order).iter().zip(&v) {
            step_err = step_err.max((a - b).abs() / (1.0 + a.abs()));
        }
    }
    (mass_err, energy_err, step_err)
}

/// Prints the largest differences of [`compare`] and checks them: M and E
/// to 1e-12, the steps to 1e-10 (the reasons at each test).
fn report(name: &str, (m, e, s): (f64, f64, f64)) {
    println!("{name}: M(q) {m:.1e}, E(q, v) {e:.1e}, 100 steps {s:.1e}");
    assert!(m < 1e-12 && e < 1e-12, "{name}: M {m:e}, E {e:e}");
    assert!(s < 1e-10, "{name}: steps {s:e}");
}

/// Mass matrices and energies agree to rounding (1e-12: a few hundred
/// operations of either derivation on numbers of order 1; measured
/// ≤ 5.1e-16); 100 steps to 1e-10 (both solvers stop at 1e-14 of the
/// momentum scale, and 100 steps carry those differences along; measured
/// ≤ 8.4e-12).
#[test]
fn planar_trees_on_the_engine_equal_their_closed_forms() {
    let sys = Branched::default();
    // placed parents first: shoulder, rail, hip, then elbow
    assert_eq!(Branched::TREE_COORDINATES, [1, 2, 3, 0]);
    assert_eq!(Branched::TREE_INPUTS, [3, 0]);
    report(
        "branched",
        compare::<_, 4, 2>(
            sys.minimal(),
            &Branched::TREE_COORDINATES,
            &Branched::TREE_INPUTS,
            sys.tree(),
        ),
    );
    let sys = TiltedCart::default();
    report(
        "tilted cart",
        compare::<_, 2, 1>(
            sys.minimal(),
            &TiltedCart::TREE_COORDINATES,
            &TiltedCart::TREE_INPUTS,
            sys.tree(),
        ),
    );
    let mut sys = DoublePendulum::default();
    sys.joints.elbow.damping = 0.3;
    report(
        "double pendulum",
        compare::<_, 2, 0>(
            sys.minimal(),
            &DoublePendulum::TREE_COORDINATES,
            &[],
            sys.tree(),
        ),
    );
    let sys = Cartpole::default();
    report(
        "cart-pole",
        compare::<_, 2, 0>(sys.minimal(), &Cartpole::TREE_COORDINATES, &[], sys.tree()),
    );
    let sys = Pendulum::default();
    report(
        "pendulum",
        compare::<_, 1, 0>(sys.minimal(), &Pendulum::TREE_COORDINATES, &[], sys.tree()),
    );
}

/// The same checks on 3-D trees (the minimal view's terms are jets
/// through the link kinematics: M to rounding, 1e-12; the steps to 1e-10
/// as above).
#[test]
fn spatial_trees_on_the_engine_equal_their_minimal_views() {
    let sys = Branched3::default();
    assert_eq!(Branched3::TREE_COORDINATES, [1, 2, 3, 0]);
    assert_eq!(Branched3::TREE_INPUTS, [3, 0]);
    report(
        "3-D branched",
        compare::<_, 4, 2>(
            sys.minimal(),
            &Branched3::TREE_COORDINATES,
            &Branched3::TREE_INPUTS,
            sys.tree(),
        ),
    );
    let sys = Furuta::default();
    report(
        "Furuta",
        compare::<_, 2, 0>(sys.minimal(), &Furuta::TREE_COORDINATES, &[], sys.tree()),
    );
    let sys = DoublePendulum3d::default();
    report(
        "3-D double pendulum",
        compare::<_, 2, 0>(
            sys.minimal(),
            &DoublePendulum3d::TREE_COORDINATES,
            &[],
            sys.tree(),
        ),
    );
    assert_eq!(
        Branched3::default().robot().unwrap().joint_names(),
        ["shoulder", "rail", "hip", "wrist"]
    );
}

/// `robot()` is the same tree with names, inputs on the actuated joints,
/// and a parameter out of its domain a typed error.
#[test]
fn planar_robots_take_names_inputs_and_refuse_bad_parameters() {
    let sys = Branched::default();
    let robot = sys.robot().unwrap();
    assert_eq!(robot.joint_names(), ["shoulder", "rail", "hip", "elbow"]);
    assert_eq!(robot.link_names(), ["arm", "slider", "side", "tip"]);
    assert_eq!(robot.input_names(), ["elbow", "shoulder"]);
    assert_eq!(robot.tree().bodies.as_slice(), sys.tree().bodies.as_slice());
    let mut bad = sys;
    bad.links.tip.mass = f64::NAN;
    let err = bad.robot().unwrap_err();
    assert!(err.to_string().contains("mass"), "{err}");
    assert!(Engine::new(bad.tree()).is_err());
}

vigp::mechanism! {
    /// Sixteen uniform rods (m = 1 kg, l = 0.5 m) in a chain: past the
    /// closed form's limit, so it has the tree engine alone.
    Rods16 {
        gravity: [0.0, -9.81],
        links {
            r0: { mass: 1.0, length: 0.5 },
            r1: { mass: 1.0, length: 0.5 },
            r2: { mass: 1.0, length: 0.5 },
            r3: { mass: 1.0, length: 0.5 },
            r4: { mass: 1.0, length: 0.5 },
            r5: { mass: 1.0, length: 0.5 },
            r6: { mass: 1.0, length: 0.5 },
            r7: { mass: 1.0, length: 0.5 },
            r8: { mass: 1.0, length: 0.5 },
            r9: { mass: 1.0, length: 0.5 },
            r10: { mass: 1.0, length: 0.5 },
            r11: { mass: 1.0, length: 0.5 },
            r12: { mass: 1.0, length: 0.5 },
            r13: { mass: 1.0, length: 0.5 },
            r14: { mass: 1.0, length: 0.5 },
            r15: { mass: 1.0, length: 0.5 },
        }
        joints {
            j0: revolute(world, r0.start),
            j1: revolute(r0.end, r1.start),
            j2: revolute(r1.end, r2.start),
            j3: revolute(r2.end, r3.start),
            j4: revolute(r3.end, r4.start),
            j5: revolute(r4.end, r5.start),
            j6: revolute(r5.end, r6.start),
            j7: revolute(r6.end, r7.start),
            j8: revolute(r7.end, r8.start),
            j9: revolute(r8.end, r9.start),
            j10: revolute(r9.end, r10.start),
            j11: revolute(r10.end, r11.start),
            j12: revolute(r11.end, r12.start),
            j13: revolute(r12.end, r13.start),
            j14: revolute(r13.end, r14.start),
            j15: revolute(r14.end, r15.start),
        }
    }
}

/// The mass matrix of a chain of n uniform rods (m, l) in relative
/// angles, by hand: in absolute angles φ, M_ij = m·l²·c_ij·cos(φ_i − φ_j)
/// with c_ii = 1/3 + (n − 1 − i) and c_ij = 1/2 + (n − 1 − max(i, j)),
/// and φ = T·q with T lower triangular of ones, so M(q) = Tᵀ·M_φ·T.
fn rod_chain_mass(q: &[f64], m: f64, l: f64) -> Vec<f64> {
    let n = q.len();
    let phi: Vec<f64> = q
        .iter()
        .scan(0.0, |s, x| {
            *s += x;
            Some(*s)
        })
        .collect();
    let c = |i: usize, j: usize| {
        let tail = (n - 1 - i.max(j)) as f64;
        if i == j { 1.0 / 3.0 + tail } else { 0.5 + tail }
    };
    let mut out = vec![0.0; n * n];
    for a in 0..n {
        for b in 0..n {
            // (Tᵀ M_φ T)_ab = Σ_(i ≥ a, j ≥ b) M_φ,ij
            let mut s = 0.0;
            for i in a..n {
                for j in b..n {
                    s += m * l * l * c(i, j) * (phi[i] - phi[j]).cos();
                }
            }
            out[a * n + b] = s;
        }
    }
    out
}

/// A 16-rod chain declared in `mechanism!` (no closed form: its
/// expansion is linear in the links) has the mass matrix of the hand
/// formula (1e-12 of the largest entry: sums of a few hundred terms of
/// order 1), and released from q = (1, −0.5, 0, …) completes 10⁴ steps of
/// 10 ms and of 5 ms with the default options, `no_std` engine and std
/// robot alike, with the energy error within 5 % of its scale (the
/// URDF chains' criterion, docs/robots.md).
#[test]
fn a_sixteen_rod_chain_past_the_closed_form_steps_on_the_engine() {
    let sys = Rods16::default();
    assert_eq!(Rods16::DOF, 16);
    let engine = Engine::new(sys.tree()).unwrap();
    let mut ws = [BodyScratch::zeroed(); 16];
    let mut mm = vec![0.0; 256];
    let mut worst = 0.0f64;
    for s in 0..10 {
        let q: Vec<f64> = (0..16).map(|i| (1.7 * (16 * s + i) as f64).sin()).collect();
        engine.mass_matrix(&q, &mut mm, &mut ws).unwrap();
        let hand = rod_chain_mass(&q, 1.0, 0.5);
        let scale = hand.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        for (a, b) in mm.iter().zip(&hand) {
            worst = worst.max((a - b).abs() / scale);
        }
    }
    println!("16 rods: M(q) against the hand formula {worst:.1e}");
    assert!(worst < 1e-12, "{worst:e}");
    let robot = sys.robot().unwrap();
    let mut q0 = vec![0.0; 16];
    (q0[0], q0[1]) = (1.0, -0.5);
    let z0 = vigp::RobotState::new(q0.clone(), vec![0.0; 16]);
    let e0 = robot.energy(&z0).unwrap();
    // the scale: the potential energy's range, Σ m·|g|·(height of the
    // centre of mass below the pivot at full stretch)
    let scale: f64 = (0..16).map(|k| 9.81 * 0.5 * (k as f64 + 0.5)).sum();
    for dt in [0.01, 0.005] {
        let run = robot.rollout(&z0, dt, 10_000).unwrap();
        let drift = run
            .states
            .iter()
            .map(|z| (robot.energy(z).unwrap() - e0).abs())
            .fold(0.0f64, f64::max);
        println!(
            "16 rods, dt = {dt}: 10^4 steps, {} subdivided, max |E - E0| = {drift:.3} J of a {scale:.1} J scale",
            run.report.subdivided
        );
        assert!(drift < 0.05 * scale, "dt {dt}: {drift} of {scale}");
        // the no_std engine on the same bodies (its iteration starts from
        // v, where the robot's extrapolates: the chaotic chain then
        // follows another path, held to the same energy)
        let (mut q, mut v, mut p) = ([0.0; 16], [0.0; 16], [0.0; 16]);
        q.copy_from_slice(&q0);
        engine.momentum_of(&q, &v, &mut p, &mut ws).unwrap();
        let mut drift = 0.0f64;
        for _ in 0..10_000 {
            engine
                .step(&mut q, &mut v, &mut p, &[0.0; 16], dt, &mut ws)
                .unwrap();
            drift = drift.max((engine.energy(&q, &v, &mut ws).unwrap() - e0).abs());
        }
        println!("  no_std engine: max |E - E0| = {drift:.3} J");
        assert!(drift < 0.05 * scale, "dt {dt}: {drift} of {scale}");
    }
}
