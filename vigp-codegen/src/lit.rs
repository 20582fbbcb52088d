//! Rust literals for numbers the macro knows: the leaf every emitter and
//! the description's default values share.

use proc_macro2::{Literal, TokenStream};
use quote::quote;

/// An unsuffixed `f64` literal, with a leading `-` for a negative value.
pub fn lit(x: f64) -> TokenStream {
    let l = Literal::f64_unsuffixed(x.abs());
    if x < 0.0 { quote!(-#l) } else { quote!(#l) }
}
