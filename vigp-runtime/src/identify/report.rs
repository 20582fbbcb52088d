//! The identification table: parameter, declared, identified, ±95 %, and
//! whether the data identify it.
//!
//! Three sections: the base parameters (the combinations the data
//! determine; a base parameter whose posterior variance is not below half
//! its prior variance is marked uninformed: its value is the prior's); the
//! standard parameters that are not identifiable by themselves (their
//! value comes from the prior through the combinations they enter); and
//! the parameters in the DSL's own names (mass, centre of mass, inertia
//! about the centre of mass, damping, stiffness, rest), identifiable when
//! every standard parameter they derive from is.
//!
//! The DSL section has one row for every parameter that the
//! identification sets, under the mechanism's own parameter name: a 3-D
//! inertia's nine entries included. Its lower entries (`inertia.yx`,
//! `.zx`, `.zy`) are the upper ones again (the tensor is symmetric): their
//! rows carry the value and status of the upper entry and name it in
//! [`Row::mirror_of`]. A tool writes the DSL section as it is.

use super::Identification;
use super::regressor::{BodySlots, SYM, Structure};
use std::fmt;

/// Whether the data determine a row of the table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    /// Identifiable and informed by the data.
    Identified,
    /// Identifiable in principle, but this log hardly informs it: the
    /// value is essentially the prior's.
    Uninformed,
    /// Not identifiable from this log: no data can tell it apart from
    /// other parameters (it enters only through base combinations).
    NotIdentifiable,
}

impl fmt::Display for Status {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Status::Identified => "identified",
            Status::Uninformed => "uninformed (prior)",
            Status::NotIdentifiable => "not identifiable",
        })
    }
}

/// One row of the table.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// The parameter (a standard name, a combination, or a DSL name).
    pub parameter: String,
    /// Its declared value.
    pub declared: f64,
    /// Its identified value.
    pub identified: f64,
    /// Half-width of its 95 % interval (base parameters only).
    pub half_width: Option<f64>,
    /// Whether the data determine it.
    pub status: Status,
    /// For a 3-D inertia's lower entry (`links.<l>.inertia.yx`, `.zx`,
    /// `.zy`): the upper entry it mirrors, whose value and status it
    /// carries.
    pub mirror_of: Option<String>,
}

/// The table of an [`Identification`] (printable).
#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    /// Base parameters.
    pub base: Vec<Row>,
    /// Standard parameters not identifiable by themselves.
    pub unidentifiable: Vec<Row>,
    /// The DSL's parameters: one row per parameter of the mechanism that
    /// the identification sets, in the layout's order (module docs).
    pub dsl: Vec<Row>,
    /// Links whose unconstrained estimate was not physically realisable,
    /// and joint dampings and stiffnesses (standard names) whose
    /// unconstrained estimate was negative: the estimate was projected.
    pub projected: Vec<String>,
}

impl Report {
    /// Names of the rows (all sections) whose status is not
    /// [`Status::Identified`].
    pub fn uninformed(&self) -> Vec<&str> {
        self.base
            .iter()
            .chain(&self.unidentifiable)
            .chain(&self.dsl)
            .filter(|r| r.status != Status::Identified)
            .map(|r| r.parameter.as_str())
            .collect()
    }
}

/// The axis letters of a 3-D inertia's entries.
const AXES: [char; 3] = ['x', 'y', 'z'];

/// The offset in π of the first joint parameter: past the last body's
/// block (`offsets` those of [`Structure::body_offsets`]).
fn joints_start(s: &Structure, offsets: &[usize]) -> usize {
    offsets
        .last()
        .map(|o| o + s.bodies.last().map_or(0, |b| b.len()))
        .unwrap_or(0)
}

