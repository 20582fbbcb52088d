//! Parameter values written as Rust expressions (`mass: 2.0 * M`): the
//! defaults equal those of the same mechanism written with literals, bit for
//! bit, and so do the steps; a value known only at run time is checked at
//! run time (a typed error), as a value set by hand is. The compile-time
//! side (folded literals checked by the macro, geometry that must be known)
//! is in `compile-fail/tests/ui/`.

use nalgebra::SVector;
use vigp::embedded::{Parameters, StepError, Stepper};
use vigp::prelude::*;
use vigp::spatial::{LieStepper, Spatial};

const M: f64 = 0.75;
const L: f64 = 1.2;
const C: f64 = 0.1;
const K: f64 = 3.0;
const G: f64 = 9.81;
const I1: f64 = 0.002;

mod physical {
    /// A rest angle reached through a path.
    pub const REST: f64 = 0.6;
}

fn half(x: f64) -> f64 {
    0.5 * x
}

vigp::mechanism! {
    /// Values named by constants, a function and arithmetic; default
    /// inertias and centres of mass derived from values only the compiler
    /// knows.
    Named {
        gravity: [0.0, -G],
        links {
            upper: { mass: 2.0 * M, length: L },
            lower: { mass: M, length: half(L), com: [L / 4.0, 0.0] },
            tip: { mass: 0.25 + 0.25, length: (1.0 - 0.5) * 2.0, inertia: M / 8.0 },
        }
        joints {
            shoulder: revolute(world, upper.start) { damping: C, stiffness: K, rest: physical::REST, actuated },
            elbow: revolute(upper.end, lower.start) { damping: C / 2.0, stiffness: 0.5 * K },
            wrist: revolute(lower.end, tip.start) { damping: 0.0 },
        }
    }
}

vigp::mechanism! {
    /// The same mechanism with the values written out.
    Literal {
        gravity: [0.0, -9.81],
        links {
            upper: { mass: 1.5, length: 1.2 },
            lower: { mass: 0.75, length: 0.6, com: [0.3, 0.0] },
            tip: { mass: 0.5, length: 1.0, inertia: 0.09375 },
        }
        joints {
            shoulder: revolute(world, upper.start) { damping: 0.1, stiffness: 3.0, rest: 0.6, actuated },
            elbow: revolute(upper.end, lower.start) { damping: 0.05, stiffness: 1.5 },
            wrist: revolute(lower.end, tip.start) { damping: 0.0 },
        }
    }
}

fn parameters<P: Parameters>(p: &P) -> Vec<(&'static str, u64)> {
    (0..P::PARAMETER_NAMES.len())
        .map(|i| (P::PARAMETER_NAMES[i], p.parameter(i).unwrap().to_bits()))
        .collect()
}

#[test]
fn expressions_give_the_literal_defaults_bit_for_bit() {
    let (named, literal) = (Named::default(), Literal::default());
    // every run-time parameter, by name (the derived m·l²/12 and l/2
    // included): the expressions evaluate in the same f64 operations
    assert_eq!(parameters(&named), parameters(&literal));
    assert_eq!(Named::PARAMETER_NAMES.len(), 2 + 3 * 5 + 3 * 3);

    // so the generated steps agree bit for bit, forced and damped
    let dt = 0.01;
    let a = Stepper::new(named, dt).unwrap();
    let b = Stepper::new(literal, dt).unwrap();
    let (mut za, mut zb) = (
        vigp::embedded::State::new([0.3, -0.2, 0.1], [0.0; 3]),
        vigp::embedded::State::new([0.3, -0.2, 0.1], [0.0; 3]),
    );
    for k in 0..200 {
        let u = SVector::from([(0.05 * k as f64).sin()]);
        za = a.step_forced(&za, &u).unwrap();
        zb = b.step_forced(&zb, &u).unwrap();
        assert_eq!(za, zb, "step {k}");
    }
}

vigp::mechanism! {
    /// A spatial mechanism with named values: principal moments and a full
    /// tensor, a default centre of mass from a named length.
    SpatialNamed {
        gravity: [0.0, 0.0, -G],
        links {
            arm: { mass: M, length: L, inertia: [I1, 2.0 * I1, 2.0 * I1] },
            bob: {
                mass: 0.5 * M,
                length: 0.5,
                inertia: [[I1, 0.0, 0.0], [0.0, I1, 0.0], [0.0, 0.0, I1 + 0.0]],
                com: [L / 4.0, 0.0, 0.0],
            },
        }
        joints {
            yaw: revolute(world, arm.start) { axis: [0.0, 0.0, 1.0], damping: C },
            pitch: revolute(arm.end, bob.start) { axis: [0.0, 1.0, 0.0], stiffness: K, rest: physical::REST, actuated },
        }
    }
}

vigp::mechanism! {
    /// The same spatial mechanism with the values written out.
    SpatialLiteral {
        gravity: [0.0, 0.0, -9.81],
        links {
            arm: { mass: 0.75, length: 1.2, inertia: [0.002, 0.004, 0.004] },
            bob: {
                mass: 0.375,
                length: 0.5,
                inertia: [[0.002, 0.0, 0.0], [0.0, 0.002, 0.0], [0.0, 0.0, 0.002]],
                com: [0.3, 0.0, 0.0],
            },
        }
        joints {
            yaw: revolute(world, arm.start) { axis: [0.0, 0.0, 1.0], damping: 0.1 },
            pitch: revolute(arm.end, bob.start) { axis: [0.0, 1.0, 0.0], stiffness: 3.0, rest: 0.6, actuated },
        }
    }
}

