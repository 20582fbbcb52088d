//! Spatial descriptions: rigid links with a mass, an inertia tensor and a
//! frame; revolute, prismatic, spherical, fixed and free joints with axes;
//! points `[x, y, z]` and `link.com`; gravity `[gx, gy, gz]`. What a
//! spatial description means beyond the checks every description shares.

use super::DefaultValue;
use super::checks::{self, Fields};
use super::validate::{JointType, Rules, shape};
use crate::ctxt::Ctxt;
use crate::geom3::{IDENTITY, cross, dot, eigenvalues, matrix_to_quaternion, mul_tn, unit};
use crate::syntax::{self, Field, JointDecl, LinkDecl, Value};
use syn::{Attribute, Ident};

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

/// A resolved point.
pub type Point = super::Point<3, Anchor>;

/// A validated joint.
pub type Joint = super::Joint<JointKind, Anchor, 3>;

/// A validated spatial mechanism.
pub type Model = super::Model<Link, JointKind, Anchor, 3>;

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

    /// A joint's reference relative rotation R_p⁰ᵀR_c⁰ as a unit
    /// quaternion (w, x, y, z).
    pub fn rel(&self, joint: &Joint) -> [f64; 4] {
        let frame_of = |p: &Point| p.link().map_or(IDENTITY, |l| self.links[l].frame);
        matrix_to_quaternion(&mul_tn(&frame_of(&joint.parent), &frame_of(&joint.child)))
    }
}

/// The rules of spatial descriptions.
pub struct Spatial;

/// The keys of a revolute or prismatic joint.
const AXIAL_KEYS: &[&str] = &["axis", "damping", "actuated", "stiffness", "rest"];

impl Rules<3> for Spatial {
    type Link = Link;
    type Kind = JointKind;
    type Anchor = Anchor;
    const LINK_KEYS: &'static [&'static str] = &["mass", "inertia", "length", "com", "frame"];
    const LINK: &'static str = "a spatial link";
    const JOINTS: &'static [JointType] = &[
        JointType::new("revolute", AXIAL_KEYS, true),
        JointType::new("prismatic", AXIAL_KEYS, true),
        JointType::new("spherical", &["damping"], false),
        JointType::new("fixed", &[], false),
        JointType::new("free", &[], false),
    ];
    const WORLD_POINT: &'static str = "a point `world @ [x, y, z]`";
    const GRAVITY: [f64; 3] = [0.0, 0.0, -9.81];

    fn gravity(cx: &mut Ctxt, _key: &Ident, v: &Value) -> Option<[DefaultValue; 3]> {
        param3(cx, v, "a spatial `gravity`")
    }

    fn name(link: &Link) -> &Ident {
        &link.name
    }

    fn link(cx: &mut Ctxt, decl: &LinkDecl, name: &str, f: &Fields) -> Link {
        let mass = checks::required_positive(cx, decl, name, f, "mass");
        let length = f
            .get("length")
            .and_then(|field| checks::positive(cx, field));
        let inertia = match f.get("inertia") {
            None => {
                cx.push(
                    decl.name.span(),
                    format!(
                        "link `{name}` needs `inertia` (principal moments `[i1, i2, i3]` or a symmetric 3×3 matrix about the centre of mass, in the link frame): a spatial link's inertia is not implied by its length"
                    ),
                );
                None
            }
            Some(field) => inertia(cx, field),
        };
        let com = f
            .get("com")
            .and_then(|field| param3(cx, &field.value, "`com`"));
        let frame = f
            .get("frame")
            .and_then(|field| frame(cx, field))
            .unwrap_or(IDENTITY);
        Link {
            attrs: decl.attrs.clone(),
            name: decl.name.clone(),
            mass,
            inertia: inertia.unwrap_or_else(|| IDENTITY.map(|r| r.map(DefaultValue::Known))),
            length,
            com,
            frame,
        }
    }

    fn kind(cx: &mut Ctxt, decl: &JointDecl, name: &str, kind: &str, f: &Fields) -> JointKind {
        let mut axis = || -> [f64; 3] {
            match f.get("axis") {
                None => {
                    cx.push(
                        decl.kind.span(),
                        format!(
                            "{kind} joint `{name}` needs `axis: [ax, ay, az]` (in the parent's frame; world coordinates for a world parent)"
                        ),
                    );
                    [0.0, 0.0, 1.0]
                }
                Some(field) => match triple(cx, &field.value, "`axis`") {
                    None => [0.0, 0.0, 1.0],
                    Some(a) => unit(a).unwrap_or_else(|| {
                        cx.push(field.value.span(), "`axis` must not be zero");
                        [0.0, 0.0, 1.0]
                    }),
                },
            }
        };
        match kind {
            "revolute" => JointKind::Revolute { axis: axis() },
            "prismatic" => JointKind::Prismatic { axis: axis() },
            "spherical" => JointKind::Spherical,
            "fixed" => JointKind::Fixed,
            _ => JointKind::Free,
        }
    }

    fn anchor(cx: &mut Ctxt, on: (&Link, &Ident), anchor: &syntax::Anchor) -> Option<Anchor> {
        let (on, link) = on;
        let mut needs_length = |s: proc_macro2::Span, which: &str| {
            if on.length.is_none() {
                cx.push(
                    s,
                    format!(
                        "link `{link}` has no `length`, so it has no `{which}`: give it a `length` or write `{link} @ [x, y, z]`"
                    ),
                );
            }
        };
        Some(match anchor {
            syntax::Anchor::Start(_) => Anchor::Start,
            syntax::Anchor::End(s) => {
                needs_length(*s, "end");
                Anchor::End
            }
            syntax::Anchor::Center(s) => {
                needs_length(*s, "center");
                Anchor::Center
            }
            syntax::Anchor::Com(_) => Anchor::Com,
            syntax::Anchor::At(v) => {
                Anchor::At(triple(cx, v, &format!("a point `{link} @ [x, y, z]`"))?)
            }
        })
    }

    fn joint(cx: &mut Ctxt, decl: &JointDecl, name: &str, child: Option<usize>) -> bool {
        if child.is_none() {
            cx.push(
                decl.child.span(),
                format!(
                    "joint `{name}` has the world as its child: write the world as the parent, `{}(world, link.point)`",
                    decl.kind
                ),
            );
        }
        child.is_some()
    }

    fn unconnected_hint(link: &Ident) -> String {
        format!(" (a floating link: `free(world, {link}.com)`)")
    }

    fn loop_joint(cx: &mut Ctxt, joint: &Joint) {
        if joint.kind == JointKind::Free {
            cx.push(
                joint.keyword.span(),
                format!(
                    "free joint `{}` closes a loop: a free joint constrains nothing, so it cannot close one",
                    joint.name
                ),
            );
        }
    }
}

