//! Cartpole swing-up by iLQR on a nominal and on a learned model, executed
//! on perturbed "true" systems.
//!
//! ```sh
//! cargo run --release --example control            # 20 true systems
//! cargo run --release --example control -- 40      # another count
//! ```
//!
//! For each random true system (masses and inertias ×U[0.9, 1.1], rail and
//! hinge friction, as in the paper's experiments):
//!
//! 1. **Nominal controller.** iLQR on the nominal model (the DSL's values,
//!    no friction) with the exact step derivatives A = ∂z₁/∂z₀ and
//!    B = ∂z₁/∂u of the variational integrator
//!    (`Variational::step_derivatives`) plans a swing-up; the plan is
//!    executed on the true system with iLQR's time-varying feedback gains.
//! 2. **Learned controller.** Six trajectories of the true system under the
//!    nominal plan's feedback law plus random piecewise-constant forces
//!    (exploration around the task) train a learned integrator
//!    (`Learned::train_forced`: nominal forced step + GP on state and
//!    input); iLQR on the learned model (started from the nominal plan's
//!    feedback policy run on the learned model) with the learned step's
//!    exact derivatives (`Learned::step_derivatives_forced`) plans again,
//!    executed the same way.
//!
//! 3. **Bounded predictions.** From every 25th state of the learned
//!    controller's executed trajectory, the learned model predicts the next
//!    `HORIZON` steps under the inputs that were applied, each state with
//!    its conformal error bound (`Learned::predict_forced`, calibrated by
//!    `Learned::error_bound_forced` on two held-out exploration runs of the
//!    true system, `Calibration::from_trajectories_forced`), and the report
//!    states how often the true trajectory stayed inside.
//!
//! Prints and writes (`target/control/`) a markdown report with the
//! closed-loop cost, the final error, failures and planning time of both,
//! the bounds' coverage, and figures (SVG + PNG): a typical run and the
//! cost distribution.

#[path = "common/font.rs"]
mod font;

use font::{FONT, register_embedded_font};
use std::cell::RefCell;
use std::error::Error;
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use nalgebra::{SMatrix, SVector};
use plotters::prelude::*;
use vigp::bound::{BoundError, BoundKind, Calibration, ErrorBound};
use vigp::gp::{TrainOptions, Workspace};
use vigp::learned::{Encoding, Learned, Prior, forced_transitions};
use vigp::{State, Variational};

vigp::mechanism! {
    /// The paper's cartpole (1 kg cart, 1 kg × 1 m pole) pushed along its
    /// rail; friction is a run-time parameter (declared 0).
    pub DrivenCartpole {
        gravity: [0.0, -9.81],
        links {
            cart: { mass: 1.0, length: 1.0 },
            pole: { mass: 1.0, length: 1.0 },
        }
        joints {
            rail: prismatic(world, cart.center) { axis: [1.0, 0.0], damping: 0.0, actuated },
            hinge: revolute(cart.center, pole.start) { damping: 0.0 },
        }
    }
}

type View = DrivenCartpoleMinimal;
type Z = SVector<f64, 4>;
type A = SMatrix<f64, 4, 4>;

const DT: f64 = 0.02;
const STEPS: usize = 150;
/// Steps of the bounded predictions along the executed trajectory (0.5 s).
const HORIZON: usize = 25;

fn stack(z: &State<2>) -> Z {
    Z::new(z.q[0], z.q[1], z.v[0], z.v[1])
}

fn unstack(x: &Z) -> State<2> {
    State::new([x[0], x[1]], [x[2], x[3]])
}

/// Upright, cart at the origin, at rest.
fn goal() -> Z {
    Z::new(0.0, std::f64::consts::PI, 0.0, 0.0)
}

/// Quadratic cost ½dxᵀQdx + ½ru² per step and ½dxᵀQ_f dx at the end.
struct Cost {
    q: A,
    r: f64,
    qf: A,
}

