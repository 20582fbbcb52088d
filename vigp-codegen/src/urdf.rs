//! `mechanism! { Name { urdf: "robot.urdf", … } }`: a robot read from a
//! URDF file when the macro runs, lowered into the spatial description a
//! user would have written by hand, then validated and emitted as every
//! spatial mechanism is.
//!
//! ```text
//! /// docs
//! pub Name {
//!     urdf: "path/relative/to/CARGO_MANIFEST_DIR.urdf",
//!     gravity?: [gx, gy, gz],          // default [0, 0, −9.81]
//!     base?: fixed | floating,         // default fixed
//!     joints? {                        // overrides, by URDF joint name
//!         name: { actuated?, damping?: c, stiffness?: k, rest?: s0 },
//!     }
//! }
//! ```
//!
//! The file is read by `vigp_urdf::parse`, the converter that the run-time
//! `vigp::Robot::from_urdf` uses: fixed joints merged, one body per
//! revolute, continuous or prismatic joint. Each body becomes a spatial
//! link whose `frame` is the body frame's axes in world coordinates at the
//! zero configuration, with its mass, its centre of mass and its full
//! inertia matrix in that frame (the spatial `inertia` takes a symmetric
//! matrix, so no eigen-decomposition is needed); each joint becomes a
//! `revolute` or `prismatic` joint from the joint origin on the parent
//! (`parent @ [x, y, z]`, or `world @ [..]` for the base) to the child's
//! `start`, its axis in the parent's frame, with the URDF damping when it
//! is not zero. A floating base adds the root link (with the links fixed
//! to it) and a `free(world, root.start)` joint named `root_joint`.
//! `<limit>` has no place in the spatial description and is not emitted.
//!
//! On a fixed base the same bodies are also emitted as constants for the
//! linear-time tree engine (`tree_items`): `Name::TREE_BODIES` (the
//! file's bodies with the joint overrides), `Name::TREE_GRAVITY`,
//! `Name::TREE_INPUTS` (the coordinate of each input) and the unit type
//! `NameTree`, which implements `vigp::embedded::tree::Tree` over them,
//! so that `Engine::new(NameTree)` steps the robot, `no_std`, with every
//! body's constants known to the compiler. As every declared 3-D tree, it
//! also gets `Name::tree()` and `Name::robot()` (`crate::spatial::tree`):
//! the same bodies built from the run-time parameters.
//!
//! Every mistake in the file or in the overrides is a compile error at the
//! `urdf:` path (or at the override), naming the URDF element and its line.

use crate::lit::lit;
use crate::number::Number;
use crate::syntax::{self, Dim, Field, Input, JointDecl, LinkDecl, PointRef, Value};
use proc_macro2::{Delimiter, Span, TokenStream, TokenTree};
use quote::quote;
use syn::ext::IdentExt;
use syn::parse::{ParseStream, Parser};
use syn::{Attribute, Ident, LitStr, Token, Visibility, braced};
use vigp_core::tree::spatial::{M3, V3, mul_mm, mul_mv};

/// The keys a joint override takes.
const OVERRIDE_KEYS: [&str; 4] = ["actuated", "damping", "stiffness", "rest"];

/// The name of the free joint of a floating base.
const ROOT_JOINT: &str = "root_joint";

/// `true` when a `mechanism!` body declares `urdf: "…"` (then this module
/// reads it instead of the hand-written grammar).
pub fn is_urdf(input: &TokenStream) -> bool {
    let Some(body) = input.clone().into_iter().find_map(|t| match t {
        TokenTree::Group(g) if g.delimiter() == Delimiter::Brace => Some(g.stream()),
        _ => None,
    }) else {
        return false;
    };
    let tokens: Vec<TokenTree> = body.into_iter().collect();
    tokens.windows(2).any(|w| {
        matches!((&w[0], &w[1]), (TokenTree::Ident(k), TokenTree::Punct(c))
            if k == "urdf" && c.as_char() == ':')
    })
}

/// One joint override: `name: { fields }`.
struct Override {
    name: Ident,
    fields: Vec<Field>,
}

/// A `urdf:` description as written.
struct UrdfInput {
    attrs: Vec<Attribute>,
    vis: Visibility,
    name: Ident,
    path: LitStr,
    gravity: Option<(Ident, Value)>,
    floating: bool,
    joints: Vec<Override>,
}

