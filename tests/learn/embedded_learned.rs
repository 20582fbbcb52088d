//! `vigp::embedded::LearnedStepper` (no_std, no allocation) against the std
//! learned step: equal to 1e-12 along rollouts, for a tree with a nominal
//! prior and sin/cos encoding, a loop (projection) with a nominal prior, and
//! a constant prior; no heap allocation per step (counting allocator); the
//! generated source compiles (its statics are included here) and matches
//! the model file it was exported from. With inputs: the forced embedded
//! step and rollout against the std learned forced step on an actuated
//! cart-pole and an actuated four-bar (loop, projection), both encodings;
//! refusal of models whose inputs do not fit the mechanism; NaN inputs.

use crate::common;
use common::{positions, state_at};
use nalgebra::{SMatrix, SVector};
use vigp::embedded::gp::ExportedGp;
use vigp::embedded::learned::{Encoding as CoreEncoding, LearnedModel, Prior as CorePrior};
use vigp::embedded::{LearnedError, LearnedStepper, Parameters, StepError, StepOptions};
use vigp::gp::{ExportedArrays, TrainOptions};
use vigp::learned::{EmbeddedExport, Encoding, Learned, Prior, transitions};
use vigp::prelude::*;
use vigp::systems::{Cartpole, Fourbar, Pendulum};

const DT: f64 = 0.01;

fn options() -> TrainOptions {
    common::train_options(1, 11)
}

/// `Learned::train` with [`options`] on the transitions of the positions
/// `q` sampled every `DT`.
fn train_on<M, const N: usize, const C: usize>(
    m: M,
    q: &[SVector<f64, N>],
    encoding: Encoding,
    prior: Prior,
) -> Learned<M, N, C>
where
    M: Mechanism<N, C> + Parameters + Clone,
{
    Learned::train(m, DT, &transitions(q, DT), encoding, prior, &options())
        .unwrap()
        .0
}

/// The `K`-step rollout of `stepper` from `z0`, asserting that it
/// allocates nothing (`what` names it in the failure).
fn rollout_without_allocating<E, const N: usize, const C: usize, const D: usize, const K: usize>(
    stepper: &LearnedStepper<'_, E, N, C, D>,
    z0: &State<N>,
    what: &str,
) -> [State<N>; K]
where
    E: vigp::embedded::Dynamics<N, C> + Parameters,
{
    let mut out = [*z0; K];
    let info = allocation_counter::measure(|| {
        stepper.rollout_into(z0, &mut out).unwrap();
    });
    assert_eq!(info.count_total, 0, "{what}");
    out
}