impl Cost {
    fn new() -> Self {
        Self {
            q: A::from_diagonal(&Z::new(1.0, 2.0, 0.1, 0.1)) * DT,
            r: 0.02 * DT,
            qf: A::from_diagonal(&Z::new(50.0, 200.0, 20.0, 20.0)),
        }
    }
    fn stage(&self, z: &Z, u: f64) -> f64 {
        let d = z - goal();
        0.5 * d.dot(&(self.q * d)) + 0.5 * self.r * u * u
    }
    fn terminal(&self, z: &Z) -> f64 {
        let d = z - goal();
        0.5 * d.dot(&(self.qf * d))
    }
}

/// A model iLQR plans on: a step and its linearization.
trait Model {
    fn step(&self, z: &Z, u: f64) -> Option<Z>;
    fn linearize(&self, z: &Z, u: f64) -> Option<(A, Z)>;
}

struct Nominal(Variational<View, 2, 0>);

impl Model for Nominal {
    fn step(&self, z: &Z, u: f64) -> Option<Z> {
        self.0
            .step_forced(&unstack(z), &SVector::<f64, 1>::new(u))
            .ok()
            .map(|z| stack(&z))
    }
    /// The exact A and B (implicit function theorem on the DEL equations).
    fn linearize(&self, z: &Z, u: f64) -> Option<(A, Z)> {
        let (_, d) = self
            .0
            .step_derivatives(&unstack(z), &SVector::<f64, 1>::new(u))
            .ok()?;
        Some((d.a.matrix::<4>(), d.b.matrix::<4>().column(0).into_owned()))
    }
}

struct LearnedModel(Learned<View, 2, 0>, RefCell<Workspace>);

/// The planner's model is a map of (z, u): the learned step takes the
/// input as held across the start (u_prev = u). The truth here is the
/// first-order VI, whose next velocity does not depend on the previous
/// input.
impl Model for LearnedModel {
    fn step(&self, z: &Z, u: f64) -> Option<Z> {
        let u = SVector::<f64, 1>::new(u);
        self.0
            .step_mean_forced_in(&unstack(z), &u, &u, &mut self.1.borrow_mut())
            .ok()
            .map(|z| stack(&z))
    }
    /// The exact derivatives of the learned step (nominal forced step's
    /// A, B plus the GP mean's gradient through the encoding).
    /// With u_prev = u, ∂z₁/∂u is B + B_prev.
    fn linearize(&self, z: &Z, u: f64) -> Option<(A, Z)> {
        let u = SVector::<f64, 1>::new(u);
        let (_, d, dp) = self
            .0
            .step_derivatives_forced(&unstack(z), &u, &u, &mut self.1.borrow_mut())
            .ok()?;
        let b = d.b.matrix::<4>().column(0) + dp.matrix::<4>().column(0);
        Some((d.a.matrix::<4>(), b))
    }
}

/// A plan: states, inputs and feedback gains.
struct Plan {
    xs: Vec<Z>,
    us: Vec<f64>,
    gains: Vec<SMatrix<f64, 1, 4>>,
    cost: f64,
}

impl Plan {
    /// The plan's feedback law at step k: u_k + K_k·(z − x_k).
    fn policy(&self, k: usize, z: &Z) -> f64 {
        self.us[k] + (self.gains[k] * (z - self.xs[k]))[0]
    }
}

fn rollout(model: &dyn Model, z0: &Z, us: &[f64], cost: &Cost) -> Option<(Vec<Z>, f64)> {
    let mut xs = vec![*z0];
    let mut j = 0.0;
    for &u in us {
        let z = *xs.last()?;
        j += cost.stage(&z, u);
        let next = model.step(&z, u)?;
        if !next.iter().all(|x| x.is_finite()) {
            return None;
        }
        xs.push(next);
    }
    j += cost.terminal(xs.last()?);
    Some((xs, j))
}

