//! Unit tests of the maximal-coordinate integrator on hand-written
//! descriptions (the `mechanism!` ones are tested in the facade crate).

extern crate std;

use super::maximal::{LieStepper, Maximal, SpatialState, pack};
use super::model::{Joint3, JointType, Link3, Spatial};
use super::so3;
use nalgebra::{SVector, UnitQuaternion, Vector3};

const ID: [f64; 4] = [1.0, 0.0, 0.0, 0.0];

fn diag(a: f64, b: f64, c: f64) -> [[f64; 3]; 3] {
    [[a, 0.0, 0.0], [0.0, b, 0.0], [0.0, 0.0, c]]
}

fn joint(kind: JointType, parent: Option<usize>, child: usize) -> Joint3 {
    Joint3 {
        kind,
        parent,
        child,
        parent_anchor: [0.0; 3],
        child_anchor: [0.0; 3],
        axis: [0.0, 0.0, 1.0],
        rel: ID,
        damping: 0.0,
    }
}

/// A free rigid body without gravity, principal moments 1, 2, 3.
#[derive(Clone, Copy)]
struct Tumbler;

impl Spatial<1, 1> for Tumbler {
    const LINKS: [&'static str; 1] = ["body"];
    const JOINTS: [&'static str; 1] = ["float"];
    const TREE: [usize; 1] = [0];
    const DISSIPATIVE: bool = false;
    fn gravity(&self) -> [f64; 3] {
        [0.0; 3]
    }
    fn links(&self) -> [Link3; 1] {
        [Link3 {
            mass: 2.0,
            inertia: diag(1.0, 2.0, 3.0),
            com: [0.0; 3],
            length: 0.0,
        }]
    }
    fn joints(&self) -> [Joint3; 1] {
        [joint(JointType::Free, None, 0)]
    }
}

/// A spherical pendulum: a rod of length 1 hanging from the origin by a
/// ball joint, gravity along −z.
#[derive(Clone, Copy)]
struct Spherical {
    damping: f64,
}

impl Spatial<1, 1> for Spherical {
    const LINKS: [&'static str; 1] = ["rod"];
    const JOINTS: [&'static str; 1] = ["ball"];
    const TREE: [usize; 1] = [0];
    const DISSIPATIVE: bool = true;
    fn gravity(&self) -> [f64; 3] {
        [0.0, 0.0, -9.81]
    }
    fn links(&self) -> [Link3; 1] {
        [Link3 {
            mass: 1.0,
            inertia: diag(0.01, 1.0 / 12.0, 1.0 / 12.0),
            com: [0.5, 0.0, 0.0],
            length: 1.0,
        }]
    }
    fn joints(&self) -> [Joint3; 1] {
        let mut j = joint(JointType::Spherical, None, 0);
        j.damping = self.damping;
        [j]
    }
}

/// Every joint type in one chain, damped, with a loop: world –revolute→ a
/// –spherical→ b –prismatic→ c –fixed→ d, and d –revolute→ world closing.
#[derive(Clone, Copy)]
struct Zoo;

impl Spatial<4, 5> for Zoo {
    const LINKS: [&'static str; 4] = ["a", "b", "c", "d"];
    const JOINTS: [&'static str; 5] = ["r", "s", "p", "f", "close"];
    const TREE: [usize; 4] = [0, 1, 2, 3];
    const DISSIPATIVE: bool = true;
    fn gravity(&self) -> [f64; 3] {
        [0.3, -1.0, -9.81]
    }
    fn links(&self) -> [Link3; 4] {
        let full = [[0.2, 0.01, -0.02], [0.01, 0.3, 0.015], [-0.02, 0.015, 0.25]];
        [
            Link3 {
                mass: 1.0,
                inertia: full,
                com: [0.5, 0.05, -0.02],
                length: 1.0,
            },
            Link3 {
                mass: 0.7,
                inertia: diag(0.05, 0.1, 0.12),
                com: [0.3, 0.0, 0.0],
                length: 0.6,
            },
            Link3 {
                mass: 0.4,
                inertia: diag(0.02, 0.03, 0.04),
                com: [0.1, 0.0, 0.1],
                length: 0.2,
            },
            Link3 {
                mass: 0.9,
                inertia: diag(0.07, 0.06, 0.05),
                com: [0.0, 0.2, 0.0],
                length: 0.4,
            },
        ]
    }
    fn joints(&self) -> [Joint3; 5] {
        let (s, c) = libm::sincos(0.35);
        let tilt = [c, s * 0.6, 0.0, s * 0.8];
        let mut r = joint(JointType::Revolute, None, 0);
        r.axis = [0.0, 0.6, 0.8];
        r.damping = 0.3;
        let mut sph = joint(JointType::Spherical, Some(0), 1);
        sph.parent_anchor = [1.0, 0.0, 0.0];
        sph.damping = 0.1;
        sph.rel = tilt;
        let mut p = joint(JointType::Prismatic, Some(1), 2);
        p.parent_anchor = [0.6, 0.0, 0.0];
        p.axis = [0.0, 0.0, 1.0];
        p.damping = 0.2;
        let mut f = joint(JointType::Fixed, Some(2), 3);
        f.parent_anchor = [0.2, 0.0, 0.0];
        f.child_anchor = [0.0, 0.1, 0.0];
        let mut close = joint(JointType::Revolute, Some(3), 0);
        close.parent_anchor = [0.4, 0.0, 0.0];
        close.child_anchor = [0.5, 0.5, 0.0];
        close.axis = [1.0, 0.0, 0.0];
        close.rel = tilt;
        close.damping = 0.05;
        [r, sph, p, f, close]
    }
}

/// A deterministic pseudo-random number in [lo, hi).
struct Rng(u64);
impl Rng {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        lo + (hi - lo) * ((self.0 >> 11) as f64 / (1u64 << 53) as f64)
    }
    fn vector(&mut self, s: f64) -> Vector3<f64> {
        Vector3::new(
            self.uniform(-s, s),
            self.uniform(-s, s),
            self.uniform(-s, s),
        )
    }
}

/// x ± h·e_k with h = 1e-6·(1 + |x_k|), and the width 2h between them.
fn plus_minus(x: &SVector<f64, 24>, k: usize) -> (SVector<f64, 24>, SVector<f64, 24>, f64) {
    let h = 1e-6 * (1.0 + x[k].abs());
    let (mut p, mut m) = (*x, *x);
    p[k] += h;
    m[k] -= h;
    (p, m, 2.0 * h)
}

/// The Newton Jacobian (∂r/∂ν, ∂r/∂λ, ∂c/∂ν) against central differences of
/// the residual, relative to the largest entry of each block, on random
/// states of a mechanism with every joint type, damping, a loop, a full
/// inertia tensor and gravity off-axis. h = 1e-6 (scaled): truncation
/// O(h²) ~ 1e-12 and rounding O(ε/h) ~ 1e-10 relative, so 1e-7 cannot fail
/// by rounding and catches any wrong term.
#[test]
fn del_jacobian_matches_finite_differences() {
    let view = Maximal::<Zoo, 4, 5, 24, 24>::new(Zoo);
    let stepper = LieStepper::new(view, 0.01).unwrap();
    let mut rng = Rng(7);
    for _ in 0..5 {
        let z = SpatialState::<4> {
            x: core::array::from_fn(|_| rng.vector(1.0)),
            q: core::array::from_fn(|_| so3::exp(&rng.vector(2.0))),
            v: core::array::from_fn(|_| rng.vector(2.0)),
            w: core::array::from_fn(|_| rng.vector(8.0)),
        };
        let nu: SVector<f64, 24> = pack::<4, 24>(
            &core::array::from_fn(|_| rng.vector(2.0)),
            &core::array::from_fn(|_| rng.vector(8.0)),
        );
        let lambda = SVector::<f64, 24>::from_fn(|_, _| rng.uniform(-5.0, 5.0));
        let (a, b, g2) = stepper.del_jacobian(&z, &nu);
        let check = |name: &str, exact: f64, fd: f64, scale: f64| {
            assert!(
                (exact - fd).abs() <= 1e-7 * scale,
                "{name}: exact {exact} vs fd {fd} (scale {scale})"
            );
        };
        for k in 0..24 {
            let (p, m, width) = plus_minus(&nu, k);
            let (rp, cp) = stepper.del_residual(&z, &p, &lambda);
            let (rm, cm) = stepper.del_residual(&z, &m, &lambda);
            for i in 0..24 {
                check("dr/dnu", a[(i, k)], (rp[i] - rm[i]) / width, a.amax());
                check("dc/dnu", g2[(i, k)], (cp[i] - cm[i]) / width, g2.amax());
            }
            let (p, m, width) = plus_minus(&lambda, k);
            let (rp, _) = stepper.del_residual(&z, &nu, &p);
            let (rm, _) = stepper.del_residual(&z, &nu, &m);
            for i in 0..24 {
                check("dr/dlambda", b[(i, k)], (rp[i] - rm[i]) / width, b.amax());
            }
        }
    }
}

/// A free body spun about its intermediate principal axis (with a 1e-4
/// perturbation) flips over (ω_y changes sign), while the discrete momentum
/// map stays constant to the solver tolerance and the energy error stays
/// small; spun about its minor and major axes it stays close.
#[test]
fn tumbling_body_conserves_momentum_and_flips_about_the_intermediate_axis() {
    let dt = 0.01;
    let stepper = LieStepper::new(Maximal::<Tumbler, 1, 1, 6, 0>::new(Tumbler), dt).unwrap();
    let start = |w: Vector3<f64>| SpatialState::<1> {
        x: [Vector3::zeros()],
        q: [UnitQuaternion::identity()],
        v: [Vector3::new(0.1, 0.0, -0.2)],
        w: [w],
    };
    let z0 = start(Vector3::new(1e-4, 2.0, 1e-4));
    let (p0, l0) = stepper.momentum(&z0);
    let e0 = stepper.energy(&z0);
    let mut z = z0;
    let (mut min_wy, mut max_dl, mut max_de, mut max_norm) = (f64::MAX, 0.0f64, 0.0f64, 0.0f64);
    // The rotational DEL rows are the change of the momentum map (rotated
    // by R(q_{k+1})): each step changes it by at most the Newton residual,
    // √3·tol·p_scale with p_scale = |μ|∞ + max J_ii ≈ 4 + 3.
    let per_step = 3f64.sqrt() * 1e-12 * 7.0;
    let mut l_prev = l0;
    for _ in 0..3000 {
        z = stepper.step(&z).unwrap();
        let (p, l) = stepper.momentum(&z);
        assert!((l - l_prev).norm() <= per_step, "{:e}", (l - l_prev).norm());
        l_prev = l;
        max_dl = max_dl.max((l - l0).norm() / l0.norm());
        assert!((p - p0).norm() <= 1e-13);
        max_de = max_de.max((stepper.energy(&z) - e0).abs() / e0);
        max_norm = max_norm.max(z.norm_error());
        min_wy = min_wy.min(z.w[0].y);
    }
    // accumulated over 3000 steps (a random walk of such increments in
    // practice: √3000·1e-12 ≈ 5e-11 relative)
    assert!(
        max_dl < 3000.0 * per_step / l0.norm(),
        "angular momentum drift {max_dl:e}"
    );
    std::println!(
        "tumbler: max relative |L − L0| = {max_dl:.2e}, max |E − E0|/E0 = {max_de:.2e}, min ω_y = {min_wy:.3}"
    );
    assert!(max_norm < 1e-15, "quaternion norm error {max_norm:e}");
    assert!(min_wy < -1.9, "no flip: min ω_y = {min_wy}");
    // first-order VI: energy oscillates at O(Δt·|ω|) relative
    assert!(max_de < 1e-3, "energy error {max_de}");
    // stable axes: ω stays near its start
    for w in [Vector3::new(2.0, 1e-4, 1e-4), Vector3::new(1e-4, 1e-4, 2.0)] {
        let mut z = start(w);
        let mut dev = 0.0f64;
        for _ in 0..3000 {
            z = stepper.step(&z).unwrap();
            dev = dev.max((z.w[0] - w).norm());
        }
        assert!(dev < 0.01, "stable axis {w}: deviation {dev}");
    }
}

/// The spherical pendulum keeps its joint to solver tolerance, its
/// quaternion unit to rounding, the vertical angular momentum to the
/// solver tolerance (1e-14 here; no damping) and its energy bounded.
#[test]
fn spherical_pendulum_keeps_constraint_norm_and_vertical_momentum() {
    let dt = 0.01;
    let view = Maximal::<Spherical, 1, 1, 6, 3>::new(Spherical { damping: 0.0 });
    let tol = 1e-14;
    let options = crate::step::StepOptions {
        tolerance: tol,
        ..Default::default()
    };
    let stepper = LieStepper::with_options(view, dt, options).unwrap();
    // rod tilted 60° from the downward vertical, turning about the vertical
    // at 2 rad/s; v₀ chosen so that configuration 1 keeps the joint
    let q0 = UnitQuaternion::from_scaled_axis(Vector3::new(
        0.0,
        core::f64::consts::FRAC_PI_6 + core::f64::consts::FRAC_PI_2,
        0.0,
    ));
    let com = Vector3::new(0.5, 0.0, 0.0);
    let w_body = q0.inverse() * Vector3::new(0.0, 0.0, 2.0);
    let q1 = so3::advance(&q0, &w_body, dt);
    let z0 = SpatialState::<1> {
        x: [q0 * com],
        q: [q0],
        v: [(q1 * com - q0 * com) / dt],
        w: [w_body],
    };
    let e0 = stepper.energy(&z0);
    let (_, l0) = stepper.momentum(&z0);
    let mut z = z0;
    let (mut max_g, mut max_de, mut max_dl) = (0.0f64, 0.0f64, 0.0f64);
    for _ in 0..5000 {
        z = stepper.step(&z).unwrap();
        max_g = max_g.max(stepper.constraint_violation(&z));
        max_de = max_de.max((stepper.energy(&z) - e0).abs());
        max_dl = max_dl.max((stepper.momentum(&z).1.z - l0.z).abs());
        assert!(z.norm_error() < 1e-15);
    }
    assert!(max_g < 1e-10, "|g| = {max_g:e}");
    // each step changes L_z by at most its rotational Newton residual,
    // √3·tol·p_scale (p_scale = |b|∞ + max(m, J_ii) < 4 here)
    assert!(
        max_dl < 5000.0 * 3f64.sqrt() * tol * 4.0,
        "L_z drift {max_dl:e}"
    );
    assert!(max_de < 0.2, "energy error {max_de}");
}

/// The Hessians of the minimal view by N column passes
/// (`JetDir`, used above `ONE_PASS_HESSIAN` coordinates) equal those of
/// one second-order jet pass to rounding, on a mechanism with every joint
/// type, damping and a loop: ∂²L/∂q² and Σ μ_i ∇²g_i at random (q, v, μ).
/// Tolerance 1e-12 of the largest entry: the same derivatives summed in
/// another order.
#[test]
fn hessians_by_columns_match_one_pass() {
    use super::minimal;
    const N: usize = 6;
    const C: usize = 6;
    let mut rng = Rng(7);
    for _ in 0..5 {
        let q = SVector::<f64, N>::from_fn(|_, _| rng.uniform(-1.0, 1.0));
        let v = SVector::<f64, N>::from_fn(|_, _| rng.uniform(-2.0, 2.0));
        let mu = SVector::<f64, C>::from_fn(|_, _| rng.uniform(-3.0, 3.0));
        let lagrangian = minimal::LagrangianAt::<Zoo, 4, 5, N> { sys: &Zoo, v: &v };
        let weighted = minimal::WeightedConstraints::<Zoo, 4, 5, C> { sys: &Zoo, mu: &mu };
        let one = minimal::hessian_one_pass(&lagrangian, &q);
        let cols = minimal::hessian_by_columns(&lagrangian, &q);
        let scale = one.amax();
        assert!(scale > 1e-3, "a Hessian that tests nothing: {scale}");
        assert!((one - cols).amax() <= 1e-12 * scale, "{one} {cols}");
        let one = minimal::hessian_one_pass(&weighted, &q);
        let cols = minimal::hessian_by_columns(&weighted, &q);
        let scale = one.amax();
        assert!(scale > 1e-3, "a Hessian that tests nothing: {scale}");
        assert!((one - cols).amax() <= 1e-12 * scale, "{one} {cols}");
    }
}