/// `Learned::train_forced` with [`options`] on forced transitions at `DT`.
fn train_forced_on<M, const N: usize, const C: usize, const U: usize>(
    m: M,
    data: &[vigp::learned::ForcedTransition<N, U>],
    encoding: Encoding,
    prior: Prior,
) -> Learned<M, N, C>
where
    M: Mechanism<N, C> + Parameters + Clone + vigp::Inputs<U>,
{
    Learned::train_forced(m, DT, data, encoding, prior, &options())
        .unwrap()
        .0
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
        // the actuated joints' names when trained with inputs
        inputs: &M::INPUT_NAMES[..l.inputs()],
        parameters: &o.parameters,
        dt: DT,
        encoding: match l.encoding() {
            Encoding::Raw => CoreEncoding::Raw,
            Encoding::SinCos => CoreEncoding::SinCos,
        },
        prior: match l.prior() {
            Prior::Nominal | Prior::Identified(_) => CorePrior::Nominal,
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
    let l = train_on(nominal.minimal(), &q, Encoding::SinCos, Prior::Nominal);
    let o = owned(&l);
    let gps: [ExportedGp<'_, 5>; 2] = [
        o.arrays[0].as_exported().unwrap(),
        o.arrays[1].as_exported().unwrap(),
    ];
    let lm = core_model(&l, &o, &gps);
    // the stepper takes the parameters from the learned model, not the default
    let stepper = LearnedStepper::new(Cartpole::default(), &lm).unwrap();
    assert_eq!(stepper.nominal().model().joints.rail.damping, 0.02);
    let z0 = state_at(&q, 5, DT);
    let diff = compare(&l, &stepper, &z0, 50);
    eprintln!("cartpole (sincos, nominal): max |std − embedded| over 50 steps = {diff:.2e}");
    assert!(diff <= 1e-12, "{diff:e}");
    let _: [_; 50] =
        rollout_without_allocating(&stepper, &z0, "the embedded learned step allocated");

    // fourbar: loops, projection, nominal prior, raw (8 inputs)
    let fb = Fourbar::default().minimal();
    let q = positions(fb, SVector::from([0.5, -0.9, -0.3, 0.9]), DT, 10, 60);
    let lf = train_on(fb, &q, Encoding::Raw, Prior::Nominal);
    assert!(lf.projects());
    let o = owned(&lf);
    let gps: [ExportedGp<'_, 8>; 4] = core::array::from_fn(|j| o.arrays[j].as_exported().unwrap());
    let lm = core_model(&lf, &o, &gps);
    let stepper = LearnedStepper::new(Fourbar::default(), &lm).unwrap();
    let z0 = state_at(&q, 7, DT);
    let diff = compare(&lf, &stepper, &z0, 50);
    eprintln!("fourbar (raw, nominal, projected): max |std − embedded| over 50 steps = {diff:.2e}");
    assert!(diff <= 1e-12, "{diff:e}");
    let out: [_; 50] =
        rollout_without_allocating(&stepper, &z0, "the projected embedded step allocated");
    // and the constraints hold after projection
    let worst = out
        .iter()
        .map(|z| fb.constraint_violation(z))
        .fold(0.0, f64::max);
    assert!(worst < 1e-10, "{worst:e}");

    // pendulum: constant prior (the GP is the whole velocity map)
    let pm = Pendulum::default().minimal();
    let q = positions(pm, SVector::from([1.0]), DT, 10, 40);
    let lp = train_on(pm, &q, Encoding::SinCos, Prior::Constant);
    let o = owned(&lp);
    let gps: [ExportedGp<'_, 3>; 1] = [o.arrays[0].as_exported().unwrap()];
    let lm = core_model(&lp, &o, &gps);
    let stepper = LearnedStepper::new(Pendulum::default(), &lm).unwrap();
    let z0 = state_at(&q, 2, DT);
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

/// A GP of 3 inputs without training points (for mismatched models).
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

/// A `LearnedModel<1, 3>` renamed: only used to build a mismatched model.
fn lm_cartpole_like<'a>(lm: &LearnedModel<'a, 1, 3>) -> LearnedModel<'a, 2, 3> {
    static NO_GPS: [ExportedGp<'static, 3>; 2] = [EMPTY_GP, EMPTY_GP];
    LearnedModel {
        mechanism: "Cartpole",
        coordinates: ["rail", "hinge"],
        inputs: &[],
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
        inputs: &[],
        parameters: &[],
        dt: DT,
        encoding: CoreEncoding::SinCos,
        prior: CorePrior::Nominal,
        project: false,
        options: StepOptions::default(),
        gps: &[EMPTY_GP],
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
    let l = train_on(
        Cartpole::default().minimal(),
        &q,
        Encoding::SinCos,
        Prior::Nominal,
    );
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
    let lm = train_on(
        Cartpole::default().maximal(),
        &qm,
        Encoding::Raw,
        Prior::Constant,
    );
    assert!(lm.to_embedded_source(&EmbeddedExport::default()).is_ok());
    let o = owned(&lm);
    let gps: [ExportedGp<'_, 12>; 6] = core::array::from_fn(|j| o.arrays[j].as_exported().unwrap());
    let core_lm = core_model(&lm, &o, &gps);
    let stepper = LearnedStepper::new(Cartpole::default().maximal(), &core_lm).unwrap();
    let z0 = Cartpole::default()
        .minimal()
        .to_maximal(&state_at(&q, 5, DT), DT);
    let diff = compare(&lm, &stepper, &z0, 30);
    eprintln!("cartpole maximal (raw, constant, projected): max |std − embedded| = {diff:.2e}");
    assert!(diff <= 1e-12, "{diff:e}");
}

/// The source written by `vigp export` (tests/fixtures, regenerated by
/// `bash scripts/learned_fixture.sh`), compiled here.
#[allow(dead_code)]
mod exported {
    include!("../fixtures/learned_cartpole.rs");
}

/// The exported source compiles, and its `LearnedStepper` equals the std
/// model loaded from the JSON it was exported from (same 1e-12 as above),
/// without allocating.
#[test]
fn exported_source_matches_the_model_file() {
    let json = include_str!("../fixtures/learned_cartpole.json");
    let l: Learned<_, 2, 0> = Learned::from_json(Cartpole::default().minimal(), json).unwrap();
    let stepper = LearnedStepper::new(Cartpole::default(), &exported::LEARNED).unwrap();
    let z0 = State::new([0.05, 0.4], [0.1, -0.3]);
    let diff = compare(&l, &stepper, &z0, 30);
    eprintln!("exported fixture: max |std − embedded| over 30 steps = {diff:.2e}");
    assert!(diff <= 1e-12, "{diff:e}");
    let _: [_; 30] = rollout_without_allocating(&stepper, &z0, "the embedded rollout allocated");
}

/// The source `vigp export` writes for a 3-D mechanism (the Furuta
/// pendulum in its minimal coordinates; tests/fixtures, regenerated by
/// `bash scripts/learned_fixture.sh`), compiled here.
#[allow(dead_code)]
mod exported_furuta {
    include!("../fixtures/learned_furuta.rs");
}

/// The exported 3-D model compiles, and its `LearnedStepper` on the
/// minimal view equals the std model loaded from its JSON (1e-12, as
/// above), without allocating.
#[test]
fn exported_furuta_source_matches_the_model_file() {
    use vigp::systems::spatial::Furuta;
    let json = include_str!("../fixtures/learned_furuta.json");
    let m = Furuta::default().minimal();
    let l: Learned<_, 2, 0> = Learned::from_json(m, json).unwrap();
    let stepper = LearnedStepper::new(m, &exported_furuta::LEARNED).unwrap();
    let z0 = State::new([0.2, 1.0], [0.8, -1.5]);
    let diff = compare(&l, &stepper, &z0, 30);
    eprintln!("exported Furuta fixture: max |std − embedded| over 30 steps = {diff:.2e}");
    assert!(diff <= 1e-12, "{diff:e}");
    let _: [_; 30] = rollout_without_allocating(&stepper, &z0, "the embedded rollout allocated");
}

use crate::drive_cartpole::DriveCartpole;

use crate::drive_fourbar::DriveFourbar;

/// Transitions of `runs` forced trajectories of `truth` (first-order VI at
/// DT) from consistent states at rest near `q0`, under random
/// piecewise-constant inputs U[−amp, amp] held 10 steps.
fn forced_data<
    M: Mechanism<N, C> + Copy + vigp::Inputs<U>,
    const N: usize,
    const C: usize,
    const U: usize,
>(
    truth: M,
    q0: SVector<f64, N>,
    amp: f64,
    runs: usize,
    steps: usize,
    rng: &mut common::Rng,
) -> Vec<vigp::learned::ForcedTransition<N, U>> {
    use vigp::learned::forced_transitions;
    let vi = Variational::new(truth, DT).unwrap();
    let mut data = Vec::new();
    for _ in 0..runs {
        let start = q0 + SVector::from_fn(|_, _| rng.uniform(-0.1, 0.1));
        let mut z =
            vigp::projection::consistent_state(&truth, &start, &SVector::zeros(), DT).unwrap();
        let mut positions = vec![z.q];
        let mut logged = vec![SVector::<f64, U>::zeros()];
        let mut u = SVector::<f64, U>::zeros();
        for k in 0..steps {
            if k % 10 == 0 {
                u = SVector::from_fn(|_, _| rng.uniform(-amp, amp));
            }
            z = vi.step_forced(&z, &u).unwrap();
            positions.push(z.q);
            logged.push(u);
        }
        data.extend(forced_transitions(&positions, &logged, DT));
    }
    data
}

/// Forced steps and rollouts of the embedded stepper against the std
/// learned forced mean step, at states with random previous and current
/// inputs and along a 30-step rollout under a random input sequence after
/// a random previous input: max |difference|.
/// Also: the unforced `step` of both is the forced step under u = 0 (bit
/// for bit on the embedded side), the input changes the step, and the
/// forced rollout does not allocate.
fn compare_forced<E, M, const N: usize, const C: usize, const D: usize, const U: usize>(
    l: &Learned<M, N, C>,
    embedded: &LearnedStepper<'_, E, N, C, D>,
    z0: &State<N>,
    amp: f64,
    rng: &mut common::Rng,
) -> f64
where
    E: vigp::Inputs<U>,
    M: Mechanism<N, C> + Clone + vigp::Inputs<U>,
    E: vigp::embedded::Dynamics<N, C> + Parameters,
{
    let mut ws = l.workspace();
    let inputs: Vec<SVector<f64, U>> = (0..30)
        .map(|_| SVector::from_fn(|_, _| rng.uniform(-amp, amp)))
        .collect();
    let u_prev = SVector::<f64, U>::from_fn(|_, _| rng.uniform(-amp, amp));
    let mut reference = vec![*z0; 30];
    l.rollout_mean_forced_into(z0, &u_prev, &inputs, &mut reference)
        .unwrap();
    let mut out = [*z0; 30];
    embedded
        .rollout_forced_into(z0, &u_prev, &inputs, &mut out)
        .unwrap();
    // the Integrator trait's rollout takes the first input as the previous
    let mut held = vec![*z0; 30];
    l.rollout_forced_into(z0, &inputs, &mut held).unwrap();
    let mut explicit = vec![*z0; 30];
    l.rollout_mean_forced_into(z0, &inputs[0], &inputs, &mut explicit)
        .unwrap();
    assert_eq!(held, explicit);
    let diff = |a: &State<N>, b: &State<N>| (a.q - b.q).amax().max((a.v - b.v).amax());
    let mut worst = reference
        .iter()
        .zip(&out)
        .map(|(a, b)| diff(a, b))
        .fold(0.0, f64::max);
    let mut derivative_worst = 0.0f64;
    // single steps from the states of the rollout, under fresh inputs
    for z in out.iter().step_by(3) {
        let u = SVector::<f64, U>::from_fn(|_, _| rng.uniform(-amp, amp));
        let up = SVector::<f64, U>::from_fn(|_, _| rng.uniform(-amp, amp));
        let a = l.step_mean_forced_in(z, &up, &u, &mut ws).unwrap();
        let b = embedded.step_forced(z, &up, &u).unwrap();
        worst = worst.max(diff(&a, &b));
        // the input is used
        let free = embedded.step(z).unwrap();
        assert!((free.v - b.v).amax() > 1e-6, "{free:?} {b:?}");
        // unforced step = forced step under u = 0, on both sides
        let zero = SVector::<f64, U>::zeros();
        assert_eq!(free, embedded.step_forced(z, &zero, &zero).unwrap());
        // U = 0 is "no input" (u = 0), as for the nominal `Stepper`
        let none = SVector::<f64, 0>::zeros();
        assert_eq!(free, embedded.step_forced::<0>(z, &none, &none).unwrap());
        let std_free = l.step_mean_in(z, &mut ws).unwrap();
        assert_eq!(
            std_free,
            l.step_mean_forced_in(z, &zero, &zero, &mut ws).unwrap()
        );
        assert_eq!(
            std_free,
            l.step_mean_forced_in::<0>(z, &none, &none, &mut ws)
                .unwrap()
        );
        worst = worst.max(diff(&std_free, &free));
        // the exact derivatives: the embedded step's state is its own
        // step's, bit for bit, and A, B and B_prev are the std model's
        // (the same nominal derivatives and projection code, two
        // implementations of the GP gradient's sum), relative to the
        // largest entry of each. Tolerance 1e-9: the gradient sums terms
        // far larger than itself when the trained noise is small (under a
        // constant prior the GP carries the whole velocity), so two
        // orders of summation differ at ~1e-10 (measured 2.1e-10 there,
        // ≤ 5e-12 under the nominal prior; 6.1e-10 after the 6 chained
        // steps of the rollout derivatives below)
        let (z1, d, dp) = embedded.step_derivatives(z, &up, &u).unwrap();
        assert_eq!(z1, b);
        let (_, sd, sdp) = l.step_derivatives_forced(z, &up, &u, &mut ws).unwrap();
        let rel = |x: f64, scale: f64| x / scale.max(1e-300);
        let blocks = |a: &vigp::embedded::StateJacobian<N>| [a.q_q, a.q_v, a.v_q, a.v_v];
        let a_diff = |a: &vigp::embedded::StateJacobian<N>,
                      b: &vigp::embedded::StateJacobian<N>| {
            let (x, y) = (blocks(a), blocks(b));
            let d = (0..4).map(|i| (x[i] - y[i]).amax()).fold(0.0, f64::max);
            rel(d, y.iter().map(|m| m.amax()).fold(0.0, f64::max))
        };
        let ea = a_diff(&d.a, &sd.a);
        let eb = rel((d.b.v_u - sd.b.v_u).amax(), sd.b.v_u.amax());
        let ep = rel(
            (dp.v_u - sdp.v_u).amax(),
            sdp.v_u.amax().max(sd.b.v_u.amax()),
        );
        derivative_worst = derivative_worst.max(ea).max(eb).max(ep);
        // U = 0: A alone, the step under u = 0
        let (f1, fd, _) = embedded.step_derivatives::<0>(z, &none, &none).unwrap();
        assert_eq!(f1, free);
        let (_, sfd, _) = l
            .step_derivatives_forced::<0>(z, &none, &none, &mut ws)
            .unwrap();
        derivative_worst = derivative_worst.max(a_diff(&fd.a, &sfd.a));
    }
    // the 6-step rollout derivatives against the std model's
    const K: usize = 6;
    let (mut states, mut initial) = ([*z0; K], [vigp::embedded::StateJacobian::<N>::zeros(); K]);
    let mut wrt_u = [vigp::embedded::InputJacobian::<N, U>::zeros(); K * K];
    let rollout = |states: &mut [State<N>], initial: &mut [_], wrt_u: &mut [_]| {
        embedded.rollout_derivatives_into(
            z0,
            &u_prev,
            &inputs[..K],
            vigp::embedded::RolloutDerivativeBuffers {
                states,
                initial,
                inputs: wrt_u,
            },
        )
    };
    rollout(&mut states, &mut initial, &mut wrt_u).unwrap();
    assert_eq!(&states[..], &out[..K]);
    let sr = l
        .rollout_derivatives_forced(z0, &u_prev, &inputs[..K], &mut ws)
        .unwrap();
    for k in 0..K {
        let a = &sr.initial[k + 1];
        let scale = [a.q_q, a.q_v, a.v_q, a.v_v]
            .iter()
            .map(|m| m.amax())
            .fold(0.0, f64::max);
        let e = &initial[k];
        let diff = [e.q_q - a.q_q, e.q_v - a.q_v, e.v_q - a.v_q, e.v_v - a.v_v]
            .iter()
            .map(|m| m.amax())
            .fold(0.0, f64::max);
        derivative_worst = derivative_worst.max(diff / scale);
        let bscale = sr.inputs[k + 1]
            .iter()
            .map(|b| b.q_u.amax().max(b.v_u.amax()))
            .fold(0.0, f64::max);
        for j in 0..K {
            let (x, y) = (&wrt_u[k * K + j], &sr.inputs[k + 1][j]);
            let d = (x.q_u - y.q_u).amax().max((x.v_u - y.v_u).amax());
            if j > k {
                assert_eq!(d, 0.0, "u_{j} reached z_{}", k + 1);
            } else if U > 0 {
                derivative_worst = derivative_worst.max(d / bscale);
            }
        }
    }
    let info = allocation_counter::measure(|| {
        rollout(&mut states, &mut initial, &mut wrt_u).unwrap();
    });
    assert_eq!(
        info.count_total, 0,
        "the embedded rollout derivatives allocated"
    );
    // buffers of the wrong length are refused before any step
    let e = rollout(&mut states[..K - 1], &mut initial, &mut wrt_u).unwrap_err();
    assert!(
        matches!(
            e,
            (
                0,
                LearnedError::BufferLength {
                    name: "states",
                    expected: K,
                    got: 5
                }
            )
        ),
        "{e:?}"
    );
    eprintln!(
        "  step and rollout derivatives: max |std − embedded| / largest entry = {derivative_worst:.2e}"
    );
    assert!(derivative_worst <= 1e-9, "{derivative_worst:e}");
    let info = allocation_counter::measure(|| {
        embedded
            .rollout_forced_into(z0, &u_prev, &inputs, &mut out)
            .unwrap();
    });
    assert_eq!(info.count_total, 0, "the forced embedded step allocated");
    let zero = SVector::<f64, U>::zeros();
    let info = allocation_counter::measure(|| {
        embedded.step_derivatives(z0, &zero, &zero).unwrap();
    });
    assert_eq!(
        info.count_total, 0,
        "the embedded step derivatives allocated"
    );
    worst
}

/// The embedded forced learned step equals the std one to 1e-12 (the same
/// tolerance and reasoning as `learned_stepper_equals_the_std_learned_step`:
/// the same nominal forced step and projection solved to 1e-12 by Newton,
/// bit-identical GP means up to libm's sin/cos), on an actuated cart-pole
/// (sin/cos and raw encodings, nominal prior; raw also with a constant
/// prior) and on an actuated four-bar (a loop: projection; raw and sin/cos,
/// nominal prior).
#[test]
fn forced_learned_stepper_equals_the_std_forced_step() {
    let mut rng = common::Rng(5);
    // cart-pole: truth heavier with more friction than the nominal model
    let mut truth = DriveCartpole::default();
    truth.links.cart.mass *= 1.1;
    truth.links.pole.mass *= 1.1;
    truth.joints.rail.damping = 0.4;
    let data = forced_data::<_, 2, 0, 1>(
        truth.minimal(),
        SVector::from([0.0, 0.4]),
        3.0,
        3,
        50,
        &mut rng,
    );
    let data: Vec<_> = data.into_iter().step_by(2).collect();
    let nominal = DriveCartpole::default();
    let z0 = data[3].z;
    for (encoding, prior) in [
        (Encoding::SinCos, Prior::Nominal),
        (Encoding::Raw, Prior::Nominal),
        (Encoding::Raw, Prior::Constant),
    ] {
        let l = train_forced_on(nominal.minimal(), &data, encoding, prior.clone());
        assert_eq!(l.inputs(), 1);
        let o = owned(&l);
        let worst = match encoding {
            Encoding::SinCos => {
                // D = 5 (encoded state) + 2 (previous and current input)
                let gps: [ExportedGp<'_, 7>; 2] =
                    core::array::from_fn(|j| o.arrays[j].as_exported().unwrap());
                let lm = core_model(&l, &o, &gps);
                assert_eq!(lm.inputs, ["rail"]);
                let stepper = LearnedStepper::new(DriveCartpole::default(), &lm).unwrap();
                assert!(stepper.takes_previous_input());
                compare_forced::<_, _, 2, 0, 7, 1>(&l, &stepper, &z0, 3.0, &mut rng)
            }
            Encoding::Raw => {
                let gps: [ExportedGp<'_, 6>; 2] =
                    core::array::from_fn(|j| o.arrays[j].as_exported().unwrap());
                let lm = core_model(&l, &o, &gps);
                let stepper = LearnedStepper::new(DriveCartpole::default(), &lm).unwrap();
                compare_forced::<_, _, 2, 0, 6, 1>(&l, &stepper, &z0, 3.0, &mut rng)
            }
        };
        eprintln!("forced cartpole ({encoding:?}, {prior:?}): max |std − embedded| = {worst:.2e}");
        assert!(worst <= 1e-12, "{worst:e}");
    }

    // four-bar: a loop, predictions projected onto it
    let mut truth = DriveFourbar::default();
    truth.links.link1.mass *= 1.1;
    truth.joints.middle1.damping = 0.1;
    let q0 = SVector::from([0.5, -0.9, -0.3, 0.9]);
    let data = forced_data::<_, 4, 2, 2>(truth.minimal(), q0, 1.0, 3, 40, &mut rng);
    let data: Vec<_> = data.into_iter().step_by(2).collect();
    let nominal = DriveFourbar::default();
    let z0 = data[2].z;
    let z0 = vigp::projection::consistent_state(&nominal.minimal(), &z0.q, &z0.v, DT).unwrap();
    for encoding in [Encoding::Raw, Encoding::SinCos] {
        let l = train_forced_on(nominal.minimal(), &data, encoding, Prior::Nominal);
        assert!(l.projects());
        let o = owned(&l);
        let worst = match encoding {
            Encoding::Raw => {
                let gps: [ExportedGp<'_, 12>; 4] =
                    core::array::from_fn(|j| o.arrays[j].as_exported().unwrap());
                let lm = core_model(&l, &o, &gps);
                assert_eq!(lm.inputs, ["top1", "bottom"]);
                let stepper = LearnedStepper::new(DriveFourbar::default(), &lm).unwrap();
                compare_forced::<_, _, 4, 2, 12, 2>(&l, &stepper, &z0, 1.0, &mut rng)
            }
            Encoding::SinCos => {
                let gps: [ExportedGp<'_, 16>; 4] =
                    core::array::from_fn(|j| o.arrays[j].as_exported().unwrap());
                let lm = core_model(&l, &o, &gps);
                let stepper = LearnedStepper::new(DriveFourbar::default(), &lm).unwrap();
                let w = compare_forced::<_, _, 4, 2, 16, 2>(&l, &stepper, &z0, 1.0, &mut rng);
                // the projected forced rollout stays on the loop
                let mut out = [z0; 30];
                let inputs = [SVector::from([0.5, -0.5]); 30];
                stepper
                    .rollout_forced_into(&z0, &inputs[0], &inputs, &mut out)
                    .unwrap();
                let viol = out
                    .iter()
                    .map(|z| nominal.minimal().constraint_violation(z))
                    .fold(0.0, f64::max);
                assert!(viol < 1e-10, "{viol:e}");
                w
            }
        };
        eprintln!(
            "forced fourbar ({encoding:?}, nominal, projected): max |std − embedded| = {worst:.2e}"
        );
        assert!(worst <= 1e-12, "{worst:e}");
    }
}

/// Inputs that do not fit: a model whose inputs are not the mechanism's is
/// refused by name, by count and by GP dimension; NaN or ±∞ in u is a typed
/// error (never a NaN state), also inside a rollout (with its step index);
/// a rollout with fewer inputs than steps fails before stepping; a model
/// trained without inputs on an actuated mechanism takes u = 0 only.
#[test]
fn forced_models_that_do_not_fit_are_refused() {
    use vigp::learned::Learned;
    let mut rng = common::Rng(8);
    let data = forced_data::<_, 2, 0, 1>(
        DriveCartpole::default().minimal(),
        SVector::from([0.0, 0.4]),
        3.0,
        1,
        40,
        &mut rng,
    );
    let l = train_forced_on(
        DriveCartpole::default().minimal(),
        &data,
        Encoding::Raw,
        Prior::Nominal,
    );
    let o = owned(&l);
    let gps: [ExportedGp<'_, 6>; 2] = core::array::from_fn(|j| o.arrays[j].as_exported().unwrap());
    let lm = core_model(&l, &o, &gps);
    let refused =
        |m: &LearnedModel<'_, 2, 6>| LearnedStepper::new(DriveCartpole::default(), m).err();
    assert_eq!(refused(&lm), None);
    assert_eq!(
        refused(&LearnedModel {
            inputs: &["hinge"],
            ..lm
        }),
        Some(LearnedError::UnknownInput(0))
    );
    assert_eq!(
        refused(&LearnedModel {
            inputs: &["rail", "hinge"],
            ..lm
        }),
        Some(LearnedError::InputCount {
            expected: 1,
            got: 2
        })
    );
    // without its inputs the model's GPs take two numbers too many
    assert_eq!(
        refused(&LearnedModel { inputs: &[], ..lm }),
        Some(LearnedError::InputDimension {
            expected: 4,
            got: 6
        })
    );
    // the unactuated cart-pole has no input to give
    let cartpole_params: Vec<(&str, f64)> = Cartpole::PARAMETER_NAMES
        .iter()
        .enumerate()
        .map(|(i, n)| (*n, Cartpole::default().parameter(i).unwrap()))
        .collect();
    let for_cartpole = LearnedModel {
        mechanism: "Cartpole",
        parameters: &cartpole_params,
        ..lm
    };
    assert_eq!(
        LearnedStepper::new(Cartpole::default(), &for_cartpole).err(),
        Some(LearnedError::InputCount {
            expected: 0,
            got: 1
        })
    );

    let stepper = LearnedStepper::new(DriveCartpole::default(), &lm).unwrap();
    let z = data[5].z;
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let ok = SVector::from([0.5]);
        assert_eq!(
            stepper.step_forced(&z, &ok, &SVector::from([bad])),
            Err(LearnedError::Step(StepError::NonFiniteInput { step: None }))
        );
        assert_eq!(
            stepper.step_forced(&z, &SVector::from([bad]), &ok),
            Err(LearnedError::Step(StepError::NonFiniteInput { step: None }))
        );
        for (up, u) in [(ok, SVector::from([bad])), (SVector::from([bad]), ok)] {
            assert_eq!(
                stepper.step_derivatives(&z, &up, &u).map(drop),
                Err(LearnedError::Step(StepError::NonFiniteInput { step: None }))
            );
        }
        let mut inputs = [ok; 10];
        inputs[4] = SVector::from([bad]);
        let mut out = [z; 10];
        assert_eq!(
            stepper.rollout_forced_into(&z, &ok, &inputs, &mut out),
            Err((
                4,
                LearnedError::Step(StepError::NonFiniteInput { step: None })
            ))
        );
        assert_eq!(
            stepper.rollout_forced_into(&z, &SVector::from([bad]), &[ok; 10], &mut out),
            Err((
                0,
                LearnedError::Step(StepError::NonFiniteInput { step: None })
            ))
        );
        assert!(out.iter().all(|s| s.is_finite()));
    }
    let mut out = [z; 10];
    assert_eq!(
        stepper.rollout_forced_into(
            &z,
            &SVector::from([0.5]),
            &[SVector::from([0.5]); 9],
            &mut out
        ),
        Err((
            9,
            LearnedError::Step(StepError::NonFiniteInput { step: None })
        ))
    );
    assert!(out.iter().all(|s| *s == z), "stepped before failing");

    // trained without inputs on the actuated mechanism: u = 0 only
    let plain: Vec<_> = data
        .iter()
        .map(|t| vigp::learned::Transition {
            z: t.z,
            v_next: t.v_next,
        })
        .collect();
    let (l0, _) = Learned::train(
        DriveCartpole::default().minimal(),
        DT,
        &plain,
        Encoding::Raw,
        Prior::Nominal,
        &options(),
    )
    .unwrap();
    let o0 = owned(&l0);
    let gps0: [ExportedGp<'_, 4>; 2] =
        core::array::from_fn(|j| o0.arrays[j].as_exported().unwrap());
    let lm0 = core_model(&l0, &o0, &gps0);
    assert!(lm0.inputs.is_empty());
    let s0 = LearnedStepper::new(DriveCartpole::default(), &lm0).unwrap();
    let zero = SVector::from([0.0]);
    assert_eq!(
        s0.step_forced(&z, &zero, &zero).unwrap(),
        s0.step(&z).unwrap()
    );
    assert_eq!(
        s0.step_forced(&z, &zero, &SVector::from([1.0])),
        Err(LearnedError::NoInputs)
    );
    // no derivative in an input the model does not take; A alone under U = 0
    assert_eq!(
        s0.step_derivatives(&z, &zero, &zero).map(drop),
        Err(LearnedError::NoInputs)
    );
    let none = SVector::<f64, 0>::zeros();
    assert_eq!(
        s0.step_derivatives(&z, &none, &none).unwrap().0,
        s0.step(&z).unwrap()
    );
    // as the std side: u = 0 is the unforced step, anything else refused
    let mut ws = l0.workspace();
    let a = vigp::Integrator::step_forced(&l0, &z, &SVector::from([0.0])).unwrap();
    let b = l0.step_mean_in(&z, &mut ws).unwrap();
    assert_eq!(a, b);
    assert!(vigp::Integrator::step_forced(&l0, &z, &SVector::from([1.0])).is_err());
    let d = s0.step(&z).unwrap();
    assert!((a.q - d.q).amax().max((a.v - d.v).amax()) <= 1e-12);
}

/// The source `vigp export` writes for a model trained with inputs
/// (tests/fixtures, regenerated by `bash scripts/learned_fixture.sh`, which
/// runs examples/learned_forced_fixture.rs), compiled here.
#[allow(dead_code)]
mod exported_forced {
    include!("../fixtures/learned_drive_cartpole.rs");
}

/// A model file and its export in the GP input layout (enc(z), u), without
/// the previous input (`previous_input` absent from the file): the format
/// every such file keeps loading as.
#[allow(dead_code)]
mod exported_forced_enc_u {
    include!("../fixtures/learned_drive_cartpole_enc_u.rs");
}

/// 30 std and embedded forced steps of `l` and `stepper` from one state
/// after `u_prev`: max |difference| (and the embedded rollout does not
/// allocate).
fn fixture_rollouts<M: Mechanism<2, 0> + Clone + vigp::Inputs<1>, const D: usize>(
    l: &Learned<M, 2, 0>,
    stepper: &LearnedStepper<'_, DriveCartpole, 2, 0, D>,
    u_prev: &SVector<f64, 1>,
) -> ([State<2>; 30], f64) {
    let z0 = State::new([0.05, 0.4], [0.1, -0.3]);
    let inputs: [SVector<f64, 1>; 30] =
        core::array::from_fn(|k| SVector::from([2.0 * (0.3 * k as f64).sin()]));
    let mut reference = [z0; 30];
    l.rollout_mean_forced_into(&z0, u_prev, &inputs, &mut reference)
        .unwrap();
    let mut out = [z0; 30];
    let info = allocation_counter::measure(|| {
        stepper
            .rollout_forced_into(&z0, u_prev, &inputs, &mut out)
            .unwrap();
    });
    assert_eq!(info.count_total, 0);
    let diff = reference
        .iter()
        .zip(&out)
        .map(|(a, b)| (a.q - b.q).amax().max((a.v - b.v).amax()))
        .fold(0.0, f64::max);
    // the input drives the prediction
    let mut free = [z0; 30];
    stepper.rollout_into(&z0, &mut free).unwrap();
    assert!((free[29].q - out[29].q).amax() > 1e-3);
    (out, diff)
}

/// The exported forced model compiles, records its input, takes the
/// previous input (D = 5 + 2), and its forced rollout equals the std model
/// loaded from the JSON it was exported from (1e-12, as above), without
/// allocating.
#[test]
fn exported_forced_source_matches_the_model_file() {
    let json = include_str!("../fixtures/learned_drive_cartpole.json");
    let l: Learned<_, 2, 0> = Learned::from_json(DriveCartpole::default().minimal(), json).unwrap();
    assert_eq!(l.inputs(), 1);
    assert!(l.takes_previous_input());
    assert!(json.contains("\"previous_input\": true"));
    assert_eq!(exported_forced::LEARNED.inputs, ["rail"]);
    let stepper = LearnedStepper::new(DriveCartpole::default(), &exported_forced::LEARNED).unwrap();
    assert!(stepper.takes_previous_input());
    let (a, diff) = fixture_rollouts(&l, &stepper, &SVector::from([0.0]));
    eprintln!("exported forced fixture: max |std − embedded| over 30 steps = {diff:.2e}");
    assert!(diff <= 1e-12, "{diff:e}");
    let (b, diff) = fixture_rollouts(&l, &stepper, &SVector::from([2.0]));
    assert!(diff <= 1e-12, "{diff:e}");
    // the previous input enters the first step
    assert!((a[0].v - b[0].v).amax() > 0.0);
}

/// A model file without `previous_input` (GP input (enc(z), u)) loads as
/// that layout on both sides: D = 5 + 1, the previous input is ignored,
/// and std and embedded agree to 1e-12.
#[test]
fn forced_model_files_without_the_previous_input_load_as_their_layout() {
    let json = include_str!("../fixtures/learned_drive_cartpole_enc_u.json");
    assert!(!json.contains("previous_input"));
    let l: Learned<_, 2, 0> = Learned::from_json(DriveCartpole::default().minimal(), json).unwrap();
    assert_eq!(l.inputs(), 1);
    assert!(!l.takes_previous_input());
    assert_eq!(l.gp().input_dim(), 6);
    let stepper =
        LearnedStepper::new(DriveCartpole::default(), &exported_forced_enc_u::LEARNED).unwrap();
    assert!(!stepper.takes_previous_input());
    let (a, diff) = fixture_rollouts(&l, &stepper, &SVector::from([0.0]));
    eprintln!("exported (enc(z), u) fixture: max |std − embedded| over 30 steps = {diff:.2e}");
    assert!(diff <= 1e-12, "{diff:e}");
    let (b, _) = fixture_rollouts(&l, &stepper, &SVector::from([2.0]));
    assert_eq!(a, b);
    // the file saves back in its own layout
    let back = l.to_json();
    assert!(!back.contains("previous_input"));
    let again: Learned<_, 2, 0> =
        Learned::from_json(DriveCartpole::default().minimal(), &back).unwrap();
    assert!(!again.takes_previous_input());
    // and claiming the previous input for it is a typed error naming the GP
    // input dimension
    let claimed = json.replacen(
        "\"inputs\": [",
        "\"previous_input\": true,\n  \"inputs\": [",
        1,
    );
    let e = Learned::<_, 2, 0>::from_json(DriveCartpole::default().minimal(), &claimed)
        .err()
        .unwrap();
    assert!(e.to_string().contains("gp.input_dim"), "{e}");
}

/// The source `vigp export` writes for a learned robot (`fit --urdf` on
/// the test arm with its elbow actuated; tests/fixtures, regenerated by
/// `bash scripts/learned_fixture.sh`), compiled here.
#[allow(dead_code)]
mod exported_arm {
    include!("../fixtures/learned_arm3.rs");
}

/// The learned robot of tests/fixtures/learned_arm3.json.
fn arm3_model() -> vigp::learned::robot::LearnedRobot {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/learned_arm3.json"
    );
    vigp::learned::robot::LearnedRobot::load(path).unwrap()
}

/// A state as the std robot's state.
fn robot_state<const N: usize>(z: &State<N>) -> vigp::robot::RobotState {
    vigp::robot::RobotState::new(z.q.as_slice().to_vec(), z.v.as_slice().to_vec())
}

/// The exported learned robot (`LearnedTreeStepper` over `LearnedTree`)
/// against the std `LearnedRobot` loaded from the JSON it was exported
/// from, over 30 steps under inputs: both run the same tree engine on the
/// same bodies, and the GP means are two implementations of one sum, so
/// they agree to 1e-12 (as the declared mechanisms' exports above;
/// measured: bit for bit). The
/// fixture is what `to_embedded_source` writes for that JSON now, byte
/// for byte; the embedded rollout allocates nothing; wrong inputs are
/// typed errors.
#[test]
fn exported_learned_robot_matches_the_model_file() {
    use vigp::embedded::tree::{BodyScratch, LearnedTreeStepper};
    let std_model = arm3_model();
    let (src, _) = std_model
        .to_embedded_source(&EmbeddedExport {
            name: "LEARNED_ARM".into(),
            header: vec!["exported by `vigp export` from learned_arm3.json".into()],
            ..EmbeddedExport::default()
        })
        .unwrap();
    assert!(
        src == include_str!("../fixtures/learned_arm3.rs"),
        "tests/fixtures/learned_arm3.rs is stale: bash scripts/learned_fixture.sh"
    );
    let stepper = LearnedTreeStepper::new(&exported_arm::LEARNED_ARM).unwrap();
    let mut ws = [BodyScratch::zeroed(); 3];
    let us: Vec<SVector<f64, 1>> = (0..30)
        .map(|k| SVector::from([3.0 + (0.2 * k as f64).sin()]))
        .collect();
    let u_prev = SVector::from([3.1]);
    let z0 = State::new([0.1, -0.2, 0.05], [0.3, -0.4, 0.02]);
    let mut out = [z0; 30];
    stepper
        .rollout_into(&z0, &u_prev, &us, &mut out, &mut ws)
        .unwrap();
    let plan: Vec<Vec<f64>> = us.iter().map(|u| vec![u[0]]).collect();
    let std_states = std_model
        .rollout(&robot_state(&z0), &[u_prev[0]], &plan)
        .unwrap();
    let mut diff = 0.0f64;
    for (a, b) in out.iter().zip(&std_states) {
        for (x, y) in a.q.iter().chain(a.v.iter()).zip(b.q.iter().chain(&b.v)) {
            diff = diff.max((x - y).abs());
        }
    }
    eprintln!("exported learned robot: max |std − embedded| over 30 steps = {diff:.2e}");
    assert!(diff <= 1e-12, "{diff:e}");
    let info = allocation_counter::measure(|| {
        stepper
            .rollout_into(&z0, &u_prev, &us, &mut out, &mut ws)
            .unwrap();
    });
    assert_eq!(info.count_total, 0);
    // the model takes one input; NaN is refused
    assert!(matches!(
        stepper.step(&z0, &SVector::<f64, 0>::zeros(), &SVector::zeros(), &mut ws),
        Err(LearnedError::InputCount {
            expected: 1,
            got: 0
        })
    ));
    assert!(matches!(
        stepper.step(&z0, &u_prev, &SVector::from([f64::NAN]), &mut ws),
        Err(LearnedError::Step(StepError::NonFiniteInput { step: None }))
    ));
}

/// The exact derivatives of the exported learned robot's step
/// (`LearnedTreeStepper::step_derivatives`) against the std
/// `LearnedRobot::step_derivatives` of the model file it was exported
/// from, at five states of a driven rollout. The std derivatives are
/// checked against differences of the step (tests of
/// vigp-runtime/tests/learned_robot.rs); here the two share the tree
/// engine's derivative code and differ in the GP mean's gradient (two
/// implementations of one sum over the training points) and in the
/// matrix types, so they agree to rounding: 1e-10 of the largest entry
/// (measured: printed). The derivative step allocates nothing.
#[test]
fn exported_learned_robot_derivatives_match_the_model_file() {
    use vigp::embedded::tree::{BodyScratch, LearnedTreeStepper, TreeDerivativeScratch};
    let std_model = arm3_model();
    let stepper = LearnedTreeStepper::new(&exported_arm::LEARNED_ARM).unwrap();
    let mut ws = [BodyScratch::zeroed(); 3];
    let mut scratch = TreeDerivativeScratch::<3>::new();
    let mut std_ws = std_model.workspace();
    let mut z = State::new([0.1, -0.2, 0.05], [0.3, -0.4, 0.02]);
    let mut u_prev = SVector::from([3.1]);
    let mut worst = 0.0f64;
    for k in 0..5 {
        let u = SVector::from([3.0 + (0.7 * k as f64).sin()]);
        let d = stepper
            .step_derivatives(&z, &u_prev, &u, &mut scratch, &mut ws)
            .unwrap();
        let zs = robot_state(&z);
        let s = std_model
            .step_derivatives(&zs, &[u_prev[0]], &[u[0]], &mut std_ws)
            .unwrap();
        let a: SMatrix<f64, 6, 6> = d.a.matrix();
        let b: SMatrix<f64, 6, 1> = d.b.matrix();
        let bp: SMatrix<f64, 6, 1> = d.b_prev.matrix();
        let scale = s.a.iter().chain(&s.b).fold(1.0f64, |m, x| m.max(x.abs()));
        for r in 0..6 {
            for c in 0..6 {
                worst = worst.max((a[(r, c)] - s.a[(r, c)]).abs() / scale);
            }
            worst = worst.max((b[(r, 0)] - s.b[(r, 0)]).abs() / scale);
            worst = worst.max((bp[(r, 0)] - s.b_prev[(r, 0)]).abs() / scale);
        }
        let next: Vec<f64> = d.state.q.iter().chain(d.state.v.iter()).copied().collect();
        let want: Vec<f64> = s.state.q.iter().chain(&s.state.v).copied().collect();
        for (x, y) in next.iter().zip(&want) {
            assert!((x - y).abs() <= 1e-12, "state {next:?} vs {want:?}");
        }
        // the GP reads both inputs and the state: none of these is zero
        assert!(d.b_prev.v_u.iter().any(|x| *x != 0.0));
        assert!(d.a.v_q.iter().any(|x| *x != 0.0));
        z = d.state;
        u_prev = u;
    }
    // the 5-step rollout derivatives against the std robot's per-step
    // derivatives chained (∂z_{k+1}/∂u_j = A_k ∂z_k/∂u_j + [j = k] B_k +
    // [j = k − 1] B_prev,k)
    const K: usize = 5;
    let z0 = State::new([0.1, -0.2, 0.05], [0.3, -0.4, 0.02]);
    let up0 = SVector::from([3.1]);
    let plan: Vec<SVector<f64, 1>> = (0..K)
        .map(|k| SVector::from([3.0 + (0.7 * k as f64).sin()]))
        .collect();
    let mut states = [z0; K];
    let mut initial = [vigp::embedded::StateJacobian::<3>::zeros(); K];
    let mut wrt_u = [vigp::embedded::InputJacobian::<3, 1>::zeros(); K * K];
    let mut rollout = |scratch: &mut TreeDerivativeScratch<3>, ws: &mut [BodyScratch; 3]| {
        let buffers = vigp::embedded::RolloutDerivativeBuffers {
            states: &mut states,
            initial: &mut initial,
            inputs: &mut wrt_u,
        };
        stepper
            .rollout_derivatives_into(&z0, &up0, &plan, buffers, scratch, ws)
            .unwrap();
    };
    rollout(&mut scratch, &mut ws);
    let info = allocation_counter::measure(|| rollout(&mut scratch, &mut ws));
    assert_eq!(info.count_total, 0, "the rollout derivatives allocated");
    let zs = robot_state(&z0);
    let plan_std: Vec<Vec<f64>> = plan.iter().map(|u| vec![u[0]]).collect();
    let steps = std_model
        .rollout_derivatives(&zs, &[up0[0]], &plan_std, &mut std_ws)
        .unwrap();
    let mut chained = nalgebra::DMatrix::<f64>::identity(6, 6);
    let mut chained_u = vec![nalgebra::DMatrix::<f64>::zeros(6, 1); K];
    let mut rollout_worst = 0.0f64;
    for (k, d) in steps.iter().enumerate() {
        chained = &d.a * &chained;
        for (j, b) in chained_u.iter_mut().enumerate().take(k + 1) {
            *b = &d.a * &*b;
            if j == k {
                *b += &d.b;
            } else if j + 1 == k {
                *b += &d.b_prev;
            }
        }
        let a: SMatrix<f64, 6, 6> = initial[k].matrix();
        let scale = chained.amax();
        rollout_worst = rollout_worst.max((a - &chained).amax() / scale);
        let bscale = chained_u.iter().map(|b| b.amax()).fold(0.0, f64::max);
        for j in 0..K {
            let b: SMatrix<f64, 6, 1> = wrt_u[k * K + j].matrix();
            if j > k {
                assert_eq!(b.amax(), 0.0);
            } else {
                rollout_worst = rollout_worst.max((b - &chained_u[j]).amax() / bscale);
            }
        }
    }
    eprintln!(
        "exported learned robot derivatives: max |std − embedded| / scale = {worst:.2e} \
         (steps), {rollout_worst:.2e} ({K}-step rollout)"
    );
    assert!(worst <= 1e-10, "{worst:e}");
    assert!(rollout_worst <= 1e-10, "{rollout_worst:e}");
    let u = SVector::from([3.2]);
    let info = allocation_counter::measure(|| {
        stepper
            .step_derivatives(&z, &u_prev, &u, &mut scratch, &mut ws)
            .unwrap();
    });
    assert_eq!(info.count_total, 0);
    assert!(matches!(
        stepper.step_derivatives(
            &z,
            &u_prev,
            &SVector::from([f64::NAN]),
            &mut scratch,
            &mut ws
        ),
        Err(LearnedError::Step(StepError::NonFiniteInput { step: None }))
    ));
}
