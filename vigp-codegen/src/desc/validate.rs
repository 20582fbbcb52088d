//! The one validation driver: it walks a parsed description in a fixed
//! order (mechanism, gravity, links, joints, connectivity) and asks the
//! dimension's [`Rules`] only for what differs.

use super::checks::{self, ACTUATION_KEYS, Fields};
use super::graph::Tree;
use super::model::{DefaultValue, Joint, Model, Point};
use crate::ctxt::Ctxt;
use crate::syntax::{self, Input, JointDecl, LinkDecl, PointRef, Value};
use std::collections::HashMap;
use syn::Ident;
use syn::ext::IdentExt;

/// A joint type of a dimension: its keyword and the keys it takes.
pub struct JointType {
    /// The keyword (`revolute`).
    pub name: &'static str,
    /// The keys it takes, in the order errors list them.
    pub keys: &'static [&'static str],
    /// `true` when the joint has a single coordinate, which inputs and
    /// springs ([`ACTUATION_KEYS`]) act on.
    pub coordinate: bool,
}

impl JointType {
    /// A joint type `name` taking `keys`; `coordinate` as the field.
    pub const fn new(
        name: &'static str,
        keys: &'static [&'static str],
        coordinate: bool,
    ) -> JointType {
        JointType {
            name,
            keys,
            coordinate,
        }
    }
}

/// What a dimension decides; [`validate`] does the rest.
pub trait Rules<const D: usize> {
    /// A validated link.
    type Link;
    /// A validated joint type (with its geometry, such as an axis).
    type Kind: Copy;
    /// Where a point sits on a link.
    type Anchor: Copy;
    /// The keys a link takes.
    const LINK_KEYS: &'static [&'static str];
    /// How errors name a link declaration ("a link").
    const LINK: &'static str;
    /// The joint types: the one place to add one.
    const JOINTS: &'static [JointType];
    /// How errors name a world point's coordinates.
    const WORLD_POINT: &'static str;
    /// Gravity when the description gives none.
    const GRAVITY: [f64; D];

    /// `gravity: value` (`key` is the `gravity` keyword).
    fn gravity(cx: &mut Ctxt, key: &Ident, v: &Value) -> Option<[DefaultValue; D]>;
    /// A validated link's name.
    fn name(link: &Self::Link) -> &Ident;
    /// A link from its fields (`name` unraw).
    fn link(cx: &mut Ctxt, decl: &LinkDecl, name: &str, f: &Fields) -> Self::Link;
    /// A joint type from the fields of a joint whose keyword is `kind`.
    fn kind(cx: &mut Ctxt, decl: &JointDecl, name: &str, kind: &str, f: &Fields) -> Self::Kind;
    /// An anchor on a link, given with its name as written.
    fn anchor(
        cx: &mut Ctxt,
        on: (&Self::Link, &Ident),
        anchor: &syntax::Anchor,
    ) -> Option<Self::Anchor>;
    /// Checks of a joint whose two points are known; `false` drops it.
    fn joint(_cx: &mut Ctxt, _decl: &JointDecl, _name: &str, _child: Option<usize>) -> bool {
        true
    }
    /// What an unconnected link's error adds to the remedy.
    fn unconnected_hint(_link: &Ident) -> String {
        String::new()
    }
    /// Checks of a joint that closes a loop.
    fn loop_joint(_cx: &mut Ctxt, _joint: &Joint<Self::Kind, Self::Anchor, D>) {}
}

/// Validate a parsed description by the rules `R` of its dimension.
pub fn validate<const D: usize, R: Rules<D>>(
    input: Input,
) -> syn::Result<Model<R::Link, R::Kind, R::Anchor, D>> {
    let mut cx = Ctxt::default();
    checks::mechanism_name(&mut cx, &input.name);
    checks::attrs(&mut cx, &input.attrs, true);
    let mut gravity = R::GRAVITY.map(DefaultValue::Known);
    if let Some((key, v)) = &input.gravity
        && let Some(g) = R::gravity(&mut cx, key, v)
    {
        gravity = g;
    }
    let (links, index) = links::<D, R>(&mut cx, &input)?;
    let joints = joints::<D, R>(&mut cx, &input, &links, &index);
    cx.check()?;
    let tree = Tree::grow(&joints, links.len());
    for (link, placed) in links.iter().zip(&tree.placed_by) {
        if placed.is_none() {
            let name = R::name(link);
            cx.push(
                name.span(),
                format!(
                    "link `{name}` is not connected to the world: add a joint whose parent is the world or an already connected link and whose child is `{name}`{}",
                    R::unconnected_hint(name)
                ),
            );
        }
    }
    for (j, joint) in joints.iter().enumerate() {
        if !tree.is_tree[j] {
            R::loop_joint(&mut cx, joint);
        }
    }
    let (tree_joints, loops) = (0..joints.len()).partition(|&j| tree.is_tree[j]);
    cx.finish(Model {
        attrs: input.attrs,
        vis: input.vis,
        name: input.name,
        gravity,
        links,
        joints,
        tree: tree_joints,
        order: tree.order,
        placed_by: tree.placed_by.into_iter().map(|p| p.unwrap_or(0)).collect(),
        placement: tree.placement,
        loops,
    })
}

/// Link names (unraw) to their index.
type Index = HashMap<String, usize>;