/// Three run-time parameters.
fn param3(cx: &mut Ctxt, v: &Value, what: &str) -> Option<[DefaultValue; 3]> {
    checks::numbers::<3>(cx, v, || shape::<3>(what)).map(|x| x.map(DefaultValue::from))
}

/// Three numbers the macro must know (geometry that shapes the code).
fn triple(cx: &mut Ctxt, v: &Value, what: &str) -> Option<[f64; 3]> {
    let x = checks::numbers::<3>(cx, v, || shape::<3>(what))?;
    checks::known(cx, x, what)
}

/// Tolerance on the orthogonality (cosine between axes) of a `frame`.
const FRAME_TOL: f64 = 1e-6;

/// The inertia: three principal moments (link frame axes) or a symmetric
/// 3×3 matrix; positive definite and physically realisable (each principal
/// moment at most the sum of the other two).
fn inertia(cx: &mut Ctxt, f: &Field) -> Option<[[DefaultValue; 3]; 3]> {
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
        cx.push(
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
    if check_inertia(cx, v, &m) {
        Some(params)
    } else {
        None
    }
}

/// The compile-time checks of a known inertia tensor; `false` after
/// reporting a problem.
fn check_inertia(cx: &mut Ctxt, v: &Value, m: &[[f64; 3]; 3]) -> bool {
    let big = m.iter().flatten().fold(0.0f64, |a, x| a.max(x.abs()));
    let asym = (m[0][1] - m[1][0])
        .abs()
        .max((m[0][2] - m[2][0]).abs())
        .max((m[1][2] - m[2][1]).abs());
    if asym > 1e-12 * big {
        cx.push(v.span(), "`inertia` must be symmetric");
        return false;
    }
    let e = eigenvalues(m);
    let big = e.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    if !e.iter().all(|x| x.is_finite()) || e.iter().any(|&x| x <= 1e-12 * big) || big == 0.0 {
        cx.push(
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
            cx.push(
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
fn frame(cx: &mut Ctxt, f: &Field) -> Option<[[f64; 3]; 3]> {
    let v = &f.value;
    let Some(items) = v.matrix3() else {
        cx.push(
            v.span(),
            "`frame` takes the link's axes in world coordinates `[[x axis], [y axis], [z axis]]`",
        );
        return None;
    };
    let mut rows = [[0.0; 3]; 3];
    for (row, r) in rows.iter_mut().zip(items) {
        *row = checks::known(cx, r, "`frame`")?;
    }
    let mut axes = [[0.0; 3]; 3];
    for (i, r) in rows.iter().enumerate() {
        match unit(*r) {
            Some(u) => axes[i] = u,
            None => {
                cx.push(v.span(), "`frame` axes must not be zero");
                return None;
            }
        }
    }
    let worst = dot(axes[0], axes[1])
        .abs()
        .max(dot(axes[0], axes[2]).abs())
        .max(dot(axes[1], axes[2]).abs());
    if worst > FRAME_TOL {
        cx.push(
            v.span(),
            format!(
                "`frame` axes must be mutually orthogonal (largest cosine {worst:.3e} > {FRAME_TOL:e})"
            ),
        );
        return None;
    }
    if dot(cross(axes[0], axes[1]), axes[2]) <= 0.0 {
        cx.push(
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
