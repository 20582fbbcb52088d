//! A planar tree description on the linear-time tree engine
//! (`Name::tree()`, `Name::robot()`): its mass matrix, energy and steps
//! against the closed-form terms and the `Variational` step of the same
//! description (another derivation of the same equations: symbolic
//! closed forms against recursive spatial-vector algorithms).

use vigp::embedded::tree::{BodyScratch, Engine, EngineOptions, Tree};
use vigp::prelude::*;
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

/// Mass matrices and energies agree to rounding (1e-12: a few hundred
/// operations of either derivation on numbers of order 1; measured
/// ≤ 5.1e-16); 100 steps to 1e-10 (both solvers stop at 1e-14 of the
/// momentum scale, and 100 steps carry those differences along; measured
/// ≤ 8.4e-12).
#[test]
fn planar_trees_on_the_engine_equal_their_closed_forms() {
    let report = |name: &str, (m, e, s): (f64, f64, f64)| {
        println!("{name}: M(q) {m:.1e}, E(q, v) {e:.1e}, 100 steps {s:.1e}");
        assert!(m < 1e-12 && e < 1e-12, "{name}: M {m:e}, E {e:e}");
        assert!(s < 1e-10, "{name}: steps {s:e}");
    };
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
            &DoublePendulum::TREE_INPUTS,
            sys.tree(),
        ),
    );
    let sys = Cartpole::default();
    report(
        "cart-pole",
        compare::<_, 2, 0>(
            sys.minimal(),
            &Cartpole::TREE_COORDINATES,
            &Cartpole::TREE_INPUTS,
            sys.tree(),
        ),
    );
    let sys = Pendulum::default();
    report(
        "pendulum",
        compare::<_, 1, 0>(
            sys.minimal(),
            &Pendulum::TREE_COORDINATES,
            &Pendulum::TREE_INPUTS,
            sys.tree(),
        ),
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
