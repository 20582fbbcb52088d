//! Meaning of a spatial description: names resolved, numbers and shapes
//! checked, frames and axes normalised, reference relative rotations of
//! the joints computed, the joint graph split into a spanning tree and
//! loop-closing joints. Every problem becomes a spanned `syn::Error`.

use super::parse::{self, Field, Input, PointRef, Value};
use crate::model::DefaultValue;
use crate::parse::Number;
use proc_macro2::Span;
use std::collections::HashMap;
use syn::ext::IdentExt;
use syn::{Attribute, Ident, Visibility};

/// A validated link.
#[derive(Clone)]
pub struct Link {
    /// Doc comments.
    pub attrs: Vec<Attribute>,
    /// Name.
    pub name: Ident,
    /// Mass (kg, > 0 when known).
    pub mass: DefaultValue,
    /// Inertia tensor about the centre of mass in the link frame
    /// (symmetric, positive definite, triangle inequality: checked here
    /// when every entry is known, by the run-time validation otherwise).
    pub inertia: [[DefaultValue; 3]; 3],
    /// Length, if declared.
    pub length: Option<DefaultValue>,
    /// Centre of mass in the link frame; `None`: (length/2, 0, 0), or the
    /// origin without a length.
    pub com: Option<[DefaultValue; 3]>,
    /// Reference orientation R⁰ (link frame → world), orthonormal.
    pub frame: [[f64; 3]; 3],
}

/// Where a point sits on a link.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Anchor {
    /// The frame origin.
    Start,
    /// (length, 0, 0).
    End,
    /// (length/2, 0, 0).
    Center,
    /// The centre of mass.
    Com,
    /// Fixed link-frame coordinates.
    At([f64; 3]),
}

/// A resolved point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Point {
    /// World coordinates.
    World([f64; 3]),
    /// A point on a link (index into `Model::links`).
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
    /// Rotation about a unit axis (parent frame).
    Revolute {
        /// Unit axis.
        axis: [f64; 3],
    },
    /// Slide along a unit axis (parent frame), orientations locked.
    Prismatic {
        /// Unit axis.
        axis: [f64; 3],
    },
    /// Ball joint.
    Spherical,
    /// Weld.
    Fixed,
    /// No constraint (a floating link).
    Free,
}

impl JointKind {
    /// The runtime's `JointType` variant name.
    pub fn variant(&self) -> &'static str {
        match self {
            JointKind::Revolute { .. } => "Revolute",
            JointKind::Prismatic { .. } => "Prismatic",
            JointKind::Spherical => "Spherical",
            JointKind::Fixed => "Fixed",
            JointKind::Free => "Free",
        }
    }

    /// The axis (zero for joints without one).
    pub fn axis(&self) -> [f64; 3] {
        match self {
            JointKind::Revolute { axis } | JointKind::Prismatic { axis } => *axis,
            _ => [0.0, 0.0, 1.0],
        }
    }

    /// Minimal coordinates as a tree joint.
    pub fn coordinates(&self) -> usize {
        match self {
            JointKind::Revolute { .. } | JointKind::Prismatic { .. } => 1,
            JointKind::Spherical => 4,
            JointKind::Fixed => 0,
            JointKind::Free => 7,
        }
    }

    /// Constraint rows (maximal coordinates, or as a loop joint).
    pub fn rows(&self) -> usize {
        match self {
            JointKind::Revolute { .. } | JointKind::Prismatic { .. } => 5,
            JointKind::Spherical => 3,
            JointKind::Fixed => 6,
            JointKind::Free => 0,
        }
    }
}

/// A validated joint.
#[derive(Clone)]
pub struct Joint {
    /// Doc comments.
    pub attrs: Vec<Attribute>,
    /// Name.
    pub name: Ident,
    /// Type.
    pub kind: JointKind,
    /// Parent point.
    pub parent: Point,
    /// Child point.
    pub child: Point,
    /// Declared damping.
    pub damping: Option<DefaultValue>,
    /// `true` when the joint declares `actuated` (an input: a torque about a
    /// revolute axis, a force along a prismatic axis).
    pub actuated: bool,
    /// Declared spring stiffness k ≥ 0 (`None` when not mentioned).
    pub stiffness: Option<DefaultValue>,
    /// Declared spring rest coordinate (`None` when not mentioned; only
    /// allowed with `stiffness`).
    pub rest: Option<DefaultValue>,
    /// Reference relative rotation R_p⁰ᵀR_c⁰ as a unit quaternion (w, x, y, z).
    pub rel: [f64; 4],
}

