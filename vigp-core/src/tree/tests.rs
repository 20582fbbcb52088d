//! The engine against finite differences of its own energy (central
//! differences of functions that are quadratic in v are exact up to
//! rounding; in q they carry an O(ε²) truncation), the mass matrix's
//! symmetry, and the step's residual and energy behaviour.

use super::spatial::{IDENTITY, axis_angle, mul_mm, rpy};
use super::*;

/// A branched 5-body tree: mixed axes, a prismatic joint, offset centres
/// of mass, full inertias, rotated joint frames, damping and a spring.
fn bodies(damped: bool) -> [Body; 5] {
    let ic = [
        [0.03, 0.002, -0.001],
        [0.002, 0.025, 0.003],
        [-0.001, 0.003, 0.02],
    ];
    let d = if damped { 0.3 } else { 0.0 };
    let base = Body {
        parent: None,
        joint: JointKind::Revolute,
        axis: [0.0, 0.0, 1.0],
        rotation: IDENTITY,
        translation: [0.0, 0.0, 0.3],
        mass: 2.0,
        com: [0.05, 0.0, 0.1],
        inertia: ic,
        damping: d,
        stiffness: 0.0,
        rest: 0.0,
        limits: Limits::NONE,
    };
    let n = 1.0 / 3f64.sqrt();
    [
        base,
        Body {
            parent: Some(0),
            axis: [0.0, 1.0, 0.0],
            rotation: rpy(0.3, -0.2, 0.5),
            translation: [0.1, 0.02, 0.2],
            mass: 1.5,
            com: [0.2, 0.01, -0.02],
            ..base
        },
        Body {
            parent: Some(1),
            joint: JointKind::Prismatic,
            axis: [n, n, n],
            rotation: axis_angle([1.0, 0.0, 0.0], 0.7),
            translation: [0.4, 0.0, 0.0],
            mass: 0.8,
            com: [0.0, 0.05, 0.0],
            stiffness: 20.0,
            rest: 0.05,
            ..base
        },
        Body {
            parent: Some(1),
            axis: [1.0, 0.0, 0.0],
            rotation: mul_mm(&rpy(0.0, 1.0, 0.0), &rpy(0.2, 0.0, 0.0)),
            translation: [0.2, -0.1, 0.05],
            mass: 0.6,
            com: [0.1, 0.1, 0.0],
            ..base
        },
        Body {
            parent: Some(3),
            axis: [0.0, 0.0, 1.0],
            rotation: rpy(-0.4, 0.1, 0.9),
            translation: [0.25, 0.0, 0.0],
            mass: 0.4,
            com: [0.12, 0.0, 0.03],
            ..base
        },
    ]
}

const Q: [f64; 5] = [0.3, -0.8, 0.12, 1.1, -0.5];
const V: [f64; 5] = [0.7, -1.3, 0.4, 2.0, -0.9];

fn engine(b: &[Body; 5]) -> Engine<TreeRef<'_>> {
    Engine::new(TreeRef {
        bodies: b,
        gravity: [0.0, 0.0, -9.81],
    })
    .unwrap()
}

#[test]
fn momentum_and_forces_match_finite_differences_of_the_energy() {
    let b = bodies(false);
    let e = engine(&b);
    let mut ws = [BodyScratch::default(); 5];
    let (mut p, mut dt, mut dv) = ([0.0; 5], [0.0; 5], [0.0; 5]);
    e.terms(&Q, &V, &mut p, &mut dt, &mut dv, &mut ws).unwrap();
    let eps = 1e-6;
    let zero = [0.0; 5];
    for i in 0..5 {
        let mut en = |q: &[f64; 5], v: &[f64; 5]| e.energy(q, v, &mut ws).unwrap();
        let (mut vp, mut vm) = (V, V);
        vp[i] += eps;
        vm[i] -= eps;
        // E is quadratic in v: the central difference is exact but for rounding
        let fd_p = (en(&Q, &vp) - en(&Q, &vm)) / (2.0 * eps);
        assert!((fd_p - p[i]).abs() < 1e-8, "p[{i}] {} vs {fd_p}", p[i]);
        let (mut qp, mut qm) = (Q, Q);
        qp[i] += eps;
        qm[i] -= eps;
        let fd_v = (en(&qp, &zero) - en(&qm, &zero)) / (2.0 * eps);
        let fd_t = (en(&qp, &V) - en(&qm, &V)) / (2.0 * eps) - fd_v;
        // truncation O(ε²)·|∂³E| ≈ 1e-12, rounding |E|·1e-16/ε ≈ 1e-10
        assert!(
            (fd_v - dv[i]).abs() < 1e-7,
            "dV/dq[{i}] {} vs {fd_v}",
            dv[i]
        );
        assert!(
            (fd_t - dt[i]).abs() < 1e-7,
            "dT/dq[{i}] {} vs {fd_t}",
            dt[i]
        );
    }
}

