//! Spatial descriptions: rigid links with a mass, an inertia tensor and a
//! frame; revolute, prismatic, spherical, universal, fixed and free joints
//! with axes;
//! points `[x, y, z]` and `link.com`; gravity `[gx, gy, gz]`. What a
//! spatial description means beyond the checks every description shares.

mod frame;
mod inertia;

use crate::ctxt::Ctxt;
use crate::desc::checks::{self, Fields};
use crate::desc::model::DefaultValue;
use crate::desc::validate::{JointType, Rules};
use crate::geom3::{IDENTITY, matrix_to_quaternion, mul_tn, unit};
use crate::syntax::{self, JointDecl, LinkDecl, Value};
use frame::frame;
use inertia::inertia;
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
    /// Hooke (cardan) joint: rotation about the first unit axis (fixed in
    /// the parent), then about the second (given in the parent frame at the
    /// reference configuration, carried by the first rotation).
    Universal {
        /// The two unit axes, not parallel.
        axes: [[f64; 3]; 2],
    },
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
            JointKind::Universal { .. } => "Universal",
        }
    }

    /// The axis (zero for joints without one).
    pub fn axis(&self) -> [f64; 3] {
        match self {
            JointKind::Revolute { axis } | JointKind::Prismatic { axis } => *axis,
            JointKind::Universal { axes } => axes[0],
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
            JointKind::Universal { .. } => 2,
        }
    }

    /// Constraint rows (maximal coordinates, or as a loop joint).
    pub fn rows(&self) -> usize {
        match self {
            JointKind::Revolute { .. } | JointKind::Prismatic { .. } => 5,
            JointKind::Spherical => 3,
            JointKind::Fixed => 6,
            JointKind::Free => 0,
            JointKind::Universal { .. } => 4,
        }
    }
}

/// A resolved point.
pub type Point = crate::desc::model::Point<3, Anchor>;

/// A validated joint.
pub type Joint = crate::desc::model::Joint<JointKind, Anchor, 3>;

/// A validated spatial mechanism.
pub type Model = crate::desc::model::Model<Link, JointKind, Anchor, 3>;

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

    /// A joint's reference relative rotation Q = R_p⁰ᵀR_c⁰ (the world's
    /// frame for a world point): the child link's frame in its parent's at
    /// the reference configuration.
    pub fn relative_rotation(&self, joint: &Joint) -> [[f64; 3]; 3] {
        let frame_of = |p: &Point| p.link().map_or(IDENTITY, |l| self.links[l].frame);
        mul_tn(&frame_of(&joint.parent), &frame_of(&joint.child))
    }

    /// [`Model::relative_rotation`] as a unit quaternion (w, x, y, z).
    pub fn rel(&self, joint: &Joint) -> [f64; 4] {
        matrix_to_quaternion(&self.relative_rotation(joint))
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
        JointType::new("universal", &["axes", "damping"], false),
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
            "universal" => JointKind::Universal {
                axes: universal_axes(cx, decl, name, f),
            },
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

/// The smallest sine of the angle between a universal joint's axes (the
/// run-time `vigp::spatial::model::UNIVERSAL_MIN_SINE`).
const UNIVERSAL_MIN_SINE: f64 = 1e-6;

/// `axes: [[ax, ay, az], [bx, by, bz]]` of a universal joint: two non-zero,
/// non-parallel axes, normalised. Errors point at the offending axis.
fn universal_axes(cx: &mut Ctxt, decl: &JointDecl, name: &str, f: &Fields) -> [[f64; 3]; 2] {
    const FALLBACK: [[f64; 3]; 2] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let shape = "`axes` of a universal joint takes two axes `[[ax, ay, az], [bx, by, bz]]` (the first fixed in the parent's frame, the second given in the parent's frame at the reference configuration and carried by the first rotation)";
    let Some(field) = f.get("axes") else {
        cx.push(
            decl.kind.span(),
            format!(
                "universal joint `{name}` needs `axes: [[ax, ay, az], [bx, by, bz]]` (the first axis fixed in the parent's frame, the second given in the parent's frame at the reference configuration and carried by the first rotation)"
            ),
        );
        return FALLBACK;
    };
    let Value::Array(_, items) = &field.value else {
        cx.push(field.value.span(), shape);
        return FALLBACK;
    };
    if items.len() != 2 {
        cx.push(field.value.span(), shape);
        return FALLBACK;
    }
    let mut out = FALLBACK;
    let mut ok = true;
    for (k, (o, v)) in out.iter_mut().zip(items).enumerate() {
        let which = if k == 0 { "first" } else { "second" };
        match triple(cx, v, &format!("the {which} axis of `axes`")) {
            None => ok = false,
            Some(a) => match unit(a) {
                Some(u) => *o = u,
                None => {
                    cx.push(
                        v.span(),
                        format!("the {which} axis of universal joint `{name}` must not be zero"),
                    );
                    ok = false;
                }
            },
        }
    }
    if ok {
        let [a, b] = out;
        let c = [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ];
        if (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt() < UNIVERSAL_MIN_SINE {
            cx.push(
                items[1].span(),
                format!(
                    "the two axes of universal joint `{name}` are parallel: a universal joint needs two different rotation axes (usually perpendicular); for a single axis use `revolute`"
                ),
            );
            return FALLBACK;
        }
    }
    out
}

/// Three run-time parameters.
fn param3(cx: &mut Ctxt, v: &Value, what: &str) -> Option<[DefaultValue; 3]> {
    checks::numbers::<3>(cx, v, || checks::shape::<3>(what)).map(|x| x.map(DefaultValue::from))
}

/// Three numbers the macro must know (geometry that shapes the code).
pub(crate) fn triple(cx: &mut Ctxt, v: &Value, what: &str) -> Option<[f64; 3]> {
    let x = checks::numbers::<3>(cx, v, || checks::shape::<3>(what))?;
    checks::known(cx, x, what)
}
