//! `vigp::embedded::LearnedStepper` (no_std, no allocation) against the std
//! learned step: equal to 1e-12 along rollouts, for a tree with a nominal
//! prior and sin/cos encoding, a loop (projection) with a nominal prior, and
//! a constant prior; no heap allocation per step (counting allocator); the
//! generated source compiles (its statics are included here) and matches
//! the model file it was exported from.

mod common;

use common::positions;
use nalgebra::SVector;
use vigp::embedded::gp::ExportedGp;
use vigp::embedded::learned::{Encoding as CoreEncoding, LearnedModel, Prior as CorePrior};
use vigp::embedded::{LearnedError, LearnedStepper, Parameters, StepOptions};
use vigp::gp::{ExportedArrays, TrainOptions};
use vigp::learned::{EmbeddedExport, Encoding, Learned, Prior, transitions};
use vigp::prelude::*;
use vigp::systems::{Cartpole, Fourbar, Pendulum};

const DT: f64 = 0.01;

fn options() -> TrainOptions {
    TrainOptions {
        restarts: 1,
        seed: 11,
        ..TrainOptions::default()
    }
}

/// Owns what a generated file would hold as statics.
struct Owned<const N: usize> {
    arrays: Vec<ExportedArrays>,
    parameters: Vec<(&'static str, f64)>,
}

fn owned<M, const N: usize, const C: usize>(l: &Learned<M, N, C>) -> Owned<N>
where
    M: Mechanism<N, C> + Parameters + Clone,
{
    Owned {
        arrays: (0..N)
            .map(|j| l.gp().export_output(j, false).unwrap())
            .collect(),
        parameters: M::PARAMETER_NAMES
            .iter()
            .enumerate()
            .map(|(i, n)| (*n, l.model().parameter(i).unwrap()))
            .collect(),
    }
}

fn core_model<'a, M, const N: usize, const C: usize, const D: usize>(
    l: &Learned<M, N, C>,
    o: &'a Owned<N>,
    gps: &'a [ExportedGp<'a, D>; N],
) -> LearnedModel<'a, N, D>
where
    M: Mechanism<N, C> + Parameters + Clone,
{
    LearnedModel {
        mechanism: M::NAME,
        coordinates: M::COORDINATES,
        parameters: &o.parameters,
        dt: DT,
        encoding: match l.encoding() {
            Encoding::Raw => CoreEncoding::Raw,
            Encoding::SinCos => CoreEncoding::SinCos,
        },
        prior: match l.prior() {
            Prior::Nominal => CorePrior::Nominal,
            Prior::Constant => CorePrior::Constant,
        },
        project: l.projects(),
        // the options `Learned` uses for its nominal steps and projection
        options: StepOptions {
            tolerance: 1e-12,
            max_iterations: 100,
            min_step: 1.0 / 256.0,
            stall_tolerance: 1e-10,
        },
        gps,
    }
}

/// Rolls both out for `steps` from `z0`: max |difference| over the states.
fn compare<E, M, const N: usize, const C: usize, const D: usize>(
    std_model: &Learned<M, N, C>,
    embedded: &LearnedStepper<'_, E, N, C, D>,
    z0: &State<N>,
    steps: usize,
) -> f64
where
    M: Mechanism<N, C> + Clone,
    E: vigp::embedded::Dynamics<N, C> + Parameters,
{
    let reference = std_model.rollout(z0, steps).unwrap();
    let mut out = vec![*z0; steps];
    embedded.rollout_into(z0, &mut out).unwrap();
    reference[1..]
        .iter()
        .zip(&out)
        .map(|(a, b)| (a.q - b.q).amax().max((a.v - b.v).amax()))
        .fold(0.0, f64::max)
}

