//! Inputs and springs on spatial mechanisms (`actuated`, `stiffness`,
//! `rest` on revolute and prismatic joints of a `gravity: [gx, gy, gz]`
//! description), in both views: the minimal view runs the planar forced
//! step and its exact derivatives unchanged; the maximal Lie-group VI takes
//! the input in the damping force's slot and the spring as a potential.
//!
//! Checked: u = 0 is the unactuated mechanism bit for bit; the generated
//! input terms against dual numbers; A and B against five-point
//! differences; a constant torque's static equilibrium (closed form); the
//! two views converge to each other at first order under the same inputs;
//! no allocation. (The parallel-axes comparison with the planar actuated
//! and sprung mechanisms is in `tests/step/spatial.rs`.) Numbers print with
//! `-- --nocapture`.

use crate::common;
use common::{Rng, ab_errors, same_bits, same_spatial_bits, tight};
use nalgebra::{SVector, UnitQuaternion, Vector3};
use vigp::embedded::Dynamics;
use vigp::projection::{consistent_state, consistent_state_holding};
use vigp::spatial::LieStepper;
use vigp::{Integrator, Mechanism, State, Variational};

/// Declares the 3-D double pendulum `$name` with the doc comment `$doc`:
/// non-parallel axes, a torsion spring on each joint, elbow damping, and a
/// motor on each joint when `$actuated` is given.
macro_rules! arm3 {
    ($(#[doc = $doc:tt])* $name:ident [$($actuated:ident)?]) => {
        vigp::mechanism! {
            $(#[doc = $doc])*
            pub $name {
                gravity: [0.0, 0.0, -9.81],
                links {
                    upper: { mass: 1.0, length: 1.0, inertia: [0.0002, 0.0834333, 0.0834333],
                             frame: [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]] },
                    lower: { mass: 1.0, length: 1.0, inertia: [0.0002, 0.0834333, 0.0834333],
                             frame: [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]] },
                }
                joints {
                    shoulder: revolute(world, upper.start) { axis: [0.0, 1.0, 0.0], $($actuated,)? stiffness: 4.0, rest: 0.3 },
                    elbow: revolute(upper.end, lower.start) { axis: [0.0, 0.6, 0.8], damping: 0.2, stiffness: 2.5, rest: -0.4 $(, $actuated)? },
                }
            }
        }
    };
}

arm3! {
    /// A 3-D double pendulum with non-parallel axes, a motor and a torsion
    /// spring on each joint, and elbow damping.
    Arm3 [actuated]
}

arm3! {
    /// `Arm3` without the motors.
    Arm3Plain []
}