fn parse(input: ParseStream) -> syn::Result<UrdfInput> {
    let attrs = input.call(Attribute::parse_outer)?;
    let vis = input.parse()?;
    let name: Ident = input.parse()?;
    let content;
    braced!(content in input);
    if !input.is_empty() {
        return Err(input.error("unexpected tokens after the mechanism body"));
    }
    let (mut path, mut gravity, mut base, mut joints) = (None, None, None, None);
    let twice = |key: &Ident| syn::Error::new(key.span(), format!("duplicate section `{key}`"));
    while !content.is_empty() {
        let key: Ident = content.parse()?;
        match key.to_string().as_str() {
            "urdf" => {
                content.parse::<Token![:]>()?;
                let lit: LitStr = content.parse()?;
                if path.replace(lit).is_some() {
                    return Err(twice(&key));
                }
            }
            "gravity" => {
                content.parse::<Token![:]>()?;
                let v = syntax::parse_value(&content)?;
                if gravity.replace((key.clone(), v)).is_some() {
                    return Err(twice(&key));
                }
            }
            "base" => {
                content.parse::<Token![:]>()?;
                let kind: Ident = content.parse()?;
                let floating = match kind.to_string().as_str() {
                    "fixed" => false,
                    "floating" => true,
                    _ => {
                        return Err(syn::Error::new(
                            kind.span(),
                            format!(
                                "unknown base `{kind}`: expected `fixed` (the root link is the world, the default) or `floating` (a free joint from the world to the root link)"
                            ),
                        ));
                    }
                };
                if base.replace(floating).is_some() {
                    return Err(twice(&key));
                }
            }
            "joints" => {
                let inner;
                braced!(inner in content);
                let list = inner.parse_terminated(
                    |i: ParseStream| {
                        let name: Ident = i.parse()?;
                        i.parse::<Token![:]>()?;
                        let fields = syntax::parse_field_block(i)?;
                        Ok(Override { name, fields })
                    },
                    Token![,],
                )?;
                if joints
                    .replace(list.into_iter().collect::<Vec<_>>())
                    .is_some()
                {
                    return Err(twice(&key));
                }
            }
            "links" => {
                return Err(syn::Error::new(
                    key.span(),
                    "a `urdf:` mechanism takes its links from the file: it has no `links` section (override joints in `joints { name: { actuated, damping: c } }`)",
                ));
            }
            _ => {
                return Err(syn::Error::new(
                    key.span(),
                    format!(
                        "unknown section `{key}`: a `urdf:` mechanism takes `urdf`, `gravity`, `base` and `joints`"
                    ),
                ));
            }
        }
        content.parse::<Option<Token![,]>>()?;
    }
    let Some(path) = path else {
        return Err(syn::Error::new(name.span(), "missing `urdf: \"path\"`"));
    };
    Ok(UrdfInput {
        attrs,
        vis,
        name,
        path,
        gravity,
        floating: base.unwrap_or(false),
        joints: joints.unwrap_or_default(),
    })
}

/// A URDF name as a Rust field name: ASCII letters lower-cased (fields are
/// snake case), other characters than letters, digits and `_` become `_`,
/// a leading digit gets a `_`; keywords become raw identifiers (`ident`).
pub fn rust_name(name: &str) -> String {
    let mut s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect();
    if s.is_empty() || s.starts_with(|c: char| c.is_ascii_digit()) || s == "_" {
        s.insert(0, '_');
    }
    s
}

fn ident(name: &str, span: Span) -> Ident {
    let s = rust_name(name);
    // keywords become raw identifiers; the few that cannot be raw get a `_`
    match syn::parse_str::<Ident>(&s) {
        Ok(_) => Ident::new(&s, span),
        Err(_) if !["self", "Self", "super", "crate"].contains(&s.as_str()) => {
            Ident::new_raw(&s, span)
        }
        Err(_) => Ident::new(&format!("{s}_"), span),
    }
}

