vigp::mechanism! {
    Empty {
        links {}
        joints {}
    }
}

fn main() {}