/// iLQR (Levenberg–Marquardt regularised backward pass, backtracking
/// forward pass).
fn ilqr(
    model: &dyn Model,
    z0: &Z,
    init: Option<&Plan>,
    cost: &Cost,
    iterations: usize,
) -> Option<Plan> {
    // start from zero inputs, or from another plan's feedback policy run on
    // this model (its open-loop inputs would diverge on a different model)
    let mut us = match init {
        None => vec![0.0; STEPS],
        Some(p) => {
            let mut z = *z0;
            let mut us = Vec::with_capacity(STEPS);
            for k in 0..STEPS {
                let u = p.policy(k, &z);
                us.push(u);
                z = model.step(&z, u)?;
            }
            us
        }
    };
    let (mut xs, mut j) = rollout(model, z0, &us, cost)?;
    let mut gains = vec![SMatrix::<f64, 1, 4>::zeros(); STEPS];
    let mut ff = vec![0.0; STEPS];
    let mut mu = 1e-6;
    for _ in 0..iterations {
        let lin: Vec<(A, Z)> = (0..STEPS)
            .map(|k| model.linearize(&xs[k], us[k]))
            .collect::<Option<_>>()?;
        // backward pass
        let mut ok = false;
        while mu < 1e8 {
            let mut vx = cost.qf * (xs[STEPS] - goal());
            let mut vxx = cost.qf;
            ok = true;
            for k in (0..STEPS).rev() {
                let (a, b) = &lin[k];
                let dx = xs[k] - goal();
                let qx = cost.q * dx + a.transpose() * vx;
                let qu = cost.r * us[k] + b.dot(&vx);
                let qxx = cost.q + a.transpose() * vxx * a;
                let quu = cost.r + b.dot(&(vxx * b)) + mu;
                let qux = (vxx * b).transpose() * a;
                if quu <= 0.0 {
                    ok = false;
                    break;
                }
                let kff = -qu / quu;
                let kfb = -qux / quu;
                ff[k] = kff;
                gains[k] = kfb;
                vx = qx
                    + kfb.transpose() * (quu * kff)
                    + kfb.transpose() * qu
                    + qux.transpose() * kff;
                vxx = qxx
                    + kfb.transpose() * quu * kfb
                    + kfb.transpose() * qux
                    + qux.transpose() * kfb;
                vxx = (vxx + vxx.transpose()) * 0.5;
            }
            if ok {
                break;
            }
            mu *= 10.0;
        }
        if !ok {
            break;
        }
        // forward pass with a line search
        let mut improved = false;
        let mut alpha = 1.0;
        while alpha > 1e-4 {
            let mut new_us = Vec::with_capacity(STEPS);
            let mut z = *z0;
            let mut fail = false;
            for k in 0..STEPS {
                let u = us[k] + alpha * ff[k] + (gains[k] * (z - xs[k]))[0];
                new_us.push(u);
                match model.step(&z, u) {
                    Some(n) => z = n,
                    None => {
                        fail = true;
                        break;
                    }
                }
            }
            if !fail
                && let Some((nx, nj)) = rollout(model, z0, &new_us, cost)
                && nj < j
            {
                let done = (j - nj) < 1e-7 * j;
                (xs, us, j) = (nx, new_us, nj);
                improved = true;
                mu = (mu * 0.3).max(1e-9);
                if done {
                    return Some(Plan {
                        xs,
                        us,
                        gains,
                        cost: j,
                    });
                }
                break;
            }
            alpha *= 0.5;
        }
        if !improved {
            mu *= 10.0;
            if mu > 1e8 {
                break;
            }
        }
    }
    Some(Plan {
        xs,
        us,
        gains,
        cost: j,
    })
}

/// Runs a plan on the true system with its feedback gains: the closed-loop
/// trajectory and cost (None: the true step failed).
fn execute(
    truth: &Variational<View, 2, 0>,
    plan: &Plan,
    z0: &Z,
    cost: &Cost,
) -> Option<(Vec<Z>, f64)> {
    let mut z = *z0;
    let mut xs = vec![z];
    let mut j = 0.0;
    for k in 0..STEPS {
        let u = plan.policy(k, &z);
        j += cost.stage(&z, u);
        z = stack(
            &truth
                .step_forced(&unstack(&z), &SVector::<f64, 1>::new(u))
                .ok()?,
        );
        xs.push(z);
    }
    j += cost.terminal(&z);
    Some((xs, j))
}

