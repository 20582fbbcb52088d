//! The identified prior (`Prior::Identified`): physical parameters
//! identified from a log (`vigp::identify`), then a GP on what they leave.
//!
//! The truth is a driven, damped double pendulum whose masses, centres of
//! mass, inertias and dampings differ from the declared ones; its logs are
//! written by the *midpoint* variational integrator, while the learned
//! models' prior is the first-order one, so that the GP has a remainder
//! to learn (the difference of the two rules) even with exact parameters.
//!
//! Numbers quoted in the report are printed with `-- --nocapture`.

use crate::common;
use nalgebra::SVector;
use vigp::gp::TrainOptions;
use vigp::identify::{DelRegressor, Log, Options, identify};
use vigp::learned::{
    Encoding, ForcedTransition, IdentifiedError, IdentifiedParameters, LearnError, Learned,
    LoadError, Prior, forced_transitions, transitions,
};
use vigp::{Parameters, State, Variational};

vigp::mechanism! {
    /// A double pendulum driven at the shoulder, both joints damped.
    pub PriorArm {
        gravity: [0.0, -9.81],
        links {
            upper: { mass: 1.0, length: 1.0 },
            lower: { mass: 0.8, length: 0.7 },
        }
        joints {
            shoulder: revolute(world, upper.start) { damping: 0.1, actuated },
            elbow: revolute(upper.end, lower.start) { damping: 0.1 },
        }
    }
}

const DT: f64 = 0.01;
type Arm = PriorArmMinimal;

fn set<P: Parameters>(p: &mut P, name: &str, value: f64) {
    let i = P::parameter_index(name).unwrap_or_else(|| panic!("no parameter {name}"));
    *p.parameter_mut(i).unwrap() = value;
}

fn get<P: Parameters>(p: &P, name: &str) -> f64 {
    p.parameter(P::parameter_index(name).unwrap()).unwrap()
}

/// The truth: every inertial parameter and damping off the declared value
/// (masses ×1.15 and ×0.9, centres of mass moved by 3–4 cm, inertias
/// ×1.2 and ×0.85, dampings 0.25 and 0.15).
fn truth() -> Arm {
    let mut t = PriorArm::default().minimal();
    for (name, factor) in [
        ("links.upper.mass", 1.15),
        ("links.lower.mass", 0.9),
        ("links.upper.inertia", 1.2),
        ("links.lower.inertia", 0.85),
    ] {
        let v = get(&t, name);
        set(&mut t, name, v * factor);
    }
    for (name, shift) in [
        ("links.upper.com.x", 0.04),
        ("links.upper.com.y", -0.03),
        ("links.lower.com.x", -0.03),
        ("links.lower.com.y", 0.02),
    ] {
        let v = get(&t, name);
        set(&mut t, name, v + shift);
    }
    set(&mut t, "joints.shoulder.damping", 0.25);
    set(&mut t, "joints.elbow.damping", 0.15);
    t
}

/// The shoulder torque at sample k: two sines (a persistently exciting
/// input, which fixes the scale of the parameters).
fn drive(k: usize, phase: f64) -> f64 {
    let t = k as f64 * DT;
    2.0 * (1.7 * t + phase).sin() + 1.0 * (4.3 * t + 0.5 + phase).cos()
}

/// `steps` + 1 positions of the truth from `q0` at rest, written by the
/// midpoint rule, with their inputs in the convention of `vigp::data`
/// (row k's input held over [t_k, t_{k+1}]; the step from z_k to
/// z_{k+1} runs under row k + 1's after row k's). The forced rollout
/// takes each step's previous input from the plan, as the midpoint rule's
/// discrete force needs; the first two rows are 0 (at rest, no input
/// before the start).
fn midpoint_log(
    q0: [f64; 2],
    steps: usize,
    phase: f64,
) -> (Vec<SVector<f64, 2>>, Vec<SVector<f64, 1>>) {
    let vi = Variational::midpoint(truth(), DT).unwrap();
    let inputs: Vec<SVector<f64, 1>> = (0..=steps)
        .map(|k| SVector::from([if k < 2 { 0.0 } else { drive(k, phase) }]))
        .collect();
    let z0 = State {
        q: SVector::from(q0),
        v: SVector::zeros(),
    };
    // z_0, …, z_{steps−1}: rollout input j is log row j + 1
    let traj = vi.rollout_forced(&z0, &inputs[1..steps]).unwrap();
    let mut positions: Vec<SVector<f64, 2>> = traj.iter().map(|z| z.q).collect();
    let last = traj.last().unwrap();
    positions.push(last.q + last.v * DT);
    assert_eq!(positions.len(), steps + 1);
    (positions, inputs)
}

