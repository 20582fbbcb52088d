//! Meaning of a description: names resolved, numbers checked, the joint
//! graph split into a spanning tree (minimal coordinates) and loop-closing
//! joints (constraints). Every problem becomes a spanned `syn::Error`.

use crate::parse::{self, Field, Input, Number, PointRef, Value};
use proc_macro2::{Span, TokenStream};
use quote::ToTokens;
use std::collections::HashMap;
use syn::ext::IdentExt;
use syn::{Attribute, Ident, Visibility};

/// The default value of a run-time parameter (a field of the generated
/// parameter struct): a number the macro knows and has checked, or a Rust
/// expression only the compiler evaluates (`2.0 * M`), which the generated
/// `constants` check when the program runs (a typed `InvalidModel`).
#[derive(Clone)]
pub enum DefaultValue {
    /// Known when the macro runs.
    Known(f64),
    /// Evaluated by the compiled program.
    Expr(syn::Expr),
}

impl DefaultValue {
    /// The value, when the macro knows it.
    pub fn known(&self) -> Option<f64> {
        match self {
            DefaultValue::Known(x) => Some(*x),
            DefaultValue::Expr(_) => None,
        }
    }

    /// The value as Rust: a literal, or the expression as written (its
    /// spans kept, so a type error points at the user's code).
    pub fn tokens(&self) -> TokenStream {
        match self {
            DefaultValue::Known(x) => crate::emit::lit(*x),
            DefaultValue::Expr(e) => e.to_token_stream(),
        }
    }
}

impl From<&Number> for DefaultValue {
    fn from(n: &Number) -> Self {
        match n.value {
            Some(x) => DefaultValue::Known(x),
            None => DefaultValue::Expr((*n.expr).clone()),
        }
    }
}

/// A validated link.
#[derive(Clone)]
pub struct Link {
    /// Doc comments and other outer attributes.
    pub attrs: Vec<Attribute>,
    /// Name.
    pub name: Ident,
    /// Mass (kg, > 0 when known).
    pub mass: DefaultValue,
    /// Length (m, > 0 when known).
    pub length: DefaultValue,
    /// Inertia about the centre of mass (kg·m², ≥ 0 when known); `None`
    /// means a uniform rod's m·l²/12.
    pub inertia: Option<DefaultValue>,
    /// Centre of mass in local coordinates; `None` means `[length/2, 0]`.
    pub com: Option<[DefaultValue; 2]>,
}

/// Where a point sits on a link.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Anchor {
    /// Local origin.
    Start,
    /// Local (length, 0).
    End,
    /// Local (length/2, 0).
    Center,
    /// Fixed local coordinates.
    At([f64; 2]),
}

/// A resolved point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Point {
    /// World coordinates.
    World([f64; 2]),
    /// A point on link `link` (index into `Model::links`).
    Link {
        /// Link index.
        link: usize,
        /// Anchor.
        anchor: Anchor,
    },
}

impl Point {
    /// The link this point is on, if any.
    pub fn link(&self) -> Option<usize> {
        match self {
            Point::World(_) => None,
            Point::Link { link, .. } => Some(*link),
        }
    }
}

/// Joint type.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum JointKind {
    /// Pins the two points together; coordinate = relative angle.
    Revolute,
    /// Slides the child point along a unit axis fixed in the parent
    /// (world coordinates for a world parent); orientations equal.
    Prismatic {
        /// Unit axis.
        axis: [f64; 2],
    },
}

/// A validated joint.
#[derive(Clone)]
pub struct Joint {
    /// Doc comments and other outer attributes.
    pub attrs: Vec<Attribute>,
    /// Name.
    pub name: Ident,
    /// Type.
    pub kind: JointKind,
    /// Parent point.
    pub parent: Point,
    /// Child point.
    pub child: Point,
    /// Declared damping (`None` when the joint does not mention it).
    pub damping: Option<DefaultValue>,
    /// `true` when the joint declares `actuated` (an input: a torque on a
    /// revolute joint, a force along a prismatic axis).
    pub actuated: bool,
    /// Declared spring stiffness k ≥ 0 (`None` when not mentioned).
    pub stiffness: Option<DefaultValue>,
    /// Declared spring rest coordinate s₀ (`None` when not mentioned; only
    /// allowed with `stiffness`).
    pub rest: Option<DefaultValue>,
}

