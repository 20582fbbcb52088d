//! URDF files as a tree of rigid bodies: the one converter behind the
//! run-time `vigp::Robot::from_urdf` and the compile-time
//! `mechanism! { Name { urdf: "robot.urdf" } }`.
//!
//! ```
//! let urdf = r#"<robot name="pendulum">
//!   <link name="base"/>
//!   <link name="arm">
//!     <inertial><origin xyz="0 0 -0.5"/><mass value="1"/>
//!       <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.001"/></inertial>
//!   </link>
//!   <joint name="hinge" type="continuous">
//!     <parent link="base"/><child link="arm"/><axis xyz="0 1 0"/>
//!   </joint>
//! </robot>"#;
//! let tree = vigp_urdf::parse(urdf)?;
//! assert_eq!(tree.joints, ["hinge"]);
//! assert_eq!(tree.bodies[0].com, [0.0, 0.0, -0.5]);
//! # Ok::<(), vigp_urdf::UrdfError>(())
//! ```
//!
//! # What is read
//!
//! * `revolute` and `continuous` joints become revolute coordinates,
//!   `prismatic` joints prismatic ones; `fixed` joints are merged: the
//!   child link's inertia (and everything fixed to it) joins its parent
//!   body. Links fixed to the root link form the base
//!   ([`UrdfTree::base`]): the world of a fixed base, the floating body of
//!   a free one.
//! * Joint `<origin>` (xyz, rpy: R = Rz(y)Ry(p)Rx(r)) places the joint frame
//!   in the parent link frame; `<axis>` (default x, normalised) is in the
//!   joint frame; `<inertial>` origin and inertia are in the link frame.
//! * `<dynamics damping>` is viscous damping on the joint rate (friction
//!   is ignored); `<limit>` is kept ([`vigp_core::tree::Limits`]; a joint
//!   without one, or a continuous joint's position, has none). Visuals,
//!   collisions, meshes, materials are ignored.
//! * Bodies are in depth-first order from the root, child joints in file
//!   order (Pinocchio's order).
//! * Refused, with a [`UrdfError`] naming the element: XML the parser
//!   rejects, mimic joints, floating, planar and spherical joints, NaN or
//!   ±∞ in any number read, a zero axis, a negative mass, inertia or
//!   damping, an unknown or duplicate link, a link with two parent joints,
//!   and no single root. [`UrdfError::line`] finds the element's line in
//!   the file.

#![forbid(unsafe_code)]
#![warn(missing_docs)]

use std::collections::HashMap;

use vigp_core::tree::spatial::{
    IDENTITY, M3, V3, add, congruence, dot, mul_mm, mul_mv, rpy, scale,
};
pub use vigp_core::tree::{Body, JointKind, Limits};

/// Mass properties of a rigid body: mass, centre of mass and the
/// rotational inertia about it, both in the body frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MassProperties {
    /// Mass (kg, ≥ 0).
    pub mass: f64,
    /// Centre of mass (m, body frame; the origin for a massless body).
    pub com: V3,
    /// Inertia about the centre of mass (kg·m², body axes, symmetric).
    pub inertia: M3,
}

/// A URDF robot as a tree of rigid bodies, one per joint coordinate.
#[derive(Clone, Debug, PartialEq)]
pub struct UrdfTree {
    /// The `<robot name>`.
    pub name: String,
    /// The bodies, parents first; `parent: None` is the base (the root
    /// link and everything fixed to it).
    pub bodies: Vec<Body>,
    /// The joint of each body.
    pub joints: Vec<String>,
    /// The link of each body (the links fixed to it are merged into it).
    pub links: Vec<String>,
    /// The root link.
    pub root: String,
    /// The base's mass properties in the root link frame: the root link
    /// and every link fixed to it.
    pub base: MassProperties,
}

