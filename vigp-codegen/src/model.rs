//! Meaning of a description: names resolved, numbers checked, the joint
//! graph split into a spanning tree (minimal coordinates) and loop-closing
//! joints (constraints). Every problem becomes a spanned `syn::Error`.

use crate::parse::{self, Field, Input, Number, PointRef, Value};
use proc_macro2::Span;
use std::collections::HashMap;
use syn::{Attribute, Ident, Visibility};

/// A validated link.
#[derive(Clone)]
pub struct Link {
    /// Doc comments and other outer attributes.
    pub attrs: Vec<Attribute>,
    /// Name.
    pub name: Ident,
    /// Mass (kg, > 0).
    pub mass: f64,
    /// Length (m, > 0).
    pub length: f64,
    /// Inertia about the centre of mass (kg·m², ≥ 0).
    pub inertia: f64,
    /// Centre of mass in local coordinates; `None` means `[length/2, 0]`.
    pub com: Option<[f64; 2]>,
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
    pub damping: Option<f64>,
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
    pub gravity: [f64; 2],
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

    /// Coordinate index of a tree joint.
    pub fn coordinate_of(&self, joint: usize) -> Option<usize> {
        self.tree.iter().position(|&j| j == joint)
    }
}

struct Errors(Option<syn::Error>);

impl Errors {
    fn push(&mut self, span: Span, msg: impl std::fmt::Display) {
        let e = syn::Error::new(span, msg);
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
        Value::Number(n) => Some(*n),
        Value::Array(s, _) => {
            errs.push(*s, format!("`{}` takes a single number", f.key));
            None
        }
    }
}

fn pair(errs: &mut Errors, f: &Field) -> Option<[f64; 2]> {
    match &f.value {
        Value::Array(_, items) if items.len() == 2 => Some([items[0].value, items[1].value]),
        other => {
            errs.push(other.span(), format!("`{}` takes a pair `[x, y]`", f.key));
            None
        }
    }
}

/// Collect fields into a map, reporting duplicates and unknown keys.
fn fields<'a>(errs: &mut Errors, fields: &'a [Field], allowed: &[&str], what: &str) -> HashMap<String, &'a Field> {
    let mut map = HashMap::new();
    for f in fields {
        let key = f.key.to_string();
        if !allowed.contains(&key.as_str()) {
            errs.push(
                f.key.span(),
                format!("unknown key `{key}` for {what}: expected one of {}", allowed.join(", ")),
            );
        } else if map.insert(key.clone(), f).is_some() {
            errs.push(f.key.span(), format!("duplicate key `{key}`"));
        }
    }
    map
}