/// Declares the spatial slider-crank `$name` with the doc comment `$doc`:
/// a torsion spring on the crankshaft and a linear one on the rail, a
/// motor on the crankshaft and a force on the rail when `$actuated` is
/// given, the joint `wristpin` or `rail` declared last (closing the loop).
macro_rules! crank3 {
    ($(#[doc = $doc:tt])* $name:ident [$($actuated:ident)?] rail last) => {
        crank3!(@joints $(#[doc = $doc])* $name [$($actuated)?]
            wristpin: spherical(rod.end, slider.com),
            rail: prismatic(world @ [0.75, 0.15, 0.0], slider.com) { axis: [1.0, 0.0, 0.0], $($actuated,)? stiffness: 20.0, rest: 0.02 },
        );
    };
    ($(#[doc = $doc:tt])* $name:ident [$($actuated:ident)?] wristpin last) => {
        crank3!(@joints $(#[doc = $doc])* $name [$($actuated)?]
            rail: prismatic(world @ [0.75, 0.15, 0.0], slider.com) { axis: [1.0, 0.0, 0.0], $($actuated,)? stiffness: 20.0, rest: 0.02 },
            wristpin: spherical(rod.end, slider.com),
        );
    };
    (@joints $(#[doc = $doc:tt])* $name:ident [$($actuated:ident)?] $($last:tt)*) => {
        vigp::mechanism! {
            $(#[doc = $doc])*
            pub $name {
                gravity: [0.0, 0.0, -9.81],
                links {
                    crank: { mass: 0.5, length: 0.2, inertia: [0.0001, 0.0017167, 0.0017167] },
                    rod: { mass: 0.4, length: 0.6, inertia: [0.00008, 0.012040, 0.012040] },
                    slider: { mass: 0.6, inertia: [0.0005, 0.0008, 0.0008] },
                }
                joints {
                    crankshaft: revolute(world, crank.start) { axis: [0.0, 1.0, 0.0], damping: 0.05, $($actuated,)? stiffness: 0.3, rest: 0.2 },
                    crankpin: spherical(crank.end, rod.start),
                    $($last)*
                }
            }
        }
    };
}

crank3! {
    /// The spatial slider-crank with its rail declared last, so that the
    /// prismatic rail closes the loop: a motor on the crankshaft (tree) and
    /// a force with a spring on the rail (a loop joint, whose coordinate
    /// the minimal view reads from the link poses).
    DriveCrank3 [actuated] rail last
}

crank3! {
    /// `DriveCrank3` without the inputs.
    PlainCrank3 [] rail last
}

crank3! {
    /// The spatial slider-crank in its usual order (the rail a tree joint,
    /// the wristpin closing the loop) with the same inputs and springs.
    DriveCrankTree [actuated] wristpin last
}

vigp::mechanism! {
    /// A damped rod hanging from a horizontal axis (y), driven by a torque:
    /// l_c = 0.5 m, I_pivot = 1/3 kg·m².
    pub TorquePendulum3 {
        gravity: [0.0, 0.0, -9.81],
        links {
            rod: { mass: 1.0, length: 1.0, inertia: [0.0002, 0.0833333, 0.0833333],
                   frame: [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]] },
        }
        joints {
            pivot: revolute(world, rod.start) { axis: [0.0, 1.0, 0.0], damping: 2.0, actuated },
        }
    }
}

vigp::mechanism! {
    /// Inputs alone (no damping, no springs, no gravity): a rotor turning
    /// about its principal axis z (I_zz = 3 kg·m², centre of mass on the
    /// axis) and a 2 kg slider on a rail along (1, 1, 0)/√2.
    pub Motors {
        gravity: [0.0, 0.0, 0.0],
        links {
            rotor: { mass: 1.0, inertia: [1.0, 2.0, 3.0] },
            slider: { mass: 2.0, inertia: [0.1, 0.1, 0.1] },
        }
        joints {
            spin: revolute(world, rotor.com) { axis: [0.0, 0.0, 1.0], actuated },
            slide: prismatic(world @ [0.0, 0.0, 1.0], slider.com) { axis: [1.0, 1.0, 0.0], actuated },
        }
    }
}

/// A consistent minimal state of the slider-crank near crank angle `a`
/// (the rod yawed to reach the off-plane rail, the slider's ball joint
/// undoing the rest so that the slider keeps the rail's orientation).
fn crank_state<M: Mechanism<9, 7>>(m: &M, a: f64, rate: f64, dt: f64) -> State<9> {
    let yaw = (0.15f64 / 0.6).asin();
    let pin = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
    let wrist = (UnitQuaternion::from_axis_angle(&Vector3::y_axis(), a) * pin).inverse();
    let (p, w) = (pin.quaternion(), wrist.quaternion());
    let q = SVector::from([a, p.w, p.i, p.j, p.k, w.w, w.i, w.j, w.k]);
    let mut v = SVector::<f64, 9>::zeros();
    v[0] = rate;
    // the crank angle and rate held: the loop is closed by the others
    // (without holding, the projection may move the crank far from `a`)
    consistent_state_holding(m, &q, &v, dt, &[0]).unwrap()
}

fn arm_states(rng: &mut Rng, n: usize) -> Vec<State<2>> {
    (0..n)
        .map(|_| {
            State::new(
                [rng.uniform(-1.5, 1.5), rng.uniform(-1.5, 1.5)],
                [rng.uniform(-2.0, 2.0), rng.uniform(-2.0, 2.0)],
            )
        })
        .collect()
}

/// u = 0 steps the actuated mechanism exactly as the same mechanism
/// without `actuated` (springs and damping in both), in both views: one
/// step and 30-step rollouts, compared bit for bit; so does an empty input
/// vector (U = 0), with the same state derivatives A as under u = 0.
#[test]
fn zero_input_is_the_unactuated_spatial_mechanism_bit_for_bit() {
    let dt = 0.01;
    let mut rng = Rng(5);
    // minimal views
    let (a, p) = (Arm3::default().minimal(), Arm3Plain::default().minimal());
    let zero = SVector::<f64, 2>::zeros();
    let (va, vp) = (
        Variational::new(a, dt).unwrap(),
        Variational::new(p, dt).unwrap(),
    );
    let (ma, mp) = (
        Variational::midpoint(a, dt).unwrap(),
        Variational::midpoint(p, dt).unwrap(),
    );
    let none = SVector::<f64, 0>::zeros();
    for z in arm_states(&mut rng, 5) {
        assert!(same_bits(
            &va.step_forced(&z, &zero).unwrap(),
            &vp.step(&z).unwrap()
        ));
        // U = 0 (no input vector) is the input-free step, derivatives
        // included, for an actuated mechanism too
        assert!(same_bits(
            &va.step_forced(&z, &none).unwrap(),
            &vp.step(&z).unwrap()
        ));
        let (z1, d1) = va.step_derivatives(&z, &zero).unwrap();
        let (z0, d0) = va.step_derivatives(&z, &none).unwrap();
        assert!(same_bits(&z0, &z1));
        assert_eq!(d0.a.matrix::<4>(), d1.a.matrix::<4>());
        assert!(same_bits(
            &ma.step_forced(&z, &zero).unwrap(),
            &mp.step(&z).unwrap()
        ));
    }
    let z0 = arm_states(&mut rng, 1)[0];
    let ra = va.rollout_forced(&z0, &[zero; 30]).unwrap();
    let rp = vp.rollout(&z0, 30).unwrap();
    assert!(ra.iter().zip(&rp).all(|(x, y)| same_bits(x, y)));
    let (c, cp) = (
        DriveCrank3::default().minimal(),
        PlainCrank3::default().minimal(),
    );
    let z = crank_state(&c, 0.3, 4.0, dt);
    let ra = Variational::new(c, dt)
        .unwrap()
        .rollout_forced(&z, &[zero; 30])
        .unwrap();
    let rp = Variational::new(cp, dt).unwrap().rollout(&z, 30).unwrap();
    assert!(ra.iter().zip(&rp).all(|(x, y)| same_bits(x, y)));

    // maximal views
    let (sa, sp) = (Arm3::default(), Arm3Plain::default());
    let (la, lp) = (
        LieStepper::new(sa.maximal(), dt).unwrap(),
        LieStepper::new(sp.maximal(), dt).unwrap(),
    );
    for z in arm_states(&mut rng, 5) {
        let x = sa.minimal().to_maximal(&z, dt);
        assert!(same_spatial_bits(
            &la.step_forced(&x, &zero).unwrap(),
            &lp.step(&x).unwrap()
        ));
        // U = 0 (no input vector) as in the minimal view
        assert!(same_spatial_bits(
            &la.step_forced(&x, &none).unwrap(),
            &lp.step(&x).unwrap()
        ));
    }
    let x0 = sa.minimal().to_maximal(&z0, dt);
    let mut ra = [x0; 31];
    let mut rp = ra;
    la.rollout_forced_into(&x0, &[zero; 30], &mut ra).unwrap();
    lp.rollout_into(&x0, &mut rp).unwrap();
    assert!(ra.iter().zip(&rp).all(|(x, y)| same_spatial_bits(x, y)));
    la.rollout_forced_into(&x0, &[none; 30], &mut ra).unwrap();
    assert!(ra.iter().zip(&rp).all(|(x, y)| same_spatial_bits(x, y)));
    let (sc, scp) = (DriveCrank3::default(), PlainCrank3::default());
    let x0 = sc.minimal().to_maximal(&z, dt);
    let (lc, lcp) = (
        LieStepper::new(sc.maximal(), dt).unwrap(),
        LieStepper::new(scp.maximal(), dt).unwrap(),
    );
    let mut ra = [x0; 31];
    let mut rp = ra;
    lc.rollout_forced_into(&x0, &[zero; 30], &mut ra).unwrap();
    lcp.rollout_into(&x0, &mut rp).unwrap();
    assert!(ra.iter().zip(&rp).all(|(x, y)| same_spatial_bits(x, y)));
}

/// The generated input terms of the minimal views against dual numbers:
/// B(q) (`Dynamics::input_matrix`, jets) against ∇_q W(q; u) of the
/// reference virtual work (`Mechanism::input_force`, num-dual) for unit
/// inputs, and Σu_i∇²s_i (`input_force_jacobian`, second-order jets)
/// against central differences of B(q)u (h = 1e-6: truncation ~1e-12,
/// rounding ~1e-10, far below the 1e-7 bound). The slider-crank's rail
/// input acts on a loop joint (its coordinate read from the link poses);
/// the springs' potential is checked through ∇V against num-dual.
#[test]
fn spatial_input_terms_match_dual_numbers() {
    let dt = 0.01;
    let c = DriveCrank3::default().minimal();
    // the spatial minimal view's constants are `()`: it only validates
    c.constants().unwrap();
    let k = ();
    let mut worst = [0.0f64; 3];
    for a in [0.3, 1.4, -2.0, 2.8] {
        let z = crank_state(&c, a, 0.0, dt);
        let q = z.q;
        let b = c.input_matrix::<2>(&k, &q);
        for i in 0..2 {
            let mut u = [0.0; 2];
            u[i] = 1.0;
            let r = c.input_force::<f64>(&q, &u);
            worst[0] = worst[0].max((b.column(i) - r).amax() / r.amax().max(1.0));
        }
        let u = SVector::<f64, 2>::new(1.3, -2.1);
        let h = 1e-6;
        let jac = c.input_force_jacobian::<2>(&k, &q, &u);
        for j in 0..9 {
            let (mut qp, mut qm) = (q, q);
            qp[j] += h;
            qm[j] -= h;
            let fd =
                (c.input_matrix::<2>(&k, &qp) * u - c.input_matrix::<2>(&k, &qm) * u) / (2.0 * h);
            worst[1] = worst[1].max((fd - jac.column(j)).amax() / jac.amax().max(1.0));
        }
        // ∇V with the springs (the loop rail's and the crankshaft's)
        let mut t = vigp::embedded::Terms::zeros();
        c.terms(&k, &q, &mut t);
        let grad = num_dual::gradient(|x| c.potential_energy(&x), &q).1;
        worst[2] = worst[2].max((t.dpotential - grad).amax() / grad.amax());
    }
    println!(
        "slider-crank: B vs dual {:.1e}, Σu∇²s vs differences {:.1e}, ∇V vs dual {:.1e}",
        worst[0], worst[1], worst[2]
    );
    assert!(worst[0] <= 1e-12 && worst[2] <= 1e-12, "{worst:?}");
    assert!(worst[1] <= 1e-7, "{worst:?}");
    // the spring energy against its closed form without gravity:
    // ½k₁(θ − 0.2)² on the crankshaft (a coordinate) plus ½k₂(s − 0.02)²
    // on the rail, s = x_slider − 0.75 read from the forward kinematics
    // (the slider's frame origin is its centre of mass), and ∇V against
    // central differences of it (h = 1e-6; bound 1e-7 relative)
    let weightless = DriveCrank3 {
        gravity: [0.0; 3],
        ..Default::default()
    };
    let w = weightless.minimal();
    w.constants().unwrap();
    let kw = ();
    let (mut e_v, mut e_g) = (0.0f64, 0.0f64);
    let closed = |q: &SVector<f64, 9>| {
        let s = weightless.link_poses(q)[2].origin[0] - 0.75;
        0.5 * 0.3 * (q[0] - 0.2).powi(2) + 0.5 * 20.0 * (s - 0.02).powi(2)
    };
    for a in [0.3, 1.4, -2.0] {
        let q = crank_state(&c, a, 0.0, dt).q;
        let v = w.potential(&kw, &q);
        e_v = e_v.max((v - closed(&q)).abs() / closed(&q));
        let mut t = vigp::embedded::Terms::zeros();
        w.terms(&kw, &q, &mut t);
        for j in 0..9 {
            let (mut qp, mut qm) = (q, q);
            qp[j] += 1e-6;
            qm[j] -= 1e-6;
            let fd = (closed(&qp) - closed(&qm)) / 2e-6;
            e_g = e_g.max((t.dpotential[j] - fd).abs() / t.dpotential.amax());
        }
    }
    println!("spring energy vs closed form {e_v:.1e}, its gradient vs differences {e_g:.1e}");
    assert!(e_v <= 1e-12 && e_g <= 1e-7, "{e_v:e} {e_g:e}");
    // the rail's loop coordinate has a configuration-dependent gradient
    let z = crank_state(&c, 0.3, 0.0, dt);
    assert!(
        c.input_force_jacobian::<2>(&k, &z.q, &SVector::from([0.0, 1.0]))
            .amax()
            > 1e-3
    );
}

/// A = ∂z₁/∂z₀ and B = ∂z₁/∂u of the spatial minimal forced step
/// (`Variational::step_derivatives`, exact, by the implicit function
/// theorem) against five-point central differences (ε scaled by the
/// entry, at least 1; steps solved to 1e-14), both rules, relative to the
/// whole of A (B), bound 1e-6, on the 3-D arm (non-parallel axes,
/// springs, damping; ε = 1e-4: truncation O(ε⁴) and solver noise
/// 1e-14/ε far below the bound) and the slider-crank (quaternions, a loop,
/// an input and a spring on the loop joint; ε = 1e-6: its step is
/// strongly nonlinear along the quaternion coordinates, where |A| reaches
/// ~3e3 (the unit-norm rows act within one Δt) and ε = 1e-4 leaves a
/// truncation error of ~2e-4 absolute; at 1e-6 truncation is negligible
/// and rounding ~1e-14·|v|/ε ~ 1e-7 absolute, 1e-10 relative).
fn check_ab<
    M: Mechanism<N, C> + Copy + vigp::Inputs<U>,
    const N: usize,
    const C: usize,
    const U: usize,
>(
    name: &str,
    m: M,
    states: &[State<N>],
    fd: f64,
) -> f64 {
    let dt = 0.01;
    let mut rng = Rng(17);
    let mut worst = 0.0f64;
    for mid in [false, true] {
        let vi = if mid {
            Variational::midpoint(m, dt).unwrap()
        } else {
            Variational::new(m, dt).unwrap()
        }
        .tolerance(1e-14)
        .unwrap();
        for z in states {
            let u = SVector::<f64, U>::from_fn(|_, _| rng.uniform(-2.0, 2.0));
            let (z1, d) = vi.step_derivatives(z, &u).unwrap();
            assert_eq!(z1, vi.step_forced(z, &u).unwrap());
            let (e_a, e_b) = ab_errors(z, &u, &d, fd, |z, u| vi.step_forced(z, u).unwrap());
            assert!(e_a <= 1e-6, "{name} mid={mid}: A relative error {e_a:.2e}");
            assert!(e_b <= 1e-6, "{name} mid={mid}: B relative error {e_b:.2e}");
            worst = worst.max(e_a).max(e_b);
        }
    }
    println!("{name}: worst relative |A − A_fd|, |B − B_fd| = {worst:.1e}");
    worst
}

#[test]
fn spatial_step_derivatives_match_central_differences() {
    let dt = 0.01;
    let mut rng = Rng(41);
    check_ab::<_, 2, 0, 2>(
        "3-D arm",
        Arm3::default().minimal(),
        &arm_states(&mut rng, 3),
        1e-4,
    );
    let c = DriveCrank3::default().minimal();
    // crank angles 0.3, 1.0 and 1.9 rad at 3 rad/s. At 1.9 rad the
    // midpoint step failed (`LineSearchFailed`) until the KKT solve checked
    // its solutions through an ill-conditioned J (see
    // `the_rail_closed_slider_crank_steps_in_quaternion_coordinates`). At
    // 1.0 rad the central differences are rounding-limited: worst relative
    // error 2.5e-6, 2.1e-6, 4.4e-7, 2.0e-7 at h = 1e-7, 1e-6, 3e-6, 1e-5
    // (falling as h grows, so not a wrong derivative); h = 1e-5.
    let states: Vec<State<9>> = [0.3, 1.0, 1.9]
        .iter()
        .map(|&a| crank_state(&c, a, 3.0, dt))
        .collect();
    check_ab::<_, 9, 7, 2>("slider-crank (loop input)", c, &states, 1e-5);
}

/// The slider-crank with its rail closing the loop (`PlainCrank3` with its
/// damping set to 0: springs and gravity only, so energy is conserved) in
/// the minimal view, 20 s from crank angle 0.3 rad. In quaternion
/// coordinates M is singular along each quaternion (the norm constraint
/// fixes that direction), so the Newton matrix J = −M + O(Δt) had
/// cond(J) ≈ 1e12–1e14 while the whole KKT system had ≈ 1e4: the solve
/// through J⁻¹ lost the multipliers, and the step stalled after 4 steps at
/// Δt = 4 ms (`LineSearchFailed`, residual 1.6e-4) and after 16 s at 1 ms
/// (1.6e-10). The KKT solve now checks such a solution's residual and
/// otherwise solves the augmented system. Every step must converge (not
/// stall), |g| stay at rounding (≤ 1e-11), and the energy error fall with
/// Δt at the rule's order: by more than 2.5 from 4 to 1 ms for the first
/// order (4 expected), more than 10 for the midpoint rule (16).
#[test]
fn the_rail_closed_slider_crank_steps_in_quaternion_coordinates() {
    let mut sys = PlainCrank3::default();
    sys.joints.crankshaft.damping = 0.0;
    let m = sys.minimal();
    let mut errors = Vec::new();
    for midpoint in [false, true] {
        let mut rule = Vec::new();
        for dt in [0.004, 0.001] {
            let vi = if midpoint {
                Variational::midpoint(m, dt).unwrap()
            } else {
                Variational::new(m, dt).unwrap()
            };
            let mut z = crank_state(&m, 0.3, 0.0, dt);
            let e0 = vi.energy(&z);
            let (mut de, mut g): (f64, f64) = (0.0, 0.0);
            let n = (20.0 / dt).round() as usize;
            for k in 0..n {
                let (z1, info) = vi
                    .step_with_report(&z)
                    .unwrap_or_else(|e| panic!("midpoint {midpoint}, Δt {dt}, step {k}: {e}"));
                assert!(
                    !info.stalled,
                    "midpoint {midpoint}, Δt {dt}, step {k}: {info:?}"
                );
                z = z1;
                de = de.max((vi.energy(&z) - e0).abs());
                g = g.max(m.constraint_violation(&z));
            }
            println!(
                "rail-closed slider-crank, midpoint {midpoint}, Δt {dt}: 20 s, max |E − E₀| {de:.2e}, max |g| {g:.1e}"
            );
            assert!(g <= 1e-11, "midpoint {midpoint}, Δt {dt}: |g| {g:e}");
            rule.push(de);
        }
        errors.push(rule);
    }
    assert!(
        errors[0][1] < errors[0][0] / 2.5,
        "first order: {:?}",
        errors[0]
    );
    assert!(
        errors[1][1] < errors[1][0] / 10.0,
        "midpoint: {:?}",
        errors[1]
    );
}

/// A damped pendulum about a horizontal axis under a constant torque u
/// settles where gravity's torque balances it, m g l_c sin θ = u (the
/// discrete equilibrium of the forced DEL with v = 0 is the continuous
/// one). The transient decays at c/(2 I_pivot) = 3/s: after 20 s the
/// angle matches to 1e-8, in both views (the maximal angle read back from
/// the two link orientations).
#[test]
fn constant_torque_settles_at_the_static_equilibrium_in_space() {
    let sys = TorquePendulum3::default();
    let (m, g, lc) = (1.0, 9.81, 0.5);
    let dt = 0.01;
    let stepper = LieStepper::with_options(sys.maximal(), dt, tight()).unwrap();
    for u0 in [2.0, -3.5] {
        let u = SVector::<f64, 1>::new(u0);
        let target = u0 / (m * g * lc);
        let inputs = vec![u; 2000];
        let z0 = State::new([0.0], [0.0]);
        for mid in [false, true] {
            let vi = if mid {
                Variational::midpoint(sys.minimal(), dt).unwrap()
            } else {
                Variational::new(sys.minimal(), dt).unwrap()
            };
            let traj = vi.rollout_forced(&z0, &inputs).unwrap();
            let err = (traj.last().unwrap().q[0].sin() - target).abs();
            println!("u = {u0}, minimal (mid = {mid}): |sin θ − u/(m g l_c)| = {err:.1e}");
            assert!(err <= 1e-8, "minimal mid={mid}: {err:.2e}");
        }
        let x0 = sys.minimal().to_maximal(&z0, dt);
        let mut out = vec![x0; inputs.len() + 1];
        stepper.rollout_forced_into(&x0, &inputs, &mut out).unwrap();
        // the std trait's rollout is the same trajectory
        assert_eq!(
            Integrator::rollout_forced(&stepper, &x0, &inputs).unwrap(),
            out
        );
        let theta = stepper.joint_coordinates(out.last().unwrap())[0];
        let err = (theta.sin() - target).abs();
        println!("u = {u0}, maximal: |sin θ − u/(m g l_c)| = {err:.1e}");
        assert!(err <= 1e-8, "maximal: {err:.2e}");
    }
}

/// The two views are different first-order discretisations of the same
/// forced equations: under the same input signal (u(t) sampled at the
/// start of each step) the maximal trajectory approaches the minimal one
/// as Δt shrinks. Centres of mass after 0.4 s at Δt = 4 and 1 ms: the gap
/// must fall by more than 2.5 (first order: 4), as in the unforced
/// comparison of `tests/step/spatial.rs`.
#[test]
fn forced_maximal_converges_to_the_minimal_view() {
    fn gaps<
        S,
        M,
        const N: usize,
        const C: usize,
        const B: usize,
        const J: usize,
        const NB: usize,
        const CB: usize,
    >(
        name: &str,
        sys: S,
        view: impl Fn(&S) -> vigp::spatial::Maximal<S, B, J, NB, CB>,
        minimal: M,
        start: impl Fn(f64) -> State<N>,
        u: impl Fn(f64) -> SVector<f64, 2>,
    ) where
        S: vigp::spatial::Spatial<B, J> + Copy + vigp::Inputs<2>,
        M: Mechanism<N, C> + Copy + vigp::Inputs<2>,
    {
        let mut out = Vec::new();
        for dt in [0.004, 0.001] {
            let z0 = start(dt);
            let n = (0.4 / dt).round() as usize;
            let inputs: Vec<SVector<f64, 2>> = (0..n).map(|k| u(k as f64 * dt)).collect();
            let a = Variational::new(minimal, dt)
                .unwrap()
                .rollout_forced(&z0, &inputs)
                .unwrap();
            let stepper = LieStepper::new(view(&sys), dt).unwrap();
            let x0 = vigp::spatial::views::to_maximal::<S, B, J, N>(&sys, &z0, dt);
            let mut b = vec![x0; n + 1];
            stepper.rollout_forced_into(&x0, &inputs, &mut b).unwrap();
            let xa = vigp::spatial::views::to_maximal::<S, B, J, N>(&sys, &a[n], dt);
            let gap = (0..B)
                .map(|i| (xa.x[i] - b[n].x[i]).norm())
                .fold(0.0, f64::max);
            // the inputs move the mechanism: the forced end differs from
            // the unforced one by far more than the gap
            let free = stepper.rollout(&x0, n).unwrap();
            let effect = (0..B)
                .map(|i| (free[n].x[i] - b[n].x[i]).norm())
                .fold(0.0, f64::max);
            assert!(
                effect > 20.0 * gap,
                "{name}: input effect {effect:e}, gap {gap:e}"
            );
            out.push(gap);
        }
        println!(
            "{name}: forced minimal vs maximal after 0.4 s: {:.2e}, {:.2e} at Δt = 4, 1 ms (ratio {:.2})",
            out[0],
            out[1],
            out[0] / out[1]
        );
        assert!(out[1] < out[0] / 2.5, "{name}: {out:?}");
    }
    let arm = Arm3::default();
    gaps(
        "3-D arm",
        arm,
        |s: &Arm3| s.maximal(),
        arm.minimal(),
        |_| State::new([0.8, -0.5], [1.0, 2.0]),
        |t| SVector::from([3.0 * (5.0 * t).sin(), -2.0 + 4.0 * t]),
    );
    let crank = DriveCrankTree::default();
    gaps(
        "slider-crank",
        crank,
        |s: &DriveCrankTree| s.maximal(),
        crank.minimal(),
        |dt| {
            consistent_state(
                &crank.minimal(),
                &SVector::from([0.3, 0.99, 0.0, 0.0, 0.12, 0.03]),
                &SVector::from([4.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
                dt,
            )
            .unwrap()
        },
        |t| SVector::from([0.4 * (6.0 * t).cos(), -3.0 + 5.0 * t]),
    );
}

/// The forced maximal step and rollout, and the minimal forced step and
/// its derivatives, allocate nothing (the std step after the thread's
/// first).
#[test]
fn forced_spatial_steps_do_not_allocate() {
    let dt = 0.01;
    let sys = DriveCrank3::default();
    let z = crank_state(&sys.minimal(), 0.3, 4.0, dt);
    let x0 = sys.minimal().to_maximal(&z, dt);
    let stepper = LieStepper::new(sys.maximal(), dt).unwrap();
    let inputs = [SVector::<f64, 2>::new(0.2, -1.0); 20];
    let mut out = [x0; 21];
    let vi = Variational::new(sys.minimal(), dt).unwrap();
    let embedded = vigp::embedded::Stepper::new(sys.minimal(), dt).unwrap();
    // the std forced step keeps a workspace of this size per thread, which
    // the thread's first such step allocates (tests/step/control.rs counts it)
    vi.step_forced(&z, &inputs[0]).unwrap();
    let info = allocation_counter::measure(|| {
        let mut x = x0;
        for u in &inputs[..10] {
            x = stepper.step_forced(&x, u).unwrap();
        }
        stepper.rollout_forced_into(&x0, &inputs, &mut out).unwrap();
        let mut zm = z;
        for u in &inputs[..5] {
            zm = vi.step_forced(&zm, u).unwrap();
        }
        let _ = embedded.step_with_derivatives(&z, &inputs[0]).unwrap();
    });
    assert_eq!(info.count_total, 0, "forced spatial steps allocated");
}

/// Constant inputs on a free rotor and a free slider (no gravity, no
/// springs, no damping): the DEL is I(ω_{k+1} − ω_k) = Δt·u, so the
/// discrete rates after n steps are exactly n·Δt·u/I (rotor, I = 3) and
/// n·Δt·F/m (slider, m = 2) — in the minimal view's coordinates, and in
/// the maximal view's body rate about z and the slider's velocity along
/// the rail. Tolerance 1e-12 (rounding over 100 steps, solver at 1e-12).
#[test]
fn constant_inputs_accelerate_a_free_rotor_and_slider_exactly() {
    let sys = Motors::default();
    let dt = 0.01;
    let u = SVector::<f64, 2>::new(1.5, -0.8);
    let n = 100;
    let inputs = vec![u; n];
    let z0 = State::new([0.0, 0.0], [0.0, 0.0]);
    let (w, v) = (n as f64 * dt * 1.5 / 3.0, n as f64 * dt * -0.8 / 2.0);
    let traj = Variational::new(sys.minimal(), dt)
        .unwrap()
        .rollout_forced(&z0, &inputs)
        .unwrap();
    let end = traj.last().unwrap();
    println!(
        "minimal: rotor rate {:.15}, slider rate {:.15} (exact {w}, {v})",
        end.v[0], end.v[1]
    );
    assert!((end.v[0] - w).abs() <= 1e-12 && (end.v[1] - v).abs() <= 1e-12);
    let stepper = LieStepper::new(sys.maximal(), dt).unwrap();
    let x0 = sys.minimal().to_maximal(&z0, dt);
    let mut out = vec![x0; n + 1];
    stepper.rollout_forced_into(&x0, &inputs, &mut out).unwrap();
    let end = out.last().unwrap();
    let along = end.v[1].dot(&Vector3::new(1.0, 1.0, 0.0).normalize());
    println!(
        "maximal: rotor body rate {:?}, slider velocity {:?}",
        end.w[0].as_slice(),
        end.v[1].as_slice()
    );
    assert!((end.w[0].z - w).abs() <= 1e-12 && end.w[0].xy().amax() <= 1e-12);
    assert!(
        (along - v).abs() <= 1e-12
            && (end.v[1] - Vector3::new(1.0, 1.0, 0.0).normalize() * v).amax() <= 1e-12
    );
    assert_eq!(Motors::INPUT_NAMES, ["spin", "slide"]);
}

/// Run-time spring parameters are validated when a stepper is built: a
/// negative or non-finite stiffness, or a non-finite rest, is a typed
/// error in both views.
#[test]
fn invalid_run_time_springs_are_typed_errors() {
    for (k, r) in [(-1.0, 0.0), (f64::NAN, 0.0), (1.0, f64::INFINITY)] {
        let mut sys = Arm3::default();
        sys.joints.elbow.stiffness = k;
        sys.joints.elbow.rest = r;
        assert!(matches!(
            LieStepper::new(sys.maximal(), 0.01).unwrap_err(),
            vigp::embedded::StepError::InvalidModel(_)
        ));
        assert!(matches!(
            vigp::embedded::Stepper::new(sys.minimal(), 0.01).unwrap_err(),
            vigp::embedded::StepError::InvalidModel(_)
        ));
    }
}

/// A non-finite input is an error, not a NaN state.
#[test]
fn non_finite_spatial_inputs_are_refused() {
    let dt = 0.01;
    let sys = Arm3::default();
    let stepper = LieStepper::new(sys.maximal(), dt).unwrap();
    let x = sys
        .minimal()
        .to_maximal(&State::new([0.1, 0.2], [0.0, 0.0]), dt);
    for bad in [f64::NAN, f64::INFINITY] {
        let u = SVector::<f64, 2>::new(0.0, bad);
        assert_eq!(
            stepper.step_forced(&x, &u).unwrap_err(),
            vigp::embedded::StepError::NonFiniteInput { step: None }
        );
        let mut out = [x; 3];
        assert!(stepper.rollout_forced_into(&x, &[u, u], &mut out).is_err());
    }
    // too few inputs for the rollout
    let mut out = [x; 4];
    assert!(
        stepper
            .rollout_forced_into(&x, &[SVector::<f64, 2>::zeros(); 2], &mut out)
            .is_err()
    );
}
