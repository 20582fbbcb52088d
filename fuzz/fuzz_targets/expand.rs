//! Any input to the `mechanism!` expansion gives code or an error, never a
//! panic: the bytes are read as source text, tokenised, and expanded both
//! through `expand` (token stream) and `expand_to_string` (text, which also
//! re-parses and pretty-prints the generated code).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(src) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(tokens) = src.parse::<proc_macro2::TokenStream>() {
        let _ = vigp_codegen::expand(tokens);
    }
    let _ = vigp_codegen::expand_to_string(src);
});