#[path = "../tests/common/rng.rs"]
mod rng;
use rng::Rng;

/// A perturbed true system (paper: masses and inertias ×U[0.9, 1.1], joint
/// friction).
fn true_system(rng: &mut Rng) -> DrivenCartpole {
    let mut s = DrivenCartpole::default();
    for l in [&mut s.links.cart, &mut s.links.pole] {
        l.mass *= rng.uniform(0.9, 1.1);
        l.inertia *= rng.uniform(0.9, 1.1);
    }
    s.joints.rail.damping = rng.uniform(0.0, 0.5);
    s.joints.hinge.damping = rng.uniform(0.0, 0.05);
    s
}

/// Positions and logged inputs (input i held from sample i) of `truth`.
type Run = (Vec<SVector<f64, 2>>, Vec<SVector<f64, 1>>);

/// One run of the nominal plan's feedback law on the true system with
/// random piecewise-constant forces added (U[−3, 3] N, held 5 steps):
/// exploration around the task.
fn explore(
    truth: &Variational<View, 2, 0>,
    plan: &Plan,
    rng: &mut Rng,
) -> Result<Run, Box<dyn Error>> {
    let mut z = State::new([rng.uniform(-0.1, 0.1), rng.uniform(-0.2, 0.2)], [0.0, 0.0]);
    let mut positions = vec![z.q];
    let mut logged = vec![SVector::<f64, 1>::zeros()];
    let mut noise = 0.0;
    for k in 0..STEPS {
        if k % 5 == 0 {
            noise = rng.uniform(-3.0, 3.0);
        }
        let u = SVector::<f64, 1>::new(plan.policy(k, &stack(&z)) + noise);
        z = truth.step_forced(&z, &u)?;
        positions.push(z.q);
        logged.push(u);
    }
    Ok((positions, logged))
}

/// Learned model of `truth` from six exploration runs ([`explore`]).
fn learn(
    truth: &Variational<View, 2, 0>,
    plan: &Plan,
    rng: &mut Rng,
) -> Result<Learned<View, 2, 0>, Box<dyn Error>> {
    let mut data = Vec::new();
    for _ in 0..6 {
        let (positions, logged) = explore(truth, plan, rng)?;
        data.extend(forced_transitions(&positions, &logged, DT));
    }
    let data: Vec<_> = data.iter().step_by(2).copied().collect();
    let options = TrainOptions {
        restarts: 1,
        seed: 1,
        ..TrainOptions::default()
    };
    let nominal = DrivenCartpole::default().minimal();
    let (l, _) = Learned::train_forced(
        nominal,
        DT,
        &data,
        Encoding::SinCos,
        Prior::Nominal,
        &options,
    )?;
    Ok(l)
}

struct Outcome {
    cost: f64,
    angle_error: f64,
    cart_error: f64,
    plan_seconds: f64,
    failed: bool,
    trajectory: Vec<Z>,
}

fn outcome(run: Option<(Vec<Z>, f64)>, plan_seconds: f64) -> Outcome {
    match run {
        Some((xs, cost)) => {
            let last = xs[STEPS];
            let angle_error = (last[1] - std::f64::consts::PI).abs();
            let cart_error = last[0].abs();
            Outcome {
                cost,
                angle_error,
                cart_error,
                plan_seconds,
                failed: angle_error > 0.1,
                trajectory: xs,
            }
        }
        None => Outcome {
            cost: f64::INFINITY,
            angle_error: f64::INFINITY,
            cart_error: f64::INFINITY,
            plan_seconds,
            failed: true,
            trajectory: Vec::new(),
        },
    }
}

