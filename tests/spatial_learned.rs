//! Learning in space (paper eq. 7/8): the learned integrator in maximal
//! coordinates with rotation-matrix GP inputs against quaternion inputs,
//! and the planar `Learned` integrator running unchanged on a spatial
//! minimal view (quaternion coordinates with their unit-norm constraint).

use nalgebra::SVector;
use vigp::gp::TrainOptions;
use vigp::learned::{Encoding, Learned, Prior, transitions as minimal_transitions};
use vigp::prelude::*;
use vigp::projection::consistent_state;
use vigp::spatial::learned::{Configuration, LearnedSpatial, Rotation, transitions};
use vigp::spatial::{LieStepper, SpatialIntegrator, SpatialState};
use vigp::systems::spatial::{Furuta, SphericalPendulum};

fn options() -> TrainOptions {
    TrainOptions {
        restarts: 2,
        seed: 3,
        ..TrainOptions::default()
    }
}

/// Largest centre-of-mass distance between two trajectories.
fn distance<const B: usize>(a: &[SpatialState<B>], b: &[SpatialState<B>]) -> f64 {
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| (0..B).map(move |i| (x.x[i] - y.x[i]).norm()))
        .fold(0.0, f64::max)
}

/// The same physical state with every quaternion negated (q and −q are the
/// same orientation).
fn twin<const B: usize>(z: &SpatialState<B>) -> SpatialState<B> {
    let mut t = *z;
    for q in &mut t.q {
        *q = nalgebra::UnitQuaternion::new_unchecked(-q.into_inner());
    }
    t
}

struct Rng(u64);
impl Rng {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        lo + (hi - lo) * ((z >> 11) as f64 / (1u64 << 53) as f64)
    }
}

/// The Furuta pendulum with unmodelled joint friction (base 0.02, pivot
/// 0.001 N·m·s/rad), learned on top of the frictionless model from 5
/// trajectories of 20 steps from random states, with rotation-matrix or
/// quaternion GP inputs; 0.3 s predictions from 10 fresh random states
/// (seeded, so the outcome is reproducible; `examples/spatial_learning`
/// repeats it at other data sizes):
///
/// * rotation-matrix inputs beat the nominal model from at least 9 of 10
///   states;
/// * negating every quaternion (the same physical state) leaves the
///   rotation-matrix prediction unchanged (1e-12), while the
///   quaternion-input GP sees inputs far from its data there: its mean
///   error grows by more than half.
///
/// On the states as sampled (one sign per trajectory), neither input wins
/// consistently: here quaternion inputs are slightly ahead (5.9e-3 against
/// 6.7e-3 m); in most data sizes of `examples/spatial_learning`
/// rotation matrices are (docs/spatial.md).
///
/// Every learned step keeps |g| ≤ 1e-10 (projection) and |‖q‖ − 1| ≤ 1e-14.
#[test]
fn rotation_matrix_inputs_are_sign_invariant_quaternion_inputs_are_not() {
    let dt = 0.01;
    let mut truth = Furuta::default();
    truth.joints.base.damping = 0.02;
    truth.joints.pivot.damping = 0.001;
    let nominal = Furuta::default();
    let t_step = LieStepper::new(truth.maximal(), dt).unwrap();
    let n_step = LieStepper::new(nominal.maximal(), dt).unwrap();
    let mut rng = Rng(5);
    let random_state = |rng: &mut Rng| {
        let q = [
            rng.uniform(0.0, std::f64::consts::TAU),
            rng.uniform(1.8, 4.4),
        ];
        let v = [rng.uniform(-4.0, 4.0), rng.uniform(-2.0, 2.0)];
        let z =
            consistent_state(&nominal.minimal(), &SVector::from(q), &SVector::from(v), dt).unwrap();
        nominal.minimal().to_maximal(&z, dt)
    };
    let mut data = Vec::new();
    for _ in 0..5 {
        let traj = t_step.rollout(&random_state(&mut rng), 21).unwrap();
        let configs: Vec<Configuration<2>> = traj.iter().map(|z| (z.x, z.q)).collect();
        data.extend(transitions(&configs, dt));
    }
    assert_eq!(data.len(), 100);
    let (matrix, _) =
        LearnedSpatial::train(n_step, &data, Rotation::Matrix, Prior::Nominal, &options()).unwrap();
    let (quat, _) = LearnedSpatial::train(
        n_step,
        &data,
        Rotation::Quaternion,
        Prior::Nominal,
        &options(),
    )
    .unwrap();

    let horizon = 30;
    let run = |m: &dyn SpatialIntegrator<2>, z: &SpatialState<2>| {
        let p = m.rollout(z, horizon).unwrap();
        for z in &p[1..] {
            assert!(t_step.constraint_violation(z) <= 1e-10);
            assert!(z.norm_error() <= 1e-14);
        }
        p
    };
    let tests = 10;
    let (mut nom, mut mat, mut qua, mut mat_twin, mut qua_twin) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let mut wins = 0;
    for _ in 0..tests {
        let z = random_state(&mut rng);
        let reference = t_step.rollout(&z, horizon).unwrap();
        let e_nom = distance(&reference, &n_step.rollout(&z, horizon).unwrap());
        let e_m = distance(&reference, &run(&matrix, &z));
        let e_mt = distance(&reference, &run(&matrix, &twin(&z)));
        assert!((e_m - e_mt).abs() <= 1e-12);
        wins += usize::from(e_m < e_nom);
        nom += e_nom / tests as f64;
        mat += e_m / tests as f64;
        mat_twin += e_mt / tests as f64;
        qua += distance(&reference, &run(&quat, &z)) / tests as f64;
        qua_twin += distance(&reference, &run(&quat, &twin(&z))) / tests as f64;
    }
    println!(
        "furuta, 0.3 s from {tests} fresh states, mean centre-of-mass error: nominal {nom:.3e} m; rotation-matrix inputs {mat:.3e} (−q: {mat_twin:.3e}, beats nominal {wins}/{tests}); quaternion inputs {qua:.3e} (−q: {qua_twin:.3e})"
    );
    assert!(wins >= 9);
    assert!((mat_twin - mat).abs() <= 1e-12);
    assert!(qua_twin > 1.5 * qua);
}

