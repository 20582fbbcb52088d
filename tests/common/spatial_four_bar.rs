//! The spatial four-bar of tests/step/{spatial,universal,tangent}.rs
//! (included with `#[path]` and `#[macro_use]`): a crank about world z, a
//! coupler on a ball joint at the crank's end, a rocker about world x
//! pivoted at (0.5, 0.6, 0), and a loop-closing joint between the rocker's
//! end and the coupler's end.

/// Declares the spatial four-bar `$name` with the doc comment `$doc`: the
/// crankshaft takes the keys `$crank` after its axis, the ball joint at the
/// crank's end is named `$ball`, and `$closing` is the loop-closing joint
/// (from `rocker.end` to `coupler.end`, with its trailing comma).
macro_rules! spatial_four_bar {
    (
        $(#[doc = $doc:tt])*
        $name:ident {
            crankshaft: [$($crank:ident),*],
            ball: $ball:ident,
            $($closing:tt)*
        }
    ) => {
        vigp::mechanism! {
            $(#[doc = $doc])*
            pub $name {
                gravity: [0.0, 0.0, -9.81],
                links {
                    crank: { mass: 0.4, length: 0.3, inertia: [0.0001, 0.0031, 0.0031] },
                    coupler: {
                        mass: 0.3,
                        length: 0.7483314773547883,
                        inertia: [0.00005, 0.014, 0.014],
                        frame: [[0.2, 0.6, -0.4], [0.6, -0.2, 0.0], [-0.08, -0.24, -0.4]],
                    },
                    rocker: {
                        mass: 0.5,
                        length: 0.4,
                        inertia: [0.0001, 0.0067, 0.0067],
                        frame: [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]],
                    },
                }
                joints {
                    crankshaft: revolute(world, crank.start) { axis: [0.0, 0.0, 1.0] $(, $crank)* },
                    $ball: spherical(crank.end, coupler.start),
                    pivot: revolute(world @ [0.5, 0.6, 0.0], rocker.start) { axis: [1.0, 0.0, 0.0] },
                    $($closing)*
                }
            }
        }
    };
}