fn links<const D: usize, R: Rules<D>>(
    cx: &mut Ctxt,
    input: &Input,
) -> syn::Result<(Vec<R::Link>, Index)> {
    let Some((links_kw, decls)) = &input.links else {
        return Err(syn::Error::new(
            input.name.span(),
            format!("mechanism `{}` has no `links {{ … }}` section", input.name),
        ));
    };
    if decls.is_empty() {
        cx.push(links_kw.span(), "a mechanism needs at least one link");
    }
    let mut links = Vec::new();
    let mut index = Index::new();
    for decl in decls {
        checks::attrs(cx, &decl.attrs, false);
        // `r#type` and `type` name the same field.
        let name = decl.name.unraw().to_string();
        if name == "world" {
            cx.push(
                decl.name.span(),
                "`world` is reserved and cannot name a link",
            );
        }
        if index.contains_key(&name) {
            cx.push(decl.name.span(), format!("duplicate link `{name}`"));
            continue;
        }
        let f = checks::fields(cx, &decl.fields, R::LINK_KEYS, R::LINK);
        links.push(R::link(cx, decl, &name, &f));
        index.insert(name, links.len() - 1);
    }
    Ok((links, index))
}

fn joints<const D: usize, R: Rules<D>>(
    cx: &mut Ctxt,
    input: &Input,
    links: &[R::Link],
    index: &Index,
) -> Vec<Joint<R::Kind, R::Anchor, D>> {
    let decls: &[JointDecl] = input.joints.as_ref().map_or(&[], |(_, d)| d);
    let mut joints = Vec::new();
    let mut names = std::collections::HashSet::new();
    for decl in decls {
        checks::attrs(cx, &decl.attrs, false);
        let name = decl.name.unraw().to_string();
        if !names.insert(name.clone()) {
            cx.push(decl.name.span(), format!("duplicate joint `{name}`"));
            continue;
        }
        let kind_name = decl.kind.to_string();
        let Some(ty) = R::JOINTS.iter().find(|t| t.name == kind_name) else {
            let known: Vec<&str> = R::JOINTS.iter().map(|t| t.name).collect();
            cx.push(
                decl.kind.span(),
                format!(
                    "unknown joint type `{kind_name}`: expected {}",
                    or_list(&known)
                ),
            );
            continue;
        };
        // inputs and springs act on a single joint coordinate: on any other
        // joint they get their own message
        let mut own = Vec::new();
        for field in &decl.fields {
            let key = field.key.to_string();
            if !ty.coordinate && ACTUATION_KEYS.contains(&key.as_str()) {
                cx.push(
                    field.key.span(),
                    format!(
                        "`{key}` is not supported on a {kind_name} joint: only revolute and prismatic joints take `actuated`, `stiffness` and `rest` (they act on the joint's single coordinate)"
                    ),
                );
            } else {
                own.push(field.clone());
            }
        }
        let f = checks::fields(cx, &own, ty.keys, &format!("a {kind_name} joint"));
        let kind = R::kind(cx, decl, &name, &kind_name, &f);
        let act = checks::actuation(cx, &f, &name);
        let parent = point::<D, R>(cx, links, index, &decl.parent);
        let child = point::<D, R>(cx, links, index, &decl.child);
        let (Some(parent), Some(child)) = (parent, child) else {
            continue;
        };
        if parent.link() == child.link() {
            let what = if parent.link().is_none() {
                "the world to itself"
            } else {
                "a link to itself"
            };
            cx.push(decl.child.span(), format!("joint `{name}` connects {what}"));
            continue;
        }
        if !R::joint(cx, decl, &name, child.link()) {
            continue;
        }
        joints.push(Joint {
            attrs: decl.attrs.clone(),
            name: decl.name.clone(),
            keyword: decl.kind.clone(),
            kind,
            parent,
            child,
            damping: act.damping,
            actuated: act.actuated,
            stiffness: act.stiffness,
            rest: act.rest,
        });
    }
    joints
}

/// "`a`, `b` or `c`".
fn or_list(names: &[&str]) -> String {
    let quoted: Vec<String> = names.iter().map(|n| format!("`{n}`")).collect();
    match quoted.as_slice() {
        [init @ .., last] if !init.is_empty() => format!("{} or {last}", init.join(", ")),
        _ => quoted.join(""),
    }
}

/// A joint's point, resolved.
fn point<const D: usize, R: Rules<D>>(
    cx: &mut Ctxt,
    links: &[R::Link],
    index: &Index,
    p: &PointRef,
) -> Option<Point<D, R::Anchor>> {
    match p {
        PointRef::World { at: None, .. } => Some(Point::World([0.0; D])),
        PointRef::World { at: Some(v), .. } => {
            let x = checks::numbers::<D>(cx, v, || checks::shape::<D>(R::WORLD_POINT))?;
            checks::known(cx, x, R::WORLD_POINT).map(Point::World)
        }
        PointRef::Link { link, anchor } => {
            let Some(&i) = index.get(&link.unraw().to_string()) else {
                cx.push(link.span(), format!("unknown link `{link}`"));
                return None;
            };
            let anchor = R::anchor(cx, (&links[i], link), anchor)?;
            Some(Point::Link { link: i, anchor })
        }
    }
}
