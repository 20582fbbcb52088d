//! What a validated description is, in either dimension: a [`Model`] of
//! links and [`Joint`]s between [`Point`]s, with run-time parameters as
//! [`DefaultValue`]s, and the joint graph split into a spanning tree and
//! loop-closing joints.

use crate::number::Number;
use proc_macro2::TokenStream;
use quote::ToTokens;
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
            DefaultValue::Known(x) => crate::lit::lit(*x),
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

/// A resolved point in `D` dimensions; `A` says where on a link.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Point<const D: usize, A> {
    /// World coordinates.
    World([f64; D]),
    /// A point on link `link` (index into `Model::links`).
    Link {
        /// Link index.
        link: usize,
        /// Anchor.
        anchor: A,
    },
}

impl<const D: usize, A> Point<D, A> {
    /// The link this point is on, if any.
    pub fn link(&self) -> Option<usize> {
        match self {
            Point::World(_) => None,
            Point::Link { link, .. } => Some(*link),
        }
    }
}

/// A validated joint of kind `K` between points in `D` dimensions.
#[derive(Clone)]
pub struct Joint<K, A, const D: usize> {
    /// Doc comments.
    pub attrs: Vec<Attribute>,
    /// Name.
    pub name: Ident,
    /// The joint type keyword as written (errors found later point at it).
    pub keyword: Ident,
    /// Type.
    pub kind: K,
    /// Parent point.
    pub parent: Point<D, A>,
    /// Child point.
    pub child: Point<D, A>,
    /// Declared damping (`None` when the joint does not mention it).
    pub damping: Option<DefaultValue>,
    /// `true` when the joint declares `actuated` (an input: a torque about
    /// the joint's axis, a force along a prismatic axis).
    pub actuated: bool,
    /// Declared spring stiffness k ≥ 0 (`None` when not mentioned).
    pub stiffness: Option<DefaultValue>,
    /// Declared spring rest coordinate s₀ (`None` when not mentioned; only
    /// allowed with `stiffness`).
    pub rest: Option<DefaultValue>,
}

/// A validated mechanism in `D` dimensions: links `L`, joints of kind `K`
/// with anchors `A`.
#[derive(Clone)]
pub struct Model<L, K, A, const D: usize> {
    /// Outer attributes of the mechanism.
    pub attrs: Vec<Attribute>,
    /// Visibility.
    pub vis: Visibility,
    /// Name.
    pub name: Ident,
    /// Gravity (m/s²).
    pub gravity: [DefaultValue; D],
    /// Links in declaration order.
    pub links: Vec<L>,
    /// Joints in declaration order.
    pub joints: Vec<Joint<K, A, D>>,
    /// Tree joints in declaration order: minimal coordinates follow them.
    pub tree: Vec<usize>,
    /// Tree joints in placement order (parents first).
    pub placement: Vec<usize>,
    /// For each link, the tree joint that places it.
    pub placed_by: Vec<usize>,
    /// Links in placement order (every parent comes first).
    pub order: Vec<usize>,
    /// Loop-closing joints in declaration order.
    pub loops: Vec<usize>,
}

impl<L, K, A, const D: usize> Model<L, K, A, D> {
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

    /// Position of a tree joint among the tree joints.
    pub fn coordinate_of(&self, joint: usize) -> Option<usize> {
        self.tree.iter().position(|&j| j == joint)
    }
}
