//! Stress cases shared by `tests/step/stress.rs` (small sizes, asserted) and
//! `examples/stress.rs` (heavy sizes, printed as the README's table).
//!
//! Each case runs, measures what happened and returns [`Row`]s whose
//! `verdict` says whether the expectation held: no panic, no NaN, and every
//! failure a typed error that names what happened. Tolerances are stated
//! where they are checked.
#![allow(dead_code)]

#[macro_use]
#[path = "../common/pinned_chain.rs"]
mod pinned_chain;

use nalgebra::{SMatrix, SVector};
use vigp::gp::{Bounds, Gp, GpError, Hyperparameters, SavedGp, TrainOptions};
use vigp::learned::{Encoding, Learned, Prior, transitions};
use vigp::prelude::*;
use vigp::projection::{consistent_state, project_configuration, project_velocity};
use vigp::systems::{DoublePendulum, Fourbar, Pendulum};

/// How big a run is: `Test` fits the test suite's budget, `Heavy` is the
/// example's (10^6-step horizons, longer sweeps).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Size {
    /// Seconds.
    Test,
    /// Minutes.
    Heavy,
}

impl Size {
    fn pick(self, test: usize, heavy: usize) -> usize {
        match self {
            Size::Test => test,
            Size::Heavy => heavy,
        }
    }
}

/// One line of the outcome table.
#[derive(Clone, Debug)]
pub struct Row {
    /// The case.
    pub case: String,
    /// What happened (measured).
    pub happened: String,
    /// The remedy used, if any.
    pub remedy: String,
    /// The typed error, if the case ends in one.
    pub error: String,
    /// `Err(why)` when the expectation did not hold.
    pub verdict: Result<(), String>,
}

impl Row {
    fn new(case: impl Into<String>) -> Self {
        Self {
            case: case.into(),
            happened: String::new(),
            remedy: "—".into(),
            error: "—".into(),
            verdict: Ok(()),
        }
    }
    fn fail(&mut self, why: impl Into<String>) {
        if self.verdict.is_ok() {
            self.verdict = Err(why.into());
        }
    }
    fn check(&mut self, ok: bool, why: impl FnOnce() -> String) {
        if !ok {
            self.fail(why());
        }
    }
}

/// Markdown table of rows (case, what happened, remedy, error).
pub fn table(rows: &[Row]) -> String {
    let mut s = String::from(
        "| case | what happened | remedy | error (type: message) |\n|---|---|---|---|\n",
    );
    for r in rows {
        let mark = if r.verdict.is_ok() {
            ""
        } else {
            " **(FAILED)**"
        };
        s += &format!(
            "| {}{} | {} | {} | {} |\n",
            r.case, mark, r.happened, r.remedy, r.error
        );
    }
    s
}

/// "Variant: message" of a step error.
pub fn describe(e: &StepError) -> String {
    describe_as("StepError", e)
}

fn describe_gp(e: &GpError) -> String {
    describe_as("GpError", e)
}

/// "`Type::Variant`: message" of an error of the type named `ty`.
fn describe_as<E: std::fmt::Debug + std::fmt::Display>(ty: &str, e: &E) -> String {
    let dbg = format!("{e:?}");
    let variant = dbg.split([' ', '(', '{']).next().unwrap_or("").to_string();
    format!("`{ty}::{variant}`: {e}")
}

