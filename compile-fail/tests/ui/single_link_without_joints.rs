// A lone link with no joint is a free body, which the DSL does not model:
// every link must be placed by a joint.
vigp::mechanism! {
    Free {
        links {
            body: { mass: 1.0, length: 1.0 },
        }
    }
}

fn main() {}