fn identify_log(positions: &[SVector<f64, 2>], inputs: &[SVector<f64, 1>]) -> Log {
    Log {
        positions: positions.iter().map(|q| q.as_slice().to_vec()).collect(),
        inputs: inputs.iter().map(|u| u.as_slice().to_vec()).collect(),
    }
}

/// The mechanism with the identified standard parameters π, converted to
/// the DSL's names by hand (mass m, centre of mass c = (m·c)/m, inertia
/// about it I_c = I_O − m|c|², damping as is): independent of
/// `IdentifiedParameters`' own conversion.
fn by_hand(p: &IdentifiedParameters) -> Arm {
    let mut m = PriorArm::default().minimal();
    let v = |n: &str| p.value(n).unwrap_or_else(|| panic!("no {n}"));
    for link in ["upper", "lower"] {
        let mass = v(&format!("links.{link}.mass"));
        let cx = v(&format!("links.{link}.mcom.x")) / mass;
        let cy = v(&format!("links.{link}.mcom.y")) / mass;
        let io = v(&format!("links.{link}.inertia_o"));
        set(&mut m, &format!("links.{link}.mass"), mass);
        set(&mut m, &format!("links.{link}.com.x"), cx);
        set(&mut m, &format!("links.{link}.com.y"), cy);
        set(
            &mut m,
            &format!("links.{link}.inertia"),
            io - mass * (cx * cx + cy * cy),
        );
    }
    for joint in ["shoulder", "elbow"] {
        let name = format!("joints.{joint}.damping");
        set(&mut m, &name, v(&name));
    }
    m
}

fn options() -> TrainOptions {
    common::train_options(0, 7)
}

/// The identified parameters of the truth's training log, with the
/// training transitions.
fn identified() -> (IdentifiedParameters, Vec<ForcedTransition<2, 1>>) {
    let (positions, inputs) = midpoint_log([0.3, -0.5], 600, 0.0);
    let regressor = DelRegressor::midpoint(PriorArm::default().minimal(), DT).unwrap();
    let id = identify(
        &regressor,
        &[identify_log(&positions, &inputs)],
        &Options::default(),
    )
    .unwrap();
    let params = IdentifiedParameters::from_identification::<Arm>(&id).unwrap();
    let all = forced_transitions(&positions, &inputs, DT);
    // 150 evenly spread transitions
    let data = (0..150).map(|i| all[i * all.len() / 150]).collect();
    (params, data)
}

/// Mean squared position error of 20-step rollouts from every 10th state
/// of a held-out log of the truth (its inputs as logged).
fn rollout_error(
    l: &Learned<Arm, 2, 0>,
    positions: &[SVector<f64, 2>],
    inputs: &[SVector<f64, 1>],
) -> f64 {
    const H: usize = 20;
    let (mut sum, mut count) = (0.0, 0usize);
    let mut out = vec![
        State {
            q: SVector::<f64, 2>::zeros(),
            v: SVector::zeros()
        };
        H
    ];
    for k in (0..positions.len() - H - 2).step_by(10) {
        let z0 = common::state_at(positions, k, DT);
        l.rollout_mean_forced_into(&z0, &inputs[k], &inputs[k + 1..k + 1 + H], &mut out)
            .unwrap();
        for (j, z) in out.iter().enumerate() {
            sum += (z.q - positions[k + 1 + j]).norm_squared();
            count += 1;
        }
    }
    sum / count as f64
}