/// The conformal and the RKHS bound of `l`'s predictions under inputs
/// (δ = 0.05, `HORIZON` steps); the conformal one calibrated on two
/// held-out exploration runs of the true system (windows every 2 samples;
/// their own random stream, so the training data and the plans do not
/// depend on it).
fn bounds(
    l: &Learned<View, 2, 0>,
    truth: &Variational<View, 2, 0>,
    plan: &Plan,
    seed: u64,
) -> Result<[ErrorBound; 2], Box<dyn Error>> {
    let mut rng = Rng(seed);
    let (positions, inputs): (Vec<_>, Vec<_>) = [
        explore(truth, plan, &mut rng)?,
        explore(truth, plan, &mut rng)?,
    ]
    .into_iter()
    .unzip();
    let cal = Calibration::from_trajectories_forced(&positions, &inputs, DT, HORIZON, 2)?;
    Ok([
        l.error_bound_forced::<1>(&BoundKind::conformal(0.05), &cal)?,
        l.error_bound_forced::<1>(&BoundKind::rkhs(0.05), &cal)?,
    ])
}

/// What the bounded predictions along one executed trajectory showed.
#[derive(Default)]
struct Coverage {
    /// Predicted states (after the start) and those inside their bound.
    states: usize,
    covered: usize,
    /// Predictions, and those whose every state was inside its bound.
    windows: usize,
    whole: usize,
    /// Bound ÷ error of the position at the horizon, per prediction.
    ratios: Vec<f64>,
    /// Predicted states flagged outside the calibrated region.
    outside: usize,
    /// Predictions without a bound: the GP variance was lost to rounding
    /// at some state (a variance-based bound on noise-free training data).
    lost: usize,
}

/// The inputs that executing `plan` with its feedback law applied along
/// `xs`.
fn applied_inputs(plan: &Plan, xs: &[Z]) -> Vec<SVector<f64, 1>> {
    (0..STEPS)
        .map(|k| SVector::<f64, 1>::new(plan.policy(k, &xs[k])))
        .collect()
}

/// From every 25th state of the executed trajectory `xs`, the learned
/// model's `HORIZON`-step prediction under the inputs that were `applied`,
/// against the true positions.
fn bounded_predictions(
    l: &Learned<View, 2, 0>,
    bound: &ErrorBound,
    xs: &[Z],
    applied: &[SVector<f64, 1>],
    c: &mut Coverage,
) -> Result<(), Box<dyn Error>> {
    for k0 in (0..=STEPS - HORIZON).step_by(25) {
        // xs[k0]'s velocity was produced by the input applied before it
        let u_prev = &applied[k0.saturating_sub(1)];
        let p = match l.predict_forced(&unstack(&xs[k0]), u_prev, &applied[k0..k0 + HORIZON], bound)
        {
            Err(BoundError::VarianceLost { .. }) => {
                c.lost += 1;
                continue;
            }
            p => p?,
        };
        let mut all = true;
        for j in 1..=HORIZON {
            let err = (p.states[j].q - unstack(&xs[k0 + j]).q).norm();
            let inside = err <= p.position_bounds[j];
            c.covered += usize::from(inside);
            all &= inside;
            if j == HORIZON {
                c.ratios.push(p.position_bounds[j] / err);
            }
        }
        c.states += HORIZON;
        c.windows += 1;
        c.whole += usize::from(all);
        c.outside += p.outside.iter().filter(|o| **o).count();
    }
    Ok(())
}

fn quantile(v: &[f64], q: f64) -> f64 {
    let mut s: Vec<f64> = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    let i = q * (s.len() - 1) as f64;
    let (lo, hi) = (i.floor() as usize, i.ceil() as usize);
    s[lo] + (s[hi] - s[lo]) * (i - lo as f64)
}