#[test]
fn mass_matrix_is_symmetric_and_gives_the_momentum() {
    let b = bodies(false);
    let e = engine(&b);
    let mut ws = [BodyScratch::default(); 5];
    let mut m = [0.0; 25];
    e.mass_matrix(&Q, &mut m, &mut ws).unwrap();
    let mut p = [0.0; 5];
    e.momentum_of(&Q, &V, &mut p, &mut ws).unwrap();
    for i in 0..5 {
        let mv: f64 = (0..5).map(|j| m[i * 5 + j] * V[j]).sum();
        assert!((mv - p[i]).abs() < 1e-13, "(Mv)[{i}]");
        for j in 0..5 {
            assert!((m[i * 5 + j] - m[j * 5 + i]).abs() < 1e-14, "M[{i},{j}]");
        }
    }
}

#[test]
fn step_solves_the_residual_and_conserves_energy_without_damping() {
    let b = bodies(false);
    let e = engine(&b);
    let mut ws = [BodyScratch::default(); 5];
    let (mut q, mut v, mut p) = (Q, V, [0.0; 5]);
    e.momentum_of(&q, &v, &mut p, &mut ws).unwrap();
    let e0 = e.energy(&q, &v, &mut ws).unwrap();
    let dt = 1e-3;
    let (q0, v0, p0) = (q, v, p);
    let r = e
        .step(&mut q, &mut v, &mut p, &[0.0; 5], dt, &mut ws)
        .unwrap();
    assert_eq!(r.substeps, 1);
    let mut res = [0.0; 5];
    e.residual(&q0, &v0, &p0, &[0.0; 5], &v, dt, &mut res, &mut ws)
        .unwrap();
    let scale = p0.iter().fold(0.0f64, |a, x| a.max(x.abs())) + 1.0;
    assert!(res.iter().all(|x| x.abs() < 1e-11 * scale), "{res:?}");
    let mut worst = 0.0f64;
    for _ in 0..2000 {
        e.step(&mut q, &mut v, &mut p, &[0.0; 5], dt, &mut ws)
            .unwrap();
        worst = worst.max((e.energy(&q, &v, &mut ws).unwrap() - e0).abs());
    }
    // a first-order VI: energy error O(Δt) and bounded, no drift
    assert!(worst < 0.05 * e0.abs().max(1.0), "energy error {worst}");
}

#[test]
fn damping_dissipates_and_a_massless_leaf_is_singular() {
    let b = bodies(true);
    let e = engine(&b);
    let mut ws = [BodyScratch::default(); 5];
    let (mut q, mut v, mut p) = (Q, V, [0.0; 5]);
    e.momentum_of(&q, &v, &mut p, &mut ws).unwrap();
    let e0 = e.energy(&q, &v, &mut ws).unwrap();
    for _ in 0..3000 {
        e.step(&mut q, &mut v, &mut p, &[0.0; 5], 2e-3, &mut ws)
            .unwrap();
    }
    assert!(e.energy(&q, &v, &mut ws).unwrap() < e0 - 1.0);
    let mut b = bodies(false);
    b[4].mass = 0.0;
    b[4].inertia = [[0.0; 3]; 3];
    let e = engine(&b);
    let r = e.step(&mut q, &mut v, &mut p, &[0.0; 5], 2e-3, &mut ws);
    assert_eq!(r, Err(EngineError::SingularMass { body: 4 }));
}

