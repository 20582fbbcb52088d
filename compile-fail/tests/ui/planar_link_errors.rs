// Every mistake in a planar link is reported, each at its token.
vigp::mechanism! {
    Links {
        links {
            rod: { mas: 1.0, length: 1.0 },
            rod: { mass: 2.0, length: 1.0 },
            // `r#rod` and `rod` are the same identifier (and would be the
            // same field of the generated `LinksLinks`).
            r#rod: { mass: 1.0, length: 1.0 },
            world: { mass: 1.0, length: 1.0 },
            twice: { mass: 1.0, length: 1.0, mass: 2.0 },
            weightless: { mass: 0.0, length: 1.0 },
            // Arithmetic of literals is evaluated by the macro and gets the
            // same checks as a literal.
            folded: { mass: -2.0 * 0.5, length: 1.0 },
            reversed: { mass: 1.0, length: -1.0 },
            spinless: { mass: 1.0, length: 1.0, inertia: -0.1 },
            shaped: { mass: [1.0], length: 1.0, com: 0.5 },
            // m·l²/12 overflows f64: the macro must report it instead of
            // panicking while writing an infinite literal.
            huge: { mass: 1e300, length: 1e300 },
        }
        joints {
            // `world` is the world even beside a link of that name.
            pivot: revolute(world, world @ [0.0, 1.0]),
        }
    }
}

fn main() {}