fn draw_typical<DB: DrawingBackend>(
    root: DrawingArea<DB, plotters::coord::Shift>,
    nominal: &[Z],
    learned: &[Z],
) -> Result<(), Box<dyn Error>>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let values = || nominal.iter().chain(learned).flat_map(|z| [z[0], z[1]]);
    let lo = values().fold(0.0f64, f64::min) - 0.3;
    let hi = values().fold(std::f64::consts::PI, f64::max) + 0.3;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Cartpole swing-up on a true system (closed loop)",
            (FONT, 20),
        )
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..(STEPS as f64 * DT), lo..hi)?;
    chart
        .configure_mesh()
        .x_desc("t (s)")
        .y_desc("pole angle θ (rad), cart x (m)")
        .label_style((FONT, 14))
        .draw()?;
    let t = |k: usize| k as f64 * DT;
    for (xs, idx, colour, label) in [
        (nominal, 1, RED, "θ, nominal iLQR"),
        (learned, 1, BLUE, "θ, learned iLQR"),
        (nominal, 0, RGBColor(250, 150, 150), "x, nominal iLQR"),
        (learned, 0, RGBColor(150, 150, 250), "x, learned iLQR"),
    ] {
        chart
            .draw_series(LineSeries::new(
                xs.iter().enumerate().map(|(k, z)| (t(k), z[idx])),
                colour.stroke_width(2),
            ))?
            .label(label)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], colour.stroke_width(2)));
    }
    chart.draw_series(LineSeries::new(
        [
            (0.0, std::f64::consts::PI),
            (STEPS as f64 * DT, std::f64::consts::PI),
        ],
        BLACK.stroke_width(1),
    ))?;
    chart
        .configure_series_labels()
        .label_font((FONT, 14))
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .position(SeriesLabelPosition::LowerRight)
        .draw()?;
    root.present()?;
    Ok(())
}

fn draw_costs<DB: DrawingBackend>(
    root: DrawingArea<DB, plotters::coord::Shift>,
    nominal: &[f64],
    learned: &[f64],
) -> Result<(), Box<dyn Error>>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let finite = nominal.iter().chain(learned).filter(|c| c.is_finite());
    let top = finite.fold(0.0f64, |a, b| a.max(*b)) * 1.1 + 1e-9;
    let mut chart = ChartBuilder::on(&root)
        .caption("Closed-loop cost per true system", (FONT, 20))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(-0.5..(nominal.len() as f64 - 0.5), 0.0..top)?;
    chart
        .configure_mesh()
        .x_desc("true system")
        .y_desc("cost")
        .label_style((FONT, 14))
        .draw()?;
    for (costs, colour, label) in [
        (nominal, RED, "nominal iLQR"),
        (learned, BLUE, "learned iLQR"),
    ] {
        chart
            .draw_series(
                costs
                    .iter()
                    .enumerate()
                    .filter(|(_, c)| c.is_finite())
                    .map(|(i, c)| Circle::new((i as f64, *c), 4, colour.filled())),
            )?
            .label(label)
            .legend(move |(x, y)| Circle::new((x + 10, y), 4, colour.filled()));
    }
    chart
        .configure_series_labels()
        .label_font((FONT, 14))
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