#[test]
fn bias_forces_match_the_euler_lagrange_terms() {
    // b = Ṁv − ∂T/∂q + ∇V, with Ṁv = d/dε M(q + εv)v by central differences
    let b = bodies(false);
    let e = engine(&b);
    let mut ws = [BodyScratch::default(); 5];
    let mut bias = [0.0; 5];
    e.bias_forces(&Q, &V, &mut bias, &mut ws).unwrap();
    let (mut p, mut dt, mut dv) = ([0.0; 5], [0.0; 5], [0.0; 5]);
    e.terms(&Q, &V, &mut p, &mut dt, &mut dv, &mut ws).unwrap();
    let eps = 1e-6;
    let (mut qp, mut qm) = (Q, Q);
    for i in 0..5 {
        qp[i] += eps * V[i];
        qm[i] -= eps * V[i];
    }
    let (mut pp, mut pm) = ([0.0; 5], [0.0; 5]);
    e.momentum_of(&qp, &V, &mut pp, &mut ws).unwrap();
    e.momentum_of(&qm, &V, &mut pm, &mut ws).unwrap();
    for i in 0..5 {
        let mdot_v = (pp[i] - pm[i]) / (2.0 * eps);
        let expect = mdot_v - dt[i] + dv[i];
        // O(ε²) truncation and 1e-16/ε rounding, on terms of order 10
        assert!(
            (bias[i] - expect).abs() < 1e-7,
            "b[{i}] {} vs {expect}",
            bias[i]
        );
    }
}

/// The closed-form pair sums of `Engine::term_derivatives` against the
/// terms evaluated on jets of the 2N directions (q then v) through the
/// generic passes: two derivations of the same derivatives, exact but for
/// rounding (1e-12 of each matrix's largest entry), on the branched tree
/// with its spring and prismatic joint, at two states.
#[test]
fn term_derivatives_match_the_terms_on_jets() {
    use crate::Jet1;
    let b = bodies(true);
    let e = engine(&b);
    for (q, v) in [
        (Q, V),
        ([-1.2, 0.4, -0.3, 0.2, 2.5], [0.1, 0.9, -1.5, -0.6, 1.7]),
    ] {
        let mut ws = [BodyScratch::default(); 5];
        let (mut p_q, mut p_v, mut t_q, mut t_v, mut v_q) =
            ([0.0; 25], [0.0; 25], [0.0; 25], [0.0; 25], [0.0; 25]);
        e.term_derivatives(
            &q,
            &v,
            TermDerivatives {
                p_q: &mut p_q,
                p_v: &mut p_v,
                t_q: &mut t_q,
                t_v: &mut t_v,
                v_q: &mut v_q,
            },
            &mut ws,
        )
        .unwrap();
        let qj: [Jet1<10>; 5] = core::array::from_fn(|i| Jet1::variable(q[i], i));
        let vj: [Jet1<10>; 5] = core::array::from_fn(|i| Jet1::variable(v[i], 5 + i));
        let zero = Jet1::constant(0.0);
        let (mut p, mut t, mut g) = ([zero; 5], [zero; 5], [zero; 5]);
        let mut jw = [BodyScratch::<Jet1<10>>::zeroed(); 5];
        e.terms(&qj, &vj, &mut p, &mut t, &mut g, &mut jw).unwrap();
        let check = |name: &str, m: &[f64; 25], f: &dyn Fn(usize, usize) -> f64| {
            let big = m.iter().fold(0.0f64, |a, x| a.max(x.abs()));
            assert!(big > 0.0, "{name} vanishes");
            for i in 0..5 {
                for j in 0..5 {
                    let (got, want) = (m[i * 5 + j], f(i, j));
                    assert!(
                        (got - want).abs() <= 1e-12 * big,
                        "{name}[{i}][{j}]: {got} vs jets {want}"
                    );
                }
            }
        };
        check("p_q", &p_q, &|i, j| p[i].g[j]);
        check("p_v", &p_v, &|i, j| p[i].g[5 + j]);
        check("t_q", &t_q, &|i, j| t[i].g[j]);
        check("t_v", &t_v, &|i, j| t[i].g[5 + j]);
        check("v_q", &v_q, &|i, j| g[i].g[j]);
        // ∇V does not depend on v
        assert!(g.iter().all(|x| x.g[5..].iter().all(|d| *d == 0.0)));
        // the momentum part alone, with p itself: the same closed forms,
        // so the same numbers to the bit, and p that of `momentum_of`
        let (mut pm, mut mq, mut mv, mut want) = ([0.0; 5], [0.0; 25], [0.0; 25], [0.0; 5]);
        e.momentum_derivatives(&q, &v, &mut pm, &mut mq, &mut mv, &mut ws)
            .unwrap();
        e.momentum_of(&q, &v, &mut want, &mut ws).unwrap();
        assert_eq!((pm, mq, mv), (want, p_q, p_v));
        check("p_q alone", &mq, &|i, j| p[i].g[j]);
    }
}