/// A validated spatial mechanism.
#[derive(Clone)]
pub struct Model {
    /// Outer attributes.
    pub attrs: Vec<Attribute>,
    /// Visibility.
    pub vis: Visibility,
    /// Name.
    pub name: Ident,
    /// Gravity (m/s²).
    pub gravity: [DefaultValue; 3],
    /// Links in declaration order.
    pub links: Vec<Link>,
    /// Joints in declaration order.
    pub joints: Vec<Joint>,
    /// Tree joints in declaration order (minimal coordinates follow them).
    pub tree: Vec<usize>,
    /// Tree joints in placement order (parents first).
    pub placement: Vec<usize>,
    /// Loop-closing joints in declaration order.
    pub loops: Vec<usize>,
}

impl Model {
    /// Number of minimal coordinates.
    pub fn coordinates(&self) -> usize {
        self.tree
            .iter()
            .map(|&j| self.joints[j].kind.coordinates())
            .sum()
    }

    /// Minimal-coordinate constraint rows: loop rows plus one unit-norm row
    /// per quaternion.
    pub fn minimal_constraints(&self) -> usize {
        let loops: usize = self.loops.iter().map(|&j| self.joints[j].kind.rows()).sum();
        let quats = self
            .tree
            .iter()
            .filter(|&&j| matches!(self.joints[j].kind, JointKind::Spherical | JointKind::Free))
            .count();
        loops + quats
    }

    /// Maximal-coordinate constraint rows (every joint).
    pub fn maximal_constraints(&self) -> usize {
        self.joints.iter().map(|j| j.kind.rows()).sum()
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
}

/// The keys of inputs and springs, which only revolute and prismatic
/// joints take.
const ACTUATION_KEYS: [&str; 3] = ["actuated", "stiffness", "rest"];

/// `actuated` (a flag), as in the planar DSL.
fn actuated(errs: &mut Errors, f: &HashMap<String, &Field>) -> bool {
    match f.get("actuated") {
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
    }
}

/// `stiffness: k` (k ≥ 0 when known), as in the planar DSL.
fn stiffness(errs: &mut Errors, f: &HashMap<String, &Field>) -> Option<DefaultValue> {
    non_negative(errs, f.get("stiffness")?)
}

/// `rest: s0`, only with `stiffness`, as in the planar DSL.
fn rest(errs: &mut Errors, f: &HashMap<String, &Field>, joint: &str) -> Option<DefaultValue> {
    let field = f.get("rest")?;
    let n = number(errs, field)?;
    if !f.contains_key("stiffness") {
        errs.push(
            field.key.span(),
            format!("`rest` of joint `{joint}` needs `stiffness` (a spring ½k(s − rest)²)"),
        );
    }
    Some(DefaultValue::from(n))
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
}

fn one_of(names: &[&str]) -> String {
    let quoted: Vec<String> = names.iter().map(|n| format!("`{n}`")).collect();
    match quoted.as_slice() {
        [] => "no keys".into(),
        [one] => one.clone(),
        _ => format!("one of {}", quoted.join(", ")),
    }
}

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
            let expected = if allowed.is_empty() {
                "this joint takes no keys".to_string()
            } else {
                format!("expected {}", one_of(allowed))
            };
            errs.push(
                f.key.span(),
                format!("unknown key `{key}` for {what}: {expected}"),
            );
        } else if map.insert(key.clone(), f).is_some() {
            errs.push(f.key.span(), format!("duplicate key `{key}`"));
        }
    }
    map
}

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
            let span = path
                .segments
                .first()
                .map_or_else(Span::call_site, |s| s.ident.span());
            errs.push(span, msg);
        }
    }
}

