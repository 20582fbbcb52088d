//! Rust emitted for a validated [`Model`]: the parameter types, forward
//! kinematics, and the minimal-coordinate [`Mechanism`] implementation.
//! Only what the scene needs is emitted: no constraint code for a tree, no
//! dissipation code when no joint declares `damping`.
//!
//! [`Mechanism`]: https://docs.rs/vigp-runtime

use crate::model::{Anchor, JointKind, Model, Point};
use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};
use syn::Ident;

/// An f64 literal (a leading minus for negative values).
pub fn lit(x: f64) -> TokenStream {
    let l = Literal::f64_unsuffixed(x.abs());
    if x < 0.0 { quote!(-#l) } else { quote!(#l) }
}

fn pair(p: [f64; 2]) -> TokenStream {
    let (a, b) = (lit(p[0]), lit(p[1]));
    quote!([#a, #b])
}

fn pose_ident(m: &Model, link: usize) -> Ident {
    format_ident!("{}_pose", m.links[link].name)
}

/// Local coordinates of an anchor, reading lengths from `params`.
fn anchor_local(m: &Model, params: &TokenStream, link: usize, anchor: Anchor) -> TokenStream {
    let name = &m.links[link].name;
    match anchor {
        Anchor::Start => quote!([0.0, 0.0]),
        Anchor::End => quote!([#params.links.#name.length, 0.0]),
        Anchor::Center => quote!([#params.links.#name.length * 0.5, 0.0]),
        Anchor::At(p) => pair(p),
    }
}

/// World position of a point, given pose locals.
fn point_expr(m: &Model, params: &TokenStream, p: Point) -> TokenStream {
    match p {
        Point::World(w) => {
            let w = pair(w);
            quote!(::vigp::kinematics::world(#w))
        }
        Point::Link { link, anchor } => {
            let pose = pose_ident(m, link);
            let local = anchor_local(m, params, link, anchor);
            quote!(#pose.point(#local))
        }
    }
}

/// Orientation of the body a point is on (world: 0).
fn theta_expr(m: &Model, p: Point) -> TokenStream {
    match p.link() {
        None => quote!(::vigp::kinematics::zero()),
        Some(l) => {
            let pose = pose_ident(m, l);
            quote!(#pose.theta)
        }
    }
}

/// World direction of a prismatic axis fixed in the parent.
fn axis_expr(m: &Model, parent: Point, axis: [f64; 2]) -> TokenStream {
    let a = pair(axis);
    match parent.link() {
        None => quote!(::vigp::kinematics::world(#a)),
        Some(l) => {
            let pose = pose_ident(m, l);
            quote!(#pose.direction(#a))
        }
    }
}

fn coordinate_index(k: usize) -> Literal {
    Literal::usize_unsuffixed(k)
}

/// `let link_pose = …;` for every link, parents first.
fn forward_kinematics(m: &Model, params: &TokenStream) -> TokenStream {
    let lets = m.order.iter().map(|&l| {
        let j = m.placed_by[l];
        let joint = &m.joints[j];
        let k = coordinate_index(m.coordinate_of(j).expect("tree joint has a coordinate"));
        let pose = pose_ident(m, l);
        let Point::Link { anchor, .. } = joint.child else {
            unreachable!("a tree joint's child is a link")
        };
        let local = anchor_local(m, params, l, anchor);
        let parent_at = point_expr(m, params, joint.parent);
        let (theta, at) = match joint.kind {
            JointKind::Revolute => {
                let theta = match joint.parent.link() {
                    None => quote!(q[#k]),
                    Some(p) => {
                        let pp = pose_ident(m, p);
                        quote!(#pp.theta + q[#k])
                    }
                };
                (theta, parent_at)
            }
            JointKind::Prismatic { axis } => {
                let dir = axis_expr(m, joint.parent, axis);
                (
                    theta_expr(m, joint.parent),
                    quote!(::vigp::kinematics::slide(#parent_at, #dir, q[#k])),
                )
            }
        };
        quote!(let #pose = ::vigp::Pose2::attach(#theta, #at, #local);)
    });
    quote!(#(#lets)*)
}

fn all_poses(m: &Model) -> Vec<Ident> {
    (0..m.links.len()).map(|l| pose_ident(m, l)).collect()
}

/// Destructuring pattern with `_` for poses the body does not use.
fn pose_pattern(m: &Model, used: &[bool]) -> TokenStream {
    let names = (0..m.links.len()).map(|l| {
        if used[l] {
            let p = pose_ident(m, l);
            quote!(#p)
        } else {
            quote!(_)
        }
    });
    quote!([#(#names),*])
}

/// Rate of a loop joint's relative coordinate, from tangent poses.
fn loop_rate(m: &Model, params: &TokenStream, j: usize) -> TokenStream {
    let joint = &m.joints[j];
    match joint.kind {
        JointKind::Revolute => {
            let (c, p) = (theta_expr(m, joint.child), theta_expr(m, joint.parent));
            quote!((#c - #p).eps)
        }
        JointKind::Prismatic { axis } => {
            let (pp, cp) = (
                point_expr(m, params, joint.parent),
                point_expr(m, params, joint.child),
            );
            let dir = axis_expr(m, joint.parent, axis);
            quote!({
                let d = ::vigp::kinematics::sub(#cp, #pp);
                let a = #dir;
                (d[0] * a[0] + d[1] * a[1]).eps
            })
        }
    }
}

fn used_by_loops(m: &Model) -> Vec<bool> {
    let mut used = vec![false; m.links.len()];
    for &j in &m.loops {
        let joint = &m.joints[j];
        for p in [joint.parent, joint.child] {
            if let Some(l) = p.link() {
                used[l] = true;
            }
        }
    }
    used
}

/// The whole expansion.
pub fn emit(m: &Model) -> TokenStream {
    let Model {
        attrs, vis, name, ..
    } = m;
    let n = Literal::usize_unsuffixed(m.dof());
    let c = Literal::usize_unsuffixed(m.loop_constraints());
    let nl = Literal::usize_unsuffixed(m.links.len());
    let links_ty = format_ident!("{}Links", name);
    let joints_ty = format_ident!("{}Joints", name);
    let minimal_ty = format_ident!("{}Minimal", name);
    let dissipative = m.dissipative();
    let svector = quote!(::vigp::__private::nalgebra::SVector);

    // ---- parameter types ----
    let link_fields = m.links.iter().map(|l| {
        let (ln, la) = (&l.name, &l.attrs);
        let doc = format!(" Link `{ln}`.");
        let doc = if la.is_empty() {
            quote!(#[doc = #doc])
        } else {
            quote!(#(#la)*)
        };
        quote!(#doc pub #ln: ::vigp::Link,)
    });
    let link_defaults = m.links.iter().map(|l| {
        let ln = &l.name;
        let (mass, length, inertia) = (lit(l.mass), lit(l.length), lit(l.inertia));
        let com = pair(l.com.unwrap_or([l.length * 0.5, 0.0]));
        quote!(#ln: ::vigp::Link { mass: #mass, length: #length, inertia: #inertia, com: #com },)
    });
    let joints_items = if dissipative {
        let fields = m.joints.iter().map(|j| {
            let (jn, ja) = (&j.name, &j.attrs);
            let doc = format!(" Joint `{jn}`.");
            let doc = if ja.is_empty() {
                quote!(#[doc = #doc])
            } else {
                quote!(#(#ja)*)
            };
            quote!(#doc pub #jn: ::vigp::Joint,)
        });
        let doc = format!(" Joint parameters of [`{name}`].");
        quote! {
            #[doc = #doc]
            #[derive(Clone, Copy, Debug, PartialEq)]
            #vis struct #joints_ty { #(#fields)* }
        }
    } else {
        quote!()
    };
    let joints_field = if dissipative {
        quote!(#[doc = " Joint parameters (damping)."] pub joints: #joints_ty,)
    } else {
        quote!()
    };
    let joints_default = if dissipative {
        let defaults = m.joints.iter().map(|j| {
            let (jn, d) = (&j.name, lit(j.damping.unwrap_or(0.0)));
            quote!(#jn: ::vigp::Joint { damping: #d },)
        });
        quote!(joints: #joints_ty { #(#defaults)* },)
    } else {
        quote!()
    };
    let gravity = pair(m.gravity);
    let link_names = m.links.iter().map(|l| l.name.to_string());
    let coord_names = m.tree.iter().map(|&j| m.joints[j].name.to_string());
    let kinds = m.tree.iter().map(|&j| match m.joints[j].kind {
        JointKind::Revolute => quote!(::vigp::CoordinateKind::Angle),
        JointKind::Prismatic { .. } => quote!(::vigp::CoordinateKind::Length),
    });

    // ---- forward kinematics ----
    let params = quote!(self);
    let fk = forward_kinematics(m, &params);
    let poses = all_poses(m);

    // ---- Mechanism impl (minimal coordinates) ----
    let sys = quote!(self.sys);
    let kinetic_terms = m.links.iter().map(|l| {
        let (ln, pose) = (&l.name, format_ident!("{}_pose", l.name));
        quote!(::vigp::kinematics::body_kinetic_energy(links.#ln.mass, links.#ln.inertia, #pose.point(links.#ln.com), #pose.theta))
    });
    let potential_terms = m.links.iter().map(|l| {
        let (ln, pose) = (&l.name, format_ident!("{}_pose", l.name));
        quote!(::vigp::kinematics::body_potential_energy(links.#ln.mass, gravity, #pose.point(links.#ln.com)))
    });
    let all_used = pose_pattern(m, &vec![true; m.links.len()]);

    let dissipation = if dissipative {
        let tree_terms = m.tree.iter().enumerate().map(|(k, &j)| {
            let (jn, k) = (&m.joints[j].name, coordinate_index(k));
            quote!(v[#k] * v[#k] * joints.#jn.damping)
        });
        let loop_terms = m.loops.iter().map(|&j| {
            let jn = &m.joints[j].name;
            let rate = loop_rate(m, &sys, j);
            quote!({ let rate = #rate; rate * rate * joints.#jn.damping })
        });
        let terms: Vec<_> = tree_terms.chain(loop_terms).collect();
        // positions enter only through the kinematics of damped loop joints
        let (q_arg, tangent) = if m.loops.is_empty() {
            (quote!(_q), quote!())
        } else {
            let pattern = pose_pattern(m, &used_by_loops(m));
            (quote!(q), quote!(let #pattern = #sys.link_poses(&::vigp::kinematics::tangent(q, v));))
        };
        quote! {
            fn dissipation<D: ::vigp::Scalar>(&self, #q_arg: &#svector<D, #n>, v: &#svector<D, #n>) -> D {
                let joints = &#sys.joints;
                #tangent
                (#(#terms)+*) * 0.5
            }
        }
    } else {
        quote!()
    };

    let constraints = if m.loops.is_empty() {
        quote!()
    } else {
        let pattern = pose_pattern(m, &used_by_loops(m));
        let mut lets = Vec::new();
        let mut rows = Vec::new();
        for &j in &m.loops {
            let joint = &m.joints[j];
            let gap = format_ident!("{}_gap", joint.name);
            let (pp, cp) = (
                point_expr(m, &sys, joint.parent),
                point_expr(m, &sys, joint.child),
            );
            match joint.kind {
                JointKind::Revolute => {
                    lets.push(quote!(let #gap = ::vigp::kinematics::sub(#pp, #cp);));
                    rows.push(quote!(#gap[0]));
                    rows.push(quote!(#gap[1]));
                }
                JointKind::Prismatic { axis } => {
                    let dir = axis_expr(m, joint.parent, axis);
                    let (tc, tp) = (theta_expr(m, joint.child), theta_expr(m, joint.parent));
                    lets.push(quote!(let #gap = ::vigp::kinematics::sub(#cp, #pp);));
                    rows.push(quote!(::vigp::kinematics::cross(#gap, #dir)));
                    rows.push(quote!(#tc - #tp));
                }
            }
        }
        quote! {
            fn constraints<D: ::vigp::Scalar>(&self, q: &#svector<D, #n>) -> #svector<D, #c> {
                let #pattern = #sys.link_poses(q);
                #(#lets)*
                #svector::from([#(#rows),*])
            }
        }
    };

    let name_str = name.to_string();
    let minimal_doc = format!(
        " Minimal-coordinate view of [`{name_str}`]: one coordinate per tree joint ({}), {} loop-closure constraint equation(s).",
        m.tree
            .iter()
            .map(|&j| format!("`{}`", m.joints[j].name))
            .collect::<Vec<_>>()
            .join(", "),
        m.loop_constraints()
    );
    let links_doc = format!(" Link parameters of [`{name_str}`].");

    quote! {
        #(#attrs)*
        #[derive(Clone, Copy, Debug, PartialEq)]
        #vis struct #name {
            #[doc = " Gravitational acceleration in world coordinates (m/s²)."]
            pub gravity: [f64; 2],
            #[doc = " Link parameters."]
            pub links: #links_ty,
            #joints_field
        }

        #[doc = #links_doc]
        #[derive(Clone, Copy, Debug, PartialEq)]
        #vis struct #links_ty { #(#link_fields)* }

        #joints_items

        impl ::core::default::Default for #name {
            fn default() -> Self {
                Self {
                    gravity: #gravity,
                    links: #links_ty { #(#link_defaults)* },
                    #joints_default
                }
            }
        }

        impl #name {
            #[doc = " Number of minimal coordinates (one per tree joint)."]
            pub const DOF: usize = #n;
            #[doc = " Number of loop-closure constraint equations in minimal coordinates."]
            pub const LOOP_CONSTRAINTS: usize = #c;
            #[doc = " Link names, in declaration order (the order of [`Self::link_poses`])."]
            pub const LINKS: [&'static str; #nl] = [#(#link_names),*];

            #[doc = " The minimal-coordinate model with these parameters."]
            pub fn minimal(&self) -> #minimal_ty {
                #minimal_ty { sys: *self }
            }

            #[doc = " Forward kinematics: the pose of every link frame (origin at the link's `start`) for minimal coordinates `q`, in [`Self::LINKS`] order. Any attachment point follows with [`::vigp::Pose2::point`]."]
            pub fn link_poses<D: ::vigp::Scalar>(&self, q: &#svector<D, #n>) -> [::vigp::Pose2<D>; #nl] {
                #fk
                [#(#poses),*]
            }
        }

        #[doc = #minimal_doc]
        #[derive(Clone, Copy, Debug, PartialEq)]
        #vis struct #minimal_ty {
            #[doc = " The parameters."]
            pub sys: #name,
        }

        impl ::vigp::Mechanism<#n, #c> for #minimal_ty {
            const COORDINATES: [&'static str; #n] = [#(#coord_names),*];
            const KINDS: [::vigp::CoordinateKind; #n] = [#(#kinds),*];
            const DISSIPATIVE: bool = #dissipative;

            fn kinetic_energy<D: ::vigp::Scalar>(&self, q: &#svector<D, #n>, v: &#svector<D, #n>) -> D {
                let links = &#sys.links;
                let #all_used = #sys.link_poses(&::vigp::kinematics::tangent(q, v));
                #(#kinetic_terms)+*
            }

            fn potential_energy<D: ::vigp::Scalar>(&self, q: &#svector<D, #n>) -> D {
                let (links, gravity) = (&#sys.links, #sys.gravity);
                let #all_used = #sys.link_poses(q);
                #(#potential_terms)+*
            }

            #dissipation

            #constraints
        }
    }
}
