//! The paper's four-bar rhombus (four 1 kg, 1 m links hanging from two
//! world pivots, closed by the joint between the lower links' ends) with
//! the joint keys of each test, shared by tests/common/drive_fourbar.rs,
//! tests/step/{control,spatial}.rs and tests/learn/identify.rs (included
//! with `#[path]` and `#[macro_use]`).

/// Declares the rhombus `$name` with the doc comment `$doc` and gravity
/// `$gravity` when given: `$top1` holds the keys of the first top pivot,
/// `$middle` those of the other tree joints (`middle1`, `top2`,
/// `middle2`; none when empty), `$bottom` those of the loop-closing joint.
macro_rules! rhombus {
    (
        $(#[doc = $doc:tt])*
        $name:ident {
            $(gravity: $gravity:tt,)?
            top1: $top1:tt,
            middle: [$($middle:tt)*],
            bottom: $bottom:tt,
        }
    ) => {
        vigp::mechanism! {
            $(#[doc = $doc])*
            pub $name {
                $(gravity: $gravity,)?
                links {
                    link1: { mass: 1.0, length: 1.0 },
                    link2: { mass: 1.0, length: 1.0 },
                    link3: { mass: 1.0, length: 1.0 },
                    link4: { mass: 1.0, length: 1.0 },
                }
                joints {
                    top1: revolute(world, link1.start) $top1,
                    middle1: revolute(link1.end, link2.start) $($middle)*,
                    top2: revolute(world, link3.start) $($middle)*,
                    middle2: revolute(link3.end, link4.start) $($middle)*,
                    bottom: revolute(link2.end, link4.end) $bottom,
                }
            }
        }
    };
}