/// Why a URDF document could not be read as a tree of bodies.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UrdfError {
    /// The XML parser refused the document (its message names the place).
    #[error("malformed URDF: {0}")]
    Parse(String),
    /// A number in the file is NaN or ±∞.
    #[error("non-finite number in {element}")]
    NonFinite {
        /// The element, e.g. "joint `elbow` `<origin>`".
        element: String,
    },
    /// A value out of its domain.
    #[error("invalid {element}: {why}")]
    Invalid {
        /// The element.
        element: String,
        /// What is wrong.
        why: &'static str,
    },
    /// A joint type that is not a single-coordinate tree joint.
    #[error(
        "joint `{joint}`: type {kind} is not supported (revolute, continuous, prismatic and fixed are)"
    )]
    UnsupportedJoint {
        /// The joint.
        joint: String,
        /// Its type.
        kind: &'static str,
    },
    /// A mimic joint (a constraint between coordinates, not a tree joint).
    #[error(
        "joint `{joint}`: mimic joints are not supported (it mimics `{mimics}`); make it fixed or free it"
    )]
    Mimic {
        /// The joint.
        joint: String,
        /// The joint it mimics.
        mimics: String,
    },
    /// The links and joints do not form one tree.
    #[error("not a tree: {0}")]
    NotATree(String),
}

impl UrdfError {
    /// The element the error names, as (tag, name): `("joint", "elbow")`.
    pub fn element(&self) -> Option<(&'static str, &str)> {
        match self {
            UrdfError::UnsupportedJoint { joint, .. } | UrdfError::Mimic { joint, .. } => {
                Some(("joint", joint.as_str()))
            }
            UrdfError::NonFinite { element } | UrdfError::Invalid { element, .. } => {
                let (tag, rest) = element.split_once(" `")?;
                let (name, _) = rest.split_once('`')?;
                let tag = match tag {
                    "joint" => "joint",
                    "link" => "link",
                    _ => return None,
                };
                Some((tag, name))
            }
            UrdfError::Parse(_) | UrdfError::NotATree(_) => None,
        }
    }

    /// The 1-based line of `text` (the document this error came from) that
    /// opens the element the error names, when it names one.
    pub fn line(&self, text: &str) -> Option<usize> {
        let (tag, name) = self.element()?;
        line_of(text, tag, name)
    }
}

/// The 1-based line on which `<tag … name="name" …>` opens in `text`.
pub fn line_of(text: &str, tag: &str, name: &str) -> Option<usize> {
    let open = format!("<{tag}");
    let mut from = 0;
    while let Some(i) = text[from..].find(&open) {
        let start = from + i;
        let after = start + open.len();
        from = after;
        // `<joint` and not `<jointx`
        if !text[after..].starts_with(|c: char| c.is_whitespace()) {
            continue;
        }
        let end = text[after..].find('>').map_or(text.len(), |e| after + e);
        let attrs = &text[after..end];
        if [format!("name=\"{name}\""), format!("name='{name}'")]
            .iter()
            .any(|a| attrs.contains(a.as_str()))
        {
            return Some(text[..start].matches('\n').count() + 1);
        }
    }
    None
}

fn finite(element: impl Fn() -> String, xs: &[f64]) -> Result<(), UrdfError> {
    if xs.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(UrdfError::NonFinite { element: element() })
    }
}

/// Mass, first moment and inertia about the body origin (body axes).
#[derive(Clone, Copy, Default)]
struct Accum {
    mass: f64,
    first: V3,
    rot: M3,
}

impl Accum {
    /// Adds a link with mass m, centre c and inertia ic about it (body axes).
    fn add(&mut self, m: f64, c: V3, ic: &M3) {
        let cc = dot(c, c);
        self.mass += m;
        self.first = add(self.first, scale(c, m));
        for i in 0..3 {
            for j in 0..3 {
                self.rot[i][j] += ic[i][j] + m * (if i == j { cc } else { 0.0 } - c[i] * c[j]);
            }
        }
    }

    fn finish(&self) -> MassProperties {
        if self.mass <= 0.0 {
            return MassProperties {
                mass: 0.0,
                com: [0.0; 3],
                inertia: self.rot,
            };
        }
        let c = scale(self.first, 1.0 / self.mass);
        let cc = dot(c, c);
        let mut ic = self.rot;
        for i in 0..3 {
            for j in 0..3 {
                ic[i][j] -= self.mass * (if i == j { cc } else { 0.0 } - c[i] * c[j]);
            }
        }
        // the parallel-axis shift leaves rounding asymmetry: symmetrise
        for (i, j) in [(1, 0), (2, 0), (2, 1)] {
            let s = 0.5 * (ic[i][j] + ic[j][i]);
            ic[i][j] = s;
            ic[j][i] = s;
        }
        MassProperties {
            mass: self.mass,
            com: c,
            inertia: ic,
        }
    }
}