/// Tolerance 1e-12: both solve the same nominal step and projection to the
/// same scaled tolerance (1e-12) with Newton, which converges
/// quadratically, so they agree to rounding; the GP means agree bit for bit
/// (shared kernels) up to the last bit of sin/cos (libm on the embedded
/// side). Over 50 steps the differences stay at the 1e-14 level.
#[test]
fn learned_stepper_equals_the_std_learned_step() {
    // cart-pole: tree, nominal prior, sin/cos (5 inputs)
    let mut truth = Cartpole::default();
    truth.links.pole.mass *= 1.1;
    truth.joints.hinge.damping = 0.05;
    let q = positions(truth.minimal(), SVector::from([0.1, 2.0]), DT, 10, 80);
    let mut nominal = Cartpole::default();
    nominal.joints.rail.damping = 0.02;
    let (l, _) = Learned::train(
        nominal.minimal(),
        DT,
        &transitions(&q, DT),
        Encoding::SinCos,
        Prior::Nominal,
        &options(),
    )
    .unwrap();
    let o = owned(&l);
    let gps: [ExportedGp<'_, 5>; 2] = [
        o.arrays[0].as_exported().unwrap(),
        o.arrays[1].as_exported().unwrap(),
    ];
    let lm = core_model(&l, &o, &gps);
    // the stepper takes the parameters from the learned model, not the default
    let stepper = LearnedStepper::new(Cartpole::default(), &lm).unwrap();
    assert_eq!(stepper.nominal().model().joints.rail.damping, 0.02);
    let z0 = State {
        q: q[5],
        v: (q[6] - q[5]) / DT,
    };
    let diff = compare(&l, &stepper, &z0, 50);
    eprintln!("cartpole (sincos, nominal): max |std − embedded| over 50 steps = {diff:.2e}");
    assert!(diff <= 1e-12, "{diff:e}");
    let mut out = [z0; 50];
    let info = allocation_counter::measure(|| {
        stepper.rollout_into(&z0, &mut out).unwrap();
    });
    assert_eq!(info.count_total, 0, "the embedded learned step allocated");

    // fourbar: loops, projection, nominal prior, raw (8 inputs)
    let fb = Fourbar::default().minimal();
    let q = positions(fb, SVector::from([0.5, -0.9, -0.3, 0.9]), DT, 10, 60);
    let (lf, _) = Learned::train(
        fb,
        DT,
        &transitions(&q, DT),
        Encoding::Raw,
        Prior::Nominal,
        &options(),
    )
    .unwrap();
    assert!(lf.projects());
    let o = owned(&lf);
    let gps: [ExportedGp<'_, 8>; 4] = core::array::from_fn(|j| o.arrays[j].as_exported().unwrap());
    let lm = core_model(&lf, &o, &gps);
    let stepper = LearnedStepper::new(Fourbar::default(), &lm).unwrap();
    let z0 = State {
        q: q[7],
        v: (q[8] - q[7]) / DT,
    };
    let diff = compare(&lf, &stepper, &z0, 50);
    eprintln!("fourbar (raw, nominal, projected): max |std − embedded| over 50 steps = {diff:.2e}");
    assert!(diff <= 1e-12, "{diff:e}");
    let mut out = [z0; 50];
    let info = allocation_counter::measure(|| {
        stepper.rollout_into(&z0, &mut out).unwrap();
    });
    assert_eq!(info.count_total, 0, "the projected embedded step allocated");
    // and the constraints hold after projection
    let worst = out
        .iter()
        .map(|z| fb.constraint_violation(z))
        .fold(0.0, f64::max);
    assert!(worst < 1e-10, "{worst:e}");

    // pendulum: constant prior (the GP is the whole velocity map)
    let pm = Pendulum::default().minimal();
    let q = positions(pm, SVector::from([1.0]), DT, 10, 40);
    let (lp, _) = Learned::train(
        pm,
        DT,
        &transitions(&q, DT),
        Encoding::SinCos,
        Prior::Constant,
        &options(),
    )
    .unwrap();
    let o = owned(&lp);
    let gps: [ExportedGp<'_, 3>; 1] = [o.arrays[0].as_exported().unwrap()];
    let lm = core_model(&lp, &o, &gps);
    let stepper = LearnedStepper::new(Pendulum::default(), &lm).unwrap();
    let z0 = State {
        q: q[2],
        v: (q[3] - q[2]) / DT,
    };
    let diff = compare(&lp, &stepper, &z0, 50);
    eprintln!("pendulum (sincos, constant): max |std − embedded| over 50 steps = {diff:.2e}");
    assert!(diff <= 1e-12, "{diff:e}");

    // a learned model of another mechanism, or with another input dimension
    assert_eq!(
        LearnedStepper::new(
            Cartpole::default(),
            &LearnedModel {
                mechanism: "Pendulum",
                ..lm_cartpole_like(&lm)
            }
        )
        .err(),
        Some(LearnedError::WrongMechanism)
    );
}

/// A `LearnedModel<1, 3>` renamed: only used to build a mismatched model.
fn lm_cartpole_like<'a>(lm: &LearnedModel<'a, 1, 3>) -> LearnedModel<'a, 2, 3> {
    static NO_GPS: [ExportedGp<'static, 3>; 2] = [EMPTY_GP, EMPTY_GP];
    const EMPTY_GP: ExportedGp<'static, 3> = ExportedGp {
        inputs: &[],
        weights: &[],
        length_scales: [1.0; 3],
        signal_variance: 1.0,
        input_shift: [0.0; 3],
        input_scale: [1.0; 3],
        output_scale: 1.0,
        prior_mean: 0.0,
        cholesky: None,
    };
    LearnedModel {
        mechanism: "Cartpole",
        coordinates: ["rail", "hinge"],
        parameters: lm.parameters,
        dt: lm.dt,
        encoding: lm.encoding,
        prior: lm.prior,
        project: false,
        options: lm.options,
        gps: &NO_GPS,
    }
}

