//! Rust emitted for a validated spatial [`Model`]: the parameter types, the
//! `vigp::spatial::Spatial` description (links, joints with anchors, axes
//! and reference rotations, the spanning tree), the maximal view, and the
//! minimal view with its `Mechanism` implementation. Behaviour lives in the
//! runtime (`vigp::spatial`): the impls here only pass the description on.
//! No damping code when no joint declares `damping`, no spring code without
//! `stiffness`, no input code without `actuated`, no constraint code when
//! the minimal view has no constraint.

use crate::desc::DefaultValue;
use crate::desc::spatial::{Anchor, JointKind, Model, Point};
use crate::lit::lit;
use crate::param_struct::{Links, parameter_struct};
use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};
use syn::ext::IdentExt;

pub(crate) fn triple(p: [f64; 3]) -> TokenStream {
    let (a, b, c) = (lit(p[0]), lit(p[1]), lit(p[2]));
    quote!([#a, #b, #c])
}

fn quad(p: [f64; 4]) -> TokenStream {
    let items = p.map(lit);
    quote!([#(#items),*])
}

fn usize_lit(n: usize) -> Literal {
    Literal::usize_unsuffixed(n)
}

/// Link-frame (or world) coordinates of a point, with lengths and centres
/// of mass read from the run-time parameters `links`.
pub(crate) fn anchor_expr(m: &Model, p: Point) -> TokenStream {
    let sp = quote!(::vigp::spatial);
    match p {
        Point::World(w) => triple(w),
        Point::Link { link, anchor } => {
            let name = &m.links[link].name;
            match anchor {
                Anchor::Start => quote!([0.0, 0.0, 0.0]),
                Anchor::End => quote!([links.#name.length, 0.0, 0.0]),
                Anchor::Center => quote!(#sp::model::center(links.#name.length)),
                Anchor::Com => quote!(links.#name.com),
                Anchor::At(p) => triple(p),
            }
        }
    }
}

/// The whole expansion of a spatial description.
pub fn emit(m: &Model, target: crate::target::Target) -> TokenStream {
    let Model { vis, name, .. } = m;
    let name_str = name.unraw().to_string();
    let b = usize_lit(m.links.len());
    let j = usize_lit(m.joints.len());
    let n_max = usize_lit(6 * m.links.len());
    let c_max = usize_lit(m.maximal_constraints());
    let nm = usize_lit(m.coordinates());
    let cm = usize_lit(m.minimal_constraints());
    let minimal_ty = format_ident!("{}Minimal", name);
    let dissipative = m.dissipative();
    let svector = quote!(::vigp::__private::nalgebra::SVector);
    let smatrix = quote!(::vigp::__private::nalgebra::SMatrix);
    let sp = quote!(::vigp::spatial);

    // ---- parameter types ----
    let link_defaults = m.links.iter().map(|l| {
        let ln = &l.name;
        let mass = l.mass.tokens();
        let inertia = {
            let rows = l.inertia.iter().map(|r| {
                let r = r.iter().map(DefaultValue::tokens);
                quote!([#(#r),*])
            });
            quote!([#(#rows),*])
        };
        let length = l
            .length
            .as_ref()
            .map_or_else(|| lit(0.0), DefaultValue::tokens);
        let com = match (&l.com, &l.length) {
            (Some(c), _) => {
                let c = c.iter().map(DefaultValue::tokens);
                quote!([#(#c),*])
            }
            (None, None) => triple([0.0; 3]),
            (None, Some(DefaultValue::Known(len))) => triple([0.5 * len, 0.0, 0.0]),
            // a default (length/2, 0, 0) of a length only the compiler
            // knows: derived at run time, the length written once
            (None, Some(DefaultValue::Expr(_))) => {
                return quote!(#ln: #sp::Link3::with_default_com(#mass, #inertia, #length),);
            }
        };
        quote!(#ln: #sp::Link3 { mass: #mass, inertia: #inertia, com: #com, length: #length },)
    });
    let elastic = m.elastic();
    let input_joints = m.inputs();
    // springs and inputs: only what is declared is generated
    let spatial_springs = if elastic {
        let springs = m.joints.iter().map(|jt| {
            let jn = &jt.name;
            quote!(::vigp::Spring { stiffness: self.joints.#jn.stiffness, rest: self.joints.#jn.rest })
        });
        quote! {
            const ELASTIC: bool = true;
            fn springs(&self) -> [::vigp::Spring; #j] {
                [#(#springs),*]
            }
        }
    } else {
        quote!()
    };
    let inputs_impl = |ty: &dyn quote::ToTokens| {
        if input_joints.is_empty() {
            quote!()
        } else {
            let u = usize_lit(input_joints.len());
            quote! {
                #[doc = " Forced steps take input vectors of its number of inputs (and of length 0)."]
                impl ::vigp::embedded::Inputs<#u> for #ty {}
            }
        }
    };
    let name_inputs_impl = inputs_impl(&name);
    let minimal_inputs_impl = inputs_impl(&minimal_ty);
    let (spatial_inputs, input_names, inputs_const, inputs_fns, mechanism_inputs) = if input_joints
        .is_empty()
    {
        (quote!(), quote!(), quote!(), quote!(), quote!())
    } else {
        let u = usize_lit(input_joints.len());
        let indices = input_joints.iter().map(|&k| usize_lit(k));
        let names: Vec<String> = input_joints
            .iter()
            .map(|&k| m.joints[k].name.unraw().to_string())
            .collect();
        (
            quote!(const INPUT_JOINTS: &'static [usize] = &[#(#indices),*];),
            quote! {
                #[doc = " Names of the inputs (the actuated joints, in declaration order): input i is a torque about a revolute axis or a force along a prismatic axis."]
                pub const INPUT_NAMES: [&'static str; #u] = [#(#names),*];
            },
            quote! {
                const INPUTS: usize = #u;
                const INPUT_NAMES: &'static [&'static str] = &[#(#names),*];
            },
            quote! {
                fn input_matrix<const U: usize>(&self, _k: &(), q: &#svector<f64, #nm>) -> #smatrix<f64, #nm, U> {
                    const { assert!(U == #u || U == 0, "U must equal Dynamics::INPUTS (or 0: no input)") };
                    if U == 0 {
                        return #smatrix::zeros();
                    }
                    #sp::minimal::input_matrix::<#name, #b, #j, #nm, U>(&self.sys, q)
                }
                fn input_force_jacobian<const U: usize>(
                    &self,
                    _k: &(),
                    q: &#svector<f64, #nm>,
                    u: &#svector<f64, U>,
                ) -> #smatrix<f64, #nm, #nm> {
                    const { assert!(U == #u || U == 0, "U must equal Dynamics::INPUTS (or 0: no input)") };
                    if U == 0 {
                        return #smatrix::zeros();
                    }
                    #sp::minimal::input_force_jacobian::<#name, #b, #j, #nm, U>(&self.sys, q, u)
                }
            },
            quote! {
                fn input_work<D: ::vigp::Scalar>(&self, q: &#svector<D, #nm>, u: &[f64]) -> D {
                    #sp::minimal::input_work::<#name, D, #b, #j, #nm>(&self.sys, q, u)
                }
            },
        )
    };
    let link_names: Vec<String> = m.links.iter().map(|l| l.name.unraw().to_string()).collect();
    let joint_names: Vec<String> = m
        .joints
        .iter()
        .map(|jt| jt.name.unraw().to_string())
        .collect();
    let placement = m.placement.iter().map(|&t| usize_lit(t));
    let link_values = m.links.iter().map(|l| {
        let ln = &l.name;
        quote!(self.links.#ln)
    });
    let joint_values = m.joints.iter().map(|jt| {
        let kind = format_ident!("{}", jt.kind.variant());
        let kind = match jt.kind {
            JointKind::Universal { axes } => {
                let second = triple(axes[1]);
                quote!(#kind { second: #second })
            }
            _ => quote!(#kind),
        };
        let parent = match jt.parent.link() {
            Some(p) => {
                let p = usize_lit(p);
                quote!(::core::option::Option::Some(#p))
            }
            None => quote!(::core::option::Option::None),
        };
        let child = usize_lit(jt.child.link().unwrap_or(0));
        let pa = anchor_expr(m, jt.parent);
        let ca = anchor_expr(m, jt.child);
        let axis = triple(jt.kind.axis());
        let rel = quad(m.rel(jt));
        let damping = if dissipative {
            let jn = &jt.name;
            quote!(self.joints.#jn.damping)
        } else {
            quote!(0.0)
        };
        quote! {
            #sp::Joint3 {
                kind: #sp::JointType::#kind,
                parent: #parent,
                child: #child,
                parent_anchor: #pa,
                child_anchor: #ca,
                axis: #axis,
                rel: #rel,
                damping: #damping,
            }
        }
    });
    let uses_links = m.joints.iter().any(|jt| {
        [jt.parent, jt.child]
            .iter()
            .any(|p| matches!(p, Point::Link { anchor, .. } if !matches!(anchor, Anchor::Start | Anchor::At(_))))
    });
    let links_binding = if uses_links {
        quote!(let links = &self.links;)
    } else {
        quote!()
    };

    // coordinate names and kinds of the minimal view
    let mut coord_names = Vec::new();
    let mut kinds = Vec::new();
    let angle = quote!(::vigp::CoordinateKind::Angle);
    let length = quote!(::vigp::CoordinateKind::Length);
    let quat = quote!(::vigp::CoordinateKind::Quaternion);
    for &t in &m.tree {
        let jt = &m.joints[t];
        let jn = jt.name.unraw().to_string();
        match jt.kind {
            JointKind::Revolute { .. } => {
                coord_names.push(jn);
                kinds.push(angle.clone());
            }
            JointKind::Prismatic { .. } => {
                coord_names.push(jn);
                kinds.push(length.clone());
            }
            JointKind::Spherical => {
                for c in ["w", "x", "y", "z"] {
                    coord_names.push(format!("{jn}.{c}"));
                    kinds.push(quat.clone());
                }
            }
            JointKind::Free => {
                for c in ["x", "y", "z"] {
                    coord_names.push(format!("{jn}.{c}"));
                    kinds.push(length.clone());
                }
                for c in ["qw", "qx", "qy", "qz"] {
                    coord_names.push(format!("{jn}.{c}"));
                    kinds.push(quat.clone());
                }
            }
            JointKind::Universal { .. } => {
                for c in ["1", "2"] {
                    coord_names.push(format!("{jn}.{c}"));
                    kinds.push(angle.clone());
                }
            }
            JointKind::Fixed => {}
        }
    }
    let tree_names: Vec<String> = m
        .tree
        .iter()
        .map(|&t| format!("`{}`", m.joints[t].name.unraw()))
        .collect();
    let minimal_doc = format!(
        " Minimal-coordinate view of [`{name_str}`]: coordinates of the tree joints ({}), {} constraint equation(s) (loop closures, then one unit-norm row per quaternion).",
        tree_names.join(", "),
        m.minimal_constraints()
    );
    let maximal_doc = format!(
        " The maximal-coordinate view: each link's centre of mass and orientation (unit quaternion), every joint a constraint ({} equations). Integrate it with `vigp::spatial::LieStepper`.",
        m.maximal_constraints()
    );

    // the parameter list of the struct and of the minimal view (saved and
    // exported models record it); the maximal view is a `vigp::spatial`
    // type, which the orphan rule keeps this crate from implementing for
    let places = parameter_places(m);
    let parameters = {
        let own = crate::describe::parameters_impl(&m.name, &quote!(#name), &quote!(self), &places);
        let minimal = crate::describe::parameters_impl(
            &m.name,
            &quote!(#minimal_ty),
            &quote!(self.sys),
            &places,
        );
        quote!(#own #minimal)
    };
    let n_inputs = usize_lit(input_joints.len());
    let mechanism_impl = if target == crate::target::Target::Std {
        let dissipation = if dissipative {
            quote! {
                fn dissipation<D: ::vigp::Scalar>(&self, q: &#svector<D, #nm>, v: &#svector<D, #nm>) -> D {
                    #sp::minimal::dissipation::<#name, D, #b, #j, #nm>(&self.sys, q, v)
                }
            }
        } else {
            quote!()
        };
        let constraints = if m.minimal_constraints() > 0 {
            quote! {
                fn constraints<D: ::vigp::Scalar>(&self, q: &#svector<D, #nm>) -> #svector<D, #cm> {
                    #sp::minimal::constraints::<#name, D, #b, #j, #nm, #cm>(&self.sys, q)
                }
            }
        } else {
            quote!()
        };
        let constraint_terms = if m.minimal_constraints() > 0 {
            quote! {
                fn constraint_values(&self, _k: &Self::Constants, q: &#svector<f64, #nm>) -> #svector<f64, #cm> {
                    #sp::minimal::constraints::<#name, f64, #b, #j, #nm, #cm>(&self.sys, q)
                }
                fn constraints_and_jacobian(
                    &self,
                    _k: &Self::Constants,
                    q: &#svector<f64, #nm>,
                ) -> (#svector<f64, #cm>, #smatrix<f64, #cm, #nm>) {
                    #sp::minimal::constraints_and_jacobian::<#name, #b, #j, #nm, #cm>(&self.sys, q)
                }
                fn constraint_hessian(
                    &self,
                    _k: &Self::Constants,
                    q: &#svector<f64, #nm>,
                    mu: &#svector<f64, #cm>,
                ) -> #smatrix<f64, #nm, #nm> {
                    #sp::minimal::constraint_hessian::<#name, #b, #j, #nm, #cm>(&self.sys, q, mu)
                }
            }
        } else {
            quote!()
        };
        quote! {
            // The engine's terms of the minimal view, by jets over the
            // spatial kinematics (the planar path generates them
            // symbolically instead).
            impl ::vigp::embedded::Dynamics<#nm, #cm> for #minimal_ty {
                const KINDS: [::vigp::CoordinateKind; #nm] = [#(#kinds),*];
                const DISSIPATIVE: bool = #dissipative;
                const CONSTANT_MASS: bool = false;
                #inputs_const
                type Constants = ();
                fn constants(&self) -> ::core::result::Result<(), ::vigp::embedded::StepError> {
                    #sp::model::validate::<#name, #b, #j>(&self.sys)
                        .map(|_| ())
                        .map_err(|e| match e {
                            #sp::model::ModelError::Invalid(why) | #sp::model::ModelError::Size(why) => {
                                ::vigp::embedded::StepError::InvalidModel(why)
                            }
                        })
                }
                fn mass(&self, _k: &(), q: &#svector<f64, #nm>) -> #smatrix<f64, #nm, #nm> {
                    #sp::minimal::mass_matrix::<#name, #b, #j, #nm>(&self.sys, q)
                }
                fn potential(&self, _k: &(), q: &#svector<f64, #nm>) -> f64 {
                    #sp::minimal::potential::<#name, #b, #j, #nm>(&self.sys, q)
                }
                fn terms(&self, _k: &(), q: &#svector<f64, #nm>, out: &mut ::vigp::embedded::Terms<#nm>) {
                    let t = #sp::minimal::terms::<#name, #b, #j, #nm>(&self.sys, q);
                    out.mass = t.mass;
                    out.dmass = t.dmass;
                    out.dpotential = t.dpotential;
                    out.damping = t.damping;
                }
                fn force_jacobian(
                    &self,
                    _k: &(),
                    q: &#svector<f64, #nm>,
                    v: &#svector<f64, #nm>,
                ) -> #smatrix<f64, #nm, #nm> {
                    #sp::minimal::force_jacobian::<#name, #b, #j, #nm>(&self.sys, q, v)
                }
                #constraint_terms
                #inputs_fns
            }

            #minimal_inputs_impl

            impl ::vigp::Mechanism<#nm, #cm> for #minimal_ty {
                const COORDINATES: [&'static str; #nm] = [#(#coord_names),*];
                #mechanism_inputs
                fn kinetic_energy<D: ::vigp::Scalar>(&self, q: &#svector<D, #nm>, v: &#svector<D, #nm>) -> D {
                    #sp::minimal::kinetic_energy::<#name, D, #b, #j, #nm>(&self.sys, q, v)
                }
                fn potential_energy<D: ::vigp::Scalar>(&self, q: &#svector<D, #nm>) -> D {
                    #sp::minimal::potential_energy::<#name, D, #b, #j, #nm>(&self.sys, q)
                }
                fn lagrangian<D: ::vigp::Scalar>(&self, q: &#svector<D, #nm>, v: &#svector<D, #nm>) -> D {
                    #sp::minimal::lagrangian::<#name, D, #b, #j, #nm>(&self.sys, q, v)
                }
                #dissipation
                #constraints
            }

            // tools generic over mechanisms (`vigp::cli::main`) take the
            // minimal view; the maximal view is not a `Mechanism`
            impl ::vigp::System for #name {
                fn visit<V: ::vigp::ViewVisitor>(&self, visitor: V) -> V::Output {
                    visitor.visit_minimal::<#minimal_ty, #nm, #cm, #n_inputs>(self.minimal())
                }
            }
        }
    } else {
        quote!()
    };

    let parameter_struct = parameter_struct(
        m,
        Links {
            ty: quote!(#sp::Link3),
            name: &|l: &crate::desc::spatial::Link| (&l.name, &l.attrs[..]),
            defaults: link_defaults.collect(),
        },
        // literals computed by the macro (reference rotations such as
        // cos(π/4)) or copied from the description are exact values
        quote!(#[allow(clippy::approx_constant)]),
    );
    let coordinates_doc = if m
        .joints
        .iter()
        .any(|j| matches!(j.kind, JointKind::Universal { .. }))
    {
        " Number of minimal coordinates (one per revolute or prismatic tree joint, two per universal, four per spherical, seven per free)."
    } else {
        " Number of minimal coordinates (one per revolute or prismatic tree joint, four per spherical, seven per free)."
    };
    quote! {
        #parameter_struct

        impl #name {
            #[doc = #coordinates_doc]
            pub const COORDINATES: usize = #nm;
            #[doc = " Number of constraint equations in minimal coordinates (loop closures, then one unit-norm row per quaternion)."]
            pub const MINIMAL_CONSTRAINTS: usize = #cm;
            #[doc = " Number of constraint equations in maximal coordinates (every joint)."]
            pub const MAXIMAL_CONSTRAINTS: usize = #c_max;
            #[doc = " Link names, in declaration order."]
            pub const LINKS: [&'static str; #b] = [#(#link_names),*];
            #input_names

            #[doc = " The minimal-coordinate model with these parameters."]
            pub fn minimal(&self) -> #minimal_ty {
                #minimal_ty { sys: *self }
            }

            #[doc = #maximal_doc]
            pub fn maximal(&self) -> #sp::Maximal<Self, #b, #j, #n_max, #c_max> {
                #sp::Maximal::new(*self)
            }

            #[doc = " Forward kinematics: the pose of every link frame (origin at the link's `start`) for minimal coordinates `q`, in [`Self::LINKS`] order."]
            pub fn link_poses<R: ::vigp::Real>(&self, q: &#svector<R, #nm>) -> [#sp::Pose3<R>; #b] {
                #sp::minimal::poses::<Self, R, #b, #j, #nm>(self, q)
            }
        }

        #name_inputs_impl

        #[allow(clippy::approx_constant)]
        impl #sp::Spatial<#b, #j> for #name {
            const LINKS: [&'static str; #b] = [#(#link_names),*];
            const JOINTS: [&'static str; #j] = [#(#joint_names),*];
            const TREE: [usize; #b] = [#(#placement),*];
            const DISSIPATIVE: bool = #dissipative;
            #spatial_springs
            #spatial_inputs
            fn gravity(&self) -> [f64; 3] {
                self.gravity
            }
            fn links(&self) -> [#sp::Link3; #b] {
                [#(#link_values),*]
            }
            fn joints(&self) -> [#sp::Joint3; #j] {
                #links_binding
                [#(#joint_values),*]
            }
        }

        #[doc = #minimal_doc]
        #[derive(Clone, Copy, Debug, PartialEq)]
        #vis struct #minimal_ty {
            #[doc = " The parameters."]
            pub sys: #name,
        }

        impl #minimal_ty {
            #[doc = " The coordinates of the reference configuration (angles and slides 0, quaternions (1, 0, 0, 0))."]
            pub fn reference(&self) -> #svector<f64, #nm> {
                #sp::views::reference::<#name, #b, #j, #nm>(&self.sys)
            }
            #[doc = " The maximal-coordinate state of a discrete minimal state: X_k from q_k and X_{k+1} from q_k + Δt·v_k."]
            pub fn to_maximal(&self, z: &::vigp::State<#nm>, dt: f64) -> #sp::SpatialState<#b> {
                #sp::views::to_maximal::<#name, #b, #j, #nm>(&self.sys, z, dt)
            }
            #[doc = " The discrete minimal state of a consistent maximal state (the inverse of [`Self::to_maximal`]); angles are unwrapped continuously over the step."]
            pub fn to_minimal(&self, z: &#sp::SpatialState<#b>, dt: f64) -> ::vigp::State<#nm> {
                #sp::views::to_minimal::<#name, #b, #j, #nm>(&self.sys, z, dt)
            }
        }

        #mechanism_impl
        #parameters
    }
}

/// `(name, place)` of every parameter of a spatial mechanism, in the order
/// documented on `vigp_core::Parameters`.
fn parameter_places(m: &Model) -> Vec<(String, TokenStream)> {
    const AXES: [&str; 3] = ["x", "y", "z"];
    let mut out: Vec<(String, TokenStream)> = (0..3)
        .map(|i| {
            let k = Literal::usize_unsuffixed(i);
            (format!("gravity.{}", AXES[i]), quote!(gravity[#k]))
        })
        .collect();
    for l in &m.links {
        let (ln, s) = (&l.name, l.name.unraw().to_string());
        out.push((format!("links.{s}.mass"), quote!(links.#ln.mass)));
        out.push((format!("links.{s}.length"), quote!(links.#ln.length)));
        for (r, row) in AXES.iter().enumerate() {
            for (c, col) in AXES.iter().enumerate() {
                let (kr, kc) = (Literal::usize_unsuffixed(r), Literal::usize_unsuffixed(c));
                out.push((
                    format!("links.{s}.inertia.{row}{col}"),
                    quote!(links.#ln.inertia[#kr][#kc]),
                ));
            }
        }
        for (i, axis) in AXES.iter().enumerate() {
            let k = Literal::usize_unsuffixed(i);
            out.push((format!("links.{s}.com.{axis}"), quote!(links.#ln.com[#k])));
        }
    }
    out.extend(crate::describe::joint_places(
        m.joints.iter().map(|j| &j.name),
        m.dissipative(),
        m.elastic(),
    ));
    out
}
