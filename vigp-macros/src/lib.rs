//! The `mechanism!` macro of vigp. It only parses and emits (through
//! `vigp-codegen`); all behaviour lives in `vigp-runtime`.

#![forbid(unsafe_code)]

use proc_macro::TokenStream;

/// Declare a planar mechanism; see the `vigp` crate documentation for the
/// DSL. Invalid descriptions become `compile_error!`s with spans.
#[proc_macro]
pub fn mechanism(input: TokenStream) -> TokenStream {
    // `vigp`'s `std` feature turns on this crate's `std` feature, so the
    // expansion matches the runtime that is present.
    let target = if cfg!(feature = "std") {
        vigp_codegen::Target::Std
    } else {
        vigp_codegen::Target::NoStd
    };
    vigp_codegen::expand_for(input.into(), target)
        .unwrap_or_else(syn::Error::into_compile_error)
        .into()
}