#[test]
fn spatial_expressions_give_the_literal_description() {
    let (named, literal) = (SpatialNamed::default(), SpatialLiteral::default());
    // Debug prints every f64 exactly (shortest round-trip form)
    assert_eq!(
        format!("{:?}", Spatial::links(&named)),
        format!("{:?}", Spatial::links(&literal))
    );
    assert_eq!(
        format!("{:?}", Spatial::joints(&named)),
        format!("{:?}", Spatial::joints(&literal))
    );
    assert_eq!(
        Spatial::gravity(&named).map(f64::to_bits),
        Spatial::gravity(&literal).map(f64::to_bits)
    );
    let (a, b) = (
        Variational::new(named.minimal(), 0.01).unwrap(),
        Variational::new(literal.minimal(), 0.01).unwrap(),
    );
    let z = named.minimal().state([0.2, 0.4], [1.0, 0.0]);
    assert_eq!(a.rollout(&z, 50).unwrap(), b.rollout(&z, 50).unwrap());
    // the spring and the input (on `pitch`) likewise
    assert_eq!(
        format!("{:?}", Spatial::springs(&named)),
        format!("{:?}", Spatial::springs(&literal))
    );
    let u = [SVector::<f64, 1>::new(0.3); 20];
    assert_eq!(
        a.rollout_forced(&z, &u).unwrap(),
        b.rollout_forced(&z, &u).unwrap()
    );
}

// ---- values the macro cannot know are checked when the program runs ----

const NEGATIVE: f64 = -1.0;
const HUGE: f64 = 1e200;

vigp::mechanism! {
    /// A negative mass the macro cannot see.
    NegativeMass {
        links { rod: { mass: NEGATIVE, length: 1.0 } }
        joints { pivot: revolute(world, rod.start) }
    }
}

vigp::mechanism! {
    /// A default inertia m·l²/12 that overflows at run time.
    Overflowing {
        links { rod: { mass: HUGE, length: HUGE } }
        joints { pivot: revolute(world, rod.start) }
    }
}

vigp::mechanism! {
    /// A negative damping and a non-finite rest angle.
    BadJoint {
        links { rod: { mass: 1.0, length: 1.0 } }
        joints { pivot: revolute(world, rod.start) { damping: -C, stiffness: K, rest: f64::NAN } }
    }
}

vigp::mechanism! {
    /// An inertia tensor that is not positive definite.
    SpatialBadInertia {
        gravity: [0.0, 0.0, -G],
        links { rod: { mass: 1.0, length: 1.0, inertia: [I1, I1, NEGATIVE * I1] } }
        joints { pivot: revolute(world, rod.start) { axis: [0.0, 1.0, 0.0] } }
    }
}

#[test]
fn values_known_only_at_run_time_are_checked_at_run_time() {
    let invalid = |r: Result<(), StepError>| matches!(r, Err(StepError::InvalidModel(_)));
    let std_invalid =
        |r: Result<(), vigp::StepError>| matches!(r, Err(vigp::StepError::InvalidModel(_)));
    assert!(invalid(
        Stepper::new(NegativeMass::default(), 0.01).map(drop)
    ));
    assert!(invalid(
        Stepper::new(Overflowing::default(), 0.01).map(drop)
    ));
    assert!(invalid(Stepper::new(BadJoint::default(), 0.01).map(drop)));
    // the std integrator reports the same typed error when it is built
    assert!(std_invalid(
        Variational::new(NegativeMass::default().minimal(), 0.01).map(drop)
    ));

    let sys = SpatialBadInertia::default();
    assert!(matches!(
        LieStepper::new(sys.maximal(), 0.01),
        Err(StepError::InvalidModel(_))
    ));
    assert!(std_invalid(Variational::new(sys.minimal(), 0.01).map(drop)));
}

// ---- what the macro emits ----

#[test]
fn arithmetic_of_literals_is_evaluated_by_the_macro() {
    // the same generated code as the literals: the value is folded, checked
    // and written out, not left to the compiler
    let folded = vigp_codegen::expand_to_string(
        "Rod { gravity: [0.0, -(9.81 * 1.0)], links { rod: { mass: 0.5 * 2.0, length: 3 / 4, com: [0.75 / 2.0, -0.0 * 1.0] } } joints { pivot: revolute(world @ [1.0 - 1.0, 2.0 * 0.5], rod.start) { damping: (0.1) } } }",
    )
    .unwrap();
    let literal = vigp_codegen::expand_to_string(
        "Rod { gravity: [0.0, -9.81], links { rod: { mass: 1.0, length: 0.75, com: [0.375, -0.0] } } joints { pivot: revolute(world @ [0.0, 1.0], rod.start) { damping: 0.1 } } }",
    )
    .unwrap();
    assert_eq!(folded, literal);
}

#[test]
fn named_values_are_emitted_once_as_written() {
    let code = vigp_codegen::expand_to_string(
        "Rod { links { rod: { mass: 2.0 * M, length: L } } joints { pivot: revolute(world, rod.start) } }",
    )
    .unwrap();
    // each expression appears once (a bad one is reported once); the
    // inertia and centre of mass that derive from them are computed at run
    // time by the runtime's `Link::with_defaults`
    assert_eq!(code.matches("2.0 * M").count(), 1, "{code}");
    // prettyplease breaks the call over lines: compare without whitespace
    let flat: String = code.split_whitespace().collect();
    assert!(
        flat.contains("::vigp::Link::with_defaults(2.0*M,L,::core::option::Option::None,::core::option::Option::None,)"),
        "{code}"
    );
}