fn pose(element: impl Fn() -> String, p: &urdf_rs::Pose) -> Result<(M3, V3), UrdfError> {
    finite(&element, &p.xyz.0)?;
    finite(&element, &p.rpy.0)?;
    Ok((rpy(p.rpy[0], p.rpy[1], p.rpy[2]), p.xyz.0))
}

/// Reads a URDF document (module docs).
pub fn parse(urdf: &str) -> Result<UrdfTree, UrdfError> {
    let r = urdf_rs::read_from_string(urdf).map_err(|e| {
        // urdf-rs's XML errors do not always say where (a badly nested
        // element does not): a second reader finds the line
        match xml_error_line(urdf) {
            Some(line) => UrdfError::Parse(format!("line {line}: {e}")),
            None => UrdfError::Parse(e.to_string()),
        }
    })?;
    from_robot(&r)
}

/// The 1-based line of the first XML error in `text` (mismatched or
/// unclosed tags, bad syntax), if a plain XML reader finds one.
pub fn xml_error_line(text: &str) -> Option<usize> {
    let mut reader = quick_xml::Reader::from_str(text);
    loop {
        match reader.read_event() {
            Ok(quick_xml::events::Event::Eof) => return None,
            Ok(_) => {}
            Err(_) => {
                let at = usize::try_from(reader.error_position())
                    .ok()?
                    .min(text.len());
                let at = (0..=at).rev().find(|&i| text.is_char_boundary(i))?;
                return Some(text[..at].matches('\n').count() + 1);
            }
        }
    }
}