#[test]
fn mismatched_learned_models_are_refused() {
    // a model whose encoding needs 5 inputs given to GPs of 3: the type
    // says D = 3, the cart-pole's sin/cos encoding has 5 components
    let lm = lm_cartpole_like(&LearnedModel {
        mechanism: "Pendulum",
        coordinates: ["pivot"],
        parameters: &[],
        dt: DT,
        encoding: CoreEncoding::SinCos,
        prior: CorePrior::Nominal,
        project: false,
        options: StepOptions::default(),
        gps: &[ExportedGp {
            inputs: &[],
            weights: &[],
            length_scales: [1.0; 3],
            signal_variance: 1.0,
            input_shift: [0.0; 3],
            input_scale: [1.0; 3],
            output_scale: 1.0,
            prior_mean: 0.0,
            cholesky: None,
        }],
    });
    // no parameters at all: the first one is reported missing
    assert_eq!(
        LearnedStepper::new(Cartpole::default(), &lm).err(),
        Some(LearnedError::MissingParameter("gravity.x"))
    );
    let all: Vec<(&str, f64)> = Cartpole::PARAMETER_NAMES
        .iter()
        .enumerate()
        .map(|(i, n)| (*n, Cartpole::default().parameter(i).unwrap()))
        .collect();
    let lm = LearnedModel {
        parameters: &all,
        ..lm
    };
    assert_eq!(
        LearnedStepper::new(Cartpole::default(), &lm).err(),
        Some(LearnedError::InputDimension {
            expected: 5,
            got: 3
        })
    );
    let mut extra = all.clone();
    extra.push(("links.stick.mass", 1.0));
    let lm2 = LearnedModel {
        parameters: &extra,
        encoding: CoreEncoding::Raw,
        ..lm
    };
    assert_eq!(
        LearnedStepper::new(Cartpole::default(), &lm2).err(),
        Some(LearnedError::UnknownParameter(all.len()))
    );
}