/// The error kinds as a list of code spans: "`a`, `b`".
fn code_list(kinds: std::collections::BTreeSet<String>) -> String {
    kinds
        .into_iter()
        .map(|k| format!("`{k}`"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// What a rollout did: steps taken, max |E − E₀| (with `energy`), max |g|,
/// and the error that stopped it.
pub struct Run {
    pub steps: usize,
    pub max_de: f64,
    pub first_tenth: f64,
    pub last_tenth: f64,
    pub max_g: f64,
    pub error: Option<StepError>,
    pub stalled: usize,
    pub regularised: usize,
}

/// Roll a variational integrator out, tracking energy, constraints and
/// solver flags; states are checked finite at every step.
pub fn run_vi<M: Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    vi: &Variational<M, N, C>,
    z0: &State<N>,
    steps: usize,
) -> Run {
    let m = *vi.model();
    let e0 = vi.energy(z0);
    let mut z = *z0;
    let mut out = Run {
        steps: 0,
        max_de: 0.0,
        first_tenth: 0.0,
        last_tenth: 0.0,
        max_g: m.constraint_violation(z0),
        error: None,
        stalled: 0,
        regularised: 0,
    };
    for k in 0..steps {
        match vi.step_with_report(&z) {
            Ok((next, info)) => {
                assert!(next.is_finite(), "step {k} returned a non-finite state");
                z = next;
                let de = (vi.energy(&z) - e0).abs();
                out.max_de = out.max_de.max(de);
                if k < steps / 10 {
                    out.first_tenth = out.first_tenth.max(de);
                }
                if k >= steps - steps / 10 {
                    out.last_tenth = out.last_tenth.max(de);
                }
                out.max_g = out.max_g.max(m.constraint_violation(&z));
                out.stalled += info.stalled as usize;
                out.regularised += info.regularised as usize;
                out.steps += 1;
            }
            Err(e) => {
                out.error = Some(e.at_step(k));
                break;
            }
        }
    }
    out
}

/// A failed run must be a typed Newton failure with finite diagnostics.
fn check_typed_failure(row: &mut Row, e: &StepError) {
    match e {
        StepError::NotConverged {
            iterations,
            residual,
            ..
        } => row.check(residual.is_finite() && *iterations > 0, || {
            format!("bad diagnostics: {e:?}")
        }),
        StepError::LineSearchFailed { residual, .. } => {
            row.check(residual.is_finite(), || format!("bad diagnostics: {e:?}"))
        }
        StepError::SingularJacobian { .. } | StepError::NonFiniteResidual { .. } => {}
        // the step failed at every sub-step down to Δt/2^depth
        StepError::NotResolved {
            depth, residual, ..
        } => row.check(*depth > 0 && !residual.is_nan(), || {
            format!("bad diagnostics: {e:?}")
        }),
        // a converged root that does not resolve the motion (the bend of
        // the step above the continuation bound)
        StepError::NotContinuation { ratio, bound, .. } => row
            .check(ratio.is_finite() && ratio > bound, || {
                format!("bad diagnostics: {e:?}")
            }),
        other => row.fail(format!("unexpected error {other:?}")),
    }
}

pinned_chain!(
    TautChain,
    3.0,
    "Three links pinned at both ends, exactly as far apart as the chain is long: the only configuration is the straight one, where the loop Jacobian loses rank (a fully stretched chain)."
);

pinned_chain!(
    SlackChain,
    2.9,
    "The same chain with its ends 2.9 m apart: one degree of freedom that swings through nearly stretched poses."
);

vigp::mechanism! {
    /// A five-link open chain, released fully stretched (horizontal).
    pub Whip {
        gravity: [0.0, -9.81],
        links {
            l1: { mass: 1.0, length: 1.0 },
            l2: { mass: 1.0, length: 1.0 },
            l3: { mass: 1.0, length: 1.0 },
            l4: { mass: 1.0, length: 1.0 },
            l5: { mass: 1.0, length: 1.0 },
        }
        joints {
            j1: revolute(world, l1.start),
            j2: revolute(l1.end, l2.start),
            j3: revolute(l2.end, l3.start),
            j4: revolute(l3.end, l4.start),
            j5: revolute(l4.end, l5.start),
        }
    }
}

vigp::mechanism! {
    /// A double pendulum whose lower link is 1e-3 as heavy and 1e-3 as long.
    pub LightTip {
        gravity: [0.0, -9.81],
        links {
            upper: { mass: 1.0, length: 1.0 },
            lower: { mass: 0.001, length: 0.001 },
        }
        joints {
            shoulder: revolute(world, upper.start),
            elbow: revolute(upper.end, lower.start),
        }
    }
}

vigp::mechanism! {
    /// A double pendulum whose lower link is 1e3 as heavy and 1e3 as long.
    pub HeavyTip {
        gravity: [0.0, -9.81],
        links {
            upper: { mass: 1.0, length: 1.0 },
            lower: { mass: 1000.0, length: 1000.0 },
        }
        joints {
            shoulder: revolute(world, upper.start),
            elbow: revolute(upper.end, lower.start),
        }
    }
}

vigp::mechanism! {
    /// Point-mass links (no rotational inertia about the centre of mass) and
    /// a flywheel-like link (inertia 1e6 kg·m²).
    pub Inertias {
        gravity: [0.0, -9.81],
        links {
            rod: { mass: 1.0, length: 1.0, inertia: 0.0 },
            bob: { mass: 1.0, length: 1.0, inertia: 0.0 },
            wheel: { mass: 1.0, length: 1.0, inertia: 1000000.0 },
        }
        joints {
            a: revolute(world, rod.start),
            b: revolute(rod.end, bob.start),
            c: revolute(bob.end, wheel.start),
        }
    }
}

const REV: f64 = std::f64::consts::TAU;

/// Long horizons: the conservative double pendulum (chaotic from
/// θ = (π/2, 0)), Δt = 0.01, 10^5 (test) or 10^6 (heavy) steps, with the
/// paper's first-order VI and the midpoint VI. Expectation: no error, every
/// state finite, and no secular energy growth: the worst |ΔE| of the last
/// tenth within 1.5× that of the first tenth (a drifting method grows by
/// orders of magnitude over these horizons; the oscillation of a symplectic
/// one is the same in every tenth up to which states a chaotic orbit
/// visits).
pub fn long_horizon(size: Size) -> Vec<Row> {
    let steps = size.pick(100_000, 1_000_000);
    let model = DoublePendulum::default().minimal();
    let z0 = State::new([std::f64::consts::FRAC_PI_2, 0.0], [0.0, 0.0]);
    let mut rows = Vec::new();
    for (name, vi) in [
        ("paper VI", Variational::new(model, 0.01).unwrap()),
        ("midpoint VI", Variational::midpoint(model, 0.01).unwrap()),
    ] {
        let r = run_vi(&vi, &z0, steps);
        let mut row = Row::new(format!(
            "long horizon: double pendulum, {name}, Δt = 0.01, {steps} steps"
        ));
        row.happened = format!(
            "all steps finite; max |ΔE| {:.3} J (first tenth {:.3}, last tenth {:.3}; E range ≈ 59 J)",
            r.max_de, r.first_tenth, r.last_tenth
        );
        if let Some(e) = &r.error {
            row.error = describe(e);
            row.fail(format!("failed: {e}"));
        }
        row.check(r.last_tenth <= 1.5 * r.first_tenth, || {
            format!(
                "energy error grows: first tenth {:.3e}, last {:.3e}",
                r.first_tenth, r.last_tenth
            )
        });
        rows.push(row);
    }
    rows
}

/// Large steps and fast motion: Δt ∈ {0.02, 0.05, 0.1} s, joint speeds of
/// 1 and 3 rev/s in opposite directions (chaotic), on the double pendulum
/// and the fourbar. Without sub-steps (and without the step's own
/// subdivision, `max_subdivision(0)`) a step either succeeds or fails with
/// `NotConverged` (the DEL equations, quadratic in v₁, have no root near
/// v₀); with sub-steps h = 2 ms every run completes with bounded energy:
/// max |ΔE| ≤ 5 % of the motion's energy scale, E_kin + the potential's
/// range (59 J double pendulum, 78 J fourbar). For scale: the unit double
/// pendulum at h = 10 ms oscillates by 3.8 % of its range (long-horizon
/// row); explicit Euler gains hundreds of joules.
pub fn large_steps(size: Size) -> Vec<Row> {
    let steps = size.pick(200, 5_000);
    let mut rows = Vec::new();
    for dt in [0.02, 0.05, 0.1] {
        for rev in [1.0, 3.0] {
            let w = rev * REV;
            let k = (dt / 0.002f64).round() as usize;
            // double pendulum
            let dp = DoublePendulum::default().minimal();
            let q0 = SVector::from([2.0, -1.0]);
            let qd = SVector::from([w, -w]);
            let plain = Variational::new(dp, dt).unwrap().max_subdivision(0);
            let z_plain = State {
                q: q0,
                v: vigp::dynamics::discrete_velocity(&dp, &q0, &qd, dt).unwrap(),
            };
            let z_sub = State {
                q: q0,
                v: vigp::dynamics::discrete_velocity(&dp, &q0, &qd, dt / k as f64).unwrap(),
            };
            let kinetic = dp.kinetic_energy(&q0, &qd);
            rows.push(large_step_row(
                &format!("Δt = {dt}, {rev} rev/s: double pendulum"),
                &plain,
                &z_plain,
                &plain.substeps(k).unwrap(),
                &z_sub,
                steps,
                kinetic + 58.9,
            ));
            // fourbar (consistent start, loop constraint)
            let fb = Fourbar::default().minimal();
            let q = SVector::from([0.9, -1.3, -0.4, 1.3]);
            let v = SVector::from([w, 0.0, 0.0, 0.0]);
            let z_plain = consistent_state(&fb, &q, &v, dt).unwrap();
            let z_sub = consistent_state(&fb, &q, &v, dt / k as f64).unwrap();
            let kinetic = fb.kinetic_energy(&z_sub.q, &z_sub.v);
            let plain = Variational::new(fb, dt).unwrap().max_subdivision(0);
            rows.push(large_step_row(
                &format!("Δt = {dt}, {rev} rev/s: fourbar"),
                &plain,
                &z_plain,
                &plain.substeps(k).unwrap(),
                &z_sub,
                steps,
                kinetic + 78.5,
            ));
        }
    }
    rows
}

fn large_step_row<M: Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    case: &str,
    plain: &Variational<M, N, C>,
    z_plain: &State<N>,
    sub: &Variational<M, N, C>,
    z_sub: &State<N>,
    steps: usize,
    e_scale: f64,
) -> Row {
    let mut row = Row::new(format!("large step: {case}, {steps} steps"));
    let a = run_vi(plain, z_plain, steps);
    let b = run_vi(sub, z_sub, steps);
    let plain_note = match &a.error {
        None => format!(
            "without subdivision: all {steps} steps, max |ΔE| {:.2} J",
            a.max_de
        ),
        Some(e) => {
            check_typed_failure(&mut row, e);
            row.error = describe(e);
            format!("without subdivision: fails at step {}", a.steps)
        }
    };
    row.remedy = format!("`substeps({})` (h = 2 ms)", sub.substep_count());
    match &b.error {
        None => {
            row.happened = format!(
                "{plain_note}; sub-stepped: all steps, max |ΔE| {:.2} J ({:.1} % of the energy scale), max |g| {:.0e}",
                b.max_de,
                100.0 * b.max_de / e_scale,
                b.max_g
            );
            row.check(b.max_de <= 0.05 * e_scale, || {
                format!(
                    "sub-stepped energy error {:.3e} of {e_scale:.0} J",
                    b.max_de
                )
            });
            row.check(b.max_g <= 1e-10, || format!("|g| = {:.1e}", b.max_g));
        }
        Some(e) => {
            row.happened = format!("{plain_note}; sub-stepped fails too");
            row.fail(format!("sub-stepped run failed: {e}"));
        }
    }
    if a.error.is_none() {
        row.remedy = format!("none needed (also fine with {})", row.remedy);
    }
    row
}

/// Smallest singular value of a C×N matrix: √λ_min(G·Gᵀ), the eigenvalue
/// by cyclic Jacobi rotations (generic sizes; nalgebra's eigen solver needs
/// type-level sizes).
fn sigma_min<const C: usize, const N: usize>(g: &SMatrix<f64, C, N>) -> f64 {
    let mut a = g * g.transpose();
    for _ in 0..50 {
        let mut off = 0.0f64;
        for p in 0..C {
            for q in p + 1..C {
                off = off.max(a[(p, q)].abs());
                if a[(p, q)] == 0.0 {
                    continue;
                }
                let theta = (a[(q, q)] - a[(p, p)]) / (2.0 * a[(p, q)]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..C {
                    let (akp, akq) = (a[(k, p)], a[(k, q)]);
                    a[(k, p)] = c * akp - s * akq;
                    a[(k, q)] = s * akp + c * akq;
                }
                for k in 0..C {
                    let (apk, aqk) = (a[(p, k)], a[(q, k)]);
                    a[(p, k)] = c * apk - s * aqk;
                    a[(q, k)] = s * apk + c * aqk;
                }
            }
        }
        if off <= 1e-300 {
            break;
        }
    }
    (0..C)
        .map(|i| a[(i, i)])
        .fold(f64::INFINITY, f64::min)
        .max(0.0)
        .sqrt()
}

/// Singular configurations: the fourbar started exactly at its folded pose
/// (all links parallel, σ_min(G) = 0) and driven through it; the same in
/// maximal coordinates; a chain pinned at both ends at full stretch; the
/// same chain slightly slack; a five-link chain released fully stretched.
pub fn singular(size: Size) -> Vec<Row> {
    let steps = size.pick(2_000, 100_000);
    let dt = 0.01;
    let mut rows = Vec::new();

    // fourbar from the exact fold, minimal coordinates
    let fb = Fourbar::default();
    let fm = fb.minimal();
    let z0 = consistent_state(
        &fm,
        &SVector::zeros(),
        &SVector::from([2.0, -4.0, -2.0, 4.0]),
        dt,
    )
    .unwrap();
    let mut row = Row::new(format!(
        "singular: fourbar started at the folded pose (σ_min(G) = 0), {steps} steps"
    ));
    let s0 = sigma_min(&fm.constraint_jacobian(&z0.q));
    let r = run_vi(&Variational::new(fm, dt).unwrap(), &z0, steps);
    row.happened = format!(
        "σ_min(G₀) = {s0:.0e}; {} steps, max |g| {:.1e}, {} stalled-accepted steps",
        r.steps, r.max_g, r.stalled
    );
    row.remedy = "complete-pivoting KKT (rank-revealing), stall acceptance ≤ 1e-10".into();
    if let Some(e) = &r.error {
        row.error = describe(e);
        row.fail(format!("{e}"));
    }
    // |g| ≤ 1e-10: the stall tolerance (attainable accuracy where g is
    // quadratic in the lost direction)
    row.check(r.max_g <= 1e-10, || format!("|g| = {:.1e}", r.max_g));
    row.check(s0 < 1e-12, || format!("not at the fold: σ = {s0:e}"));
    rows.push(row);

    // the same through the fold in maximal coordinates
    let fx = fb.maximal();
    let zx = fm.to_maximal(&z0, dt);
    let zx = consistent_state(&fx, &zx.q, &zx.v, dt).unwrap();
    let n = size.pick(1_000, 20_000);
    let mut row = Row::new(format!(
        "singular: fourbar in maximal coordinates (12 + 10 constraints) from the fold, {n} steps"
    ));
    let r = run_vi(&Variational::new(fx, dt).unwrap(), &zx, n);
    row.happened = format!(
        "{} steps, max |g| {:.1e}, {} stalled-accepted steps",
        r.steps, r.max_g, r.stalled
    );
    if let Some(e) = &r.error {
        row.error = describe(e);
        row.fail(format!("{e}"));
    }
    row.check(r.max_g <= 1e-10, || format!("|g| = {:.1e}", r.max_g));
    rows.push(row);

    // taut chain: the straight pose is the only configuration
    let taut = TautChain::default().minimal();
    let zt = State::new([std::f64::consts::FRAC_PI_2, 0.0, 0.0], [0.0; 3]);
    let mut row =
        Row::new("singular: chain pinned at both ends at full stretch (no motion admissible)");
    let s0 = sigma_min(&taut.constraint_jacobian(&zt.q));
    match Variational::new(taut, dt).unwrap().step(&zt) {
        Ok(z) => {
            row.happened = format!("step accepted, |g| {:.1e}", taut.constraint_violation(&z));
            row.fail("gravity cannot be balanced at the straight pose: a step must not converge");
        }
        Err(e) => {
            row.happened = format!(
                "σ_min(G) = {s0:.0e}; gravity cannot be balanced by finite tension: the first step reports"
            );
            row.check(
                matches!(
                    e,
                    StepError::NotConverged { .. } | StepError::LineSearchFailed { .. }
                ),
                || format!("expected a Newton failure, got {e:?}"),
            );
            row.error = describe(&e);
        }
    }
    rows.push(row);

    // slack chain swinging through nearly stretched poses
    let slack = SlackChain::default().minimal();
    let zs = consistent_state(
        &slack,
        &SVector::from([1.4, 0.1, 0.1]),
        &SVector::from([-1.0, 0.5, 0.5]),
        dt,
    )
    .unwrap();
    let mut row = Row::new(format!(
        "singular: chain 2.9 m between pins (3 m long), {steps} steps"
    ));
    let r = run_vi(&Variational::new(slack, dt).unwrap(), &zs, steps);
    row.happened = format!(
        "{} steps, max |g| {:.1e}, max |ΔE| {:.2e} J",
        r.steps, r.max_g, r.max_de
    );
    if let Some(e) = &r.error {
        row.error = describe(e);
        row.fail(format!("{e}"));
    }
    row.check(r.max_g <= 1e-10, || format!("|g| = {:.1e}", r.max_g));
    rows.push(row);

    // five-link chain released fully stretched: minimal and maximal; the
    // whip's tip speeds up, a run counts only if its energy error stays
    // within 10 % of the potential's range (123 J from horizontal to
    // hanging; a bounded first-order oscillation; the default minimal run
    // at 2·10^4 steps blows up to ~8e3 J before Newton fails)
    let whip = Whip::default();
    let (wm, wx) = (whip.minimal(), whip.maximal());
    let zw = State::new([std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0, 0.0], [0.0; 5]);
    let n = size.pick(500, 20_000);
    let v_range = wm.potential_energy(&SVector::<f64, 5>::zeros()).abs();
    rows.push(with_substep_remedy(
        &format!("stretched 5-link chain released horizontally, minimal, {n} steps"),
        wm,
        &zw,
        dt,
        n,
        v_range,
        0.1,
    ));
    let wz = |h: f64| wm.to_maximal(&zw, h);
    let mut row = with_substep_remedy(
        &format!("stretched 5-link chain released horizontally, maximal, {n} steps"),
        wx,
        &wz(dt),
        dt,
        n,
        v_range,
        0.1,
    );
    row.happened = format!("{} (potential range {v_range:.0} J)", row.happened);
    rows.push(row);
    rows
}

/// Extreme parameters: lower/upper mass and length ratios 1e-3…1e3, the
/// DSL-declared `LightTip`, `HeavyTip` and `Inertias`, zero inertia in
/// maximal coordinates, and invariance under scaling every mass.
pub fn extreme_parameters(size: Size) -> Vec<Row> {
    let steps = size.pick(1_000, 20_000);
    let dt = 0.01;
    let mut rows = Vec::new();
    let z0 = State::new([1.0, 0.5], [0.0, 0.0]);
    for mr in [1e-3, 1.0, 1e3] {
        for lr in [1e-3, 1.0, 1e3] {
            if mr == 1.0 && lr == 1.0 {
                continue;
            }
            let mut sys = DoublePendulum::default();
            let l = &mut sys.links.lower;
            (l.mass, l.length) = (mr, lr);
            l.inertia = mr * lr * lr / 12.0;
            l.com = [lr / 2.0, 0.0];
            rows.push(ratio_row(
                &format!("mass ratio {mr:e}, length ratio {lr:e}"),
                sys.minimal(),
                &z0,
                dt,
                steps,
            ));
        }
    }
    rows.push(ratio_row(
        "DSL `LightTip` (1e-3 kg, 1 mm tip)",
        LightTip::default().minimal(),
        &z0,
        dt,
        steps,
    ));
    rows.push(ratio_row(
        "DSL `HeavyTip` (1e3 kg, 1 km tip)",
        HeavyTip::default().minimal(),
        &z0,
        dt,
        steps,
    ));
    rows.push(ratio_row(
        "DSL `Inertias` (J = 0, 0, 1e6)",
        Inertias::default().minimal(),
        &State::new([1.0, 0.5, -0.3], [0.0; 3]),
        dt,
        steps,
    ));

    // zero inertia in maximal coordinates: the θ rows of the mass matrix
    // vanish, J is singular, the KKT matrix is not
    let sys = Inertias::default();
    let zm = sys
        .minimal()
        .to_maximal(&State::new([1.0, 0.5, -0.3], [0.0; 3]), dt);
    let mut row = Row::new(format!(
        "zero rotational inertia, maximal coordinates (singular mass matrix), {steps} steps"
    ));
    let r = run_vi(&Variational::new(sys.maximal(), dt).unwrap(), &zm, steps);
    row.remedy = "regularised KKT (J + ρ·B·A, same solution)".into();
    row.happened = format!(
        "{} steps, {} needed the regularisation, max |g| {:.1e}, max |ΔE| {:.2e} J",
        r.steps, r.regularised, r.max_g, r.max_de
    );
    if let Some(e) = &r.error {
        row.error = describe(e);
        row.fail(format!("{e}"));
    }
    row.check(r.regularised > 0, || {
        "regularisation was not exercised".into()
    });
    row.check(r.max_g <= 1e-10, || format!("|g| = {:.1e}", r.max_g));
    // the same motion as in minimal coordinates (both are the same VI on
    // the same Lagrangian up to the constraint solve): energy error close
    let rm = run_vi(
        &Variational::new(sys.minimal(), dt).unwrap(),
        &State::new([1.0, 0.5, -0.3], [0.0; 3]),
        steps,
    );
    row.check(rm.error.is_none() && r.max_de.is_finite(), || {
        "minimal reference failed".into()
    });
    rows.push(row);
    // explicit integrators use the acceleration-level KKT: same remedy
    let mut row = Row::new("zero rotational inertia, maximal, RK4 (acceleration-level KKT)");
    match Rk4::new(sys.maximal(), dt).rollout(&zm, 100) {
        Ok(t) => {
            row.happened = format!("100 steps, all finite: {}", t.iter().all(|z| z.is_finite()));
            row.remedy = "regularised KKT".into();
            row.check(t.iter().all(|z| z.is_finite()), || "non-finite".into());
        }
        Err(e) => {
            row.error = describe(&e);
            row.fail(format!("{e}"));
        }
    }
    rows.push(row);

    // scaling every mass and inertia by s leaves the motion unchanged
    let reference = Variational::new(DoublePendulum::default().minimal(), dt)
        .unwrap()
        .rollout(&State::new([2.0, -1.0], [3.0, -2.0]), 200)
        .unwrap();
    let mut worst = 0.0f64;
    let mut row = Row::new("all masses ×1e-9 … ×1e9 (from rest and moving), 200 steps");
    for s in [1e-9, 1e-3, 1e3, 1e9] {
        let mut sys = DoublePendulum::default();
        for l in [&mut sys.links.upper, &mut sys.links.lower] {
            l.mass *= s;
            l.inertia *= s;
        }
        let vi = Variational::new(sys.minimal(), dt).unwrap();
        match vi.rollout(&State::new([2.0, -1.0], [3.0, -2.0]), 200) {
            Ok(t) => worst = worst.max((t[200].q - reference[200].q).amax()),
            Err(e) => {
                row.error = describe(&e);
                row.fail(format!("scale {s:e}: {e}"));
            }
        }
        if let Err(e) = vi.step(&State::new([1.0, 0.5], [0.0, 0.0])) {
            row.error = describe(&e);
            row.fail(format!("scale {s:e} from rest: {e}"));
        }
    }
    row.happened = format!("max |q − q(unit masses)| after 200 steps: {worst:.1e} rad");
    row.remedy = "momentum residual scaled by |p₀| + m̄ (was 1 + |p₀|)".into();
    // 1e-9: the Newton tolerance (1e-12 relative) propagated through 200
    // chaotic-ish steps stays far below it; before the fix 2.5e-2
    row.check(worst <= 1e-9, || {
        format!("trajectories differ by {worst:e}")
    });
    rows.push(row);
    rows
}

/// A double-pendulum-like model at Δt = 0.01 from rest; on failure, retry
/// with 10 and 100 sub-steps. Expectation: a run completes (possibly with
/// sub-steps), every state finite; failures typed.
fn ratio_row<M: Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    case: &str,
    m: M,
    z0: &State<N>,
    dt: f64,
    steps: usize,
) -> Row {
    let e_scale = m.potential_energy(&z0.q).abs();
    with_substep_remedy(
        &format!("extreme: {case}, {steps} steps"),
        m,
        z0,
        dt,
        steps,
        e_scale,
        f64::INFINITY,
    )
}

/// Run at Δt; if a step fails or max |ΔE| exceeds `max_rel·e_scale`, retry
/// with 10 and then 100 sub-steps (the state's velocity recomputed for the
/// sub-step). Expectation: some run completes within that bound; failures
/// are typed.
fn with_substep_remedy<M: Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    case: &str,
    m: M,
    z0: &State<N>,
    dt: f64,
    steps: usize,
    e_scale: f64,
    max_rel: f64,
) -> Row {
    let mut row = Row::new(case);
    let max_de = max_rel * e_scale;
    let mut first_error = None;
    for k in [1usize, 10, 100] {
        let vi = Variational::new(m, dt)
            .unwrap()
            .substeps(k)
            .unwrap()
            .max_subdivision(0);
        let z = if k == 1 {
            *z0
        } else {
            State {
                q: z0.q,
                v: vigp::dynamics::discrete_velocity(&m, &z0.q, &z0.v, dt / k as f64).unwrap(),
            }
        };
        let r = run_vi(&vi, &z, steps);
        match &r.error {
            None if r.max_de > max_de => {
                if k == 1 {
                    first_error = Some(r.steps);
                    row.error = format!("none, but max |ΔE| = {:.0} J", r.max_de);
                }
            }
            None => {
                row.happened = format!(
                    "{}all steps, max |ΔE| = {:.2e} J = {:.1e} of the energy scale, max |g| {:.0e}",
                    if k == 1 {
                        String::new()
                    } else {
                        format!(
                            "without subdivision fails at step {}; ",
                            first_error.unwrap_or(0)
                        )
                    },
                    r.max_de,
                    r.max_de / e_scale,
                    r.max_g
                );
                row.check(r.max_g <= 1e-10, || format!("|g| = {:.1e}", r.max_g));
                if k > 1 {
                    row.remedy = format!("`substeps({k})` (stiff or fast part)");
                }
                return row;
            }
            Some(e) => {
                check_typed_failure(&mut row, e);
                if k == 1 {
                    first_error = Some(r.steps);
                    row.error = describe(e);
                }
            }
        }
    }
    row.happened = "fails even with 100 sub-steps".into();
    row.fail("no run completed");
    row
}