/// Converts a parsed URDF robot (module docs).
pub fn from_robot(r: &urdf_rs::Robot) -> Result<UrdfTree, UrdfError> {
    let mut link_index = HashMap::new();
    for (i, l) in r.links.iter().enumerate() {
        if link_index.insert(l.name.as_str(), i).is_some() {
            return Err(UrdfError::NotATree(format!(
                "link `{}` is declared twice",
                l.name
            )));
        }
    }
    // link inertias in their own frames
    let mut link_inertia = Vec::with_capacity(r.links.len());
    for l in &r.links {
        let el = |what: &str| format!("link `{}` <inertial> {what}", l.name);
        let (ro, c) = pose(|| el("<origin>"), &l.inertial.origin)?;
        let m = l.inertial.mass.value;
        finite(|| el("<mass>"), &[m])?;
        if m < 0.0 {
            return Err(UrdfError::Invalid {
                element: el("<mass>"),
                why: "negative mass",
            });
        }
        let i = &l.inertial.inertia;
        let ii = [
            [i.ixx, i.ixy, i.ixz],
            [i.ixy, i.iyy, i.iyz],
            [i.ixz, i.iyz, i.izz],
        ];
        finite(
            || el("<inertia>"),
            &[i.ixx, i.ixy, i.ixz, i.iyy, i.iyz, i.izz],
        )?;
        if i.ixx < 0.0 || i.iyy < 0.0 || i.izz < 0.0 {
            return Err(UrdfError::Invalid {
                element: el("<inertia>"),
                why: "a negative principal moment (ixx, iyy, izz)",
            });
        }
        link_inertia.push((m, c, congruence(&ro, &ii)));
    }
    // the tree: children of each link, in file order
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); r.links.len()];
    let mut has_parent = vec![None::<&str>; r.links.len()];
    for j in &r.joints {
        let find = |name: &str| {
            link_index.get(name).copied().ok_or_else(|| {
                UrdfError::NotATree(format!("joint `{}` names an unknown link `{name}`", j.name))
            })
        };
        let (p, c) = (find(&j.parent.link)?, find(&j.child.link)?);
        if let Some(other) = has_parent[c] {
            return Err(UrdfError::NotATree(format!(
                "link `{}` is the child of both `{other}` and `{}`",
                j.child.link, j.name
            )));
        }
        has_parent[c] = Some(j.name.as_str());
        children[p].push(c);
    }
    let roots: Vec<usize> = (0..r.links.len())
        .filter(|&i| has_parent[i].is_none())
        .collect();
    let root = match roots.as_slice() {
        [root] => *root,
        [] => {
            return Err(UrdfError::NotATree(
                "no root link (a cycle of joints)".into(),
            ));
        }
        [a, b, ..] => {
            return Err(UrdfError::NotATree(format!(
                "links `{}` and `{}` both have no parent joint",
                r.links[*a].name, r.links[*b].name
            )));
        }
    };
    let joint_of_child: HashMap<usize, &urdf_rs::Joint> = r
        .joints
        .iter()
        .map(|j| (link_index[j.child.link.as_str()], j))
        .collect();

    let mut bodies = Vec::new();
    let mut joints = Vec::new();
    let mut links = Vec::new();
    let mut accum: Vec<Accum> = Vec::new();
    let mut base = Accum::default();
    // (link, body it is fixed to (None: the base), rotation and origin of
    // the link frame in that body's frame, and the body its movable joint
    // opens, numbered when the link is taken off the stack); depth first,
    // children in file order (pushed in reverse, so popped in order)
    type Entry = (usize, Option<usize>, M3, V3, Option<(Body, String)>);
    let mut stack: Vec<Entry> = vec![(root, None, IDENTITY, [0.0; 3], None)];
    let mut visited = 0usize;
    while let Some((link, mut body, mut rot, mut pos, opens)) = stack.pop() {
        visited += 1;
        if let Some((b, joint)) = opens {
            body = Some(bodies.len());
            (rot, pos) = (IDENTITY, [0.0; 3]);
            bodies.push(b);
            accum.push(Accum::default());
            joints.push(joint);
            links.push(r.links[link].name.clone());
        }
        let (m, c, ic) = link_inertia[link];
        let at = match body {
            Some(b) => &mut accum[b],
            None => &mut base,
        };
        at.add(m, add(pos, mul_mv(&rot, c)), &congruence(&rot, &ic));
        for &child in children[link].iter().rev() {
            let j = joint_of_child[&child];
            let el = |what: &str| format!("joint `{}` {what}", j.name);
            if let Some(m) = &j.mimic {
                return Err(UrdfError::Mimic {
                    joint: j.name.clone(),
                    mimics: m.joint.clone(),
                });
            }
            let (ro, xyz) = pose(|| el("<origin>"), &j.origin)?;
            let jrot = mul_mm(&rot, &ro);
            let jpos = add(pos, mul_mv(&rot, xyz));
            let unsupported = |kind| UrdfError::UnsupportedJoint {
                joint: j.name.clone(),
                kind,
            };
            let kind = match j.joint_type {
                urdf_rs::JointType::Fixed => {
                    stack.push((child, body, jrot, jpos, None));
                    continue;
                }
                urdf_rs::JointType::Revolute | urdf_rs::JointType::Continuous => {
                    JointKind::Revolute
                }
                urdf_rs::JointType::Prismatic => JointKind::Prismatic,
                urdf_rs::JointType::Floating => return Err(unsupported("floating")),
                urdf_rs::JointType::Planar => return Err(unsupported("planar")),
                urdf_rs::JointType::Spherical => return Err(unsupported("spherical")),
            };
            let a = j.axis.xyz.0;
            finite(|| el("<axis>"), &a)?;
            let n = dot(a, a).sqrt();
            if n < 1e-12 {
                return Err(UrdfError::Invalid {
                    element: el("<axis>"),
                    why: "zero axis",
                });
            }
            let damping = match &j.dynamics {
                Some(d) => {
                    finite(|| el("<dynamics>"), &[d.damping, d.friction])?;
                    if d.damping < 0.0 {
                        return Err(UrdfError::Invalid {
                            element: el("<dynamics>"),
                            why: "negative damping",
                        });
                    }
                    d.damping
                }
                None => 0.0,
            };
            let l = &j.limit;
            let limits = if j.joint_type == urdf_rs::JointType::Continuous {
                Limits {
                    lower: f64::NEG_INFINITY,
                    upper: f64::INFINITY,
                    ..limit_values(l)
                }
            } else {
                limit_values(l)
            };
            if [limits.lower, limits.upper, limits.effort, limits.velocity]
                .iter()
                .any(|x| x.is_nan())
            {
                return Err(UrdfError::NonFinite {
                    element: el("<limit>"),
                });
            }
            if limits.lower > limits.upper {
                return Err(UrdfError::Invalid {
                    element: el("<limit>"),
                    why: "lower > upper",
                });
            }
            let opens = Body {
                parent: body,
                joint: kind,
                axis: scale(a, 1.0 / n),
                rotation: jrot,
                translation: jpos,
                mass: 0.0,
                com: [0.0; 3],
                inertia: [[0.0; 3]; 3],
                damping,
                stiffness: 0.0,
                rest: 0.0,
                limits,
            };
            stack.push((child, body, jrot, jpos, Some((opens, j.name.clone()))));
        }
    }
    if visited != r.links.len() {
        return Err(UrdfError::NotATree(
            "some links are not reached from the root".into(),
        ));
    }
    for (b, a) in bodies.iter_mut().zip(&accum) {
        let p = a.finish();
        b.mass = p.mass;
        b.com = p.com;
        b.inertia = p.inertia;
    }
    Ok(UrdfTree {
        name: r.name.clone(),
        bodies,
        joints,
        links,
        root: r.links[root].name.clone(),
        base: base.finish(),
    })
}

