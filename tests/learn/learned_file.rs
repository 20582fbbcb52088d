//! One file for a whole learned model: a saved and reloaded `Learned`
//! predicts bit for bit as the original; every mismatch with the model it is
//! loaded into is a typed error naming the field; no byte flip and no
//! truncation of a model file makes loading (or the first step) panic.

use crate::common;
use common::positions;
use nalgebra::SVector;
use vigp::gp::TrainOptions;
use vigp::learned::{Encoding, Learned, LoadError, Prior, SavedLearned, transitions};
use vigp::prelude::*;
use vigp::systems::{Cartpole, CartpoleMaximal, CartpoleMinimal, Fourbar, Pendulum};

const DT: f64 = 0.01;

fn options() -> TrainOptions {
    common::train_options(0, 3)
}

/// A cart-pole model trained on `n` transitions of a perturbed cart-pole.
fn cartpole_model(n: usize, encoding: Encoding) -> Learned<CartpoleMinimal, 2, 0> {
    let mut truth = Cartpole::default();
    truth.links.pole.mass *= 1.1;
    truth.joints.hinge.damping = 0.05;
    let q = positions(truth.minimal(), SVector::from([0.2, 1.2]), DT, 10, n + 2);
    let data = transitions(&q, DT);
    let mut nominal = Cartpole::default();
    nominal.joints.rail.damping = 0.01; // a non-default parameter must survive
    Learned::train(
        nominal.minimal(),
        DT,
        &data,
        encoding,
        Prior::Nominal,
        &options(),
    )
    .unwrap()
    .0
}

/// Rollouts (projected when the model has constraints) and one step's
/// standard deviations of both models, compared bit for bit.
fn assert_same_predictions<M: Mechanism<N, C> + Clone, const N: usize, const C: usize>(
    a: &Learned<M, N, C>,
    b: &Learned<M, N, C>,
    z0: &State<N>,
) {
    let (ra, rb) = (a.rollout(z0, 30).unwrap(), b.rollout(z0, 30).unwrap());
    assert_eq!(ra, rb, "rollouts differ");
    let (mut wa, mut wb) = (a.workspace(), b.workspace());
    let (sa, ia) = a.step_in(z0, &mut wa).unwrap();
    let (sb, ib) = b.step_in(z0, &mut wb).unwrap();
    assert_eq!(sa, sb);
    assert_eq!(ia, ib);
}