fn weyl(i: usize, k: f64) -> f64 {
    (i as f64 * k).fract()
}

fn sine_data(n: usize) -> (Vec<f64>, Vec<f64>) {
    let x: Vec<f64> = (0..n).map(|i| 4.0 * weyl(i + 1, 0.618_034) - 2.0).collect();
    let y = x.iter().map(|v| (1.5 * v).sin()).collect();
    (x, y)
}

/// GP edge cases: duplicated points, noise → 0, extrapolation, length
/// scales 1e-6 and 1e16, hyperparameter starts far off, huge targets.
pub fn gp_cases(_size: Size) -> Vec<Row> {
    let mut rows = Vec::new();
    let (x, y) = sine_data(30);

    // exact duplicates with noise allowed down to 1e-300
    let mut row = Row::new("GP: every point three times, noise bound 1e-300");
    let xd: Vec<f64> = x.iter().chain(&x).chain(&x).copied().collect();
    let yd: Vec<f64> = y.iter().chain(&y).chain(&y).copied().collect();
    let opts = TrainOptions {
        bounds: Bounds {
            noise_variance: (1e-300, 10.0),
            ..Bounds::default()
        },
        restarts: 2,
        ..Default::default()
    };
    match Gp::train(&xd, 1, &yd, 1, &opts) {
        Ok((gp, rep)) => {
            let p = gp.predict(&x).unwrap();
            let err = p
                .mean
                .iter()
                .zip(&y)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            row.happened = format!(
                "fitted σ_n² = {:.0e}, jitter {:.0e} added; max error at the data {err:.0e}",
                gp.output(0).hyperparameters().noise_variance,
                rep.outputs[0].jitter
            );
            row.remedy = "jitter ladder (1e-12 … 1e-3 of σ_f² + σ_n²), reported".into();
            // the jitter (≤ 1e-3 of σ_f²) bounds the interpolation error
            row.check(err < 1e-3, || format!("error at data {err:e}"));
            row.check(
                p.variance.iter().all(|v| v.is_finite() && *v >= 0.0),
                || "variance".into(),
            );
        }
        Err(e) => {
            row.error = describe_gp(&e);
            row.fail(format!("{e}"));
        }
    }
    rows.push(row);

    // fixed hyperparameters at the extremes
    for (l, noise) in [(1e-6, 1e-300), (1e16, 1e-300), (1e-6, 1e-2), (1e16, 1e-2)] {
        let mut row = Row::new(format!("GP: fixed ℓ = {l:e}, σ_n² = {noise:e}"));
        let hp = Hyperparameters::isotropic(1, l, 1.0, noise);
        match Gp::fit(&x, 1, &y, 1, &[hp], &TrainOptions::default()) {
            Ok(gp) => {
                let q = [x[3], 0.123, 1e6, 1e300, f64::MAX, -f64::MAX];
                let p = gp.predict(&q).unwrap();
                let ok = p
                    .mean
                    .iter()
                    .chain(&p.variance)
                    .all(|v| v.is_finite() && !v.is_nan());
                row.happened = format!(
                    "jitter {:.0e}; mean at a datum {:.4} (target {:.4}), at 1e300 {:.4}",
                    gp.output(0).jitter(),
                    p.mean[0],
                    y[3],
                    p.mean[3]
                );
                row.check(ok, || format!("non-finite prediction {p:?}"));
                // far away the posterior is the prior: constant mean, σ_f²
                let prior = y.iter().sum::<f64>() / y.len() as f64;
                if l < 1.0 {
                    row.check((p.mean[3] - prior).abs() < 1e-12, || {
                        format!("far mean {} vs prior {prior}", p.mean[3])
                    });
                }
            }
            Err(e) => {
                row.error = describe_gp(&e);
                row.fail(format!("{e}"));
            }
        }
        rows.push(row);
    }

    // far-off starts
    let good = Gp::train(&x, 1, &y, 1, &TrainOptions::default())
        .unwrap()
        .1
        .outputs[0]
        .log_marginal_likelihood;
    for (init, what) in [
        (Hyperparameters::isotropic(1, 1e-6, 1.0, 1e-2), "ℓ = 1e-6"),
        (
            Hyperparameters::isotropic(1, 1e16, 1e8, 1e-12),
            "ℓ = 1e16, σ_f² = 1e8",
        ),
    ] {
        let mut row = Row::new(format!("GP: hyperparameter start {what}, bounds 1e-8…1e20"));
        let single = TrainOptions {
            bounds: Bounds::uniform(1e-8, 1e20),
            initial: Some(init.clone()),
            restarts: 0,
            ..Default::default()
        };
        let with_restarts = TrainOptions {
            restarts: 5,
            bounds: Bounds::default(),
            ..single.clone()
        };
        match (
            Gp::train(&x, 1, &y, 1, &single),
            Gp::train(&x, 1, &y, 1, &with_restarts),
        ) {
            (Ok((_, r1)), Ok((_, r2))) => {
                let (a, b) = (
                    r1.outputs[0].log_marginal_likelihood,
                    r2.outputs[0].log_marginal_likelihood,
                );
                row.happened = format!(
                    "alone: stops on a flat LML plateau (zero gradient), LML {a:.1} vs optimum {good:.1}; with default bounds and 5 restarts: LML {b:.1}"
                );
                row.remedy = "random restarts in the bounds (default 5)".into();
                row.check(a.is_finite(), || "non-finite LML".into());
                // the restarts find the optimum of the default run to 1e-6
                // relative (same data, same bounds, different start)
                row.check((b - good).abs() <= 1e-6 * good.abs(), || {
                    format!("restarts reach {b}, optimum {good}")
                });
            }
            (Err(e), _) | (_, Err(e)) => {
                row.error = describe_gp(&e);
                row.fail(format!("{e}"));
            }
        }
        rows.push(row);
    }

    // inputs of size 1e300, targets 1e300 (squares overflow; the variance
    // s_y²·σ_f² ≈ 1e600 is not an f64) and 1e150 (variance representable)
    let mut row = Row::new("GP: inputs of size 1e300, targets of size 1e150 and 1e300");
    let xs: Vec<f64> = x.iter().map(|v| v * 1e300).collect();
    let ys: Vec<f64> = y.iter().map(|v| v * 1e150).collect();
    let ys_huge: Vec<f64> = y.iter().map(|v| v * 1e300).collect();
    match (
        Gp::train(&xs, 1, &ys, 1, &TrainOptions::default()),
        Gp::train(&xs, 1, &ys_huge, 1, &TrainOptions::default()),
    ) {
        (Ok((gp, _)), Ok((huge, _))) => {
            let p = gp.predict(&[0.123e300]).unwrap();
            let rel = (p.mean[0] / 1e150 - (1.5f64 * 0.123).sin()).abs();
            let mut ws = huge.workspace();
            let mut mean = [0.0];
            huge.predict_mean_into(&[0.123e300], &mut mean, &mut ws)
                .unwrap();
            let rel_huge = (mean[0] / 1e300 - (1.5f64 * 0.123).sin()).abs();
            let var = huge.predict(&[0.123e300]);
            row.happened = format!(
                "both train (before: `NotPositiveDefinite {{ jitter: 0 }}`, the squares overflowed); relative error at 0.123e300: {rel:.0e} (1e150), mean {rel_huge:.0e} (1e300)"
            );
            row.remedy = "overflow-free output scale and input standardisation".into();
            // the same problem as unit data, whose error is ~1e-6 here
            row.check(rel < 1e-4 && rel_huge < 1e-4, || {
                format!("relative errors {rel:e}, {rel_huge:e}")
            });
            match var {
                Err(e @ GpError::NonFinite { .. }) => {
                    row.error = format!("1e300: variance ≈ 1e600 → {}", describe_gp(&e))
                }
                other => row.fail(format!("1e300 variance should be reported, got {other:?}")),
            }
        }
        (Err(e), _) | (_, Err(e)) => {
            row.error = describe_gp(&e);
            row.fail(format!("{e}"));
        }
    }
    rows.push(row);
    rows
}

