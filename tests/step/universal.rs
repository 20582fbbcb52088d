//! The universal (Hooke, cardan) joint of the 3-D DSL in both views: a
//! Hooke pendulum against the same pendulum built from two revolute joints
//! and a cross of negligible mass (the minimal view, where that cross is
//! harmless), against the small-oscillation closed form, and between the
//! minimal and the maximal view; a spatial R-S-U-R four-bar in both views
//! with no cross link at all.
//!
//! Numbers quoted in docs/mechanisms.md are printed with `-- --nocapture`.

use nalgebra::SVector;
use vigp::Integrator;
use vigp::prelude::*;
use vigp::projection::consistent_state;
use vigp::spatial::{LieStepper, SpatialState, summarize};

vigp::mechanism! {
    /// A 1 m, 1 kg rod hanging from a Hooke joint at the origin: the first
    /// axis is the world x axis, the second the world y axis at the
    /// reference configuration (rod hanging along −z), carried by the first
    /// rotation.
    HookePendulum {
        gravity: [0.0, 0.0, -9.81],
        links {
            rod: { mass: 1.0, length: 1.0, inertia: [0.0002, 0.0834333, 0.0834333],
                   frame: [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]] },
        }
        joints {
            cardan: universal(world, rod.start) { axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] },
        }
    }
}

vigp::mechanism! {
    /// The same pendulum as users had to build it without `universal`: a
    /// cross of 1e-12 kg between a revolute joint about world x and one
    /// about the cross's y axis. Its minimal coordinates are the Hooke
    /// joint's (θ₁, θ₂) exactly.
    CrossPendulum {
        gravity: [0.0, 0.0, -9.81],
        links {
            cross: { mass: 1e-12, inertia: [1e-15, 1e-15, 1e-15] },
            rod: { mass: 1.0, length: 1.0, inertia: [0.0002, 0.0834333, 0.0834333],
                   frame: [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]] },
        }
        joints {
            outer: revolute(world, cross.start) { axis: [1.0, 0.0, 0.0] },
            inner: revolute(cross.start, rod.start) { axis: [0.0, 1.0, 0.0] },
        }
    }
}