/// A validated mechanism.
#[derive(Clone)]
pub struct Model {
    /// Outer attributes of the mechanism.
    pub attrs: Vec<Attribute>,
    /// Visibility.
    pub vis: Visibility,
    /// Name.
    pub name: Ident,
    /// Gravity (m/s²).
    pub gravity: [DefaultValue; 2],
    /// Links in declaration order.
    pub links: Vec<Link>,
    /// Joints in declaration order.
    pub joints: Vec<Joint>,
    /// Tree joints in declaration order: coordinate k is joint `tree[k]`.
    pub tree: Vec<usize>,
    /// For each link, the tree joint that places it.
    pub placed_by: Vec<usize>,
    /// Links in an order where every parent comes first.
    pub order: Vec<usize>,
    /// Loop-closing joints in declaration order.
    pub loops: Vec<usize>,
}

impl Model {
    /// Number of minimal coordinates.
    pub fn dof(&self) -> usize {
        self.tree.len()
    }

    /// Number of loop-closure constraint equations (2 per loop joint).
    pub fn loop_constraints(&self) -> usize {
        2 * self.loops.len()
    }

    /// `true` when any joint declares `damping`.
    pub fn dissipative(&self) -> bool {
        self.joints.iter().any(|j| j.damping.is_some())
    }

    /// `true` when any joint declares `stiffness` (then every joint gets a
    /// run-time spring: stiffness and rest coordinate).
    pub fn elastic(&self) -> bool {
        self.joints.iter().any(|j| j.stiffness.is_some())
    }

    /// The actuated joints in declaration order: input i drives joint
    /// `inputs()[i]`.
    pub fn inputs(&self) -> Vec<usize> {
        (0..self.joints.len())
            .filter(|&j| self.joints[j].actuated)
            .collect()
    }

    /// Coordinate index of a tree joint.
    pub fn coordinate_of(&self, joint: usize) -> Option<usize> {
        self.tree.iter().position(|&j| j == joint)
    }
}

struct Errors(Option<syn::Error>);

impl Errors {
    fn push(&mut self, span: Span, msg: impl std::fmt::Display) {
        self.add(syn::Error::new(span, msg));
    }
    fn add(&mut self, e: syn::Error) {
        match &mut self.0 {
            Some(all) => all.combine(e),
            None => self.0 = Some(e),
        }
    }
    fn finish<T>(self, ok: T) -> syn::Result<T> {
        match self.0 {
            Some(e) => Err(e),
            None => Ok(ok),
        }
    }
}

fn number(errs: &mut Errors, f: &Field) -> Option<Number> {
    match &f.value {
        Value::Number(n) => Some(n.clone()),
        Value::Array(s, _) | Value::Flag(s) => {
            errs.push(*s, format!("`{}` takes a single number", f.key));
            None
        }
    }
}

/// A run-time parameter that must not be negative (when known).
fn non_negative(errs: &mut Errors, f: &Field) -> Option<DefaultValue> {
    let n = number(errs, f)?;
    match n.value {
        Some(x) if x < 0.0 => {
            errs.add(n.error(format!("`{}` must not be negative, got {x}", f.key)));
            None
        }
        _ => Some(DefaultValue::from(&n)),
    }
}

/// The two numbers of a pair `[x, y]`.
fn pair_numbers<'a>(errs: &mut Errors, f: &'a Field) -> Option<&'a [Number]> {
    match &f.value {
        Value::Array(_, items) if items.len() == 2 => Some(items),
        other => {
            errs.push(other.span(), format!("`{}` takes a pair `[x, y]`", f.key));
            None
        }
    }
}

/// A pair of run-time parameters.
fn param_pair(errs: &mut Errors, f: &Field) -> Option<[DefaultValue; 2]> {
    pair_numbers(errs, f).map(|p| [DefaultValue::from(&p[0]), DefaultValue::from(&p[1])])
}

