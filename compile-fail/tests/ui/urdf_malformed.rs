// XML the parser refuses: the error points at the path with the parser's
// message.
vigp::mechanism! {
    Broken { urdf: "urdf/malformed.urdf" }
}

fn main() {}