/// Projection from far off the manifold: the fourbar's velocity projection
/// from v_u up to 1e6 rad/s away, the configuration projection from
/// random configurations up to 100 rad away, and a learned integrator
/// stepped from a state far outside its data.
pub fn projection_cases(size: Size) -> Vec<Row> {
    let n = size.pick(60, 2_000);
    let fb = Fourbar::default().minimal();
    let dt = 0.01;
    let z0 = consistent_state(
        &fb,
        &SVector::from([0.9, -1.3, -0.4, 1.3]),
        &SVector::zeros(),
        dt,
    )
    .unwrap();
    let mut rng = stress_rng(5);
    let mut rows = Vec::new();
    for scale in [1e1, 1e3, 1e6] {
        let mut row = Row::new(format!(
            "projection: fourbar velocity, v_u off by up to {scale:e} rad/s, {n} draws"
        ));
        let (mut restarted, mut worst, mut failed) = (0, 0.0f64, 0);
        for _ in 0..n {
            let vu = SVector::<f64, 4>::from_fn(|_, _| (2.0 * rng() - 1.0) * scale);
            match project_velocity(&fb, &z0.q, &vu, dt, &StepOptions::default()) {
                Ok((v, info)) => {
                    restarted += info.restarted as usize;
                    let q2 = z0.q + v * dt;
                    let g = fb.constraints(&q2).amax();
                    worst = worst.max(
                        g / vigp::mechanism::length_scale::<vigp::systems::FourbarMinimal, 4, 2>(
                            &q2,
                        ),
                    );
                }
                Err(e) => {
                    failed += 1;
                    row.error = describe(&e);
                    check_typed_failure(&mut row, &e);
                }
            }
        }
        row.happened = format!(
            "first Newton run failed for {} of {n}; the restart recovered {restarted}, {failed} remain typed errors; max |g| {worst:.0e}",
            restarted + failed
        );
        row.remedy = "restart from the configuration projection (feasible start)".into();
        if scale >= 1e3 {
            row.check(restarted > 0, || "the restart was not exercised".into());
        }
        // stall tolerance: |g| ≤ 1e-10 relative
        row.check(worst <= 1e-10, || format!("|g| = {worst:e}"));
        rows.push(row);
    }
    let mut row = Row::new(format!(
        "projection: fourbar configuration from up to 100 rad off, {n} draws"
    ));
    let mut failed = 0;
    for i in 0..n {
        let scale = [0.1, 1.0, 10.0, 100.0][i % 4];
        let q = SVector::<f64, 4>::from_fn(|_, _| (2.0 * rng() - 1.0) * scale);
        match project_configuration(&fb, &q, &StepOptions::default()) {
            Ok((p, _)) => row.check(fb.constraints(&p).amax() <= 1e-12, || "|g|".into()),
            Err(e) => {
                failed += 1;
                row.error = describe(&e);
            }
        }
    }
    row.happened = format!(
        "{} of {n} converged (Gauss–Newton, minimum norm)",
        n - failed
    );
    row.check(failed == 0, || format!("{failed} failed"));
    rows.push(row);

    // a GP-only learned fourbar (5 samples) stepped from 100 rad/s
    let traj = vigp::Variational::midpoint(fb, dt / 10.0)
        .unwrap()
        .rollout(
            &consistent_state(&fb, &z0.q, &SVector::zeros(), dt / 10.0).unwrap(),
            400,
        )
        .unwrap();
    let positions: Vec<_> = traj.iter().step_by(10).map(|z| z.q).collect();
    let data = transitions(&positions, dt);
    let data: Vec<_> = data.iter().step_by(7).take(5).copied().collect();
    let opts = TrainOptions {
        restarts: 1,
        ..Default::default()
    };
    let mut row = Row::new("learned fourbar (5 samples, no prior) stepped from 100 rad/s");
    match Learned::train(fb, dt, &data, Encoding::Raw, Prior::Constant, &opts) {
        Ok((l, _)) => {
            let z = State {
                q: z0.q,
                v: SVector::from([100.0, -50.0, 80.0, 30.0]),
            };
            let mut ws = l.workspace();
            match l.step_in(&z, &mut ws) {
                Ok((next, info)) => {
                    let g = fb.constraint_violation(&State {
                        q: next.q + next.v * dt,
                        v: next.v,
                    });
                    row.happened = format!(
                        "prediction reverts to the data mean; projection corrects by {:.1} rad/s, |g(q + Δt·v)| {g:.0e}",
                        info.correction
                    );
                    row.check(g <= 1e-10 && next.is_finite(), || format!("|g| = {g:e}"));
                }
                Err(e) => {
                    row.error = describe(&e);
                    check_typed_failure(&mut row, &e);
                    row.happened = "typed error".into();
                }
            }
        }
        Err(e) => {
            row.error = format!("{e}");
            row.fail(format!("training failed: {e}"));
        }
    }
    rows.push(row);
    rows
}

