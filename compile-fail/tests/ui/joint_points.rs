// A joint's points are read while the description is parsed, and parsing
// stops at the first mistake: one mechanism a mistake.
vigp::mechanism! {
    WithoutAnchor {
        links { upper: { mass: 1.0, length: 1.0 }, lower: { mass: 1.0, length: 1.0 } }
        joints { shoulder: revolute(world, upper.start), elbow: revolute(upper, lower.start) }
    }
}

vigp::mechanism! {
    UnknownAnchor {
        links { upper: { mass: 1.0, length: 1.0 }, lower: { mass: 1.0, length: 1.0 } }
        joints { elbow: revolute(upper.middle, lower.start) }
    }
}

vigp::mechanism! {
    AnchoredWorld {
        links { rod: { mass: 1.0, length: 1.0 } }
        joints { pivot: revolute(world.center, rod.start) }
    }
}

vigp::mechanism! {
    ThreePoint {
        links { rod: { mass: 1.0, length: 1.0 } }
        joints { pivot: revolute(world @ [0.0, 1.0, 2.0], rod.start) }
    }
}

fn main() {}