/// `#[doc = text]`.
fn doc(text: &str) -> Vec<Attribute> {
    vec![syn::parse_quote!(#[doc = #text])]
}

/// A number the macro knows, spanned at the `urdf:` path.
fn number(x: f64, span: Span) -> Value {
    let tokens: TokenStream = lit(x)
        .into_iter()
        .map(|mut t| {
            t.set_span(span);
            t
        })
        .collect();
    let expr = syn::parse2(tokens).expect("a float literal is an expression");
    Value::Number(Number {
        value: Some(x),
        expr: Box::new(expr),
    })
}

fn triple(v: V3, span: Span) -> Value {
    Value::Array(span, v.iter().map(|&x| number(x, span)).collect())
}

fn matrix(m: &M3, span: Span) -> Value {
    Value::Array(span, m.iter().map(|r| triple(*r, span)).collect())
}

fn field(key: &str, value: Value, span: Span) -> Field {
    Field {
        key: Ident::new(key, span),
        value,
    }
}

/// The 3×3 transpose.
fn transpose(m: &M3) -> M3 {
    std::array::from_fn(|i| std::array::from_fn(|j| m[j][i]))
}

/// A number as a constant expression: the macro's value when it knows it
/// (±∞ by name), else the expression as written (a named constant).
fn constant(value: Option<f64>, expr: Option<&syn::Expr>) -> TokenStream {
    match (value, expr) {
        (Some(x), _) if x == f64::INFINITY => quote!(::core::f64::INFINITY),
        (Some(x), _) if x == f64::NEG_INFINITY => quote!(::core::f64::NEG_INFINITY),
        (Some(x), _) => lit(x),
        (None, Some(e)) => quote!(#e),
        (None, None) => quote!(0.0),
    }
}

/// The bodies of a fixed-base robot as constants of the tree engine
/// (module docs): the file's bodies in its order, each joint's `damping`,
/// `stiffness`, `rest` and `actuated` read from `joints`, its lowered
/// declaration with the block's overrides applied (joint k is body k's),
/// the gravity as declared (default (0, 0, −9.81)), and the inputs in the
/// order `actuated` appears in the file.
fn tree_items(
    vis: &Visibility,
    name: &Ident,
    tree: &vigp_urdf::UrdfTree,
    joints: &[JointDecl],
    gravity: Option<&Value>,
) -> TokenStream {
    let core = quote!(::vigp::embedded::tree);
    let f = |x: f64| constant(Some(x), None);
    let v3 = |v: &V3| {
        let (a, b, c) = (f(v[0]), f(v[1]), f(v[2]));
        quote!([#a, #b, #c])
    };
    let mut inputs = Vec::new();
    let bodies: Vec<TokenStream> = tree
        .bodies
        .iter()
        .enumerate()
        .map(|(k, b)| {
            // the joint's declaration, with the file's damping and the
            // block's overrides already applied
            let mut damping = f(b.damping);
            let (mut stiffness, mut rest) = (f(b.stiffness), f(b.rest));
            for field in &joints[k].fields {
                let number = |v: &Value| match v {
                    Value::Number(n) => Some(constant(n.value, Some(&n.expr))),
                    _ => None,
                };
                match (field.key.to_string().as_str(), &field.value) {
                    ("actuated", Value::Flag(_)) => inputs.push(k),
                    ("damping", v) => damping = number(v).unwrap_or(damping),
                    ("stiffness", v) => stiffness = number(v).unwrap_or(stiffness),
                    ("rest", v) => rest = number(v).unwrap_or(rest),
                    _ => {}
                }
            }
            let parent = match b.parent {
                Some(p) => quote!(::core::option::Option::Some(#p)),
                None => quote!(::core::option::Option::None),
            };
            let joint = match b.joint {
                vigp_core::tree::JointKind::Revolute => quote!(#core::JointKind::Revolute),
                vigp_core::tree::JointKind::Prismatic => quote!(#core::JointKind::Prismatic),
            };
            let (axis, translation, com) = (v3(&b.axis), v3(&b.translation), v3(&b.com));
            let (rot, inertia) = (b.rotation.map(|r| v3(&r)), b.inertia.map(|r| v3(&r)));
            let mass = f(b.mass);
            let l = &b.limits;
            let (lower, upper, effort, velocity) =
                (f(l.lower), f(l.upper), f(l.effort), f(l.velocity));
            quote! {
                #core::Body {
                    parent: #parent,
                    joint: #joint,
                    axis: #axis,
                    rotation: [#(#rot),*],
                    translation: #translation,
                    mass: #mass,
                    com: #com,
                    inertia: [#(#inertia),*],
                    damping: #damping,
                    stiffness: #stiffness,
                    rest: #rest,
                    limits: #core::Limits { lower: #lower, upper: #upper, effort: #effort, velocity: #velocity },
                }
            }
        })
        .collect();
    let gravity = match gravity.and_then(|g| g.items(3)) {
        Some(g) => {
            let g: Vec<TokenStream> = g.iter().map(|n| constant(n.value, Some(&n.expr))).collect();
            quote!([#(#g),*])
        }
        None => v3(&[0.0, 0.0, -9.81]),
    };
    let n = bodies.len();
    // with inputs, `TREE_INPUTS` comes with `tree()` (`tree_items`): the
    // same bodies, as the file's order is the placement order
    let tree_inputs = if inputs.is_empty() {
        quote! {
            /// The coordinate (body) each input drives, in input order.
            pub const TREE_INPUTS: [usize; 0] = [];
        }
    } else {
        quote!()
    };
    let tree_name = Ident::new(&format!("{name}Tree"), name.span());
    let doc_bodies = format!(
        " The robot of `{name}` as the tree engine's bodies, parents first (the \
         file's joints with a coordinate, fixed joints merged), with the joint \
         overrides of the block: the constants `{tree_name}` gives \
         `vigp::embedded::tree::Engine`."
    );
    let doc_tree = format!(
        " The tree of `{name}` as compile-time constants \
         (`{name}::TREE_BODIES`, `{name}::TREE_GRAVITY`): \
         `vigp::embedded::tree::Engine::new({tree_name})` steps it on the \
         linear-time engine, `no_std`, with every body's constants known to the \
         compiler (the run-time `vigp::Robot::from_urdf` of the same file \
         steps the same bodies)."
    );
    quote! {
        // the file's numbers as written: a limit of 0.5235987755982988 is
        // the file's, not an approximation of π/6
        #[allow(clippy::approx_constant)]
        impl #name {
            #[doc = #doc_bodies]
            pub const TREE_BODIES: [#core::Body; #n] = [#(#bodies),*];
            /// Gravity of the tree engine's model (m/s², world axes).
            pub const TREE_GRAVITY: [f64; 3] = #gravity;
            #tree_inputs
        }

        #[doc = #doc_tree]
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
        #vis struct #tree_name;

        impl #core::Tree for #tree_name {
            #[inline(always)]
            fn len(&self) -> usize {
                #n
            }
            #[inline(always)]
            fn body(&self, i: usize) -> &#core::Body {
                &#name::TREE_BODIES[i]
            }
            #[inline(always)]
            fn gravity(&self) -> [f64; 3] {
                #name::TREE_GRAVITY
            }
        }
    }
}

/// Reads the file of a `urdf:` description and lowers it to the spatial
/// description a user would write by hand; also returns the tokens that
/// make the compiled crate depend on the file (`include_bytes!`), so that
/// editing it recompiles the mechanism, and on a fixed base the tree
/// engine's constants (`tree_items`).
pub fn lower(tokens: TokenStream) -> syn::Result<(Input, TokenStream)> {
    let u = parse.parse2(tokens)?;
    let span = u.path.span();
    let rel = u.path.value();
    let dir = std::env::var_os("CARGO_MANIFEST_DIR").ok_or_else(|| {
        syn::Error::new(
            span,
            "CARGO_MANIFEST_DIR is not set: `urdf:` paths are relative to the invoking crate's manifest directory, which cargo sets",
        )
    })?;
    let file = std::path::Path::new(&dir).join(&rel);
    let text = std::fs::read_to_string(&file).map_err(|e| {
        syn::Error::new(
            span,
            format!("cannot read URDF file \"{rel}\" (relative to CARGO_MANIFEST_DIR): {e}"),
        )
    })?;
    let tree = vigp_urdf::parse(&text).map_err(|e| {
        let at = e
            .line(&text)
            .map_or_else(String::new, |l| format!(", line {l}"));
        syn::Error::new(span, format!("URDF \"{rel}\"{at}: {e}"))
    })?;

    // world poses at the zero configuration: rotation (body → world) and
    // origin of each body frame; the base is the world (fixed) or the root
    // link at the origin (floating)
    let n = tree.bodies.len();
    let mut rot: Vec<M3> = Vec::with_capacity(n);
    for b in &tree.bodies {
        let parent = b
            .parent
            .map_or(vigp_core::tree::spatial::IDENTITY, |p| rot[p]);
        rot.push(mul_mm(&parent, &b.rotation));
    }
    let names: Vec<Ident> = tree.links.iter().map(|l| ident(l, span)).collect();
    let root = ident(&tree.root, span);
    let mass_fields = |m: f64, com: V3, inertia: &M3, r: &M3| {
        vec![
            field("mass", number(m, span), span),
            field("com", triple(com, span), span),
            field("inertia", matrix(inertia, span), span),
            // the frame's rows are the body axes in world coordinates: the
            // columns of the body → world rotation
            field("frame", matrix(&transpose(r), span), span),
        ]
    };
    let mut links = Vec::new();
    let mut joints = Vec::new();
    if u.floating {
        let b = &tree.base;
        links.push(LinkDecl {
            attrs: doc(&format!(
                " URDF link `{}` and the links fixed to it, on a free joint.",
                tree.root
            )),
            name: root.clone(),
            fields: mass_fields(
                b.mass,
                b.com,
                &b.inertia,
                &vigp_core::tree::spatial::IDENTITY,
            ),
        });
        joints.push(JointDecl {
            attrs: Vec::new(),
            name: Ident::new(ROOT_JOINT, span),
            kind: Ident::new("free", span),
            parent: PointRef::World { span, at: None },
            child: PointRef::Link {
                link: root.clone(),
                anchor: syntax::Anchor::Start(span),
            },
            fields: Vec::new(),
        });
    }
    for (k, b) in tree.bodies.iter().enumerate() {
        links.push(LinkDecl {
            attrs: doc(&format!(
                " URDF link `{}` (with the links fixed to it).",
                tree.links[k]
            )),
            name: names[k].clone(),
            fields: mass_fields(b.mass, b.com, &b.inertia, &rot[k]),
        });
        let parent = match (b.parent, u.floating) {
            (Some(p), _) => PointRef::Link {
                link: names[p].clone(),
                anchor: syntax::Anchor::At(triple(b.translation, span)),
            },
            (None, true) => PointRef::Link {
                link: root.clone(),
                anchor: syntax::Anchor::At(triple(b.translation, span)),
            },
            (None, false) => PointRef::World {
                span,
                at: Some(triple(b.translation, span)),
            },
        };
        let kind = match b.joint {
            vigp_core::tree::JointKind::Revolute => "revolute",
            vigp_core::tree::JointKind::Prismatic => "prismatic",
        };
        let mut fields = vec![field(
            "axis",
            triple(mul_mv(&b.rotation, b.axis), span),
            span,
        )];
        if b.damping != 0.0 {
            fields.push(field("damping", number(b.damping, span), span));
        }
        joints.push(JointDecl {
            attrs: doc(&format!(" URDF joint `{}`.", tree.joints[k])),
            name: ident(&tree.joints[k], span),
            kind: Ident::new(kind, span),
            parent,
            child: PointRef::Link {
                link: names[k].clone(),
                anchor: syntax::Anchor::Start(span),
            },
            fields,
        });
    }

    // the overrides, by joint name
    let mut errors: Option<syn::Error> = None;
    let mut err = |e: syn::Error| match &mut errors {
        Some(all) => all.combine(e),
        None => errors = Some(e),
    };
    for o in u.joints {
        // the user may write the URDF spelling or the field name
        let wanted = rust_name(&o.name.unraw().to_string());
        let Some(decl) = joints.iter_mut().find(|j| j.name.unraw() == wanted) else {
            let known: Vec<String> = tree.joints.iter().map(|j| rust_name(j)).collect();
            let why = if vigp_urdf::line_of(&text, "joint", &o.name.to_string()).is_some() {
                " (it is a fixed joint, merged into its parent link: it has no coordinate)"
            } else {
                ""
            };
            err(syn::Error::new(
                o.name.span(),
                format!(
                    "no joint `{}` with a coordinate in \"{rel}\"{why}; joints with a coordinate: {}",
                    o.name,
                    known.join(", ")
                ),
            ));
            continue;
        };
        for f in o.fields {
            let key = f.key.to_string();
            if !OVERRIDE_KEYS.contains(&key.as_str()) {
                err(syn::Error::new(
                    f.key.span(),
                    format!(
                        "a URDF joint override takes `actuated`, `damping`, `stiffness` or `rest`, not `{key}` (the geometry comes from the file)"
                    ),
                ));
                continue;
            }
            // a declared damping replaces the file's
            decl.fields.retain(|g| g.key != key || key != "damping");
            decl.fields.push(f);
        }
    }
    if let Some(e) = errors {
        return Err(e);
    }

    let track = if std::path::Path::new(&rel).is_absolute() {
        quote!(
            const _: &[u8] = include_bytes!(#rel);
        )
    } else {
        let rel = format!("/{rel}");
        quote!(
            const _: &[u8] = include_bytes!(concat!(env!("CARGO_MANIFEST_DIR"), #rel));
        )
    };
    // on a fixed base, joint k is body k's
    let tree_items = if u.floating {
        TokenStream::new()
    } else {
        tree_items(
            &u.vis,
            &u.name,
            &tree,
            &joints,
            u.gravity.as_ref().map(|g| &g.1),
        )
    };
    let track = quote!(#track #tree_items);
    let input = Input {
        dim: Dim::Spatial,
        attrs: u.attrs,
        vis: u.vis,
        name: u.name,
        gravity: u.gravity,
        links: Some((Ident::new("links", span), links)),
        joints: Some((Ident::new("joints", span), joints)),
    };
    Ok((input, track))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urdf_names_become_rust_identifiers() {
        assert_eq!(rust_name("panda_link0"), "panda_link0");
        assert_eq!(rust_name("FL-HAA.joint"), "fl_haa_joint");
        assert_eq!(rust_name("3rd"), "_3rd");
        assert_eq!(ident("type", Span::call_site()).to_string(), "r#type");
        assert_eq!(ident("self", Span::call_site()).to_string(), "self_");
    }

    #[test]
    fn a_urdf_key_selects_this_grammar() {
        let t = |s: &str| is_urdf(&s.parse().unwrap());
        assert!(t(r#"pub A { urdf: "a.urdf" }"#));
        assert!(t(r#"A { gravity: [0.0, 0.0, -1.0], urdf: "a.urdf" }"#));
        assert!(!t(
            "A { gravity: [0.0, 0.0, -1.0], links { urdf: { mass: 1.0 } } }"
        ));
    }

    /// The sizes of the expansion follow from the file (the tests run in
    /// this crate's directory): the wrist has 3 coordinates (its weld
    /// merged), one input per `actuated`; the Panda on a floating base has
    /// 7 + 7 coordinates and one unit-quaternion constraint.
    #[test]
    fn expansions_have_the_files_sizes() {
        let wrist = crate::expand_to_string(
            r#"W { urdf: "../tests/fixtures/robots/wrist.urdf", joints { slide: { actuated } } }"#,
        )
        .unwrap();
        assert!(wrist.contains("impl ::vigp::Mechanism<3, 0> for WMinimal"));
        assert!(!wrist.contains("pub hand") && wrist.contains("pub fore"));
        assert!(wrist.contains("include_bytes!"));
        let panda = crate::expand_to_string(
            r#"P { urdf: "../tests/fixtures/robots/panda.urdf", base: floating }"#,
        )
        .unwrap();
        assert!(panda.contains("impl ::vigp::Mechanism<14, 1> for PMinimal"));
        // the other robots of the fixtures: the UR5 (6 joints), the Solo-12
        // legs (12, upper-case names) and the G1 humanoid (29)
        for (file, n) in [("ur5", 6), ("solo12", 12), ("g1", 29)] {
            let code = crate::expand_to_string(&format!(
                r#"R {{ urdf: "../tests/fixtures/robots/{file}.urdf" }}"#
            ))
            .unwrap_or_else(|e| panic!("{file}: {e}"));
            assert!(code.contains(&format!("impl ::vigp::Mechanism<{n}, 0> for RMinimal")));
        }
        let solo = crate::expand_to_string(
            r#"S { urdf: "../tests/fixtures/robots/solo12.urdf", joints { FL_HAA: { actuated }, fl_hfe: { actuated } } }"#,
        )
        .unwrap();
        assert!(solo.contains("pub fl_") && !solo.contains("pub FL_"));
        let e = crate::expand_to_string(r#"P { urdf: "../tests/fixtures/robots/none.urdf" }"#)
            .unwrap_err();
        assert!(e.contains("cannot read URDF file"), "{e}");
        // the wrist's base link has no mass: it cannot float
        let e = crate::expand_to_string(
            r#"W { urdf: "../tests/fixtures/robots/wrist.urdf", base: floating }"#,
        )
        .unwrap_err();
        assert!(e.contains("mass"), "{e}");
    }
}