/// `Prior::Identified` is the nominal prior of the mechanism with the
/// identified parameters: trained on the same transitions, it predicts as
/// `Prior::Nominal` on that mechanism built by hand from π, and it beats
/// `Prior::Nominal` with the declared parameters in 20-step error on a
/// held-out log.
///
/// Tolerances: the identified π is that of the truth to 1e-8 relative
/// (a log written by the midpoint rule is fitted exactly by the midpoint
/// regressor; `tests/learn/identify.rs`); the hand-built parameters agree
/// with the library's conversion to 1e-14 relative (the same arithmetic,
/// up to the order of a few roundings), and the two models' predictions to
/// 1e-9 relative (hyperparameter optimisation from the same start on
/// targets equal to rounding).
#[test]
fn identified_prior_learns_on_the_identified_mechanism() {
    let (params, data) = identified();
    let truth = truth();
    // the identification itself (checked in detail in identify.rs)
    for name in ["joints.shoulder.damping", "joints.elbow.damping"] {
        let (got, want) = (params.value(name).unwrap(), get(&truth, name));
        assert!((got - want).abs() <= 1e-8 * want, "{name}: {got} vs {want}");
    }
    assert_eq!(params.mechanism(), "PriorArm");
    assert_eq!(params.covariance().nrows(), params.parameters().len());

    let declared = PriorArm::default().minimal();
    let hand = by_hand(&params);
    let train = |model: Arm, prior: Prior| {
        Learned::train_forced(model, DT, &data, Encoding::SinCos, prior, &options())
            .unwrap()
            .0
    };
    let with_identified = train(declared, Prior::Identified(params.clone()));
    let with_hand = train(hand, Prior::Nominal);
    let with_declared = train(declared, Prior::Nominal);
    // the learned model keeps the identified mechanism and its parameters
    assert_eq!(with_identified.identified(), Some(&params));
    for (i, name) in Arm::PARAMETER_NAMES.iter().enumerate() {
        let (a, b) = (
            with_identified.model().parameter(i).unwrap(),
            hand.parameter(i).unwrap(),
        );
        assert!(
            (a - b).abs() <= 1e-14 * a.abs().max(b.abs()).max(1.0),
            "{name}: {a} vs {b}"
        );
    }

    let (test_q, test_u) = midpoint_log([-0.4, 1.0], 300, 1.3);
    let test = forced_transitions(&test_q, &test_u, DT);
    let (mut ws, mut wh) = (with_identified.workspace(), with_hand.workspace());
    let mut worst: f64 = 0.0;
    for t in &test {
        let (a, sa) = with_identified
            .predict_velocity_forced(&t.z, &t.u_prev, &t.u, &mut ws)
            .unwrap();
        let (b, sb) = with_hand
            .predict_velocity_forced(&t.z, &t.u_prev, &t.u, &mut wh)
            .unwrap();
        worst = worst
            .max((a - b).norm() / b.norm().max(1.0))
            .max((sa - sb).norm() / sb.norm().max(1e-12));
    }
    println!("identified vs hand-built nominal prior: largest relative difference {worst:.1e}");
    assert!(worst <= 1e-9, "{worst:e}");

    let e_identified = rollout_error(&with_identified, &test_q, &test_u);
    let e_hand = rollout_error(&with_hand, &test_q, &test_u);
    let e_declared = rollout_error(&with_declared, &test_q, &test_u);
    println!(
        "20-step MSE on a held-out log (N = {}): identified + GP {e_identified:.3e}, \
         hand-built + GP {e_hand:.3e}, declared + GP {e_declared:.3e} ({:.0}× larger)",
        data.len(),
        e_declared / e_identified
    );
    assert!((e_identified - e_hand).abs() <= 1e-9 * e_hand.max(1e-300));
    assert!(
        e_identified * 10.0 < e_declared,
        "{e_identified:e} vs {e_declared:e}"
    );

    // `Learned::train` (no inputs) takes the identified prior the same way
    let plain = transitions(&test_q[..120], DT);
    let (a, _) = Learned::train(
        declared,
        DT,
        &plain,
        Encoding::Raw,
        Prior::Identified(params.clone()),
        &options(),
    )
    .unwrap();
    let (b, _) =
        Learned::train(hand, DT, &plain, Encoding::Raw, Prior::Nominal, &options()).unwrap();
    let (mut wa, mut wb) = (a.workspace(), b.workspace());
    for t in &plain {
        let va = a.predict_mean_velocity(&t.z, &mut wa).unwrap();
        let vb = b.predict_mean_velocity(&t.z, &mut wb).unwrap();
        assert!(
            (va - vb).norm() <= 1e-9 * vb.norm().max(1.0),
            "{va} vs {vb}"
        );
    }
}