spatial_four_bar! {
    /// A spatial four-bar R-S-U-R: a crank about world z, a coupler on a
    /// ball joint at the crank's end, a rocker about world x, and a Hooke
    /// joint between the rocker's end and the coupler (axes: the rocker's
    /// y and z, i.e. world y and x at the reference configuration). One
    /// degree of freedom: the universal joint stops the coupler's spin
    /// about its own axis, which an R-S-S-R leaves free.
    Rsur {
        crankshaft: [],
        ball: ball,
        cardan: universal(rocker.end, coupler.end) { axes: [[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] },
    }
}

fn sci(x: &[f64]) -> String {
    x.iter()
        .map(|v| format!("{v:.3e}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Largest distance between the links' centres of mass of two maximal
/// states.
fn gap<const B: usize>(a: &SpatialState<B>, b: &SpatialState<B>) -> f64 {
    (0..B).map(|i| (a.x[i] - b.x[i]).norm()).fold(0.0, f64::max)
}

/// The minimal view of the Hooke joint is the two-revolute chain with a
/// massless cross: same coordinates, same kinetic and potential energy.
/// Over 2 s (2000 steps of 1 ms) from a large swing the two trajectories
/// agree to 1e-7 rad: the cross's 1e-12 kg and 1e-15 kg·m² change the
/// mass matrix by 1e-12 of the rod's, and the Newton tolerance (1e-12,
/// scaled) bounds what each step adds, so 1e-7 leaves four decades over
/// what 2000 steps accumulate while being 1e4 below the first-order
/// discretisation error (≈ Δt·|v| ≈ 3e-3) that a wrong joint map would
/// show as a bigger gap.
#[test]
fn hooke_pendulum_matches_two_revolutes_with_a_massless_cross() {
    let dt = 1e-3;
    let (h, c) = (
        HookePendulum::default().minimal(),
        CrossPendulum::default().minimal(),
    );
    let z = State {
        q: SVector::from([0.6, -0.4]),
        v: SVector::from([0.0, 1.5]),
    };
    // energies agree at random states before any stepping
    for (q, v) in [([0.3, 1.1], [2.0, -1.0]), ([-2.0, 0.4], [0.5, 3.0])] {
        let s = State {
            q: SVector::from(q),
            v: SVector::from(v),
        };
        let (eh, ec) = (h.energy(&s), c.energy(&s));
        assert!((eh - ec).abs() <= 1e-10 * (1.0 + eh.abs()), "{eh} vs {ec}");
    }
    let n = 2000;
    let a = Variational::new(h, dt).unwrap().rollout(&z, n).unwrap();
    let b = Variational::new(c, dt).unwrap().rollout(&z, n).unwrap();
    let worst = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x.q - y.q).amax())
        .fold(0.0, f64::max);
    println!(
        "Hooke vs two revolutes + 1e-12 kg cross, minimal view, 2 s: max |Δq| {worst:.3e} rad"
    );
    assert!(worst <= 1e-7, "{worst:e}");
}

/// Small oscillations about the hanging rest decouple into two compound
/// pendulums, each of frequency ω = √(m·g·l_c / I_p) with I_p the moment
/// about the pivot (0.0834333 + m·l_c², l_c = 0.5 m). Measured from the
/// upward zero crossings of both angles over 10 s at Δt = 1 ms. The first-
/// order VI's frequency error is O((ωΔt)²) ≈ 1e-6 and the amplitude
/// (1e-3 rad) shifts it by ≈ θ²/16 ≈ 1e-7; 1e-4 relative is the resolution
/// of the linearly interpolated crossings over ~6 periods, with margin.
#[test]
fn hooke_pendulum_small_oscillations_match_the_closed_form() {
    let dt = 1e-3;
    let m = HookePendulum::default().minimal();
    let ip: f64 = 0.0834333 + 0.25;
    let omega = (9.81 * 0.5 / ip).sqrt();
    let z = State {
        q: SVector::from([1e-3, 0.0]),
        v: SVector::from([0.0, 0.7e-3 * omega]),
    };
    let n = 10_000;
    let traj = Variational::new(m, dt).unwrap().rollout(&z, n).unwrap();
    for k in 0..2 {
        let mut ups = Vec::new();
        for i in 0..n {
            let (a, b) = (traj[i].q[k], traj[i + 1].q[k]);
            if a < 0.0 && b >= 0.0 {
                ups.push((i as f64 + a / (a - b)) * dt);
            }
        }
        let periods = (ups.len() - 1) as f64;
        let period = (ups[ups.len() - 1] - ups[0]) / periods;
        let measured = 2.0 * std::f64::consts::PI / period;
        let rel = (measured - omega).abs() / omega;
        println!(
            "Hooke pendulum small oscillation, angle {}: ω {measured:.6} rad/s vs closed form {omega:.6} (rel. {rel:.2e})",
            k + 1
        );
        assert!(rel <= 1e-4, "angle {k}: {measured} vs {omega}");
    }
}

/// The maximal view of the Hooke pendulum (two bodies' worth of
/// constraints: the point, and the second axis keeping its angle to the
/// first) integrates what the minimal view does: a consistent start maps
/// both ways exactly, the two first-order discretisations approach each
/// other as Δt shrinks, and over 10 s at 5 ms the maximal view keeps
/// |g| ≤ 1e-10 and a bounded energy error.
#[test]
fn hooke_pendulum_minimal_and_maximal_views_agree() {
    let sys = HookePendulum::default();
    let m = sys.minimal();
    let z = State {
        q: SVector::from([0.6, -0.4]),
        v: SVector::from([0.0, 1.5]),
    };
    let mut gaps = Vec::new();
    for dt in [0.004, 0.001] {
        let zmax = m.to_maximal(&z, dt);
        let stepper = LieStepper::new(sys.maximal(), dt).unwrap();
        assert!(stepper.constraint_violation(&zmax) <= 1e-14);
        let back = m.to_minimal(&zmax, dt);
        assert!((back.q - z.q).amax() <= 1e-12 && (back.v - z.v).amax() <= 1e-9);
        let n = (0.4 / dt) as usize;
        let a = Variational::new(m, dt).unwrap().rollout(&z, n).unwrap();
        let b = stepper.rollout(&zmax, n).unwrap();
        gaps.push(gap(&m.to_maximal(&a[n], dt), &b[n]));
    }
    println!(
        "Hooke pendulum minimal vs maximal after 0.4 s: {} m at Δt = 4, 1 ms",
        sci(&gaps)
    );
    // first order: a quarter of Δt gives (about) a quarter of the gap
    assert!(gaps[1] < gaps[0] / 2.5, "{gaps:?}");
    let dt = 0.005;
    let stepper = LieStepper::new(sys.maximal(), dt).unwrap();
    let s = summarize(
        &stepper,
        &stepper.rollout(&m.to_maximal(&z, dt), 2000).unwrap(),
    );
    println!(
        "Hooke pendulum, maximal view, 10 s at 5 ms: max |ΔE| {:.3e} J (first tenth {:.3e}, last tenth {:.3e}), max |g| {:.2e}",
        s.max_energy_error, s.first_tenth, s.last_tenth, s.max_violation
    );
    assert!(s.max_violation <= 1e-10, "{s:?}");
    assert!(s.max_norm_error <= 1e-14, "{s:?}");
    assert!(s.last_tenth <= 1.5 * s.first_tenth + 1e-9, "{s:?}");
}

/// The R-S-U-R four-bar runs in both views, with no cross link: 10 s at
/// Δt = 5 ms (the 1e-9 kg cross version failed at step 36 there) keep the
/// loop closed (|g| ≤ 1e-10 in the maximal view, ≤ 1e-9 in the minimal
/// one, whose loop rows are solved to the Newton tolerance) and the energy
/// error bounded; the two views approach each other as Δt shrinks.
#[test]
fn rsur_four_bar_runs_in_both_views() {
    let sys = Rsur::default();
    let m = sys.minimal();
    let start = |dt: f64| {
        let mut v = SVector::<f64, 6>::zeros();
        v[0] = 3.0;
        consistent_state(&m, &m.reference(), &v, dt).unwrap()
    };
    let dt = 0.005;
    let z = start(dt);
    let n = 2000;
    let a = Variational::new(m, dt).unwrap().rollout(&z, n).unwrap();
    let worst_min = a
        .iter()
        .map(|s| m.constraint_violation(s))
        .fold(0.0, f64::max);
    let e0 = m.energy(&a[0]);
    let drift_min = a
        .iter()
        .map(|s| (m.energy(s) - e0).abs())
        .fold(0.0, f64::max);
    let stepper = LieStepper::new(sys.maximal(), dt).unwrap();
    let s = summarize(
        &stepper,
        &stepper.rollout(&m.to_maximal(&z, dt), n).unwrap(),
    );
    println!(
        "R-S-U-R, 10 s at 5 ms: minimal max |g| {worst_min:.2e}, max |ΔE| {drift_min:.3e} J; maximal max |g| {:.2e}, max |ΔE| {:.3e} J (first tenth {:.3e}, last tenth {:.3e})",
        s.max_violation, s.max_energy_error, s.first_tenth, s.last_tenth
    );
    assert!(worst_min <= 1e-9, "{worst_min:e}");
    assert!(s.max_violation <= 1e-10, "{s:?}");
    assert!(s.last_tenth <= 1.5 * s.first_tenth + 1e-9, "{s:?}");
    // the crank swings (to 0.43 rad from 3 rad/s at rest): the loop is
    // not locked by a wrong constraint
    let turned = a.iter().map(|s| s.q[0].abs()).fold(0.0, f64::max);
    println!("R-S-U-R crank swing: {turned:.3} rad");
    assert!(turned > 0.3, "{turned}");
    let mut gaps = Vec::new();
    for dt in [0.004, 0.001] {
        let z = start(dt);
        let n = (0.4 / dt) as usize;
        let a = Variational::new(m, dt).unwrap().rollout(&z, n).unwrap();
        let stepper = LieStepper::new(sys.maximal(), dt).unwrap();
        let b = stepper.rollout(&m.to_maximal(&z, dt), n).unwrap();
        gaps.push(gap(&m.to_maximal(&a[n], dt), &b[n]));
    }
    println!(
        "R-S-U-R minimal vs maximal after 0.4 s: {} m at Δt = 4, 1 ms",
        sci(&gaps)
    );
    assert!(gaps[1] < gaps[0] / 2.5, "{gaps:?}");
}

/// `LieStepper` refuses a link whose inertia is negligible against the
/// mechanism's (`NEGLIGIBLE_INERTIA` = 1e-8 of the largest link mass, and
/// of max(J_max, m_max·L²) for principal moments), naming the link and the
/// value, instead of failing at the first step ("line search failed at
/// Newton iteration 2"). A light link above the bound still integrates,
/// and agrees with the universal joint it stands for.
#[test]
fn maximal_view_refuses_negligible_links_by_name() {
    // the 1e-12 kg cross: its mass is below 1e-8 × 1 kg
    let err = LieStepper::new(CrossPendulum::default().maximal(), 0.005).unwrap_err();
    println!("1e-12 kg cross: {err}");
    assert_eq!(
        err,
        vigp::embedded::StepError::NegligibleInertia {
            link: "cross",
            what: "mass",
            value: 1e-12,
            bound: 1e-8,
        }
    );
    assert!(err.to_string().contains("link `cross`") && err.to_string().contains("universal"));
    // a cross of reasonable mass but a 1e-12 kg·m² moment: the scale is
    // m_max·L² = 1 kg × (1 m)²
    let mut thin = CrossPendulum::default();
    thin.links.cross.mass = 0.01;
    thin.links.cross.inertia = [[1e-12, 0.0, 0.0], [0.0, 1e-3, 0.0], [0.0, 0.0, 1e-3]];
    match LieStepper::new(thin.maximal(), 0.005) {
        Err(vigp::embedded::StepError::NegligibleInertia {
            link,
            what,
            value,
            bound,
        }) => {
            assert_eq!(
                (link, what),
                ("cross", "smallest principal moment of inertia")
            );
            assert!(
                (value - 1e-12).abs() < 1e-24 && (bound - 1e-8).abs() < 1e-20,
                "{value} {bound}"
            );
        }
        other => panic!("expected NegligibleInertia, got {other:?}"),
    }
    // its message names the link and the value
    assert!(
        err.to_string().contains("link `cross`: mass 1.000e-12"),
        "{err}"
    );
    // a 1e-6 kg cross (1e-7 kg·m²) is above the bound: it integrates 2 s
    // at 1 ms with the loop held, and follows the Hooke joint's maximal
    // view to within what its 1e-6 relative mass changes (≤ 1e-5 m, the
    // measured gap is printed)
    let mut light = CrossPendulum::default();
    light.links.cross.mass = 1e-6;
    light.links.cross.inertia = [[1e-7, 0.0, 0.0], [0.0, 1e-7, 0.0], [0.0, 0.0, 1e-7]];
    let dt = 0.001;
    let z = State {
        q: SVector::from([0.6, -0.4]),
        v: SVector::from([0.0, 1.5]),
    };
    let st = LieStepper::new(light.maximal(), dt).unwrap();
    let a = st
        .rollout(&light.minimal().to_maximal(&z, dt), 2000)
        .unwrap();
    let hooke = HookePendulum::default();
    let sh = LieStepper::new(hooke.maximal(), dt).unwrap();
    let b = sh
        .rollout(&hooke.minimal().to_maximal(&z, dt), 2000)
        .unwrap();
    let worst = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x.x[1] - y.x[0]).norm())
        .fold(0.0, f64::max);
    let s = summarize(&st, &a);
    println!(
        "1e-6 kg cross, maximal view, 2 s at 1 ms: max |g| {:.2e}, rod centre vs the Hooke joint's {worst:.2e} m",
        s.max_violation
    );
    assert!(s.max_violation <= 1e-12, "{s:?}");
    assert!(worst <= 1e-5, "{worst:e}");
}