/// The limits of a `<limit>` element. The parser gives an absent element
/// as all zeros (lower = upper = effort = velocity = 0, which no moving
/// joint can mean): that reads as no limits.
fn limit_values(l: &urdf_rs::JointLimit) -> Limits {
    if l.lower == 0.0 && l.upper == 0.0 && l.effort == 0.0 && l.velocity == 0.0 {
        return Limits::NONE;
    }
    Limits {
        lower: l.lower,
        upper: l.upper,
        effort: l.effort,
        velocity: l.velocity,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ARM: &str = r#"<robot name="arm">
  <link name="base"><inertial><mass value="3"/>
    <inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <link name="a"><inertial><origin xyz="0.1 0 0"/><mass value="1"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>
  <link name="tip"><inertial><mass value="1"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <joint name="hinge" type="revolute">
    <parent link="base"/><child link="a"/><axis xyz="0 0 2"/>
    <limit lower="-1" upper="1" effort="5" velocity="2"/>
  </joint>
  <joint
     name='weld' type="fixed">
    <parent link="a"/><child link="tip"/><origin xyz="0.3 0 0"/>
  </joint>
</robot>"#;

    #[test]
    fn fixed_children_merge_and_the_base_is_kept() {
        let t = parse(ARM).unwrap();
        assert_eq!(
            (t.joints.as_slice(), t.root.as_str()),
            (&["hinge".to_string()][..], "base")
        );
        let b = &t.bodies[0];
        assert_eq!(b.axis, [0.0, 0.0, 1.0]);
        // two unit masses at x = 0.1 and x = 0.3: centre 0.2, and the
        // parallel-axis terms 2·0.1² about z and y
        assert_eq!(b.mass, 2.0);
        assert!((b.com[0] - 0.2).abs() < 1e-15);
        assert!((b.inertia[2][2] - (0.02 + 0.01 + 0.02)).abs() < 1e-15);
        assert!((b.inertia[0][0] - 0.02).abs() < 1e-15);
        assert_eq!(b.limits.upper, 1.0);
        assert_eq!(t.base.mass, 3.0);
    }

    #[test]
    fn errors_name_their_element_and_its_line() {
        let mimic = ARM.replace(
            "<parent link=\"a\"/>",
            "<parent link=\"a\"/><mimic joint=\"hinge\"/>",
        );
        let mimic = mimic.replace("type=\"fixed\"", "type=\"revolute\"");
        let e = parse(&mimic).unwrap_err();
        assert_eq!(e.element(), Some(("joint", "weld")));
        // `<joint` of `weld` opens on line 12 (its name on the next)
        assert_eq!(e.line(&mimic), Some(12));
        let bad = ARM.replace("ixx=\"0.01\" ixy", "ixx=\"-0.01\" ixy");
        let e = parse(&bad).unwrap_err();
        assert_eq!(e.element(), Some(("link", "a")));
        assert_eq!(e.line(&bad), Some(4));
        assert!(matches!(parse("<robot"), Err(UrdfError::Parse(_))));
        // a badly nested element: the line of the mismatched end tag
        let nested = ARM.replace("<parent link=\"a\"/>", "<parent link=\"a\">");
        let e = parse(&nested).unwrap_err();
        assert!(e.to_string().contains("line 15:"), "{e}");
    }
}
