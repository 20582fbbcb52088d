//! Spatial (3-D) descriptions: `gravity: [gx, gy, gz]` selects this path.
//!
//! The grammar is the planar one with 3-D values:
//!
//! ```text
//! /// docs
//! pub Name {
//!     gravity: [gx, gy, gz],
//!     links {
//!         name: { mass: m, inertia: [i1, i2, i3] | [[..], [..], [..]],
//!                 length?: l, com?: [x, y, z], frame?: [[x axis], [y axis], [z axis]] },
//!     }
//!     joints {
//!         name: revolute(parent, child) { axis: [ax, ay, az], damping?, actuated?, stiffness?, rest? },
//!         name: prismatic(parent, child) { axis: [ax, ay, az], damping?, actuated?, stiffness?, rest? },
//!         name: spherical(parent, child) { damping? },
//!         name: fixed(parent, child),
//!         name: free(parent, child),
//!     }
//! }
//! ```
//!
//! `actuated` (a bare flag) makes a revolute or prismatic joint an input: a
//! torque about the axis, a force along it; inputs are numbered in joint
//! declaration order and named by their joints. `stiffness: k` (≥ 0) and
//! `rest: s0` (default 0, only with `stiffness`) add the spring
//! ½k(s − s0)² on the joint coordinate s (zero in the reference
//! configuration). Spherical, fixed and free joints have no single
//! coordinate and reject all three. As in the planar DSL, only what is
//! declared is generated.
//!
//! Points: `world`, `world @ [x, y, z]`, `link.start`, `link.end`,
//! `link.center`, `link.com`, `link @ [x, y, z]`.
//!
//! Pipeline as for planar descriptions: [`parse`] → [`model`] (every mistake
//! a spanned error) → [`emit`] (the parameter types, the
//! `vigp::spatial::Spatial` description, the maximal view and the
//! minimal-coordinate `Mechanism` view, which call generic runtime code).

pub mod emit;
pub mod model;
pub mod parse;

use proc_macro2::{Delimiter, TokenStream, TokenTree};

/// `true` when the description's `gravity` has three components (a
/// spatial mechanism). Scans the tokens only; the planar path reports every
/// other shape of `gravity`.
pub fn is_spatial(input: &TokenStream) -> bool {
    let Some(body) = input.clone().into_iter().find_map(|t| match t {
        TokenTree::Group(g) if g.delimiter() == Delimiter::Brace => Some(g.stream()),
        _ => None,
    }) else {
        return false;
    };
    let tokens: Vec<TokenTree> = body.into_iter().collect();
    for w in tokens.windows(3) {
        if let (TokenTree::Ident(key), TokenTree::Punct(colon), TokenTree::Group(g)) =
            (&w[0], &w[1], &w[2])
            && key == "gravity"
            && colon.as_char() == ':'
            && g.delimiter() == Delimiter::Bracket
        {
            return components(g.stream()) == 3;
        }
    }
    false
}

/// Number of comma-separated items (a trailing comma does not count).
fn components(stream: TokenStream) -> usize {
    let mut count = 0;
    let mut item = false;
    for t in stream {
        match t {
            TokenTree::Punct(p) if p.as_char() == ',' => {
                if item {
                    count += 1;
                }
                item = false;
            }
            _ => item = true,
        }
    }
    count + usize::from(item)
}

/// Expand a spatial description.
pub fn expand(input: TokenStream, target: crate::Target) -> syn::Result<TokenStream> {
    let parsed: parse::Input = syn::parse2(input)?;
    let model = model::validate(parsed)?;
    Ok(emit::emit(&model, target))
}