/// An engine over a borrowed tree with other options steps as one made
/// with those options from the start (bit for bit), and refuses options
/// out of range as `with_options` does.
#[test]
fn borrowed_engine_steps_as_a_new_one() {
    let b = bodies(true);
    let e = engine(&b);
    let options = EngineOptions {
        max_depth: 0,
        tolerance: 1e-13,
        ..EngineOptions::default()
    };
    let borrowed = e.with_options_borrowed(options).unwrap();
    let fresh = Engine::with_options(
        TreeRef {
            bodies: &b,
            gravity: [0.0, 0.0, -9.81],
        },
        options,
    )
    .unwrap();
    let mut out = [[0.0; 5]; 2];
    for (k, slot) in out.iter_mut().enumerate() {
        let (mut q, mut v, mut p) = (Q, V, [0.0; 5]);
        let mut ws = [BodyScratch::default(); 5];
        e.momentum_of(&q, &v, &mut p, &mut ws).unwrap();
        let r = if k == 0 {
            borrowed.step(&mut q, &mut v, &mut p, &[0.1; 5], 2e-3, &mut ws)
        } else {
            fresh.step(&mut q, &mut v, &mut p, &[0.1; 5], 2e-3, &mut ws)
        };
        assert_eq!(r.unwrap().depth, 0);
        *slot = v;
    }
    assert_eq!(out[0], out[1]);
    for bad in [
        EngineOptions {
            tolerance: f64::NAN,
            ..options
        },
        EngineOptions {
            max_iterations: 0,
            ..options
        },
        EngineOptions {
            max_contraction: 1.5,
            ..options
        },
        EngineOptions {
            energy_tolerance: 0.0,
            ..options
        },
        EngineOptions {
            max_depth: 31,
            ..options
        },
    ] {
        assert!(matches!(
            e.with_options_borrowed(bad),
            Err(EngineError::InvalidOptions(_))
        ));
    }
}

/// The O(N) solve of the step's Newton matrix K = M + h·D − h·∂(∂T/∂q)/∂v
/// (`Engine::factor`) against a dense solve with K assembled from the
/// closed-form term derivatives (`Engine::term_derivatives`, themselves
/// checked against jets above), on the branched damped tree at h = 0.05
/// and fast velocities (so that h·C is not small against M), and at
/// h·C = 0. Both solves are exact but for rounding: 1e-12 relative.
#[test]
fn newton_solve_matches_a_dense_solve() {
    let b = bodies(true);
    let e = engine(&b);
    let mut ws = [BodyScratch::default(); 5];
    let rhs = [0.3, -1.1, 0.7, 0.25, -0.6];
    for (h, scale_v) in [(0.05, 4.0), (0.002, 1.0), (0.0, 1.0)] {
        let v: [f64; 5] = core::array::from_fn(|i| V[i] * scale_v);
        let mut x = [0.0; 5];
        e.newton_solve(&Q, &v, h, &rhs, &mut x, &mut ws).unwrap();
        let mut buf = [0.0; 125];
        e.term_derivatives(&Q, &v, TermDerivatives::split(&mut buf, 5), &mut ws)
            .unwrap();
        let (p_v, t_v) = (&buf[25..50], &buf[75..100]);
        let mut k = [0.0; 25];
        for i in 0..5 {
            for j in 0..5 {
                k[i * 5 + j] = p_v[i * 5 + j] - h * t_v[i * 5 + j];
            }
            k[i * 5 + i] += h * b[i].damping;
        }
        // h·C is a sizeable part of K at the first setting
        let hc = (0..25).fold(0.0f64, |m, i| m.max((h * t_v[i]).abs()));
        let mut dense = rhs;
        assert!(super::derivatives::dense_solve(&mut k, 5, &mut dense, 1));
        let big = dense.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for i in 0..5 {
            assert!(
                (x[i] - dense[i]).abs() <= 1e-12 * big,
                "h {h}: x[{i}] {} vs dense {} (max |h·C| {hc:.2e})",
                x[i],
                dense[i]
            );
        }
        if h == 0.05 {
            assert!(hc > 0.05, "max |h·C| {hc}");
        }
    }
}