/// A pair the macro must know (geometry that shapes the generated code).
fn known_pair(errs: &mut Errors, p: &[Number], what: &str) -> Option<[f64; 2]> {
    let mut out = [0.0; 2];
    for (o, n) in out.iter_mut().zip(p) {
        match n.known(what) {
            Ok(x) => *o = x,
            Err(e) => {
                errs.add(e);
                return None;
            }
        }
    }
    Some(out)
}

/// "`a`" or "one of `a`, `b`".
fn one_of(names: &[&str]) -> String {
    let quoted: Vec<String> = names.iter().map(|n| format!("`{n}`")).collect();
    match quoted.as_slice() {
        [one] => one.clone(),
        _ => format!("one of {}", quoted.join(", ")),
    }
}

/// Collect fields into a map, reporting duplicates and unknown keys.
fn fields<'a>(
    errs: &mut Errors,
    fields: &'a [Field],
    allowed: &[&str],
    what: &str,
) -> HashMap<String, &'a Field> {
    let mut map = HashMap::new();
    for f in fields {
        let key = f.key.to_string();
        if !allowed.contains(&key.as_str()) {
            errs.push(
                f.key.span(),
                format!(
                    "unknown key `{key}` for {what}: expected {}",
                    one_of(allowed)
                ),
            );
        } else if map.insert(key.clone(), f).is_some() {
            errs.push(f.key.span(), format!("duplicate key `{key}`"));
        }
    }
    map
}

/// Links and joints become fields of generated structs (joints only when
/// some joint is damped), so only doc comments carry over meaningfully; a
/// `cfg` would leave the generated code inconsistent. On the mechanism, the
/// derives are fixed and a `cfg` would not reach the generated impls.
fn check_attrs(errs: &mut Errors, attrs: &[Attribute], on_mechanism: bool) {
    for attr in attrs {
        let path = attr.path();
        let ok = if on_mechanism {
            !["derive", "cfg", "cfg_attr"]
                .iter()
                .any(|name| path.is_ident(name))
        } else {
            path.is_ident("doc")
        };
        if !ok {
            let msg = if on_mechanism {
                "`derive`, `cfg` and `cfg_attr` are not supported on a mechanism: the generated types derive `Clone, Copy, Debug, PartialEq`"
            } else {
                "only doc comments are allowed on links and joints"
            };
            errs.push(path_span(path), msg);
        }
    }
}

fn path_span(path: &syn::Path) -> Span {
    path.segments
        .first()
        .map_or_else(Span::call_site, |s| s.ident.span())
}

