// A mimic joint couples two coordinates, which a tree of joints cannot
// express: the error points at the path and names the joint and its line.
vigp::mechanism! {
    Mimic { urdf: "urdf/mimic.urdf" }
}

fn main() {}