/// Bad input: NaN/±∞ states and parameters into every integrator, solver
/// and GP entry point; wrong dimensions; corrupt model files.
pub fn bad_input(size: Size) -> Vec<Row> {
    let mut rows = Vec::new();
    let dt = 0.01;
    let dp = DoublePendulum::default().minimal();
    let fb = Fourbar::default().minimal();
    let bad_states = [
        State::new([f64::NAN, 0.0], [0.0, 0.0]),
        State::new([0.0, f64::INFINITY], [0.0, 0.0]),
        State::new([0.0, 0.0], [f64::NEG_INFINITY, 0.0]),
    ];
    let mut row = Row::new("NaN / ±∞ in the state: every integrator and solver");
    let mut kinds = std::collections::BTreeSet::new();
    for z in &bad_states {
        let results = [
            Variational::new(dp, dt).unwrap().step(z),
            Variational::midpoint(dp, dt).unwrap().step(z),
            Variational::new(dp, dt)
                .unwrap()
                .substeps(4)
                .unwrap()
                .step(z),
            ExplicitEuler::new(dp, dt).step(z),
            SymplecticEuler::new(dp, dt).step(z),
            Rk4::new(dp, dt).step(z),
            vigp::dynamics::acceleration(&dp, &z.q, &z.v).map(|_| *z),
            project_velocity(&dp, &z.q, &z.v, dt, &StepOptions::default())
                .map(|(v, _)| State { q: z.q, v }),
        ];
        for r in results {
            match r {
                Err(e @ StepError::NonFiniteState { .. }) => {
                    kinds.insert(describe(&e));
                }
                other => row.fail(format!("expected NonFiniteState, got {other:?}")),
            }
        }
    }
    let q4 = SVector::from([f64::NAN, 0.0, 0.0, 0.0]);
    for r in [
        project_configuration(&fb, &q4, &StepOptions::default()).map(|_| ()),
        consistent_state(&fb, &q4, &SVector::zeros(), dt).map(|_| ()),
    ] {
        row.check(matches!(r, Err(StepError::NonFiniteState { .. })), || {
            format!("projection: {r:?}")
        });
    }
    row.happened = "every call returns the same typed error; no NaN state is ever produced".into();
    row.error = kinds.into_iter().collect::<Vec<_>>().join("; ");
    rows.push(row);

    let mut row = Row::new("NaN / ∞ parameters, Δt ∉ (0, ∞), absurd options");
    let mut errs = Vec::new();
    let z = State::new([1.0, 0.0], [1.0, 0.0]);
    let s = DoublePendulum {
        gravity: [f64::NAN, -9.81],
        ..Default::default()
    };
    errs.push(Variational::new(s.minimal(), dt).and_then(|vi| vi.step(&z)));
    let mut s = DoublePendulum::default();
    s.links.lower.mass = f64::INFINITY;
    errs.push(Variational::new(s.minimal(), dt).and_then(|vi| vi.step(&z)));
    errs.push(Rk4::new(s.minimal(), dt).step(&z));
    let mut s = DoublePendulum::default();
    s.links.lower.mass = 0.0;
    s.links.lower.inertia = 0.0;
    errs.push(Variational::new(s.minimal(), dt).and_then(|vi| vi.step(&z)));
    for bad_dt in [0.0, -0.01, f64::NAN, f64::INFINITY] {
        errs.push(Variational::new(dp, bad_dt).and_then(|vi| vi.step(&z)));
        errs.push(Rk4::new(dp, bad_dt).step(&z));
    }
    errs.push(Variational::new(dp, f64::MAX).and_then(|vi| vi.step(&z)));
    errs.push(Variational::new(dp, 1e300).and_then(|vi| vi.step(&z)));
    errs.push(
        Variational::new(dp, dt)
            .and_then(|vi| vi.substeps(0))
            .and_then(|vi| vi.step(&z)),
    );
    errs.push(
        Variational::new(dp, dt)
            .and_then(|vi| vi.tolerance(f64::NAN))
            .and_then(|vi| vi.step(&z)),
    );
    errs.push(
        Variational::new(dp, dt)
            .and_then(|vi| {
                vi.with_options(StepOptions {
                    min_step: 0.0,
                    ..Default::default()
                })
            })
            .and_then(|vi| vi.step(&z)),
    );
    // velocities whose kinetic terms overflow (1e200² · ∂M/∂q); a state
    // [1e200, 0] alone is a valid, finite step: with the elbow still,
    // ∂M/∂q vanishes there and the DEL residual is exactly zero
    errs.push(
        Variational::new(dp, dt)
            .unwrap()
            .step(&State::new([0.0, 0.0], [1e200, 1e200])),
    );
    let mut kinds = std::collections::BTreeSet::new();
    for r in &errs {
        match r {
            Ok(z) => row.fail(format!("accepted: {z:?}")),
            Err(e) => {
                let d = describe(e);
                kinds.insert(d.split('`').nth(1).unwrap_or("").to_string());
            }
        }
    }
    row.happened = format!("{} calls, each a typed error", errs.len());
    row.error = code_list(kinds);
    rows.push(row);

    // GP: wrong dimensions and NaN
    let (x, y) = sine_data(20);
    let (gp, _) = Gp::train(
        &x,
        1,
        &y,
        1,
        &TrainOptions {
            restarts: 1,
            ..Default::default()
        },
    )
    .unwrap();
    let mut row = Row::new("GP: wrong dimensions, NaN inputs, workspace of another model");
    // a workspace of a model with another output count is refused; one of
    // a model of the same shape but another N is resized and reused (the
    // workspace is scratch, and online updates change N)
    let y2: Vec<f64> = y[..10].iter().flat_map(|v| [*v, -*v]).collect();
    let (other, _) = Gp::train(&x[..10], 1, &y2, 2, &TrainOptions::default()).unwrap();
    let (small, _) = Gp::train(&x[..10], 1, &y[..10], 1, &TrainOptions::default()).unwrap();
    let (mut m_fresh, mut v_fresh, mut m_reused, mut v_reused) = ([0.0], [0.0], [0.0], [0.0]);
    gp.predict_into(&[0.3], &mut m_fresh, &mut v_fresh, &mut gp.workspace())
        .unwrap();
    gp.predict_into(&[0.3], &mut m_reused, &mut v_reused, &mut small.workspace())
        .unwrap();
    if (m_fresh, v_fresh) != (m_reused, v_reused) {
        row.fail("a reused workspace of another N changed the prediction");
    }
    let mut ws = gp.workspace();
    let mut ws_other = other.workspace();
    let (mut m, mut v) = ([0.0], [0.0]);
    let mut m2 = [0.0; 2];
    let checks: Vec<Result<(), GpError>> = vec![
        gp.predict_into(&[1.0, 2.0], &mut m, &mut v, &mut ws),
        gp.predict_into(&[f64::NAN], &mut m, &mut v, &mut ws),
        gp.predict_into(&[1.0], &mut m2, &mut v, &mut ws),
        gp.predict_into(&[1.0], &mut m, &mut v, &mut ws_other),
        Gp::train(&x, 3, &y, 1, &TrainOptions::default()).map(|_| ()),
        Gp::train(&x, 1, &y[..5], 1, &TrainOptions::default()).map(|_| ()),
        Gp::fit(&x, 1, &y, 1, &[], &TrainOptions::default()).map(|_| ()),
    ];
    let mut kinds = std::collections::BTreeSet::new();
    for c in &checks {
        match c {
            Ok(()) => row.fail("accepted a bad call"),
            Err(e) => {
                kinds.insert(describe_gp(e).split('`').nth(1).unwrap_or("").to_string());
            }
        }
    }
    row.happened = format!("{} bad calls, each a typed error", checks.len());
    row.error = code_list(kinds);
    rows.push(row);

    // corrupt model files
    let saved = gp.to_saved();
    let json = serde_json::to_string(&saved).unwrap();
    let mut row = Row::new("GP model file: hand-made corruptions");
    let mut variants: Vec<(String, SavedGp)> = Vec::new();
    let mut b = saved.clone();
    b.output_dim = usize::MAX;
    variants.push(("output_dim = usize::MAX".into(), b));
    let mut b = saved.clone();
    b.outputs[0].jitter = 1e300;
    variants.push(("jitter 1e300".into(), b));
    let mut b = saved.clone();
    b.outputs[0].hyperparameters.signal_variance = 1e300;
    b.outputs[0].output_scale = 1e300;
    variants.push(("σ_f² = s_y = 1e300".into(), b));
    let mut b = saved.clone();
    b.input_normaliser.scale[0] = 0.0;
    variants.push(("normaliser scale 0".into(), b));
    let mut b = saved.clone();
    b.version = 99;
    variants.push(("version 99".into(), b));
    let mut msgs = Vec::new();
    for (what, b) in &variants {
        match Gp::from_saved(b, None).and_then(|g| g.predict(&[0.3])) {
            Ok(p) => row.fail(format!("{what}: accepted, predicts {p:?}")),
            Err(e) => msgs.push(format!("{what} → {}", describe_gp(&e))),
        }
    }
    row.happened = "each rejected, on load or (σ_f²·s_y² = ∞) at prediction".into();
    row.remedy = "`from_saved` checks N·p for overflow and the jitter ceiling; `predict` checks the variance".into();
    row.error = msgs.join("; ");
    rows.push(row);

    // byte-level corruption of the JSON text
    let mut row = Row::new("GP model file: truncations and byte flips of the JSON");
    let (mut parse_err, mut load_err, mut loaded) = (0, 0, 0);
    let stride = size.pick(13, 1);
    let bytes = json.as_bytes();
    let mut check = |text: &[u8], row: &mut Row| {
        let Ok(s) = std::str::from_utf8(text) else {
            return;
        };
        match serde_json::from_str::<SavedGp>(s) {
            Err(_) => parse_err += 1,
            Ok(sv) => match Gp::from_saved(&sv, None) {
                Err(_) => load_err += 1,
                Ok(g) => {
                    loaded += 1;
                    let probe: Vec<f64> = vec![0.3; g.input_dim()];
                    match g.predict(&probe) {
                        Ok(p) => row.check(
                            p.mean.iter().chain(&p.variance).all(|v| v.is_finite()),
                            || format!("non-finite prediction from {s}"),
                        ),
                        Err(_) => load_err += 1,
                    }
                }
            },
        }
    };
    for cut in (0..bytes.len()).step_by(stride) {
        check(&bytes[..cut], &mut row);
    }
    let flips = [b'0', b'9', b'-', b'e', b'.', b',', b'}', b'"', b' '];
    for pos in (0..bytes.len()).step_by(stride) {
        for f in flips {
            let mut t = bytes.to_vec();
            t[pos] = f;
            check(&t, &mut row);
        }
    }
    row.happened = format!(
        "{parse_err} rejected by the parser, {load_err} by `from_saved`, {loaded} loaded (still-valid models) and predict finite values"
    );
    row.error = "serde_json::Error, or `GpError::InvalidModel` / `DimensionMismatch` / `NonFinite` / `InvalidHyperparameter` / `NotPositiveDefinite`".into();
    rows.push(row);
    rows
}