/// The planar `Learned` integrator (paper eq. 7/8) runs unchanged on a
/// spatial minimal view: the spherical pendulum's coordinates are a
/// quaternion, the unit norm is its constraint, and the projection keeps
/// |‖u‖² − 1| at solver tolerance every learned step while the GP corrects
/// the unmodelled damping (learned error at least 5× below nominal).
#[test]
fn learned_minimal_view_projects_onto_the_unit_quaternion() {
    let dt = 0.01;
    let mut truth = SphericalPendulum::default();
    truth.joints.ball.damping = 0.05;
    let nominal = SphericalPendulum::default().minimal();
    let z0 = consistent_state(
        &nominal,
        &SVector::from([0.8, 0.1, 0.55, 0.2]),
        &SVector::from([0.0, 0.5, 0.0, 1.5]),
        dt,
    )
    .unwrap();
    let traj = Variational::new(truth.minimal(), dt)
        .rollout(&z0, 61)
        .unwrap();
    let positions: Vec<_> = traj.iter().map(|z| z.q).collect();
    let data = minimal_transitions(&positions, dt);
    let (learned, _) = Learned::train(
        nominal,
        dt,
        &data,
        Encoding::Raw,
        Prior::Nominal,
        &options(),
    )
    .unwrap();
    let zt = traj[20];
    let horizon = 30;
    let reference = Variational::new(truth.minimal(), dt)
        .rollout(&zt, horizon)
        .unwrap();
    let nominal_run = Variational::new(nominal, dt).rollout(&zt, horizon).unwrap();
    let learned_run = learned.rollout(&zt, horizon).unwrap();
    let err = |a: &[State<4>]| {
        a.iter()
            .zip(&reference)
            .map(|(x, y)| (x.q - y.q).amax())
            .fold(0.0, f64::max)
    };
    let worst_norm = learned_run
        .iter()
        .skip(1)
        .map(|z| {
            let u = z.q + z.v * dt; // the configuration the projection closed
            (u.norm_squared() - 1.0).abs()
        })
        .fold(0.0, f64::max);
    println!(
        "spherical pendulum (minimal view), 0.3 s: nominal {:.3e}, learned {:.3e} (quaternion components); max |‖u‖² − 1| after projection {worst_norm:.1e}",
        err(&nominal_run),
        err(&learned_run)
    );
    assert!(err(&learned_run) < err(&nominal_run) / 5.0);
    assert!(worst_norm <= 1e-10);
}

/// A learned spatial step with a caller-owned workspace allocates nothing
/// (prior step, GP mean, projection).
#[test]
fn learned_spatial_step_does_not_allocate() {
    let dt = 0.01;
    let sys = Furuta::default();
    let stepper = LieStepper::new(sys.maximal(), dt).unwrap();
    let zmin = consistent_state(
        &sys.minimal(),
        &SVector::from([0.3, 2.5]),
        &SVector::from([2.0, 0.5]),
        dt,
    )
    .unwrap();
    let z0 = sys.minimal().to_maximal(&zmin, dt);
    let traj = stepper.rollout(&z0, 12).unwrap();
    let configs: Vec<Configuration<2>> = traj.iter().map(|z| (z.x, z.q)).collect();
    let (learned, _) = LearnedSpatial::train(
        stepper,
        &transitions(&configs, dt),
        Rotation::Matrix,
        Prior::Nominal,
        &TrainOptions {
            restarts: 0,
            ..TrainOptions::default()
        },
    )
    .unwrap();
    let mut ws = learned.workspace();
    let mut z = z0;
    let info = allocation_counter::measure(|| {
        for _ in 0..10 {
            z = learned.step_with(&z, &mut ws).unwrap();
        }
    });
    assert_eq!(info.count_total, 0, "learned spatial step allocated");
}