pub(crate) fn build(id: &Identification) -> Report {
    let s = &id.structure;
    let base = (0..id.base.rank())
        .map(|i| Row {
            parameter: id.base_names[i].clone(),
            declared: id.base_declared[i],
            identified: id.base_estimate[i],
            half_width: Some(id.base_half_width[i]),
            status: if id.base_informed[i] {
                Status::Identified
            } else {
                Status::Uninformed
            },
            mirror_of: None,
        })
        .collect();
    let ident = id.standard_identifiable();
    let unidentifiable = (0..s.len())
        .filter(|i| !ident[*i])
        .map(|i| Row {
            parameter: s.names[i].clone(),
            declared: id.declared[i],
            identified: id.estimate[i],
            half_width: None,
            status: Status::NotIdentifiable,
            mirror_of: None,
        })
        .collect();
    // A standard parameter counts as identified when identifiable and
    // every base parameter it enters is informed.
    let informed = |i: usize| {
        ident[i] && (0..id.base.rank()).all(|b| id.base.k[(b, i)] == 0.0 || id.base_informed[b])
    };
    let status = |idx: &[usize]| {
        if idx.iter().all(|i| informed(*i)) {
            Status::Identified
        } else if idx.iter().all(|i| ident[*i]) {
            Status::Uninformed
        } else {
            Status::NotIdentifiable
        }
    };
    let dsl_of = |pi: &[f64]| -> Vec<(String, f64)> {
        let mut out = Vec::new();
        let offsets = s.body_offsets();
        for (b, o) in s.bodies.iter().zip(&offsets) {
            let l = b.name();
            let m = pi[*o];
            out.push((format!("links.{l}.mass"), m));
            match b {
                BodySlots::Planar { .. } => {
                    let c = [pi[o + 1] / m, pi[o + 2] / m];
                    out.push((format!("links.{l}.com.x"), c[0]));
                    out.push((format!("links.{l}.com.y"), c[1]));
                    out.push((
                        format!("links.{l}.inertia"),
                        pi[o + 3] - m * (c[0] * c[0] + c[1] * c[1]),
                    ));
                }
                BodySlots::Spatial { .. } => {
                    let c = [pi[o + 1] / m, pi[o + 2] / m, pi[o + 3] / m];
                    for (a, v) in ["x", "y", "z"].iter().zip(c) {
                        out.push((format!("links.{l}.com.{a}"), v));
                    }
                    let cc = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
                    // the nine entries row by row, each lower one the
                    // value of its upper mirror
                    for (r, t) in (0..3).flat_map(|r| (0..3).map(move |t| (r, t))) {
                        let k = SYM
                            .iter()
                            .position(|x| *x == (r.min(t), r.max(t)))
                            .unwrap_or(0);
                        let d = if r == t { cc } else { 0.0 };
                        out.push((
                            format!("links.{l}.inertia.{}{}", AXES[r], AXES[t]),
                            pi[o + 4 + k] - m * (d - c[r] * c[t]),
                        ));
                    }
                }
            }
        }
        let mut at = joints_start(s, &offsets);
        for j in &s.joints {
            if j.damping.is_some() {
                out.push((format!("joints.{}.damping", j.name), pi[at]));
                at += 1;
            }
            if j.spring.is_some() {
                out.push((format!("joints.{}.stiffness", j.name), pi[at]));
                out.push((format!("joints.{}.rest", j.name), pi[at + 1] / pi[at]));
                at += 2;
            }
        }
        out
    };
    // Which standard entries each DSL value derives from.
    let mut deps: Vec<Vec<usize>> = Vec::new();
    let mut mirrors: Vec<Option<String>> = Vec::new();
    let offsets = s.body_offsets();
    for (b, o) in s.bodies.iter().zip(&offsets) {
        deps.push(vec![*o]);
        mirrors.push(None);
        let (h, inertia) = match b {
            BodySlots::Planar { .. } => (2, 1),
            BodySlots::Spatial { .. } => (3, 9),
        };
        for a in 0..h {
            deps.push(vec![*o, o + 1 + a]);
            mirrors.push(None);
        }
        for e in 0..inertia {
            deps.push((*o..o + b.len()).collect());
            // a lower entry (row r > column t) mirrors (t, r)
            let (r, t) = (e / 3, e % 3);
            mirrors.push(
                (inertia == 9 && r > t)
                    .then(|| format!("links.{}.inertia.{}{}", b.name(), AXES[t], AXES[r])),
            );
        }
    }
    let mut at = joints_start(s, &offsets);
    for j in &s.joints {
        if j.damping.is_some() {
            deps.push(vec![at]);
            mirrors.push(None);
            at += 1;
        }
        if j.spring.is_some() {
            deps.push(vec![at]);
            deps.push(vec![at, at + 1]);
            mirrors.extend([None, None]);
            at += 2;
        }
    }
    let declared = dsl_of(&id.declared);
    let identified = dsl_of(&id.estimate);
    let dsl = declared
        .into_iter()
        .zip(identified)
        .zip(deps.iter().zip(mirrors))
        .map(|(((name, d), (_, v)), (dep, mirror_of))| Row {
            parameter: name,
            declared: d,
            identified: v,
            half_width: None,
            status: status(dep),
            mirror_of,
        })
        .collect();
    Report {
        base,
        unidentifiable,
        dsl,
        projected: id
            .projected
            .iter()
            .map(|b| s.bodies[*b].name().to_string())
            .chain(id.projected_joints.iter().map(|i| s.names[*i].clone()))
            .collect(),
    }
}

impl fmt::Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let width = self
            .base
            .iter()
            .chain(&self.unidentifiable)
            .chain(&self.dsl)
            .map(|r| r.parameter.chars().count())
            .max()
            .unwrap_or(9)
            .max(9);
        let row = |f: &mut fmt::Formatter<'_>, r: &Row| {
            let hw = r
                .half_width
                .map_or_else(|| "—".to_string(), |h| format!("{h:.3e}"));
            let status = match &r.mirror_of {
                Some(m) => format!("{} (mirror of {m})", r.status),
                None => r.status.to_string(),
            };
            writeln!(
                f,
                "{:<width$}  {:>13.6e}  {:>13.6e}  {:>10}  {status}",
                r.parameter, r.declared, r.identified, hw
            )
        };
        let header = |f: &mut fmt::Formatter<'_>, title: &str| {
            writeln!(f, "{title}")?;
            writeln!(
                f,
                "{:<width$}  {:>13}  {:>13}  {:>10}  status",
                "parameter", "declared", "identified", "±95 %"
            )
        };
        header(f, "base parameters (identifiable combinations)")?;
        for r in &self.base {
            row(f, r)?;
        }
        if !self.unidentifiable.is_empty() {
            writeln!(f)?;
            header(
                f,
                "standard parameters not identifiable by themselves (value from the prior)",
            )?;
            for r in &self.unidentifiable {
                row(f, r)?;
            }
        }
        writeln!(f)?;
        header(f, "in the mechanism's own parameters")?;
        for r in &self.dsl {
            row(f, r)?;
        }
        if !self.projected.is_empty() {
            writeln!(
                f,
                "\nprojected onto physically consistent parameters: {}",
                self.projected.join(", ")
            )?;
        }
        Ok(())
    }
}
