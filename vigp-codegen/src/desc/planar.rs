//! Planar descriptions: links in a plane with a mass, a length and a
//! scalar inertia; revolute and prismatic joints; points `[x, y]`;
//! gravity `[gx, gy]`. What a planar description means beyond the checks
//! every description shares.

use super::checks::{self, Fields};
use super::model::DefaultValue;
use super::validate::{JointType, Rules};
use crate::ctxt::Ctxt;
use crate::syntax::{self, JointDecl, LinkDecl, Value};
use syn::{Attribute, Ident};

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

/// A resolved point.
pub type Point = super::model::Point<2, Anchor>;

/// A validated joint.
pub type Joint = super::model::Joint<JointKind, Anchor, 2>;

/// A validated planar mechanism.
pub type Model = super::model::Model<Link, JointKind, Anchor, 2>;

impl Model {
    /// Number of minimal coordinates.
    pub fn dof(&self) -> usize {
        self.tree.len()
    }

    /// Number of loop-closure constraint equations (2 per loop joint).
    pub fn loop_constraints(&self) -> usize {
        2 * self.loops.len()
    }
}

/// The rules of planar descriptions.
pub struct Planar;

impl Rules<2> for Planar {
    type Link = Link;
    type Kind = JointKind;
    type Anchor = Anchor;
    const LINK_KEYS: &'static [&'static str] = &["mass", "length", "inertia", "com"];
    const LINK: &'static str = "a link";
    const JOINTS: &'static [JointType] = &[
        JointType::new(
            "revolute",
            &["damping", "actuated", "stiffness", "rest"],
            true,
        ),
        JointType {
            name: "prismatic",
            keys: &["damping", "axis", "actuated", "stiffness", "rest"],
            coordinate: true,
        },
    ];
    const WORLD_POINT: &'static str = "a world point";
    const GRAVITY: [f64; 2] = [0.0, -9.81];

    fn gravity(cx: &mut Ctxt, key: &Ident, v: &Value) -> Option<[DefaultValue; 2]> {
        // three numbers select the spatial rules before this point
        checks::numbers::<2>(cx, v, || {
            format!(
                "`{key}` must have 2 components `[gx, gy]` (planar) or 3 `[gx, gy, gz]` (spatial)"
            )
        })
        .map(|g| g.map(DefaultValue::from))
    }

    fn name(link: &Link) -> &Ident {
        &link.name
    }

    fn link(cx: &mut Ctxt, decl: &LinkDecl, name: &str, f: &Fields) -> Link {
        let mass = checks::required_positive(cx, decl, name, f, "mass");
        let length = checks::required_positive(cx, decl, name, f, "length");
        let inertia = match f.get("inertia") {
            None => match (mass.known(), length.known()) {
                (Some(m), Some(l)) if !(m * l * l).is_finite() => {
                    cx.push(
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
            Some(field) => checks::non_negative(cx, field),
        };
        let com = f
            .get("com")
            .and_then(|field| pair(cx, field))
            .map(|p| p.map(DefaultValue::from));
        Link {
            attrs: decl.attrs.clone(),
            name: decl.name.clone(),
            mass,
            length,
            inertia,
            com,
        }
    }

    fn kind(cx: &mut Ctxt, decl: &JointDecl, name: &str, kind: &str, f: &Fields) -> JointKind {
        if kind != "prismatic" {
            return JointKind::Revolute;
        }
        let Some(field) = f.get("axis") else {
            cx.push(
                decl.kind.span(),
                format!("prismatic joint `{name}` needs `axis: [ax, ay]`"),
            );
            return JointKind::Prismatic { axis: [1.0, 0.0] };
        };
        let [ax, ay] = pair(cx, field)
            .and_then(|p| checks::known(cx, p, "`axis`"))
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
            cx.push(field.value.span(), "`axis` must not be zero");
            JointKind::Prismatic { axis: [1.0, 0.0] }
        }
    }

    fn anchor(cx: &mut Ctxt, _on: (&Link, &Ident), anchor: &syntax::Anchor) -> Option<Anchor> {
        const WHAT: &str = "an attachment point";
        Some(match anchor {
            syntax::Anchor::Start(_) => Anchor::Start,
            syntax::Anchor::End(_) => Anchor::End,
            syntax::Anchor::Center(_) => Anchor::Center,
            syntax::Anchor::At(v) => {
                let p = checks::numbers::<2>(cx, v, || checks::shape::<2>(WHAT))?;
                Anchor::At(checks::known(cx, p, WHAT)?)
            }
            // the planar grammar does not read `link.com`
            syntax::Anchor::Com(s) => {
                cx.push(
                    *s,
                    "a planar link has no `com` point: write `link @ [x, y]`",
                );
                return None;
            }
        })
    }
}

/// The two numbers of a key that takes a pair `[x, y]`.
fn pair<'a>(cx: &mut Ctxt, f: &'a crate::syntax::Field) -> Option<[&'a crate::number::Number; 2]> {
    checks::numbers::<2>(cx, &f.value, || {
        format!("`{}` takes a pair `[x, y]`", f.key)
    })
}