fn main() -> Result<(), Box<dyn Error>> {
    let systems: usize = std::env::args().nth(1).map_or(Ok(20), |s| s.parse())?;
    let out = Path::new("target/control");
    std::fs::create_dir_all(out)?;
    let cost = Cost::new();
    let z0 = Z::zeros();
    let nominal = Nominal(Variational::new(DrivenCartpole::default().minimal(), DT)?);
    let t = Instant::now();
    let nominal_plan = ilqr(&nominal, &z0, None, &cost, 200).ok_or("nominal iLQR failed")?;
    let nominal_seconds = t.elapsed().as_secs_f64();
    println!(
        "nominal iLQR plan: predicted cost {:.4}, {:.2} s",
        nominal_plan.cost, nominal_seconds
    );
    let mut rng = Rng(2024);
    let bar = ProgressBar::new(systems as u64).with_style(ProgressStyle::with_template(
        "{bar:40} {pos}/{len} true systems, {elapsed} ({eta} left)",
    )?);
    let mut rows = Vec::new();
    let mut coverage = [Coverage::default(), Coverage::default()];
    for system in 0..systems {
        let sys = true_system(&mut rng);
        let truth = Variational::new(sys.minimal(), DT)?;
        let n = outcome(execute(&truth, &nominal_plan, &z0, &cost), nominal_seconds);
        let t = Instant::now();
        let l = learn(&truth, &nominal_plan, &mut rng)?;
        let ws = RefCell::new(l.workspace());
        let learned = LearnedModel(l, ws);
        let train_seconds = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let plan = ilqr(&learned, &z0, Some(&nominal_plan), &cost, 60);
        let plan_seconds = t.elapsed().as_secs_f64();
        if std::env::var("CONTROL_VERBOSE").is_ok()
            && let Some(p) = &plan
        {
            eprintln!("learned plan: predicted cost {:.4}", p.cost);
        }
        let l = match plan {
            Some(p) => {
                let run = execute(&truth, &p, &z0, &cost);
                if let Some((xs, _)) = &run {
                    let b = bounds(&learned.0, &truth, &nominal_plan, 7000 + system as u64)?;
                    let applied = applied_inputs(&p, xs);
                    for (bound, c) in b.iter().zip(&mut coverage) {
                        bounded_predictions(&learned.0, bound, xs, &applied, c)?;
                    }
                }
                outcome(run, plan_seconds)
            }
            None => outcome(None, plan_seconds),
        };
        rows.push((sys, n, l, train_seconds));
        bar.inc(1);
    }
    bar.finish();

    let nominal_costs: Vec<f64> = rows.iter().map(|r| r.1.cost).collect();
    let learned_costs: Vec<f64> = rows.iter().map(|r| r.2.cost).collect();
    let (mn, ml) = (quantile(&nominal_costs, 0.5), quantile(&learned_costs, 0.5));
    let mut md = String::new();
    writeln!(md, "# Cartpole swing-up: nominal vs learned iLQR\n")?;
    writeln!(
        md,
        "`cargo run --release --example control -- {systems}`: {systems} true systems (masses and inertias ×U[0.9, 1.1], rail friction U[0, 0.5] N·s/m, hinge friction U[0, 0.05] N·m·s), Δt = {DT} s, {STEPS} steps, start hanging at rest, goal upright at the origin. Failure: final |θ − π| > 0.1 rad or a failed step.\n"
    )?;
    writeln!(md, "| | nominal iLQR | learned iLQR |")?;
    writeln!(md, "|---|---|---|")?;
    let row = |name: &str, f: &dyn Fn(&Outcome) -> f64, q: f64| -> String {
        let a: Vec<f64> = rows.iter().map(|r| f(&r.1)).collect();
        let b: Vec<f64> = rows.iter().map(|r| f(&r.2)).collect();
        format!(
            "| {name} | {:.4} | {:.4} |",
            quantile(&a, q),
            quantile(&b, q)
        )
    };
    writeln!(md, "{}", row("median closed-loop cost", &|o| o.cost, 0.5))?;
    writeln!(md, "{}", row("cost, 25th percentile", &|o| o.cost, 0.25))?;
    writeln!(md, "{}", row("cost, 75th percentile", &|o| o.cost, 0.75))?;
    writeln!(
        md,
        "{}",
        row("median final |θ − π| (rad)", &|o| o.angle_error, 0.5)
    )?;
    writeln!(
        md,
        "{}",
        row("median final |x| (m)", &|o| o.cart_error, 0.5)
    )?;
    writeln!(
        md,
        "{}",
        row("median planning time (s)", &|o| o.plan_seconds, 0.5)
    )?;
    let (nominal_fails, learned_fails) = (
        rows.iter().filter(|r| r.1.failed).count(),
        rows.iter().filter(|r| r.2.failed).count(),
    );
    writeln!(
        md,
        "| failures | {nominal_fails} / {systems} | {learned_fails} / {systems} |"
    )?;
    let better = rows.iter().filter(|r| r.2.cost < r.1.cost).count();
    let train: Vec<f64> = rows.iter().map(|r| r.3).collect();
    writeln!(
        md,
        "\nThe learned controller's cost is lower on {better} of {systems} systems; median cost {ml:.4} vs {mn:.4} (ratio {:.3}). Median GP training time {:.2} s. Both plans use exact step derivatives (the VI's; the learned step's: nominal forced step + GP mean gradient); the nominal plan is computed once. Feedback during execution: iLQR's time-varying gains, one 4-vector product per control step.",
        ml / mn,
        quantile(&train, 0.5)
    )?;
    if coverage[0].windows > 0 {
        writeln!(
            md,
            "\n**Bounded predictions.** From every 25th state of the learned controller's executed trajectories, the learned model predicted the next {HORIZON} steps ({:.1} s) under the applied inputs, each state with its position bound (δ = 0.05; `Learned::predict_forced`). Conformal: calibrated per system on two held-out exploration runs (windows every 2 samples); where a state leaves the calibrated region its bound is the larger of the conformal and the RKHS bound. The executed trajectories are not drawn like the calibration runs (no exploration forces), so the conformal guarantee is approximate here.\n",
            HORIZON as f64 * DT
        )?;
        writeln!(md, "| | conformal | RKHS |")?;
        writeln!(md, "|---|---|---|")?;
        let cell =
            |f: &dyn Fn(&Coverage) -> String| format!("{} | {}", f(&coverage[0]), f(&coverage[1]));
        writeln!(
            md,
            "| predicted states inside their bound | {} |",
            cell(&|c| format!(
                "{} / {} ({:.1} %)",
                c.covered,
                c.states,
                100.0 * c.covered as f64 / c.states.max(1) as f64
            ))
        )?;
        writeln!(
            md,
            "| predictions inside at every step | {} |",
            cell(&|c| format!("{} / {}", c.whole, c.windows))
        )?;
        writeln!(
            md,
            "| bound ÷ error at the horizon: median (10 %, 90 %) | {} |",
            cell(&|c| if c.ratios.is_empty() {
                "–".into()
            } else {
                format!(
                    "{:.2} ({:.2}, {:.2})",
                    quantile(&c.ratios, 0.5),
                    quantile(&c.ratios, 0.1),
                    quantile(&c.ratios, 0.9)
                )
            })
        )?;
        writeln!(
            md,
            "| predicted states outside the bound's region | {} |",
            cell(&|c| c.outside.to_string())
        )?;
        writeln!(
            md,
            "| predictions without a bound (variance lost to rounding) | {} |",
            cell(&|c| c.lost.to_string())
        )?;
    }
    std::fs::write(out.join("report.md"), &md)?;
    print!("{md}");

    register_embedded_font()?;
    let typical = rows
        .iter()
        .enumerate()
        .min_by(|a, b| {
            let d = |r: &(DrivenCartpole, Outcome, Outcome, f64)| (r.1.cost - mn).abs();
            d(a.1).total_cmp(&d(b.1))
        })
        .map(|(i, _)| i)
        .unwrap_or(0);
    let (n, l) = (&rows[typical].1.trajectory, &rows[typical].2.trajectory);
    if !n.is_empty() && !l.is_empty() {
        draw_typical(
            SVGBackend::new(&out.join("typical.svg"), (900, 500)).into_drawing_area(),
            n,
            l,
        )?;
        draw_typical(
            BitMapBackend::new(&out.join("typical.png"), (900, 500)).into_drawing_area(),
            n,
            l,
        )?;
    }
    draw_costs(
        SVGBackend::new(&out.join("costs.svg"), (900, 500)).into_drawing_area(),
        &nominal_costs,
        &learned_costs,
    )?;
    draw_costs(
        BitMapBackend::new(&out.join("costs.png"), (900, 500)).into_drawing_area(),
        &nominal_costs,
        &learned_costs,
    )?;
    println!(
        "\nwrote {}/report.md, typical.svg/png, costs.svg/png",
        out.display()
    );
    Ok(())
}