#[test]
fn reload_predicts_bit_identically() {
    let dir = std::env::temp_dir().join(format!("vigp-learned-file-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // tree, nominal prior, sin/cos encoding; through a file on disk
    let l = cartpole_model(30, Encoding::SinCos);
    let path = dir.join("cartpole.json");
    l.save(&path).unwrap();
    let back = Learned::load(&path, Cartpole::default().minimal()).unwrap();
    assert_eq!(back.model(), l.model(), "parameters restored from the file");
    assert_same_predictions(&l, &back, &State::new([0.1, 1.0], [0.3, -0.2]));

    // loop (projection on), constant prior, raw encoding; through text
    let four = Fourbar::default().minimal();
    let q0 = SVector::from([0.4, -0.8, -0.4, 0.8]);
    let q = positions(four, q0, DT, 10, 32);
    let (lf, _) = Learned::train(
        four,
        DT,
        &transitions(&q, DT),
        Encoding::Raw,
        Prior::Constant,
        &options(),
    )
    .unwrap();
    assert!(lf.projects());
    let back = Learned::from_json(four, &lf.to_json()).unwrap();
    let z0 = common::state_at(&q, 3, DT);
    assert_same_predictions(&lf, &back, &z0);
    std::fs::remove_dir_all(&dir).ok();
}

/// Loads `json` (edited by `edit`) into the cart-pole's minimal view.
fn load_edited(
    json: &str,
    edit: impl FnOnce(&mut serde_json::Value),
) -> Result<Learned<CartpoleMinimal, 2, 0>, LoadError> {
    let mut v: serde_json::Value = serde_json::from_str(json).unwrap();
    edit(&mut v);
    Learned::from_json(Cartpole::default().minimal(), &v.to_string())
}

fn field_of(e: &LoadError) -> String {
    match e {
        LoadError::Field { field, .. } => field.clone(),
        other => panic!("expected a Field error, got {other:?}"),
    }
}

#[test]
fn every_mismatch_is_a_typed_error_naming_the_field() {
    let l = cartpole_model(12, Encoding::SinCos);
    let json = l.to_json();
    // into another mechanism
    let e = Learned::from_json(Pendulum::default().minimal(), &json).unwrap_err();
    assert!(
        matches!(&e, LoadError::Mechanism { expected, found } if expected == "Pendulum" && found == "Cartpole"),
        "{e}"
    );
    assert!(e.to_string().contains("mechanism"), "{e}");
    // into the other coordinate view of the same mechanism
    let e = Learned::<CartpoleMaximal, 6, 4>::from_json(Cartpole::default().maximal(), &json)
        .unwrap_err();
    assert!(matches!(e, LoadError::Coordinates { .. }), "{e}");
    // renamed coordinates
    let e = load_edited(&json, |v| v["coordinates"][1] = "pole".into()).unwrap_err();
    assert!(matches!(e, LoadError::Coordinates { .. }), "{e}");
    // other inputs
    let e = load_edited(&json, |v| v["inputs"] = serde_json::json!(["u_rail"])).unwrap_err();
    assert!(matches!(e, LoadError::Inputs { .. }), "{e}");
    assert!(e.to_string().contains("u_rail"), "{e}");
    // kinds
    let e = load_edited(&json, |v| v["kinds"][0] = "angle".into()).unwrap_err();
    assert_eq!(field_of(&e), "kinds");
    // the GP's input dimension edited (today's message was about `targets`)
    let e = load_edited(&json, |v| v["gp"]["input_dim"] = 6.into()).unwrap_err();
    assert_eq!(field_of(&e), "gp.input_dim", "{e}");
    let e = load_edited(&json, |v| v["gp"]["output_dim"] = 3.into()).unwrap_err();
    assert_eq!(field_of(&e), "gp.output_dim", "{e}");
    let e = load_edited(&json, |v| {
        v["gp"]["targets"].as_array_mut().unwrap().pop();
    })
    .unwrap_err();
    assert_eq!(field_of(&e), "gp.targets", "{e}");
    let e = load_edited(&json, |v| {
        v["gp"]["input_normaliser"]["scale"]
            .as_array_mut()
            .unwrap()
            .pop();
    })
    .unwrap_err();
    assert_eq!(field_of(&e), "gp.input_normaliser.scale", "{e}");
    let e = load_edited(&json, |v| {
        v["gp"]["outputs"][1]["hyperparameters"]["length_scales"]
            .as_array_mut()
            .unwrap()
            .pop();
    })
    .unwrap_err();
    assert_eq!(field_of(&e), "gp.outputs[1].hyperparameters.length_scales");
    // a prior that does not fit the GP's mean
    let e = load_edited(&json, |v| v["prior"] = "constant".into()).unwrap_err();
    assert_eq!(field_of(&e), "gp.mean", "{e}");
    // an encoding whose dimension does not fit the GP
    let e = load_edited(&json, |v| v["encoding"] = "raw".into()).unwrap_err();
    assert_eq!(field_of(&e), "gp.input_dim", "{e}");
    // parameters
    let e = load_edited(&json, |v| {
        v["parameters"]
            .as_object_mut()
            .unwrap()
            .remove("links.pole.mass");
    })
    .unwrap_err();
    assert!(
        matches!(&e, LoadError::MissingParameter(p) if p == "links.pole.mass"),
        "{e}"
    );
    let e = load_edited(&json, |v| v["parameters"]["links.stick.mass"] = 1.0.into()).unwrap_err();
    assert!(
        matches!(&e, LoadError::UnknownParameter(p) if p == "links.stick.mass"),
        "{e}"
    );
    let e = load_edited(&json, |v| {
        v["parameters"]["links.cart.mass"] = (-1.0).into()
    })
    .unwrap_err();
    assert_eq!(field_of(&e), "parameters.links.cart.mass");
    // a zero mass passes the mechanism's own check, so it passes here too
    // (`vigp fit --set links.pole.mass=0` wrote files that nothing loaded)
    load_edited(&json, |v| v["parameters"]["links.cart.mass"] = 0.0.into()).unwrap();
    let e = load_edited(&json, |v| {
        v["parameters"]["joints.hinge.damping"] = serde_json::Value::Null
    })
    .unwrap_err();
    assert!(matches!(e, LoadError::Syntax { .. }), "{e}");
    // scalars
    let e = load_edited(&json, |v| v["dt"] = 0.0.into()).unwrap_err();
    assert_eq!(field_of(&e), "dt");
    let e = load_edited(&json, |v| v["version"] = 2.into()).unwrap_err();
    assert_eq!(field_of(&e), "version");
    let e = load_edited(&json, |v| v["format"] = "vigp-gp".into()).unwrap_err();
    assert_eq!(field_of(&e), "format");
    let e = load_edited(&json, |v| v["newton"]["tolerance"] = (-1.0).into()).unwrap_err();
    assert_eq!(field_of(&e), "newton");
    let e = load_edited(&json, |v| v["project"] = true.into()).unwrap_err();
    assert_eq!(field_of(&e), "project");
    // missing and unknown fields: serde names them
    let e = load_edited(&json, |v| {
        v.as_object_mut().unwrap().remove("dt");
    })
    .unwrap_err();
    assert!(e.to_string().contains("missing field `dt`"), "{e}");
    let e = load_edited(&json, |v| v["colour"] = "red".into()).unwrap_err();
    assert!(e.to_string().contains("unknown field `colour`"), "{e}");
    // a GP that its own checks reject (a negative length scale)
    let e = load_edited(&json, |v| {
        v["gp"]["outputs"][0]["hyperparameters"]["length_scales"][0] = (-1.0).into()
    })
    .unwrap_err();
    assert!(matches!(e, LoadError::Gp(_)), "{e}");
    assert!(e.to_string().starts_with("field `gp`"), "{e}");
    // reading a file that is not there
    let e = Learned::load("/nonexistent/model.json", Cartpole::default().minimal()).unwrap_err();
    assert!(matches!(e, LoadError::Io { .. }), "{e}");
    // the untouched text still loads
    load_edited(&json, |_| {}).unwrap();
    // and the header can be read without a model
    let saved = SavedLearned::from_json(&json).unwrap();
    assert_eq!(saved.mechanism, "Cartpole");
    assert_eq!(saved.coordinates, ["rail", "hinge"]);
}

/// Every byte of a model file flipped (one bit at a time, bit 2: digits
/// stay digits or become other characters, quotes and brackets break) and
/// every truncation: loading returns a model or a typed error, never
/// panics; a model that loads takes one step without panicking, and a
/// step that succeeds is finite.
/// A length of 0 loads where the mechanism's own check takes it: a 3-D
/// link declared without a length (the tumbler's body) saves and loads,
/// predicting bit for bit; a planar link of length 0 is refused, naming
/// the field.
#[test]
fn a_zero_length_loads_only_where_the_mechanism_takes_it() {
    let json = cartpole_model(12, Encoding::SinCos).to_json();
    let e = load_edited(&json, |v| v["parameters"]["links.pole.length"] = 0.0.into()).unwrap_err();
    assert_eq!(field_of(&e), "parameters.links.pole.length");

    let sys = vigp::systems::spatial::Tumbler::default();
    assert_eq!(sys.links.body.length, 0.0);
    let z0 = State {
        q: SVector::from([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]),
        v: SVector::from([0.1, 0.0, 0.0, 0.0, 0.05, 0.5, 0.01]),
    };
    let traj = Variational::new(sys.minimal(), DT)
        .unwrap()
        .rollout(&z0, 20)
        .unwrap();
    let q: Vec<_> = traj.iter().map(|z| z.q).collect();
    let (l, _) = Learned::train(
        sys.minimal(),
        DT,
        &transitions(&q, DT),
        Encoding::Raw,
        Prior::Nominal,
        &options(),
    )
    .unwrap();
    let back = Learned::from_json(sys.minimal(), &l.to_json()).unwrap();
    assert_same_predictions(&l, &back, &z0);
}

#[test]
fn byte_flips_and_truncations_never_panic() {
    let l = cartpole_model(8, Encoding::SinCos);
    let json = l.to_json().into_bytes();
    let model = Cartpole::default().minimal();
    let z0 = State::new([0.1, 1.0], [0.3, -0.2]);
    let (mut loaded, mut rejected) = (0usize, 0usize);
    let mut try_bytes = |bytes: &[u8]| {
        let Ok(text) = std::str::from_utf8(bytes) else {
            rejected += 1;
            return;
        };
        match Learned::from_json(model, text) {
            Ok(m) => {
                loaded += 1;
                if let Ok(z) = m.step(&z0) {
                    assert!(z.is_finite());
                }
            }
            Err(e) => {
                rejected += 1;
                assert!(!e.to_string().is_empty());
            }
        }
    };
    for i in 0..json.len() {
        let mut b = json.clone();
        b[i] ^= 0x04;
        try_bytes(&b);
    }
    for len in 0..json.len() {
        try_bytes(&json[..len]);
    }
    eprintln!(
        "{} bytes: {} flips + {} truncations: {loaded} loaded, {rejected} rejected",
        json.len(),
        json.len(),
        json.len()
    );
    assert_eq!(loaded + rejected, 2 * json.len());
    assert!(rejected >= json.len(), "every truncation must be rejected");
}
