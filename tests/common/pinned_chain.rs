//! Three 1 m, 1 kg links pinned at the origin and at (x, 0), shared by
//! tests/stress_cases/mod.rs and tests/data/mistakes.rs (included with
//! `#[path]` and `#[macro_use]`): the chain reaches 3 m, so it closes for
//! |x| ≤ 3 m only, and only stretched straight at |x| = 3 m.

/// Declares the pinned three-link chain as the mechanism `$name` with the
/// far pin at (`$x`, 0) and the doc comment `$doc`.
macro_rules! pinned_chain {
    ($name:ident, $x:tt, $doc:tt) => {
        vigp::mechanism! {
            #[doc = $doc]
            pub $name {
                gravity: [0.0, -9.81],
                links {
                    a: { mass: 1.0, length: 1.0 },
                    b: { mass: 1.0, length: 1.0 },
                    c: { mass: 1.0, length: 1.0 },
                }
                joints {
                    p: revolute(world, a.start),
                    q: revolute(a.end, b.start),
                    r: revolute(b.end, c.start),
                    s: revolute(c.end, world @ [$x, 0.0]),
                }
            }
        }
    };
}
