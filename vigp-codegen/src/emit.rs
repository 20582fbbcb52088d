//! Rust emitted for a validated [`Model`]: the parameter types, forward
//! kinematics, and the minimal-coordinate [`Mechanism`] implementation.
//! Only what the scene needs is emitted: no constraint code for a tree, no
//! dissipation code when no joint declares `damping`.
//!
//! [`Mechanism`]: https://docs.rs/vigp-runtime

use crate::desc::planar::{Anchor, JointKind, Model, Point};
use crate::lit::lit;
use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};
use syn::Ident;
use syn::ext::IdentExt;

fn pair(p: [f64; 2]) -> TokenStream {
    let (a, b) = (lit(p[0]), lit(p[1]));
    quote!([#a, #b])
}

fn pose_ident(m: &Model, link: usize) -> Ident {
    format_ident!("pose_{}", m.links[link].name)
}

/// Local coordinates of an anchor, reading lengths from `params`.
pub(crate) fn anchor_local(
    m: &Model,
    params: &TokenStream,
    link: usize,
    anchor: Anchor,
) -> TokenStream {
    let name = &m.links[link].name;
    match anchor {
        Anchor::Start => quote!([0.0, 0.0]),
        Anchor::End => quote!([#params.links.#name.length, 0.0]),
        Anchor::Center => quote!(::vigp::kinematics::center(#params.links.#name.length)),
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
            let name = &m.links[link].name;
            // points on the link's axis skip the products by zero
            match anchor {
                Anchor::Start => quote!([#pose.x, #pose.y]),
                Anchor::End => quote!(#pose.point_on_axis(#params.links.#name.length)),
                Anchor::Center => {
                    quote!(#pose.point_on_axis(#params.links.#name.length * 0.5))
                }
                Anchor::At(_) => {
                    let local = anchor_local(m, params, link, anchor);
                    quote!(#pose.point(#local))
                }
            }
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

/// θ_child − θ_parent of a joint (the world's θ is 0 and is left out).
fn relative_theta(m: &Model, parent: Point, child: Point) -> TokenStream {
    match (child.link(), parent.link()) {
        (Some(_), None) => theta_expr(m, child),
        (None, Some(_)) => {
            let p = theta_expr(m, parent);
            quote!(-#p)
        }
        _ => {
            let (c, p) = (theta_expr(m, child), theta_expr(m, parent));
            quote!(#c - #p)
        }
    }
}

/// A prismatic axis for a dot product with a scalar point: a plain `[f64; 2]`
/// for a world parent, the rotated direction for a link parent.
fn axis_for_dot(m: &Model, parent: Point, axis: [f64; 2]) -> TokenStream {
    match parent.link() {
        None => pair(axis),
        Some(_) => axis_expr(m, parent, axis),
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
        if anchor == Anchor::Start {
            quote!(let #pose = ::vigp::Pose2::attach_start(#theta, #at);)
        } else {
            quote!(let #pose = ::vigp::Pose2::attach(#theta, #at, #local);)
        }
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

/// Relative coordinate of a joint (angle or slide) from link poses, for any
/// scalar; on tangent poses its `eps` part is the joint rate.
fn joint_coordinate(m: &Model, params: &TokenStream, j: usize) -> TokenStream {
    let joint = &m.joints[j];
    match joint.kind {
        JointKind::Revolute => relative_theta(m, joint.parent, joint.child),
        JointKind::Prismatic { axis } => {
            let (pp, cp) = (
                point_expr(m, params, joint.parent),
                point_expr(m, params, joint.child),
            );
            let dir = axis_for_dot(m, joint.parent, axis);
            quote!({
                let d = ::vigp::kinematics::sub(#cp, #pp);
                let a = #dir;
                d[0] * a[0] + d[1] * a[1]
            })
        }
    }
}

/// Constraint rows of a joint (2 equations) from link poses, pushing any
/// `let` bindings they need.
fn joint_constraint_rows(
    m: &Model,
    params: &TokenStream,
    j: usize,
    lets: &mut Vec<TokenStream>,
    rows: &mut Vec<TokenStream>,
) {
    let joint = &m.joints[j];
    let gap = format_ident!("gap_{}", joint.name);
    let (pp, cp) = (
        point_expr(m, params, joint.parent),
        point_expr(m, params, joint.child),
    );
    match joint.kind {
        JointKind::Revolute => {
            lets.push(quote!(let #gap = ::vigp::kinematics::sub(#pp, #cp);));
            rows.push(quote!(#gap[0]));
            rows.push(quote!(#gap[1]));
        }
        JointKind::Prismatic { axis } => {
            // off-axis offset, and relative orientation (bound to a name:
            // binary operators inside array literals trip clippy's
            // `possible_missing_comma` in macro output)
            let dir = axis_expr(m, joint.parent, axis);
            let turn = format_ident!("turn_{}", joint.name);
            let rel = relative_theta(m, joint.parent, joint.child);
            lets.push(quote!(let #gap = ::vigp::kinematics::sub(#cp, #pp);));
            lets.push(quote!(let #turn = #rel;));
            rows.push(quote!(::vigp::kinematics::cross(#gap, #dir)));
            rows.push(quote!(#turn));
        }
    }
}

/// Links whose poses the coordinates of `joints` read.
fn used_by_joints(m: &Model, joints: &[usize]) -> Vec<bool> {
    let mut used = vec![false; m.links.len()];
    for &j in joints {
        let joint = &m.joints[j];
        for p in [joint.parent, joint.child] {
            if let Some(l) = p.link() {
                used[l] = true;
            }
        }
    }
    used
}

/// A joint's coordinate s_j(q) for the reference path: `q[k]` for a tree
/// joint in minimal coordinates, else from the link poses in scope.
fn coordinate_tokens(m: &Model, params: &TokenStream, j: usize, minimal: bool) -> TokenStream {
    match (minimal, m.coordinate_of(j)) {
        (true, Some(k)) => {
            let k = coordinate_index(k);
            quote!(q[#k])
        }
        _ => joint_coordinate(m, params, j),
    }
}

/// `let` of the link poses the coordinates of `joints` need (none when
/// every one is a minimal tree coordinate). `poses` computes all poses
/// from `q`.
fn poses_for(m: &Model, joints: &[usize], minimal: bool, poses: &TokenStream) -> TokenStream {
    let need: Vec<usize> = joints
        .iter()
        .copied()
        .filter(|&j| !(minimal && m.coordinate_of(j).is_some()))
        .collect();
    if need.is_empty() {
        return quote!();
    }
    let pattern = pose_pattern(m, &used_by_joints(m, &need));
    quote!(let #pattern = #poses;)
}

/// The reference path's spring energy Σ ½k_j (s_j − r_j)² over every
/// joint (a `D` expression over `q`), or `None` without springs.
fn spring_energy(
    m: &Model,
    params: &TokenStream,
    minimal: bool,
    poses: &TokenStream,
) -> Option<TokenStream> {
    if !m.elastic() {
        return None;
    }
    let all: Vec<usize> = (0..m.joints.len()).collect();
    let lets = poses_for(m, &all, minimal, poses);
    let terms = all.iter().map(|&j| {
        let jn = &m.joints[j].name;
        let s = coordinate_tokens(m, params, j, minimal);
        quote!(({ let stretch = #s - joints.#jn.rest; stretch * stretch * (0.5 * joints.#jn.stiffness) }))
    });
    Some(quote!(({
        let joints = &#params.joints;
        #lets
        #(#terms)+*
    })))
}

/// The reference path's `input_work` Σ_i u_i s_i(q) over the actuated
/// joints, or nothing for an unactuated mechanism.
fn input_work(
    m: &Model,
    params: &TokenStream,
    minimal: bool,
    poses: &TokenStream,
    n: &Literal,
) -> TokenStream {
    let inputs = m.inputs();
    if inputs.is_empty() {
        return quote!();
    }
    let svector = quote!(::vigp::__private::nalgebra::SVector);
    let lets = poses_for(m, &inputs, minimal, poses);
    let terms = inputs.iter().enumerate().map(|(i, &j)| {
        let s = coordinate_tokens(m, params, j, minimal);
        let i = coordinate_index(i);
        quote!((#s) * u.get(#i).copied().unwrap_or(0.0))
    });
    quote! {
        fn input_work<D: ::vigp::Scalar>(&self, q: &#svector<D, #n>, u: &[f64]) -> D {
            #lets
            #(#terms)+*
        }
    }
}

/// The maximal-coordinate view: each link's centre-of-mass pose (x, y, θ),
/// every joint a constraint (2 equations), plus the coordinate maps.
/// Returns the items of every target and those of the std runtime
/// (the dual-number `Mechanism` and `Coordinates` impls).
fn emit_maximal(m: &Model) -> (TokenStream, TokenStream) {
    let name = &m.name;
    let vis = &m.vis;
    let maximal_ty = format_ident!("{}Maximal", name);
    let minimal_ty = format_ident!("{}Minimal", name);
    let nl = m.links.len();
    let nm = Literal::usize_unsuffixed(3 * nl);
    let n = Literal::usize_unsuffixed(m.dof());
    let cm = Literal::usize_unsuffixed(2 * m.joints.len());
    let nll = Literal::usize_unsuffixed(nl);
    let svector = quote!(::vigp::__private::nalgebra::SVector);
    let sys = quote!(self.sys);
    let poses = all_poses(m);
    let all_used = pose_pattern(m, &vec![true; nl]);

    let attach = m.links.iter().enumerate().map(|(l, link)| {
        let (ln, pose) = (&link.name, pose_ident(m, l));
        let (ix, iy, it) = (
            coordinate_index(3 * l),
            coordinate_index(3 * l + 1),
            coordinate_index(3 * l + 2),
        );
        quote!(let #pose = ::vigp::Pose2::attach(x[#it], [x[#ix], x[#iy]], self.sys.links.#ln.com);)
    });
    let coord_names = m
        .links
        .iter()
        .flat_map(|l| ["x", "y", "theta"].map(|c| format!("{}.{c}", l.name.unraw())));
    let kinetic = m.links.iter().enumerate().map(|(l, link)| {
        let ln = &link.name;
        let (ix, iy, it) = (coordinate_index(3 * l), coordinate_index(3 * l + 1), coordinate_index(3 * l + 2));
        quote!((v[#ix] * v[#ix] + v[#iy] * v[#iy]) * (0.5 * links.#ln.mass) + v[#it] * v[#it] * (0.5 * links.#ln.inertia))
    });
    let potential = m.links.iter().enumerate().map(|(l, link)| {
        let ln = &link.name;
        let (ix, iy) = (coordinate_index(3 * l), coordinate_index(3 * l + 1));
        quote!(::vigp::kinematics::body_potential_energy(links.#ln.mass, gravity, [q[#ix], q[#iy]]))
    });
    let mut lets = Vec::new();
    let mut rows = Vec::new();
    for j in 0..m.joints.len() {
        joint_constraint_rows(m, &sys, j, &mut lets, &mut rows);
    }
    let dissipation = if m.dissipative() {
        let terms = (0..m.joints.len()).map(|j| {
            let jn = &m.joints[j].name;
            let coordinate = joint_coordinate(m, &sys, j);
            quote!({ let coordinate = #coordinate; let rate = coordinate.eps; rate * rate * joints.#jn.damping })
        });
        quote! {
            fn dissipation<D: ::vigp::Scalar>(&self, q: &#svector<D, #nm>, v: &#svector<D, #nm>) -> D {
                let joints = &#sys.joints;
                let #all_used = self.link_poses(&::vigp::kinematics::tangent(q, v));
                (#(#terms)+*) * 0.5
            }
        }
    } else {
        quote!()
    };
    let max_poses = quote!(self.link_poses(q));
    let springs = match spring_energy(m, &sys, false, &max_poses) {
        Some(e) => quote!(+ #e),
        None => quote!(),
    };
    let inputs = input_work(m, &sys, false, &max_poses, &nm);
    let maximal_entries = m.links.iter().enumerate().flat_map(|(l, link)| {
        let (ln, pose) = (&link.name, pose_ident(m, l));
        [
            quote!(#pose.point(links.#ln.com)[0]),
            quote!(#pose.point(links.#ln.com)[1]),
            quote!(#pose.theta),
        ]
    });
    let coord_idents: Vec<Ident> = m
        .tree
        .iter()
        .map(|&j| format_ident!("coord_{}", m.joints[j].name))
        .collect();
    let coord_lets = m.tree.iter().zip(&coord_idents).map(|(&j, id)| {
        let e = joint_coordinate(m, &quote!(self.sys), j);
        quote!(let #id = #e;)
    });
    let doc = format!(
        " Maximal-coordinate view of [`{name}`]: the pose (x, y, θ) of each link's centre of mass ({} coordinates), every joint a constraint ({} equations).",
        3 * nl,
        2 * m.joints.len()
    );

    let items = quote! {
        impl #name {
            #[doc = " The maximal-coordinate model with these parameters."]
            pub fn maximal(&self) -> #maximal_ty {
                #maximal_ty { sys: *self }
            }
        }

        #[doc = #doc]
        #[derive(Clone, Copy, Debug, PartialEq)]
        #vis struct #maximal_ty {
            #[doc = " The parameters."]
            pub sys: #name,
        }

        impl #maximal_ty {
            #[doc = " Link frame poses (origin at each link's `start`) from maximal coordinates, in link declaration order."]
            pub fn link_poses<D: ::vigp::Real>(&self, x: &#svector<D, #nm>) -> [::vigp::Pose2<D>; #nll] {
                #(#attach)*
                [#(#poses),*]
            }
        }
    };
    let std_items = quote! {
        impl ::vigp::Mechanism<#nm, #cm> for #maximal_ty {
            const COORDINATES: [&'static str; #nm] = [#(#coord_names),*];

            fn kinetic_energy<D: ::vigp::Scalar>(&self, _q: &#svector<D, #nm>, v: &#svector<D, #nm>) -> D {
                let links = &#sys.links;
                #(#kinetic)+*
            }

            fn potential_energy<D: ::vigp::Scalar>(&self, q: &#svector<D, #nm>) -> D {
                let (links, gravity) = (&#sys.links, #sys.gravity);
                #(#potential)+* #springs
            }

            #dissipation

            #inputs

            fn constraints<D: ::vigp::Scalar>(&self, q: &#svector<D, #nm>) -> #svector<D, #cm> {
                let #all_used = self.link_poses(q);
                #(#lets)*
                #svector::from([#(#rows),*])
            }
        }

        impl ::vigp::Coordinates<#n, #nm> for #minimal_ty {
            fn maximal_positions<D: ::vigp::Scalar>(&self, q: &#svector<D, #n>) -> #svector<D, #nm> {
                let links = &#sys.links;
                let #all_used = #sys.link_poses(q);
                #svector::from([#(#maximal_entries),*])
            }

            fn minimal_positions(&self, x: &#svector<f64, #nm>) -> #svector<f64, #n> {
                let #all_used = #sys.maximal().link_poses(x);
                #(#coord_lets)*
                #svector::from([#(#coord_idents),*])
            }
        }
    };
    (items, std_items)
}

/// The parameter types of a planar description and the items of
/// `impl Name` that need no closed-form terms: what every planar
/// mechanism has, with or without its coordinate views.
pub(crate) struct ParameterItems {
    /// The parameter struct, its link and joint types and `Default`.
    pub types: TokenStream,
    /// `DOF`, `LOOP_CONSTRAINTS`, `LINKS` and `INPUT_NAMES`.
    pub consts: TokenStream,
    /// The forward kinematics `link_poses`.
    pub link_poses: TokenStream,
}

/// The [`ParameterItems`] of `m`.
pub(crate) fn parameter_items(m: &Model) -> ParameterItems {
    let n = Literal::usize_unsuffixed(m.dof());
    let c = Literal::usize_unsuffixed(m.loop_constraints());
    let nl = Literal::usize_unsuffixed(m.links.len());
    let svector = quote!(::vigp::__private::nalgebra::SVector);

    // ---- parameter types ----
    let link_defaults = m.links.iter().map(|l| {
        let ln = &l.name;
        let (mass, length) = (l.mass.tokens(), l.length.tokens());
        let given_com = l.com.as_ref().map(|[x, y]| {
            let (x, y) = (x.tokens(), y.tokens());
            quote!([#x, #y])
        });
        match (&l.inertia, given_com, l.length.known()) {
            // every value is written once: no defaults to derive
            (Some(inertia), Some(com), _) => {
                let inertia = inertia.tokens();
                quote!(#ln: ::vigp::Link { mass: #mass, length: #length, inertia: #inertia, com: #com },)
            }
            (Some(inertia), None, Some(len)) => {
                let (inertia, com) = (inertia.tokens(), pair([len * 0.5, 0.0]));
                quote!(#ln: ::vigp::Link { mass: #mass, length: #length, inertia: #inertia, com: #com },)
            }
            // a default (m·l²/12, [l/2, 0]) of a value only the compiler
            // knows: derived at run time, each expression written once
            (inertia, com, _) => {
                let some = |t: TokenStream| quote!(::core::option::Option::Some(#t));
                let none = quote!(::core::option::Option::None);
                let inertia = inertia
                    .as_ref()
                    .map_or_else(|| none.clone(), |p| some(p.tokens()));
                let com = com.map_or(none, some);
                quote!(#ln: ::vigp::Link::with_defaults(#mass, #length, #inertia, #com),)
            }
        }
    });
    let link_names = m.links.iter().map(|l| l.name.unraw().to_string());
    let input_joints = m.inputs();
    let input_names = if input_joints.is_empty() {
        quote!()
    } else {
        let u = Literal::usize_unsuffixed(input_joints.len());
        let names = input_joints
            .iter()
            .map(|&j| m.joints[j].name.unraw().to_string());
        quote! {
            #[doc = " Names of the inputs (the actuated joints, in declaration order): input i is a torque on a revolute joint or a force along a prismatic axis."]
            pub const INPUT_NAMES: [&'static str; #u] = [#(#names),*];
        }
    };
    let fk = forward_kinematics(m, &quote!(self));
    let poses = all_poses(m);
    ParameterItems {
        types: crate::param_struct::parameter_struct(
            m,
            crate::param_struct::Links {
                ty: quote!(::vigp::Link),
                name: &|l: &crate::desc::planar::Link| (&l.name, &l.attrs[..]),
                defaults: link_defaults.collect(),
            },
            quote!(),
        ),
        consts: quote! {
            #[doc = " Number of minimal coordinates (one per tree joint)."]
            pub const DOF: usize = #n;
            #[doc = " Number of loop-closure constraint equations in minimal coordinates."]
            pub const LOOP_CONSTRAINTS: usize = #c;
            #[doc = " Link names, in declaration order (the order of [`Self::link_poses`])."]
            pub const LINKS: [&'static str; #nl] = [#(#link_names),*];
            #input_names
        },
        link_poses: quote! {
            #[doc = " Forward kinematics: the pose of every link frame (origin at the link's `start`) for minimal coordinates `q`, in [`Self::LINKS`] order. Any attachment point follows with [`::vigp::Pose2::point`]."]
            pub fn link_poses<D: ::vigp::Real>(&self, q: &#svector<D, #n>) -> [::vigp::Pose2<D>; #nl] {
                #fk
                [#(#poses),*]
            }
        },
    }
}

/// The whole expansion.
/// The generated items for a validated model; `target` chooses whether the
/// std runtime's items (dual-number views) are included.
pub fn emit(m: &Model, target: crate::target::Target) -> syn::Result<TokenStream> {
    let Model { vis, name, .. } = m;
    let n = Literal::usize_unsuffixed(m.dof());
    let c = Literal::usize_unsuffixed(m.loop_constraints());
    let minimal_ty = format_ident!("{}Minimal", name);
    let dissipative = m.dissipative();
    let svector = quote!(::vigp::__private::nalgebra::SVector);

    let coord_names = m.tree.iter().map(|&j| m.joints[j].name.unraw().to_string());
    let kinds: Vec<_> = m
        .tree
        .iter()
        .map(|&j| match m.joints[j].kind {
            JointKind::Revolute => quote!(::vigp::CoordinateKind::Angle),
            JointKind::Prismatic { .. } => quote!(::vigp::CoordinateKind::Length),
        })
        .collect();

    let params = quote!(self);

    // ---- Mechanism impl (minimal coordinates) ----
    let sys = quote!(self.sys);
    let kinetic_terms = m.links.iter().map(|l| {
        let (ln, pose) = (&l.name, format_ident!("pose_{}", l.name));
        quote!(::vigp::kinematics::body_kinetic_energy(links.#ln.mass, links.#ln.inertia, #pose.point(links.#ln.com), #pose.theta))
    });
    let potential_terms = m.links.iter().map(|l| {
        let (ln, pose) = (&l.name, format_ident!("pose_{}", l.name));
        quote!(::vigp::kinematics::body_potential_energy(links.#ln.mass, gravity, #pose.point(links.#ln.com)))
    });
    let lagrangian_terms = m.links.iter().map(|l| {
        let (ln, pose) = (&l.name, format_ident!("pose_{}", l.name));
        quote!(::vigp::kinematics::body_lagrangian(links.#ln.mass, links.#ln.inertia, gravity, #pose.point(links.#ln.com), #pose.theta))
    });
    let all_used = pose_pattern(m, &vec![true; m.links.len()]);

    let dissipation = if dissipative {
        let tree_terms = m.tree.iter().enumerate().map(|(k, &j)| {
            let (jn, k) = (&m.joints[j].name, coordinate_index(k));
            quote!(v[#k] * v[#k] * joints.#jn.damping)
        });
        let loop_terms = m.loops.iter().map(|&j| {
            let jn = &m.joints[j].name;
            let coordinate = joint_coordinate(m, &sys, j);
            quote!({ let coordinate = #coordinate; let rate = coordinate.eps; rate * rate * joints.#jn.damping })
        });
        let terms: Vec<_> = tree_terms.chain(loop_terms).collect();
        // positions enter only through the kinematics of damped loop joints
        let (q_arg, tangent) = if m.loops.is_empty() {
            (quote!(_q), quote!())
        } else {
            let pattern = pose_pattern(m, &used_by_loops(m));
            (
                quote!(q),
                quote!(let #pattern = #sys.link_poses(&::vigp::kinematics::tangent(q, v));),
            )
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
        quote! {
            fn constraints<D: ::vigp::Scalar>(&self, q: &#svector<D, #n>) -> #svector<D, #c> {
                ::vigp::embedded::Model::constraints(&#sys, q)
            }
        }
    };
    let embedded_constraints = if m.loops.is_empty() {
        quote!()
    } else {
        let pattern = pose_pattern(m, &used_by_loops(m));
        let mut lets = Vec::new();
        let mut rows = Vec::new();
        for &j in &m.loops {
            joint_constraint_rows(m, &params, j, &mut lets, &mut rows);
        }
        quote! {
            fn constraints<R: ::vigp::Real>(&self, q: &#svector<R, #n>) -> #svector<R, #c> {
                let #pattern = self.link_poses(q);
                #(#lets)*
                #svector::from([#(#rows),*])
            }
        }
    };
    let body_visits = m.links.iter().map(|l| {
        let (ln, pose) = (&l.name, format_ident!("pose_{}", l.name));
        quote!(visit(::vigp::embedded::Body { mass: links.#ln.mass, inertia: links.#ln.inertia, com: #pose.point(links.#ln.com), theta: #pose.theta });)
    });
    let embedded_dampers = if dissipative {
        let tree_visits = m.tree.iter().enumerate().map(|(k, &j)| {
            let (jn, k) = (&m.joints[j].name, coordinate_index(k));
            quote!(visit(joints.#jn.damping, q[#k]);)
        });
        let loop_visits: Vec<_> = m
            .loops
            .iter()
            .map(|&j| {
                let jn = &m.joints[j].name;
                let coordinate = joint_coordinate(m, &params, j);
                quote!(visit(joints.#jn.damping, #coordinate);)
            })
            .collect();
        let poses = if m.loops.is_empty() {
            quote!()
        } else {
            let pattern = pose_pattern(m, &used_by_loops(m));
            quote!(let #pattern = self.link_poses(q);)
        };
        quote! {
            fn for_each_damper<R: ::vigp::Real>(&self, q: &#svector<R, #n>, visit: &mut impl FnMut(f64, R)) {
                let joints = &self.joints;
                #(#tree_visits)*
                #poses
                #(#loop_visits)*
            }
        }
    } else {
        quote!()
    };

    let input_joints = m.inputs();
    let name_inputs_impl = if input_joints.is_empty() {
        quote!()
    } else {
        let u = Literal::usize_unsuffixed(input_joints.len());
        quote! {
            #[doc = " Forced steps take input vectors of its number of inputs (and of length 0)."]
            impl ::vigp::embedded::Inputs<#u> for #name {}
        }
    };
    let (inputs_delegate_const, inputs_delegate_fns) = if input_joints.is_empty() {
        (quote!(), quote!())
    } else {
        let u = Literal::usize_unsuffixed(input_joints.len());
        (
            quote! {
                const INPUTS: usize = #u;
                const INPUT_NAMES: &'static [&'static str] = <#minimal_ty as ::vigp::embedded::Dynamics<#n, #c>>::INPUT_NAMES;
            },
            quote! {
                fn input_matrix<const U: usize>(&self, k: &Self::Constants, q: &#svector<f64, #n>) -> ::vigp::__private::nalgebra::SMatrix<f64, #n, U> {
                    ::vigp::embedded::Dynamics::input_matrix::<U>(&self.minimal(), k, q)
                }
                fn input_force_jacobian<const U: usize>(&self, k: &Self::Constants, q: &#svector<f64, #n>, u: &#svector<f64, U>) -> ::vigp::__private::nalgebra::SMatrix<f64, #n, #n> {
                    ::vigp::embedded::Dynamics::input_force_jacobian::<U>(&self.minimal(), k, q, u)
                }
            },
        )
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
    let (maximal_items, maximal_std) = emit_maximal(m);
    let maximal_kinds: Vec<TokenStream> = m
        .links
        .iter()
        .flat_map(|_| {
            [
                quote!(::vigp::CoordinateKind::Length),
                quote!(::vigp::CoordinateKind::Length),
                quote!(::vigp::CoordinateKind::Angle),
            ]
        })
        .collect();
    let minimal_mech = crate::mechanics::Mechanics::new(m, crate::mechanics::View::Minimal);
    let maximal_mech = crate::mechanics::Mechanics::new(m, crate::mechanics::View::Maximal);
    if !(minimal_mech.coefficients_are_finite() && maximal_mech.coefficients_are_finite()) {
        return Err(syn::Error::new(
            name.span(),
            format!(
                "the numbers of `{name}` (anchors, world points, axes) are too large: products of them overflow f64 in its closed-form terms"
            ),
        ));
    }
    let minimal_dynamics = crate::emit_terms::emit_dynamics(m, &minimal_mech, &minimal_ty, &kinds);
    let maximal_dynamics = crate::emit_terms::emit_dynamics(
        m,
        &maximal_mech,
        &format_ident!("{}Maximal", name),
        &maximal_kinds,
    );

    let min_poses = quote!(#sys.link_poses(q));
    let (min_springs, min_springs_neg) = match spring_energy(m, &sys, true, &min_poses) {
        Some(e) => (quote!(+ #e), quote!(- #e)),
        None => (quote!(), quote!()),
    };
    let min_inputs = input_work(m, &sys, true, &min_poses, &n);
    let lagrangian_body = if m.elastic() {
        quote!((#(#lagrangian_terms)+*) #min_springs_neg)
    } else {
        quote!(#(#lagrangian_terms)+*)
    };
    let std_items = if target == crate::target::Target::Std {
        quote! {
            impl ::vigp::Mechanism<#n, #c> for #minimal_ty {
            const COORDINATES: [&'static str; #n] = [#(#coord_names),*];

            fn kinetic_energy<D: ::vigp::Scalar>(&self, q: &#svector<D, #n>, v: &#svector<D, #n>) -> D {
                let links = &#sys.links;
                let #all_used = #sys.link_poses(&::vigp::kinematics::tangent(q, v));
                #(#kinetic_terms)+*
            }

            fn potential_energy<D: ::vigp::Scalar>(&self, q: &#svector<D, #n>) -> D {
                let (links, gravity) = (&#sys.links, #sys.gravity);
                let #all_used = #sys.link_poses(q);
                #(#potential_terms)+* #min_springs
            }

            fn lagrangian<D: ::vigp::Scalar>(&self, q: &#svector<D, #n>, v: &#svector<D, #n>) -> D {
                let (links, gravity) = (&#sys.links, #sys.gravity);
                let #all_used = #sys.link_poses(&::vigp::kinematics::tangent(q, v));
                #lagrangian_body
            }

            #dissipation

            #min_inputs

            #constraints

            }

            #maximal_std
        }
    } else {
        quote!()
    };

    let ParameterItems {
        types,
        consts,
        link_poses,
    } = parameter_items(m);
    Ok(quote! {
        #types

        impl #name {
            #consts

            #[doc = " The minimal-coordinate model with these parameters."]
            pub fn minimal(&self) -> #minimal_ty {
                #minimal_ty { sys: *self }
            }

            #link_poses
        }

        impl ::vigp::embedded::Model<#n, #c> for #name {
            const KINDS: [::vigp::CoordinateKind; #n] = [#(#kinds),*];
            const DISSIPATIVE: bool = #dissipative;

            fn gravity(&self) -> [f64; 2] {
                self.gravity
            }

            fn for_each_body<R: ::vigp::Real>(&self, q: &#svector<R, #n>, visit: &mut impl FnMut(::vigp::embedded::Body<R>)) {
                let links = &self.links;
                let #all_used = self.link_poses(q);
                #(#body_visits)*
            }

            #embedded_dampers

            #embedded_constraints
        }

        #[doc = #minimal_doc]
        #[derive(Clone, Copy, Debug, PartialEq)]
        #vis struct #minimal_ty {
            #[doc = " The parameters."]
            pub sys: #name,
        }

        #minimal_dynamics

        #name_inputs_impl

        #[doc = " The parameter struct is its minimal-coordinate model: `Stepper::new(sys, dt)` steps `sys.minimal()`."]
        impl ::vigp::embedded::Dynamics<#n, #c> for #name {
            const KINDS: [::vigp::CoordinateKind; #n] = <#minimal_ty as ::vigp::embedded::Dynamics<#n, #c>>::KINDS;
            const DISSIPATIVE: bool = <#minimal_ty as ::vigp::embedded::Dynamics<#n, #c>>::DISSIPATIVE;
            const CONSTANT_MASS: bool = <#minimal_ty as ::vigp::embedded::Dynamics<#n, #c>>::CONSTANT_MASS;
            const DMASS_PATTERN: [[[bool; #n]; #n]; #n] = <#minimal_ty as ::vigp::embedded::Dynamics<#n, #c>>::DMASS_PATTERN;
            const CONSTRAINT_PATTERN: [[bool; #n]; #c] = <#minimal_ty as ::vigp::embedded::Dynamics<#n, #c>>::CONSTRAINT_PATTERN;
            #inputs_delegate_const
            type Constants = <#minimal_ty as ::vigp::embedded::Dynamics<#n, #c>>::Constants;
            fn constants(&self) -> ::core::result::Result<Self::Constants, ::vigp::embedded::StepError> {
                ::vigp::embedded::Dynamics::constants(&self.minimal())
            }
            fn mass(&self, k: &Self::Constants, q: &#svector<f64, #n>) -> ::vigp::__private::nalgebra::SMatrix<f64, #n, #n> {
                ::vigp::embedded::Dynamics::mass(&self.minimal(), k, q)
            }
            fn potential(&self, k: &Self::Constants, q: &#svector<f64, #n>) -> f64 {
                ::vigp::embedded::Dynamics::potential(&self.minimal(), k, q)
            }
            fn terms(&self, k: &Self::Constants, q: &#svector<f64, #n>, out: &mut ::vigp::embedded::Terms<#n>) {
                ::vigp::embedded::Dynamics::terms(&self.minimal(), k, q, out)
            }
            fn force_jacobian(&self, k: &Self::Constants, q: &#svector<f64, #n>, v: &#svector<f64, #n>) -> ::vigp::__private::nalgebra::SMatrix<f64, #n, #n> {
                ::vigp::embedded::Dynamics::force_jacobian(&self.minimal(), k, q, v)
            }
            #[inline(always)]
            fn kinetic(t: &::vigp::embedded::Terms<#n>, v: &#svector<f64, #n>) -> (::vigp::__private::nalgebra::SMatrix<f64, #n, #n>, #svector<f64, #n>) {
                <#minimal_ty as ::vigp::embedded::Dynamics<#n, #c>>::kinetic(t, v)
            }
            #[inline(always)]
            fn quadratic_max(t: &::vigp::embedded::Terms<#n>, dv: &#svector<f64, #n>) -> f64 {
                <#minimal_ty as ::vigp::embedded::Dynamics<#n, #c>>::quadratic_max(t, dv)
            }
            // the minimal model's sparse products, not the trait's dense
            // defaults: `Stepper::new(sys, dt)` must step exactly as
            // `Stepper::new(sys.minimal(), dt)`
            #[inline(always)]
            fn mass_times(t: &::vigp::embedded::Terms<#n>, v: &#svector<f64, #n>) -> #svector<f64, #n> {
                <#minimal_ty as ::vigp::embedded::Dynamics<#n, #c>>::mass_times(t, v)
            }
            #[inline(always)]
            fn damping_times(t: &::vigp::embedded::Terms<#n>, v: &#svector<f64, #n>) -> #svector<f64, #n> {
                <#minimal_ty as ::vigp::embedded::Dynamics<#n, #c>>::damping_times(t, v)
            }
            fn constraint_values(&self, k: &Self::Constants, q: &#svector<f64, #n>) -> #svector<f64, #c> {
                ::vigp::embedded::Dynamics::constraint_values(&self.minimal(), k, q)
            }
            fn constraints_and_jacobian(&self, k: &Self::Constants, q: &#svector<f64, #n>) -> (#svector<f64, #c>, ::vigp::__private::nalgebra::SMatrix<f64, #c, #n>) {
                ::vigp::embedded::Dynamics::constraints_and_jacobian(&self.minimal(), k, q)
            }
            fn constraint_hessian(&self, k: &Self::Constants, q: &#svector<f64, #n>, mu: &#svector<f64, #c>) -> ::vigp::__private::nalgebra::SMatrix<f64, #n, #n> {
                ::vigp::embedded::Dynamics::constraint_hessian(&self.minimal(), k, q, mu)
            }
            #inputs_delegate_fns
        }

        #maximal_items

        #maximal_dynamics

        #std_items
    })
}