fn number<'a>(errs: &mut Errors, f: &'a Field) -> Option<&'a Number> {
    match &f.value {
        Value::Number(n) => Some(n),
        Value::Array(s, _) | Value::Flag(s) => {
            errs.push(*s, format!("`{}` takes a single number", f.key));
            None
        }
    }
}

/// A run-time parameter that must be positive (when known).
fn positive(errs: &mut Errors, f: &Field) -> Option<DefaultValue> {
    let n = number(errs, f)?;
    match n.value {
        Some(x) if x <= 0.0 => {
            errs.add(n.error(format!("`{}` must be positive, got {x}", f.key)));
            None
        }
        _ => Some(DefaultValue::from(n)),
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
        _ => Some(DefaultValue::from(n)),
    }
}

fn items3<'a>(errs: &mut Errors, v: &'a Value, what: &str) -> Option<[&'a Number; 3]> {
    match v.items(3) {
        Some(x) => Some([x[0], x[1], x[2]]),
        None => {
            errs.push(v.span(), format!("{what} takes three numbers `[x, y, z]`"));
            None
        }
    }
}

/// Three numbers the macro must know (geometry that shapes the code).
fn triple(errs: &mut Errors, v: &Value, what: &str) -> Option<[f64; 3]> {
    let x = items3(errs, v, what)?;
    known3(errs, x, what)
}

fn known3(errs: &mut Errors, x: [&Number; 3], what: &str) -> Option<[f64; 3]> {
    let mut out = [0.0; 3];
    for (o, n) in out.iter_mut().zip(x) {
        match n.known(what) {
            Ok(v) => *o = v,
            Err(e) => {
                errs.add(e);
                return None;
            }
        }
    }
    Some(out)
}

