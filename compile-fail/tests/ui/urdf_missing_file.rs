// A `urdf:` file that does not exist (paths are relative to the invoking
// crate's CARGO_MANIFEST_DIR): the error points at the path.
vigp::mechanism! {
    Ghost { urdf: "urdf/no_such_robot.urdf" }
}

fn main() {}
