//! Code generator behind vigp's `mechanism!` macro.
//!
//! `vigp-macros` is a thin shell around [`expand`]; this crate is a plain
//! library so that users and tests can see exactly what a description
//! expands to ([`expand_to_string`]) and snapshot it.
//!
//! Pipeline: tokens → [`syntax`] (one grammar for planar and spatial
//! descriptions, with spans) → [`desc`] (one validation driver with the
//! rules of each dimension: names resolved, numbers checked, joint graph
//! split into a spanning tree and loop-closing joints; every mistake
//! collected in a [`ctxt::Ctxt`]) → [`emit`] (Rust generic over a scalar:
//! `vigp::Real` for the kinematics and the `no_std` model, num-dual numbers
//! for the std runtime's views; [`Target`] selects which are emitted), plus
//! [`describe`] (the mechanism's name and named parameters, and the
//! `vigp::System` impl). A description with a 3-component gravity is
//! spatial ([`syntax::Dim::of`]) and is emitted by [`spatial`] instead;
//! one with `urdf: "robot.urdf"` is read from that file by [`urdf`] into
//! the same spatial description.
//!
//! To add a source of descriptions (another syntax), produce a
//! [`syntax::Input`] and hand it to [`desc::validate()`]; to add a joint
//! type, add it to the dimension's `JOINTS` table ([`desc::planar`],
//! [`desc::spatial`]) and to its `kind`.

#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod ctxt;
pub mod desc;
pub mod describe;
pub mod emit;
pub mod emit_terms;
pub mod geom3;
pub mod lit;
pub mod mechanics;
pub mod number;
mod param_struct;
pub mod planar_tree;
pub mod spatial;
pub mod symbolic;
pub mod syntax;
pub mod target;
pub mod tree_items;
pub mod urdf;

pub use target::Target;

use proc_macro2::TokenStream;

/// The largest planar expansion with closed-form views, in bytes of token
/// text (past it a tree gets the tree engine's items alone and a loop is
/// refused: [`planar_tree`]). The closed-form planar terms grow about 1.5× per link of a chain (a
/// 12-link chain expands to 3.3 MB, which rustc compiled in 40 s using
/// 3.9 GB; 14 links 7.8 MB; 16 links 17 MB, which rustc could not
/// finish in 5 minutes on a 24 GB machine).
pub const MAX_PLANAR_EXPANSION: usize = 8_000_000;

/// Expand a `mechanism!` body into Rust items ([`Target::Std`]), or a
/// spanned error.
pub fn expand(input: TokenStream) -> syn::Result<TokenStream> {
    expand_for(input, Target::Std)
}

/// Expand a `mechanism!` body into the items of `target`, or a spanned
/// error.
pub fn expand_for(input: TokenStream, target: Target) -> syn::Result<TokenStream> {
    // `urdf: "robot.urdf"` reads a file into a spatial description
    if urdf::is_urdf(&input) {
        let (parsed, track) = urdf::lower(input)?;
        let model = desc::validate::<3, desc::spatial::Spatial>(parsed)?;
        let mut out = spatial::emit::emit(&model, target);
        // `tree()` and `robot()` from the run-time parameters, as for a
        // declared 3-D tree (a fixed base: the file's order is the
        // placement order, so the bodies and inputs are those of
        // `TREE_BODIES` and `TREE_INPUTS`)
        out.extend(spatial::tree::emit(&model, target));
        out.extend(track);
        return Ok(out);
    }
    // `gravity: [gx, gy, gz]` selects the spatial rules; everything else is
    // planar (which reports any other shape of `gravity`).
    let dim = syntax::Dim::of(&input);
    let parsed = syntax::Input::parse2(input, dim)?;
    if dim == syntax::Dim::Spatial {
        let model = desc::validate::<3, desc::spatial::Spatial>(parsed)?;
        let mut out = spatial::emit::emit(&model, target);
        out.extend(spatial::tree::emit(&model, target));
        return Ok(out);
    }
    let model = desc::validate::<2, desc::planar::Planar>(parsed)?;
    // the closed-form terms while they compile; past that a tree steps on
    // the tree engine alone, and a loop is refused
    let depth = planar_tree::depth(&model);
    if depth > planar_tree::MAX_CLOSED_FORM_DEPTH {
        let why = format!(
            "its longest chain has {depth} joints, and the closed form's size grows about \
             1.5× per joint past {} (14 joints: 7.8 MB of Rust)",
            planar_tree::MAX_CLOSED_FORM_DEPTH
        );
        return too_large(&model, target, &why);
    }
    let mut out = emit::emit(&model, target)?;
    out.extend(describe::emit(&model, target));
    out.extend(planar_tree::emit(&model, target));
    let bytes = out.to_string().len();
    if bytes > MAX_PLANAR_EXPANSION {
        let why = format!(
            "they would expand to {:.1} MB of Rust, more than rustc compiles in reasonable \
             time and memory (limit {} MB)",
            bytes as f64 / 1e6,
            MAX_PLANAR_EXPANSION / 1_000_000
        );
        return too_large(&model, target, &why);
    }
    Ok(out)
}

/// A planar description whose closed form is too large: a tree gets the
/// tree engine's items alone ([`planar_tree::emit_tree_only`]); a loop,
/// which the tree engine does not step, is refused.
fn too_large(model: &desc::planar::Model, target: Target, why: &str) -> syn::Result<TokenStream> {
    if model.loops.is_empty() {
        return Ok(planar_tree::emit_tree_only(model, target, why));
    }
    Err(syn::Error::new(
        model.name.span(),
        format!(
            "mechanism `{}` has a loop and closed-form terms too large to compile: {why}. \
             Declare it with the 3-D syntax (`gravity: [gx, gy, 0.0]`, revolute axes \
             `[0.0, 0.0, 1.0]`, each link's `inertia: [i1, i2, i3]`), whose terms are \
             evaluated at run time, or use fewer links",
            model.name
        ),
    ))
}

/// Expand a description given as source text and pretty-print the result,
/// as reviewed in snapshots. Errors are returned as their messages.
///
/// ```
/// let src = vigp_codegen::expand_to_string(
///     "pub Pendulum { links { rod: { mass: 1.0, length: 1.0 } } joints { pivot: revolute(world, rod.start) } }",
/// )
/// .unwrap();
/// assert!(src.contains("impl ::vigp::Mechanism<1, 0> for PendulumMinimal"));
/// ```
pub fn expand_to_string(src: &str) -> Result<String, String> {
    expand_to_string_for(src, Target::Std)
}

/// [`expand_to_string`] for a chosen [`Target`].
pub fn expand_to_string_for(src: &str, target: Target) -> Result<String, String> {
    let tokens: TokenStream = src.parse().map_err(|e| format!("{e}"))?;
    let out = expand_for(tokens, target).map_err(|e| {
        e.into_iter()
            .map(|e| e.to_string())
            .collect::<Vec<_>>()
            .join("\n")
    })?;
    let file: syn::File =
        syn::parse2(out).map_err(|e| format!("generated code does not parse: {e}"))?;
    Ok(prettyplease::unparse(&file))
}