/// Validate a parsed description.
pub fn validate(input: Input) -> syn::Result<Model> {
    let mut errs = Errors(None);
    if let Some(e) = crate::check_mechanism_name(&input.name) {
        errs.add(e);
    }
    check_attrs(&mut errs, &input.attrs, true);

    // gravity
    let mut gravity = [DefaultValue::Known(0.0), DefaultValue::Known(-9.81)];
    if let Some((key, v)) = &input.gravity {
        match v {
            Value::Array(_, g) if g.len() == 2 => gravity = [(&g[0]).into(), (&g[1]).into()],
            // three numbers select the spatial path before this point
            other => errs.push(
                other.span(),
                format!(
                    "`{key}` must have 2 components `[gx, gy]` (planar) or 3 `[gx, gy, gz]` (spatial)"
                ),
            ),
        }
    }

    // links
    let Some((links_kw, link_decls)) = &input.links else {
        return Err(syn::Error::new(
            input.name.span(),
            format!("mechanism `{}` has no `links {{ … }}` section", input.name),
        ));
    };
    if link_decls.is_empty() {
        errs.push(links_kw.span(), "a mechanism needs at least one link");
    }
    let mut links = Vec::new();
    let mut index: HashMap<String, usize> = HashMap::new();
    for decl in link_decls {
        check_attrs(&mut errs, &decl.attrs, false);
        // `r#type` and `type` name the same field.
        let name = decl.name.unraw().to_string();
        if name == "world" {
            errs.push(
                decl.name.span(),
                "`world` is reserved and cannot name a link",
            );
        }
        if index.contains_key(&name) {
            errs.push(decl.name.span(), format!("duplicate link `{name}`"));
            continue;
        }
        let f = fields(
            &mut errs,
            &decl.fields,
            &["mass", "length", "inertia", "com"],
            "a link",
        );
        let positive = |errs: &mut Errors, key: &str| -> DefaultValue {
            match f.get(key) {
                None => {
                    errs.push(decl.name.span(), format!("link `{name}` needs `{key}`"));
                    DefaultValue::Known(1.0)
                }
                Some(field) => match number(errs, field) {
                    Some(n) => match n.value {
                        Some(x) if x <= 0.0 => {
                            errs.add(n.error(format!("`{key}` must be positive, got {x}")));
                            DefaultValue::Known(1.0)
                        }
                        _ => DefaultValue::from(&n),
                    },
                    None => DefaultValue::Known(1.0),
                },
            }
        };
        let mass = positive(&mut errs, "mass");
        let length = positive(&mut errs, "length");
        let inertia = match f.get("inertia") {
            None => match (mass.known(), length.known()) {
                (Some(m), Some(l)) if !(m * l * l).is_finite() => {
                    errs.push(
                        decl.name.span(),
                        format!(
                            "the default inertia m·l²/12 of link `{name}` overflows: give `inertia`"
                        ),
                    );
                    None
                }
                (Some(m), Some(l)) => Some(DefaultValue::Known(m * l * l / 12.0)),
                // computed by the compiled program (and checked at run time)
                _ => None,
            },
            Some(field) => non_negative(&mut errs, field),
        };
        let com = f.get("com").and_then(|field| param_pair(&mut errs, field));
        index.insert(name, links.len());
        links.push(Link {
            attrs: decl.attrs.clone(),
            name: decl.name.clone(),
            mass,
            length,
            inertia,
            com,
        });
    }

    // joints
    let joint_decls: &[parse::JointDecl] = match &input.joints {
        Some((_, j)) => j,
        None => &[],
    };
    let resolve = |errs: &mut Errors, p: &PointRef| -> Option<Point> {
        match p {
            PointRef::World { at, .. } => match at {
                None => Some(Point::World([0.0, 0.0])),
                Some(a) => known_pair(errs, a, "a world point").map(Point::World),
            },
            PointRef::Link { link, anchor } => {
                let Some(&i) = index.get(&link.unraw().to_string()) else {
                    errs.push(link.span(), format!("unknown link `{link}`"));
                    return None;
                };
                let anchor = match anchor {
                    parse::Anchor::Start => Anchor::Start,
                    parse::Anchor::End => Anchor::End,
                    parse::Anchor::Center => Anchor::Center,
                    parse::Anchor::At(a) => Anchor::At(known_pair(errs, a, "an attachment point")?),
                };
                Some(Point::Link { link: i, anchor })
            }
        }
    };
    let point_span = |p: &PointRef| match p {
        PointRef::World { span, .. } => *span,
        PointRef::Link { link, .. } => link.span(),
    };
    let mut joints = Vec::new();
    let mut joint_names: HashMap<String, ()> = HashMap::new();
    for decl in joint_decls {
        check_attrs(&mut errs, &decl.attrs, false);
        let name = decl.name.unraw().to_string();
        if joint_names.insert(name.clone(), ()).is_some() {
            errs.push(decl.name.span(), format!("duplicate joint `{name}`"));
            continue;
        }
        let kind_name = decl.kind.to_string();
        let allowed: &[&str] = match kind_name.as_str() {
            "revolute" => &["damping", "actuated", "stiffness", "rest"],
            "prismatic" => &["damping", "axis", "actuated", "stiffness", "rest"],
            _ => {
                errs.push(
                    decl.kind.span(),
                    format!("unknown joint type `{kind_name}`: expected `revolute` or `prismatic`"),
                );
                continue;
            }
        };
        let f = fields(
            &mut errs,
            &decl.fields,
            allowed,
            &format!("a {kind_name} joint"),
        );
        let kind = if kind_name == "prismatic" {
            match f.get("axis") {
                None => {
                    errs.push(
                        decl.kind.span(),
                        format!("prismatic joint `{name}` needs `axis: [ax, ay]`"),
                    );
                    JointKind::Prismatic { axis: [1.0, 0.0] }
                }
                Some(field) => {
                    let [ax, ay] = pair_numbers(&mut errs, field)
                        .and_then(|p| known_pair(&mut errs, p, "`axis`"))
                        .unwrap_or([1.0, 0.0]);
                    // Numbers are finite, so `s` is 0 exactly for a zero axis;
                    // dividing by it first keeps the norm of a huge axis finite.
                    let s = ax.abs().max(ay.abs());
                    if s > 0.0 {
                        let (ax, ay) = (ax / s, ay / s);
                        let n = ax.hypot(ay);
                        JointKind::Prismatic {
                            axis: [ax / n, ay / n],
                        }
                    } else {
                        errs.push(field.value.span(), "`axis` must not be zero");
                        JointKind::Prismatic { axis: [1.0, 0.0] }
                    }
                }
            }
        } else {
            JointKind::Revolute
        };
        let damping = f
            .get("damping")
            .and_then(|field| non_negative(&mut errs, field));
        let actuated = match f.get("actuated") {
            None => false,
            Some(field) => match &field.value {
                Value::Flag(_) => true,
                other => {
                    errs.push(
                        other.span(),
                        "`actuated` takes no value: write `actuated` to make the joint an input",
                    );
                    false
                }
            },
        };
        let stiffness = f
            .get("stiffness")
            .and_then(|field| non_negative(&mut errs, field));
        let rest = f.get("rest").and_then(|field| {
            let n = number(&mut errs, field)?;
            if !f.contains_key("stiffness") {
                errs.push(
                    field.key.span(),
                    format!("`rest` of joint `{name}` needs `stiffness` (a spring ½k(s − rest)²)"),
                );
            }
            Some(DefaultValue::from(&n))
        });
        let parent = resolve(&mut errs, &decl.parent);
        let child = resolve(&mut errs, &decl.child);
        let (Some(parent), Some(child)) = (parent, child) else {
            continue;
        };
        if parent.link() == child.link() {
            let what = if parent.link().is_none() {
                "the world to itself"
            } else {
                "a link to itself"
            };
            errs.push(
                point_span(&decl.child),
                format!("joint `{name}` connects {what}"),
            );
            continue;
        }
        joints.push(Joint {
            attrs: decl.attrs.clone(),
            name: decl.name.clone(),
            kind,
            parent,
            child,
            damping,
            actuated,
            stiffness,
            rest,
        });
    }
    if let Some(e) = errs.0.take() {
        return Err(e);
    }

    // spanning tree from the world, joints in declaration order
    let mut placed_by: Vec<Option<usize>> = vec![None; links.len()];
    let mut is_tree = vec![false; joints.len()];
    let mut order = Vec::new();
    loop {
        let mut progress = false;
        for (j, joint) in joints.iter().enumerate() {
            if is_tree[j] {
                continue;
            }
            let parent_ready = joint.parent.link().is_none_or(|l| placed_by[l].is_some());
            if let Some(c) = joint.child.link()
                && parent_ready
                && placed_by[c].is_none()
            {
                placed_by[c] = Some(j);
                is_tree[j] = true;
                order.push(c);
                progress = true;
            }
        }
        if !progress {
            break;
        }
    }
    for (l, link) in links.iter().enumerate() {
        if placed_by[l].is_none() {
            errs.push(
                link.name.span(),
                format!(
                    "link `{}` is not connected to the world: add a joint whose parent is the world or an already connected link and whose child is `{}`",
                    link.name, link.name
                ),
            );
        }
    }
    let tree: Vec<usize> = (0..joints.len()).filter(|&j| is_tree[j]).collect();
    let loops: Vec<usize> = (0..joints.len()).filter(|&j| !is_tree[j]).collect();
    let placed_by = placed_by.into_iter().map(|p| p.unwrap_or(0)).collect();
    errs.finish(Model {
        attrs: input.attrs,
        vis: input.vis,
        name: input.name,
        gravity,
        links,
        joints,
        tree,
        placed_by,
        order,
        loops,
    })
}