/// A small deterministic generator in [0, 1) (SplitMix64).
pub fn stress_rng(seed: u64) -> impl FnMut() -> f64 {
    let mut s = seed;
    move || {
        s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = s;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Every case, in the README's order.
pub fn all(size: Size) -> Vec<Row> {
    let mut rows = long_horizon(size);
    rows.push(pendulum_fast(size));
    rows.extend(large_steps(size));
    rows.extend(singular(size));
    rows.extend(extreme_parameters(size));
    rows.extend(gp_cases(size));
    rows.extend(projection_cases(size));
    rows.extend(bad_input(size));
    rows
}

/// The pendulum at Δt = 0.1 s and 6 rev/s (no remedy needed): a sanity row.
pub fn pendulum_fast(size: Size) -> Row {
    let steps = size.pick(1_000, 100_000);
    let p = Pendulum::default().minimal();
    let z0 = State::new([2.0], [6.0 * REV]);
    let r = run_vi(&Variational::new(p, 0.1).unwrap(), &z0, steps);
    let mut row = Row::new(format!(
        "large step: pendulum, Δt = 0.1, 6 rev/s, {steps} steps"
    ));
    let e0 = p.energy(&z0);
    row.happened = format!("all steps; max |ΔE| {:.1} J of E₀ {e0:.0} J", r.max_de);
    if let Some(e) = &r.error {
        row.error = describe(e);
        row.fail(format!("{e}"));
    }
    // first-order energy oscillation at Δt·ω ≈ 3.8 rad per step: ≤ 10 %
    row.check(r.max_de <= 0.1 * e0, || format!("ΔE {}", r.max_de));
    row
}