/// Three run-time parameters.
fn param3(errs: &mut Errors, v: &Value, what: &str) -> Option<[DefaultValue; 3]> {
    items3(errs, v, what).map(|x| x.map(DefaultValue::from))
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `a` scaled to unit length without overflow; `None` for a zero vector.
fn unit(a: [f64; 3]) -> Option<[f64; 3]> {
    let s = a.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if s == 0.0 {
        return None;
    }
    let b = a.map(|x| x / s);
    let n = dot(b, b).sqrt();
    Some(b.map(|x| x / n))
}

/// Eigenvalues of a symmetric 3×3 matrix (trigonometric closed form).
pub fn eigenvalues(m: &[[f64; 3]; 3]) -> [f64; 3] {
    let p1 = m[0][1] * m[0][1] + m[0][2] * m[0][2] + m[1][2] * m[1][2];
    let q = (m[0][0] + m[1][1] + m[2][2]) / 3.0;
    if p1 == 0.0 {
        return [m[0][0], m[1][1], m[2][2]];
    }
    let p2 = (m[0][0] - q).powi(2) + (m[1][1] - q).powi(2) + (m[2][2] - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    let b: Vec<Vec<f64>> = (0..3)
        .map(|i| {
            (0..3)
                .map(|j| (m[i][j] - if i == j { q } else { 0.0 }) / p)
                .collect()
        })
        .collect();
    let det = b[0][0] * (b[1][1] * b[2][2] - b[1][2] * b[2][1])
        - b[0][1] * (b[1][0] * b[2][2] - b[1][2] * b[2][0])
        + b[0][2] * (b[1][0] * b[2][1] - b[1][1] * b[2][0]);
    let r = (det / 2.0).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let e1 = q + 2.0 * p * phi.cos();
    let e3 = q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
    [e1, 3.0 * q - e1 - e3, e3]
}

/// The unit quaternion (w, x, y, z), w ≥ 0, of a rotation matrix.
pub fn matrix_to_quaternion(m: &[[f64; 3]; 3]) -> [f64; 4] {
    let t = m[0][0] + m[1][1] + m[2][2];
    let q = if t > 0.0 {
        let s = (t + 1.0).sqrt() * 2.0;
        [
            0.25 * s,
            (m[2][1] - m[1][2]) / s,
            (m[0][2] - m[2][0]) / s,
            (m[1][0] - m[0][1]) / s,
        ]
    } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
        let s = (1.0 + m[0][0] - m[1][1] - m[2][2]).sqrt() * 2.0;
        [
            (m[2][1] - m[1][2]) / s,
            0.25 * s,
            (m[0][1] + m[1][0]) / s,
            (m[0][2] + m[2][0]) / s,
        ]
    } else if m[1][1] > m[2][2] {
        let s = (1.0 + m[1][1] - m[0][0] - m[2][2]).sqrt() * 2.0;
        [
            (m[0][2] - m[2][0]) / s,
            (m[0][1] + m[1][0]) / s,
            0.25 * s,
            (m[1][2] + m[2][1]) / s,
        ]
    } else {
        let s = (1.0 + m[2][2] - m[0][0] - m[1][1]).sqrt() * 2.0;
        [
            (m[1][0] - m[0][1]) / s,
            (m[0][2] + m[2][0]) / s,
            (m[1][2] + m[2][1]) / s,
            0.25 * s,
        ]
    };
    let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    let sign = if q[0] < 0.0 { -1.0 } else { 1.0 };
    q.map(|x| sign * x / n)
}

/// Aᵀ·B.
fn mul_tn(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut out = [[0.0; 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = (0..3).map(|k| a[k][i] * b[k][j]).sum();
        }
    }
    out
}

const IDENTITY: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// Tolerance on the orthogonality (cosine between axes) of a `frame`.
const FRAME_TOL: f64 = 1e-6;

/// The inertia: three principal moments (link frame axes) or a symmetric
/// 3×3 matrix; positive definite and physically realisable (each principal
/// moment at most the sum of the other two).
fn inertia(errs: &mut Errors, f: &Field) -> Option<[[DefaultValue; 3]; 3]> {
    let v = &f.value;
    let zero = || DefaultValue::Known(0.0);
    let params = if let Some(d) = v.items(3) {
        let d: Vec<DefaultValue> = d.into_iter().map(DefaultValue::from).collect();
        [
            [d[0].clone(), zero(), zero()],
            [zero(), d[1].clone(), zero()],
            [zero(), zero(), d[2].clone()],
        ]
    } else if let Some(m) = v.matrix3() {
        m.map(|r| r.map(DefaultValue::from))
    } else {
        errs.push(
            v.span(),
            "`inertia` takes principal moments `[i1, i2, i3]` or a symmetric matrix `[[..], [..], [..]]` (kg·m², about the centre of mass, link frame)",
        );
        return None;
    };
    // Checked here when the macro knows every entry; otherwise the
    // generated model's run-time validation checks symmetry and
    // definiteness (a typed error).
    let mut m = [[0.0; 3]; 3];
    for (row, prow) in m.iter_mut().zip(&params) {
        for (x, p) in row.iter_mut().zip(prow) {
            match p.known() {
                Some(k) => *x = k,
                None => return Some(params),
            }
        }
    }
    if check_inertia(errs, v, &m) {
        Some(params)
    } else {
        None
    }
}

/// The compile-time checks of a known inertia tensor; `false` after
/// reporting a problem.
fn check_inertia(errs: &mut Errors, v: &Value, m: &[[f64; 3]; 3]) -> bool {
    let big = m.iter().flatten().fold(0.0f64, |a, x| a.max(x.abs()));
    let asym = (m[0][1] - m[1][0])
        .abs()
        .max((m[0][2] - m[2][0]).abs())
        .max((m[1][2] - m[2][1]).abs());
    if asym > 1e-12 * big {
        errs.push(v.span(), "`inertia` must be symmetric");
        return false;
    }
    let e = eigenvalues(m);
    let big = e.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    if !e.iter().all(|x| x.is_finite()) || e.iter().any(|&x| x <= 1e-12 * big) || big == 0.0 {
        errs.push(
            v.span(),
            format!(
                "`inertia` must be positive definite (principal moments {:.6e}, {:.6e}, {:.6e}): every rotation of a rigid link needs inertia",
                e[0], e[1], e[2]
            ),
        );
        return false;
    }
    for i in 0..3 {
        let others = e[(i + 1) % 3] + e[(i + 2) % 3];
        if e[i] > others * (1.0 + 1e-9) {
            errs.push(
                v.span(),
                format!(
                    "`inertia` is not physically realisable: principal moment {:.6e} exceeds the sum {:.6e} of the other two",
                    e[i], others
                ),
            );
            return false;
        }
    }
    true
}

/// `frame: [[x axis], [y axis], [z axis]]`: the link's axes in world
/// coordinates in the reference configuration (rows normalised, mutually
/// orthogonal to 1e-6, right-handed), as the rotation R⁰ (columns = axes),
/// re-orthonormalised exactly.
fn frame(errs: &mut Errors, f: &Field) -> Option<[[f64; 3]; 3]> {
    let v = &f.value;
    let Some(items) = v.matrix3() else {
        errs.push(
            v.span(),
            "`frame` takes the link's axes in world coordinates `[[x axis], [y axis], [z axis]]`",
        );
        return None;
    };
    let mut rows = [[0.0; 3]; 3];
    for (row, r) in rows.iter_mut().zip(items) {
        *row = known3(errs, r, "`frame`")?;
    }
    let mut axes = [[0.0; 3]; 3];
    for (i, r) in rows.iter().enumerate() {
        match unit(*r) {
            Some(u) => axes[i] = u,
            None => {
                errs.push(v.span(), "`frame` axes must not be zero");
                return None;
            }
        }
    }
    let worst = dot(axes[0], axes[1])
        .abs()
        .max(dot(axes[0], axes[2]).abs())
        .max(dot(axes[1], axes[2]).abs());
    if worst > FRAME_TOL {
        errs.push(
            v.span(),
            format!(
                "`frame` axes must be mutually orthogonal (largest cosine {worst:.3e} > {FRAME_TOL:e})"
            ),
        );
        return None;
    }
    if dot(cross(axes[0], axes[1]), axes[2]) <= 0.0 {
        errs.push(
            v.span(),
            "`frame` must be right-handed: x axis × y axis = z axis",
        );
        return None;
    }
    // Gram–Schmidt: x, then y ⊥ x, then z = x × y
    let x = axes[0];
    let y = unit({
        let d = dot(axes[1], x);
        [
            axes[1][0] - d * x[0],
            axes[1][1] - d * x[1],
            axes[1][2] - d * x[2],
        ]
    })?;
    let z = cross(x, y);
    // columns are the axes
    Some([[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]])
}

/// Validate a parsed spatial description.
pub fn validate(input: Input) -> syn::Result<Model> {
    let mut errs = Errors(None);
    if let Some(e) = crate::check_mechanism_name(&input.name) {
        errs.add(e);
    }
    check_attrs(&mut errs, &input.attrs, true);

    let mut gravity = [0.0, 0.0, -9.81].map(DefaultValue::Known);
    if let Some((_, v)) = &input.gravity {
        if let Some(g) = param3(&mut errs, v, "a spatial `gravity`") {
            gravity = g;
        }
    }

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
            &["mass", "inertia", "length", "com", "frame"],
            "a spatial link",
        );
        let mass = match f.get("mass") {
            None => {
                errs.push(decl.name.span(), format!("link `{name}` needs `mass`"));
                DefaultValue::Known(1.0)
            }
            Some(field) => positive(&mut errs, field).unwrap_or(DefaultValue::Known(1.0)),
        };
        let length = f.get("length").and_then(|field| positive(&mut errs, field));
        let inertia = match f.get("inertia") {
            None => {
                errs.push(
                    decl.name.span(),
                    format!(
                        "link `{name}` needs `inertia` (principal moments `[i1, i2, i3]` or a symmetric 3×3 matrix about the centre of mass, in the link frame): a spatial link's inertia is not implied by its length"
                    ),
                );
                IDENTITY.map(|r| r.map(DefaultValue::Known))
            }
            Some(field) => inertia(&mut errs, field)
                .unwrap_or_else(|| IDENTITY.map(|r| r.map(DefaultValue::Known))),
        };
        let com = f
            .get("com")
            .and_then(|field| param3(&mut errs, &field.value, "`com`"));
        let frame = f
            .get("frame")
            .and_then(|field| frame(&mut errs, field))
            .unwrap_or(IDENTITY);
        index.insert(name, links.len());
        links.push(Link {
            attrs: decl.attrs.clone(),
            name: decl.name.clone(),
            mass,
            inertia,
            length,
            com,
            frame,
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
                None => Some(Point::World([0.0; 3])),
                Some(v) => triple(errs, v, "a point `world @ [x, y, z]`").map(Point::World),
            },
            PointRef::Link { link, anchor } => {
                let Some(&i) = index.get(&link.unraw().to_string()) else {
                    errs.push(link.span(), format!("unknown link `{link}`"));
                    return None;
                };
                let needs_length = |errs: &mut Errors, s: Span, which: &str| {
                    if links[i].length.is_none() {
                        errs.push(
                            s,
                            format!(
                                "link `{link}` has no `length`, so it has no `{which}`: give it a `length` or write `{link} @ [x, y, z]`"
                            ),
                        );
                    }
                };
                let anchor = match anchor {
                    parse::Anchor::Start(_) => Anchor::Start,
                    parse::Anchor::End(s) => {
                        needs_length(errs, *s, "end");
                        Anchor::End
                    }
                    parse::Anchor::Center(s) => {
                        needs_length(errs, *s, "center");
                        Anchor::Center
                    }
                    parse::Anchor::Com(_) => Anchor::Com,
                    parse::Anchor::At(v) => {
                        Anchor::At(triple(errs, v, &format!("a point `{link} @ [x, y, z]`"))?)
                    }
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
    let mut free_spans = Vec::new();
    for decl in joint_decls {
        check_attrs(&mut errs, &decl.attrs, false);
        let name = decl.name.unraw().to_string();
        if joint_names.insert(name.clone(), ()).is_some() {
            errs.push(decl.name.span(), format!("duplicate joint `{name}`"));
            continue;
        }
        let kind_name = decl.kind.to_string();
        let allowed: &[&str] = match kind_name.as_str() {
            "revolute" | "prismatic" => &["axis", "damping", "actuated", "stiffness", "rest"],
            "spherical" => &["damping"],
            "fixed" | "free" => &[],
            _ => {
                errs.push(
                    decl.kind.span(),
                    format!(
                        "unknown joint type `{kind_name}`: expected `revolute`, `prismatic`, `spherical`, `fixed` or `free`"
                    ),
                );
                continue;
            }
        };
        // inputs and springs act on a single joint coordinate: on any other
        // joint they get their own message
        let one_coordinate = matches!(kind_name.as_str(), "revolute" | "prismatic");
        let mut own = Vec::new();
        for field in &decl.fields {
            let key = field.key.to_string();
            if !one_coordinate && ACTUATION_KEYS.contains(&key.as_str()) {
                errs.push(
                    field.key.span(),
                    format!(
                        "`{key}` is not supported on a {kind_name} joint: only revolute and prismatic joints take `actuated`, `stiffness` and `rest` (they act on the joint's single coordinate)"
                    ),
                );
            } else {
                own.push(field.clone());
            }
        }
        let f = fields(&mut errs, &own, allowed, &format!("a {kind_name} joint"));
        let mut axis = || -> [f64; 3] {
            match f.get("axis") {
                None => {
                    errs.push(
                        decl.kind.span(),
                        format!(
                            "{kind_name} joint `{name}` needs `axis: [ax, ay, az]` (in the parent's frame; world coordinates for a world parent)"
                        ),
                    );
                    [0.0, 0.0, 1.0]
                }
                Some(field) => match triple(&mut errs, &field.value, "`axis`") {
                    None => [0.0, 0.0, 1.0],
                    Some(a) => unit(a).unwrap_or_else(|| {
                        errs.push(field.value.span(), "`axis` must not be zero");
                        [0.0, 0.0, 1.0]
                    }),
                },
            }
        };
        let kind = match kind_name.as_str() {
            "revolute" => JointKind::Revolute { axis: axis() },
            "prismatic" => JointKind::Prismatic { axis: axis() },
            "spherical" => JointKind::Spherical,
            "fixed" => JointKind::Fixed,
            _ => JointKind::Free,
        };
        let damping = f
            .get("damping")
            .and_then(|field| non_negative(&mut errs, field));
        let actuated = actuated(&mut errs, &f);
        let stiffness = stiffness(&mut errs, &f);
        let rest = rest(&mut errs, &f, &name);
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
        if child.link().is_none() {
            errs.push(
                point_span(&decl.child),
                format!(
                    "joint `{name}` has the world as its child: write the world as the parent, `{kind_name}(world, link.point)`"
                ),
            );
            continue;
        }
        let frame_of = |p: &Point| p.link().map_or(IDENTITY, |l| links[l].frame);
        let rel = matrix_to_quaternion(&mul_tn(&frame_of(&parent), &frame_of(&child)));
        if kind == JointKind::Free {
            free_spans.push((joints.len(), decl.kind.span()));
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
            rel,
        });
    }
    if let Some(e) = errs.0.take() {
        return Err(e);
    }

    // spanning tree from the world, joints in declaration order
    let mut placed = vec![false; links.len()];
    let mut is_tree = vec![false; joints.len()];
    let mut placement = Vec::new();
    loop {
        let mut progress = false;
        for (j, joint) in joints.iter().enumerate() {
            if is_tree[j] {
                continue;
            }
            let parent_ready = joint.parent.link().is_none_or(|l| placed[l]);
            if let Some(c) = joint.child.link()
                && parent_ready
                && !placed[c]
            {
                placed[c] = true;
                is_tree[j] = true;
                placement.push(j);
                progress = true;
            }
        }
        if !progress {
            break;
        }
    }
    for (l, link) in links.iter().enumerate() {
        if !placed[l] {
            errs.push(
                link.name.span(),
                format!(
                    "link `{}` is not connected to the world: add a joint whose parent is the world or an already connected link and whose child is `{}` (a floating link: `free(world, {}.com)`)",
                    link.name, link.name, link.name
                ),
            );
        }
    }
    for (j, span) in free_spans {
        if !is_tree[j] {
            errs.push(
                span,
                format!(
                    "free joint `{}` closes a loop: a free joint constrains nothing, so it cannot close one",
                    joints[j].name
                ),
            );
        }
    }
    if let Some(e) = errs.0.take() {
        return Err(e);
    }
    let tree: Vec<usize> = (0..joints.len()).filter(|&j| is_tree[j]).collect();
    let loops: Vec<usize> = (0..joints.len()).filter(|&j| !is_tree[j]).collect();
    Ok(Model {
        attrs: input.attrs,
        vis: input.vis,
        name: input.name,
        gravity,
        links,
        joints,
        tree,
        placement,
        loops,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eigenvalues_of_a_rotated_diagonal_matrix() {
        // R diag(1, 2, 3) Rᵀ for a rotation about (1, 1, 1)/√3 by 0.7
        let (s, c) = 0.7f64.sin_cos();
        let a = [1.0 / 3f64.sqrt(); 3];
        let r: Vec<Vec<f64>> = (0..3)
            .map(|i| {
                (0..3)
                    .map(|j| {
                        let k = [[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]];
                        let kk: f64 = (0..3).map(|l| k[i][l] * k[l][j]).sum();
                        f64::from(u8::from(i == j)) + s * k[i][j] + (1.0 - c) * kk
                    })
                    .collect()
            })
            .collect();
        let d = [1.0, 2.0, 3.0];
        let mut m = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] = (0..3).map(|l| r[i][l] * d[l] * r[j][l]).sum();
            }
        }
        let mut e = eigenvalues(&m);
        e.sort_by(f64::total_cmp);
        for (x, y) in e.iter().zip(d) {
            assert!((x - y).abs() < 1e-12, "{e:?}");
        }
    }

    #[test]
    fn quaternion_of_a_rotation_matrix() {
        // rotation by π/2 about z: (cos π/4, 0, 0, sin π/4)
        let m = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        let q = matrix_to_quaternion(&m);
        let h = std::f64::consts::FRAC_1_SQRT_2;
        for (x, y) in q.iter().zip([h, 0.0, 0.0, h]) {
            assert!((x - y).abs() < 1e-15);
        }
        // rotation by π about x: trace −1 branch
        let m = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]];
        let q = matrix_to_quaternion(&m);
        assert!((q[1].abs() - 1.0).abs() < 1e-15);
    }
}