/// The model file records the identified standard parameters and their
/// covariance in its prior; loading restores them and predicts bit for bit
/// as the saved model. A file whose identified values disagree with its
/// `parameters`, or of another mechanism, is refused; a file without the
/// section (written before identified priors existed) loads as before.
#[test]
fn identified_prior_round_trips_through_the_model_file() {
    let (params, data) = identified();
    let declared = PriorArm::default().minimal();
    let (l, _) = Learned::train_forced(
        declared,
        DT,
        &data,
        Encoding::Raw,
        Prior::Identified(params.clone()),
        &options(),
    )
    .unwrap();
    let json = l.to_json();
    let file: serde_json::Value = serde_json::from_str(&json).unwrap();
    let section = &file["prior"]["identified"];
    assert_eq!(section["mechanism"], "PriorArm");
    let rows = section["parameters"].as_array().unwrap();
    assert_eq!(rows.len(), params.parameters().len());
    let cov = params.covariance();
    for (i, (row, p)) in rows.iter().zip(params.parameters()).enumerate() {
        assert_eq!(row["name"], p.name.as_str());
        assert_eq!(row["value"].as_f64().unwrap(), p.value);
        let cov_row = section["covariance"][i].as_array().unwrap();
        for (j, c) in cov_row.iter().enumerate() {
            assert_eq!(c.as_f64().unwrap(), cov[(i, j)]);
        }
    }
    // the DSL's values in `parameters` are the identified mechanism's
    assert_eq!(
        file["parameters"]["joints.elbow.damping"].as_f64().unwrap(),
        get(l.model(), "joints.elbow.damping")
    );

    // loaded into the declared mechanism: the file's values win
    let back = Learned::from_json(declared, &json).unwrap();
    assert_eq!(back.identified(), Some(&params));
    assert_eq!(back.prior(), Prior::Identified(params.clone()));
    let (mut w1, mut w2) = (l.workspace(), back.workspace());
    for t in &data {
        let a = l
            .predict_velocity_forced(&t.z, &t.u_prev, &t.u, &mut w1)
            .unwrap();
        let b = back
            .predict_velocity_forced(&t.z, &t.u_prev, &t.u, &mut w2)
            .unwrap();
        assert_eq!(a, b);
    }
    assert_eq!(back.to_json(), json);

    // a parameter that the identified values do not give
    let mut tampered = file.clone();
    tampered["parameters"]["links.upper.mass"] = serde_json::json!(5.0);
    let e = Learned::from_json(declared, &tampered.to_string()).unwrap_err();
    assert!(
        matches!(&e, LoadError::Field { field, .. } if field == "prior.identified"),
        "{e}"
    );
    // identified values of another mechanism
    let mut other = file.clone();
    other["prior"]["identified"]["mechanism"] = serde_json::json!("Acrobot");
    let e = Learned::from_json(declared, &other.to_string()).unwrap_err();
    assert!(e.to_string().contains("identified for `Acrobot`"), "{e}");
    // a covariance row too short
    let mut short = file.clone();
    short["prior"]["identified"]["covariance"][0] = serde_json::json!([1.0]);
    let e = Learned::from_json(declared, &short.to_string()).unwrap_err();
    assert!(e.to_string().contains("covariance"), "{e}");

    // a model file without the section, as written before: nominal prior
    let old = include_str!("../fixtures/learned_cartpole.json");
    let l = Learned::from_json(vigp::systems::Cartpole::default().minimal(), old).unwrap();
    assert_eq!(l.prior(), Prior::Nominal);
    assert_eq!(l.identified(), None);
}