/// A step from the state that `momentum_of` or `momentum_derivatives`
/// just evaluated (whose poses it reuses for its starting energy) equals,
/// bit for bit, the step from a workspace that holds nothing.
#[test]
fn a_step_after_the_momentum_equals_a_cold_step_bit_for_bit() {
    let b = bodies(true);
    let e = engine(&b);
    let step = |ws: &mut [BodyScratch], p: &mut [f64; 5]| {
        let (mut q, mut v) = (Q, V);
        e.step(&mut q, &mut v, p, &[0.1; 5], 2e-3, ws).unwrap();
        (q, v, *p)
    };
    let (mut p, mut ws) = ([0.0; 5], [BodyScratch::default(); 5]);
    e.momentum_of(&Q, &V, &mut p, &mut ws).unwrap();
    let warm = step(&mut ws, &mut p.clone());
    let mut cold_ws = [BodyScratch::default(); 5];
    assert_eq!(warm, step(&mut cold_ws, &mut p.clone()));
    let (mut pq, mut pv) = ([0.0; 25], [0.0; 25]);
    let mut p2 = [0.0; 5];
    e.momentum_derivatives(&Q, &V, &mut p2, &mut pq, &mut pv, &mut ws)
        .unwrap();
    assert_eq!(p2, p);
    assert_eq!(warm, step(&mut ws, &mut p2));
}

/// The derivative step started from a guess (as a rollout starts it)
/// converges to the state of the unguessed one, and its A and B agree, to
/// the solver's tolerance (1e-13 here): 1e-10 of the largest entry.
#[test]
fn a_guessed_derivative_step_agrees_with_the_unguessed_one() {
    let b = bodies(true);
    let e = Engine::with_options(
        TreeRef {
            bodies: &b,
            gravity: [0.0, 0.0, -9.81],
        },
        EngineOptions {
            tolerance: 1e-13,
            ..EngineOptions::default()
        },
    )
    .unwrap();
    let inputs = [1, 3];
    let tau = [0.0, 0.4, 0.0, -0.2, 0.0];
    let run = |guess: Option<&[f64]>| {
        let (mut q, mut v, mut p) = (Q, V, [0.0; 5]);
        let (mut a, mut bm) = ([0.0; 100], [0.0; 20]);
        let mut scratch = [0.0; derivative_scratch_len(5, 2)];
        let mut ws = [BodyScratch::default(); 5];
        let out = DerivativeBuffers {
            a: &mut a,
            b: &mut bm,
            scratch: &mut scratch,
            start_known: false,
        };
        let r = e
            .step_derivatives_guessed(
                &mut q, &mut v, &mut p, &tau, &inputs, 2e-3, guess, out, &mut ws,
            )
            .unwrap();
        (q, v, a, bm, r.iterations)
    };
    let plain = run(None);
    // a guess near the root (the plain step's v₁, moved off it)
    let near = plain.1.map(|x| x + 1e-4);
    let guessed = run(Some(&near));
    assert!(guessed.4 < plain.4, "{} vs {}", guessed.4, plain.4);
    let close = |x: &[f64], y: &[f64], what: &str| {
        let big = x.iter().fold(0.0f64, |m, a| m.max(a.abs()));
        let err = x
            .iter()
            .zip(y)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(err <= 1e-10 * big, "{what}: {err:e} of {big:e}");
    };
    close(&plain.1, &guessed.1, "v");
    close(&plain.2, &guessed.2, "A");
    close(&plain.3, &guessed.3, "B");
    assert_eq!(plain.0, guessed.0);
}