/// The size of an export: N·(d + 1) numbers per velocity component for the
/// mean; the Cholesky factor only when asked.
#[test]
fn export_writes_only_what_the_mean_needs() {
    let q = positions(
        Cartpole::default().minimal(),
        SVector::from([0.1, 2.0]),
        DT,
        10,
        42,
    );
    let (l, _) = Learned::train(
        Cartpole::default().minimal(),
        DT,
        &transitions(&q, DT),
        Encoding::SinCos,
        Prior::Nominal,
        &options(),
    )
    .unwrap();
    let (src, size) = l.to_embedded_source(&EmbeddedExport::default()).unwrap();
    assert_eq!((size.n, size.input_dim, size.outputs), (40, 5, 2));
    // per output: N·(d+1) = 240 array numbers, 3d + 3 = 18 scalars
    assert_eq!(size.numbers, 2 * (240 + 18));
    assert_eq!(size.source_bytes, src.len());
    assert!(!src.contains("CHOLESKY"));
    assert!(
        src.contains("pub static LEARNED: vigp::embedded::learned::LearnedModel<'static, 2, 5>")
    );
    let (src_v, size_v) = l
        .to_embedded_source(&EmbeddedExport {
            variance: true,
            ..Default::default()
        })
        .unwrap();
    assert!(src_v.contains("CHOLESKY"));
    assert_eq!(size_v.numbers, size.numbers + 2 * 40 * 41 / 2);
    // maximal coordinates export too (the engine steps either view); the
    // embedded step of the maximal model equals the std one
    let qm: Vec<_> = q
        .iter()
        .map(|x| Cartpole::default().minimal().maximal_positions(x))
        .collect();
    let (lm, _) = Learned::train(
        Cartpole::default().maximal(),
        DT,
        &transitions(&qm, DT),
        Encoding::Raw,
        Prior::Constant,
        &options(),
    )
    .unwrap();
    assert!(lm.to_embedded_source(&EmbeddedExport::default()).is_ok());
    let o = owned(&lm);
    let gps: [ExportedGp<'_, 12>; 6] = core::array::from_fn(|j| o.arrays[j].as_exported().unwrap());
    let core_lm = core_model(&lm, &o, &gps);
    let stepper = LearnedStepper::new(Cartpole::default().maximal(), &core_lm).unwrap();
    let z0 = Cartpole::default().minimal().to_maximal(
        &State {
            q: q[5],
            v: (q[6] - q[5]) / DT,
        },
        DT,
    );
    let diff = compare(&lm, &stepper, &z0, 30);
    eprintln!("cartpole maximal (raw, constant, projected): max |std − embedded| = {diff:.2e}");
    assert!(diff <= 1e-12, "{diff:e}");
}

/// The source written by `vigp export` (tests/fixtures, regenerated by
/// `bash scripts/learned_fixture.sh`), compiled here.
#[allow(dead_code)]
mod exported {
    include!("fixtures/learned_cartpole.rs");
}

/// The exported source compiles, and its `LearnedStepper` equals the std
/// model loaded from the JSON it was exported from (same 1e-12 as above),
/// without allocating.
#[test]
fn exported_source_matches_the_model_file() {
    let json = include_str!("fixtures/learned_cartpole.json");
    let l: Learned<_, 2, 0> = Learned::from_json(Cartpole::default().minimal(), json).unwrap();
    let stepper = LearnedStepper::new(Cartpole::default(), &exported::LEARNED).unwrap();
    let z0 = State::new([0.05, 0.4], [0.1, -0.3]);
    let diff = compare(&l, &stepper, &z0, 30);
    eprintln!("exported fixture: max |std − embedded| over 30 steps = {diff:.2e}");
    assert!(diff <= 1e-12, "{diff:e}");
    let mut out = [z0; 30];
    let info = allocation_counter::measure(|| {
        stepper.rollout_into(&z0, &mut out).unwrap();
    });
    assert_eq!(info.count_total, 0);
}