/// Wrong identified parameters are typed errors, before any training.
#[test]
fn identified_prior_errors() {
    let (params, data) = identified();
    let declared = PriorArm::default().minimal();
    let train = |p: IdentifiedParameters| {
        Learned::train_forced(
            declared,
            DT,
            &data,
            Encoding::Raw,
            Prior::Identified(p),
            &options(),
        )
        .map(|_| ())
    };
    let names: Vec<String> = params.parameters().iter().map(|p| p.name.clone()).collect();
    let values: Vec<f64> = params.parameters().iter().map(|p| p.value).collect();
    let cov = params.covariance();

    // another mechanism's
    let other = IdentifiedParameters::new("Acrobot", &names, &values, &cov).unwrap();
    assert!(matches!(
        train(other),
        Err(LearnError::Identified(IdentifiedError::Mechanism { .. }))
    ));
    // a name the mechanism does not have, one missing
    let mut renamed = names.clone();
    renamed[0] = "links.fore.mass".into();
    let p = IdentifiedParameters::new("PriorArm", &renamed, &values, &cov).unwrap();
    assert!(matches!(
        train(p),
        Err(LearnError::Identified(IdentifiedError::UnknownParameter(n))) if n == "links.fore.mass"
    ));
    let p = IdentifiedParameters::new(
        "PriorArm",
        &names[1..],
        &values[1..],
        &cov.view((1, 1), (names.len() - 1, names.len() - 1))
            .into_owned(),
    )
    .unwrap();
    assert!(matches!(
        train(p),
        Err(LearnError::Identified(IdentifiedError::MissingParameter(n))) if n == names[0]
    ));
    // a zero mass has no centre of mass
    let mut zero = values.clone();
    zero[0] = 0.0;
    let p = IdentifiedParameters::new("PriorArm", &names, &zero, &cov).unwrap();
    assert!(matches!(
        train(p),
        Err(LearnError::Identified(IdentifiedError::NoDslForm(_)))
    ));
    // NaN values or covariances, a covariance of the wrong size
    let mut nan = values.clone();
    nan[2] = f64::NAN;
    assert!(matches!(
        IdentifiedParameters::new("PriorArm", &names, &nan, &cov),
        Err(IdentifiedError::NonFinite(_))
    ));
    let mut bad = cov.clone();
    bad[(1, 1)] = f64::INFINITY;
    assert!(matches!(
        IdentifiedParameters::new("PriorArm", &names, &values, &bad),
        Err(IdentifiedError::Covariance(_))
    ));
    assert!(matches!(
        IdentifiedParameters::new("PriorArm", &names, &values, &nalgebra::DMatrix::zeros(2, 2)),
        Err(IdentifiedError::Covariance(_))
    ));
}

/// The Lie-group learned models take their parameters from their stepper's
/// mechanism: an identified prior is refused with a typed error (build the
/// stepper from the mechanism with the identified parameters instead).
#[test]
fn spatial_learned_refuses_an_identified_prior() {
    use vigp::Integrator;
    use vigp::spatial::LieStepper;
    use vigp::spatial::learned::{
        Configuration, LearnSpatialError, LearnedSpatial, Rotation, transitions as spatial,
    };
    let dt = 0.01;
    let sys = vigp::systems::spatial::Furuta::default();
    let stepper = LieStepper::new(sys.maximal(), dt).unwrap();
    let z0 = common::furuta_start(dt);
    let traj = stepper.rollout(&z0, 6).unwrap();
    let configs: Vec<Configuration<2>> = traj.iter().map(|z| (z.x, z.q)).collect();
    let params = IdentifiedParameters::new(
        "Furuta",
        &["links.arm.mass".to_string()],
        &[1.0],
        &nalgebra::DMatrix::zeros(1, 1),
    )
    .unwrap();
    let e = LearnedSpatial::train(
        stepper,
        &spatial(&configs, dt),
        Rotation::Matrix,
        Prior::Identified(params),
        &options(),
    )
    .unwrap_err();
    assert!(matches!(e, LearnSpatialError::IdentifiedPrior), "{e}");
}