/// Validate a parsed description.
pub fn validate(input: Input) -> syn::Result<Model> {
    let mut errs = Errors(None);

    // gravity
    let mut gravity = [0.0, -9.81];
    if let Some((key, v)) = &input.gravity {
        match v {
            Value::Array(_, g) if g.len() == 2 => gravity = [g[0].value, g[1].value],
            Value::Array(s, g) if g.len() == 3 => errs.push(
                *s,
                "spatial (3-D) mechanisms are not supported yet: give planar gravity `[gx, gy]`",
            ),
            other => errs.push(
                other.span(),
                format!("`{key}` must have 2 components `[gx, gy]` for a planar mechanism"),
            ),
        }
    }

    // links
    let Some((links_kw, link_decls)) = &input.links else {
        return Err(syn::Error::new(input.body_span, "missing `links { … }` section"));
    };
    if link_decls.is_empty() {
        errs.push(links_kw.span(), "a mechanism needs at least one link");
    }
    let mut links = Vec::new();
    let mut index: HashMap<String, usize> = HashMap::new();
    for decl in link_decls {
        let name = decl.name.to_string();
        if name == "world" {
            errs.push(decl.name.span(), "`world` is reserved and cannot name a link");
        }
        if index.contains_key(&name) {
            errs.push(decl.name.span(), format!("duplicate link `{name}`"));
            continue;
        }
        let f = fields(&mut errs, &decl.fields, &["mass", "length", "inertia", "com"], "a link");
        let positive = |errs: &mut Errors, key: &str| -> f64 {
            match f.get(key) {
                None => {
                    errs.push(decl.name.span(), format!("link `{name}` needs `{key}`"));
                    1.0
                }
                Some(field) => match number(errs, field) {
                    Some(n) if n.value > 0.0 => n.value,
                    Some(n) => {
                        errs.push(n.span, format!("`{key}` must be positive, got {}", n.value));
                        1.0
                    }
                    None => 1.0,
                },
            }
        };
        let mass = positive(&mut errs, "mass");
        let length = positive(&mut errs, "length");
        let inertia = match f.get("inertia") {
            None => mass * length * length / 12.0,
            Some(field) => match number(&mut errs, field) {
                Some(n) if n.value >= 0.0 => n.value,
                Some(n) => {
                    errs.push(n.span, format!("`inertia` must not be negative, got {}", n.value));
                    0.0
                }
                None => 0.0,
            },
        };
        let com = f.get("com").and_then(|field| pair(&mut errs, field));
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
            PointRef::World { at, .. } => Some(Point::World(at.map_or([0.0, 0.0], |a| [a[0].value, a[1].value]))),
            PointRef::Link { link, anchor } => {
                let Some(&i) = index.get(&link.to_string()) else {
                    errs.push(link.span(), format!("unknown link `{link}`"));
                    return None;
                };
                let anchor = match anchor {
                    parse::Anchor::Start => Anchor::Start,
                    parse::Anchor::End => Anchor::End,
                    parse::Anchor::Center => Anchor::Center,
                    parse::Anchor::At(a) => Anchor::At([a[0].value, a[1].value]),
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
        let name = decl.name.to_string();
        if joint_names.insert(name.clone(), ()).is_some() {
            errs.push(decl.name.span(), format!("duplicate joint `{name}`"));
            continue;
        }
        let kind_name = decl.kind.to_string();
        let allowed: &[&str] = match kind_name.as_str() {
            "revolute" => &["damping"],
            "prismatic" => &["damping", "axis"],
            _ => {
                errs.push(
                    decl.kind.span(),
                    format!("unknown joint type `{kind_name}`: expected `revolute` or `prismatic`"),
                );
                continue;
            }
        };
        let f = fields(&mut errs, &decl.fields, allowed, &format!("a {kind_name} joint"));
        let kind = if kind_name == "prismatic" {
            match f.get("axis") {
                None => {
                    errs.push(decl.kind.span(), format!("prismatic joint `{name}` needs `axis: [ax, ay]`"));
                    JointKind::Prismatic { axis: [1.0, 0.0] }
                }
                Some(field) => {
                    let axis = pair(&mut errs, field).unwrap_or([1.0, 0.0]);
                    let n = axis[0].hypot(axis[1]);
                    if !(n > 0.0) {
                        errs.push(field.value.span(), "`axis` must not be zero");
                        JointKind::Prismatic { axis: [1.0, 0.0] }
                    } else {
                        JointKind::Prismatic {
                            axis: [axis[0] / n, axis[1] / n],
                        }
                    }
                }
            }
        } else {
            JointKind::Revolute
        };
        let damping = f.get("damping").and_then(|field| match number(&mut errs, field) {
            Some(n) if n.value >= 0.0 => Some(n.value),
            Some(n) => {
                errs.push(n.span, format!("`damping` must not be negative, got {}", n.value));
                None
            }
            None => None,
        });
        let parent = resolve(&mut errs, &decl.parent);
        let child = resolve(&mut errs, &decl.child);
        let (Some(parent), Some(child)) = (parent, child) else {
            continue;
        };
        if parent.link() == child.link() {
            let what = if parent.link().is_none() { "the world to itself" } else { "a link to itself" };
            errs.push(point_span(&decl.child), format!("joint `{name}` connects {what}"));
            continue;
        }
        joints.push(Joint {
            attrs: decl.attrs.clone(),
            name: decl.name.clone(),
            kind,
            parent,
            child,
            damping,
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
