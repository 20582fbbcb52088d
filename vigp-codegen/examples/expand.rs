fn main() {
    let src = std::fs::read_to_string(std::env::args().nth(1).unwrap()).unwrap();
    match vigp_codegen::expand_to_string(&src) {
        Ok(s) => println!("{s}"),
        Err(e) => println!("ERR {e}"),
    }
}
