//! The discrete regressor: the DEL residual of one transition
//! (x_{k−1}, x_k, x_{k+1}) written as Y·π − b, with π the standard
//! parameters of every body and joint.
//!
//! # Standard parameters
//!
//! Per link, in declaration order:
//!
//! * planar: `mass` m, first moments `mcom.x`, `mcom.y` (m·c, c the centre
//!   of mass in the link frame) and `inertia_o`, the inertia about the link
//!   frame's origin I_O = I_c + m|c|²;
//! * spatial: `mass`, `mcom.x`, `.y`, `.z`, and the six entries
//!   `inertia_o.xx`, `.xy`, `.xz`, `.yy`, `.yz`, `.zz` of the inertia tensor
//!   about the frame origin, I_O = I_c + m(|c|²·1 − c cᵀ), in the link frame.
//!
//! then per joint that declares them: `damping` c, `stiffness` k and
//! `stiffness_rest` k·s₀ (the spring's potential ½k(s − s₀)² is
//! ½k s² − k s₀ s + const, affine in (k, k s₀)). Lengths and gravity are
//! not parameters: they shape the kinematics, where the residual is not
//! linear in them.
//!
//! # The generic route
//!
//! The Lagrangian is linear in (m, m·c, I_O) of each body and the Rayleigh
//! function in c, so the DEL residual is affine in π. [`DelRegressor`]
//! obtains Y column by column from the residual of the mechanism itself,
//! evaluated at a base point π₀ and at π₀ + s_i·e_i (π converted to the
//! DSL's names through [`Parameters`]): column i = (r(π₀ + s_i e_i) − r(π₀))/s_i,
//! exact to rounding because r is affine, and b = Y·π₀ − r(π₀). Any other
//! source of rows (a recursive engine with the parameters pulled out)
//! implements [`Regressor`] with the same layout ([`Structure`]).
//!
//! # Loops
//!
//! The residual of a mechanism with loop constraints carries −G(x_k)ᵀλ
//! with unknown multipliers λ. The rows are projected onto the null space
//! of G(x_k) (an orthonormal basis Z with G Z = 0, from the eigenvectors of
//! GᵀG): Zᵀ·(−Gᵀλ) = 0, so the projected residual Zᵀr does not involve λ,
//! and a transition gives N − C rows. The multipliers are not estimated.

use super::{IdentifyError, check_finite_vector, check_length, check_time_step};
use crate::del;
use crate::mechanism::{Mechanism, Scalar};
use nalgebra::{Const, DMatrix, DVector, SVector};
use num_dual::DualVec;
use vigp_core::Parameters;

/// Where one body's parameters live among the DSL's named parameters
/// ([`Parameters::PARAMETER_NAMES`] indices).
#[derive(Clone, Debug, PartialEq)]
pub enum BodySlots {
    /// A planar link: `mass`, `com.x`, `com.y`, scalar `inertia`.
    Planar {
        /// The link's name.
        name: String,
        /// Index of `links.<l>.mass`.
        mass: usize,
        /// Indices of `links.<l>.com.x`, `.y`.
        com: [usize; 2],
        /// Index of `links.<l>.inertia` (about the centre of mass).
        inertia: usize,
        /// Index of `links.<l>.length`, if any (a length scale for priors).
        length: Option<usize>,
    },
    /// A spatial link: `mass`, `com.x/y/z`, the nine `inertia.<rc>` entries.
    Spatial {
        /// The link's name.
        name: String,
        /// Index of `links.<l>.mass`.
        mass: usize,
        /// Indices of `links.<l>.com.x`, `.y`, `.z`.
        com: [usize; 3],
        /// Indices of `links.<l>.inertia.xx`, `.xy`, …, `.zz` (row by row).
        inertia: [usize; 9],
        /// Index of `links.<l>.length`, if any.
        length: Option<usize>,
    },
}

impl BodySlots {
    /// The link's name.
    pub fn name(&self) -> &str {
        match self {
            BodySlots::Planar { name, .. } | BodySlots::Spatial { name, .. } => name,
        }
    }

    /// Number of standard parameters of this body (4 planar, 10 spatial).
    pub fn len(&self) -> usize {
        match self {
            BodySlots::Planar { .. } => 4,
            BodySlots::Spatial { .. } => 10,
        }
    }

    /// Always false: a body has 4 or 10 standard parameters.
    pub fn is_empty(&self) -> bool {
        false
    }
}

/// Where one joint's parameters live among the DSL's named parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct JointSlots {
    /// The joint's name.
    pub name: String,
    /// Index of `joints.<j>.damping`, if the mechanism has damping.
    pub damping: Option<usize>,
    /// Indices of `joints.<j>.stiffness` and `.rest`, if it has springs.
    pub spring: Option<(usize, usize)>,
}

/// The layout of the standard parameter vector π of a mechanism (module
/// docs): its bodies, then its joints, and the names of π's entries.
#[derive(Clone, Debug, PartialEq)]
pub struct Structure {
    /// The bodies, in declaration order.
    pub bodies: Vec<BodySlots>,
    /// The joints with damping or springs, in declaration order.
    pub joints: Vec<JointSlots>,
    /// Names of π's entries (`links.<l>.mass`, `links.<l>.mcom.x`, …,
    /// `joints.<j>.damping`, …).
    pub names: Vec<String>,
}

/// What one entry of π is (for priors and scales).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParameterKind {
    /// A body's mass.
    Mass,
    /// A body's first moment m·c (one component).
    FirstMoment,
    /// An entry of a body's inertia about its frame origin.
    Inertia,
    /// A joint's viscous damping.
    Damping,
    /// A joint's spring stiffness.
    Stiffness,
    /// A joint's stiffness times its rest coordinate.
    StiffnessRest,
}

impl Structure {
    /// The layout read off a mechanism's parameter names (the order
    /// documented on [`Parameters`]).
    pub fn of<P: Parameters>() -> Result<Self, IdentifyError> {
        Self::from_names(P::PARAMETER_NAMES)
    }

    /// The layout read off a list of parameter names.
    pub fn from_names(all: &[&str]) -> Result<Self, IdentifyError> {
        let find = |n: &str| all.iter().position(|x| *x == n);
        let need = |n: String| {
            find(&n).ok_or_else(|| IdentifyError::Layout {
                message: format!("parameter `{n}` is missing"),
            })
        };
        let mut bodies = Vec::new();
        let mut joints: Vec<JointSlots> = Vec::new();
        for n in all {
            if let Some(l) = n
                .strip_prefix("links.")
                .and_then(|s| s.strip_suffix(".mass"))
            {
                let mass = need(format!("links.{l}.mass"))?;
                let length = find(&format!("links.{l}.length"));
                if let Some(inertia) = find(&format!("links.{l}.inertia")) {
                    let com = [
                        need(format!("links.{l}.com.x"))?,
                        need(format!("links.{l}.com.y"))?,
                    ];
                    bodies.push(BodySlots::Planar {
                        name: l.to_string(),
                        mass,
                        com,
                        inertia,
                        length,
                    });
                } else {
                    let com = [
                        need(format!("links.{l}.com.x"))?,
                        need(format!("links.{l}.com.y"))?,
                        need(format!("links.{l}.com.z"))?,
                    ];
                    let mut inertia = [0; 9];
                    for (k, rc) in ["xx", "xy", "xz", "yx", "yy", "yz", "zx", "zy", "zz"]
                        .iter()
                        .enumerate()
                    {
                        inertia[k] = need(format!("links.{l}.inertia.{rc}"))?;
                    }
                    bodies.push(BodySlots::Spatial {
                        name: l.to_string(),
                        mass,
                        com,
                        inertia,
                        length,
                    });
                }
            } else if let Some(rest) = n.strip_prefix("joints.") {
                let Some((j, field)) = rest.rsplit_once('.') else {
                    continue;
                };
                let slot = match joints.iter().position(|s| s.name == j) {
                    Some(i) => i,
                    None => {
                        joints.push(JointSlots {
                            name: j.to_string(),
                            damping: None,
                            spring: None,
                        });
                        joints.len() - 1
                    }
                };
                match field {
                    "damping" => joints[slot].damping = find(n),
                    "stiffness" => {
                        let k = need(format!("joints.{j}.stiffness"))?;
                        let r = need(format!("joints.{j}.rest"))?;
                        joints[slot].spring = Some((k, r));
                    }
                    _ => {}
                }
            }
        }
        if bodies.is_empty() {
            return Err(IdentifyError::Layout {
                message: "the mechanism has no link parameters".into(),
            });
        }
        let mut names = Vec::new();
        for b in &bodies {
            let l = b.name();
            names.push(format!("links.{l}.mass"));
            match b {
                BodySlots::Planar { .. } => {
                    names.push(format!("links.{l}.mcom.x"));
                    names.push(format!("links.{l}.mcom.y"));
                    names.push(format!("links.{l}.inertia_o"));
                }
                BodySlots::Spatial { .. } => {
                    for a in ["x", "y", "z"] {
                        names.push(format!("links.{l}.mcom.{a}"));
                    }
                    for a in ["xx", "xy", "xz", "yy", "yz", "zz"] {
                        names.push(format!("links.{l}.inertia_o.{a}"));
                    }
                }
            }
        }
        for j in &joints {
            if j.damping.is_some() {
                names.push(format!("joints.{}.damping", j.name));
            }
            if j.spring.is_some() {
                names.push(format!("joints.{}.stiffness", j.name));
                names.push(format!("joints.{}.stiffness_rest", j.name));
            }
        }
        Ok(Structure {
            bodies,
            joints,
            names,
        })
    }

    /// Number of standard parameters.
    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// True if π is empty (never, for a structure built by [`Structure::of`]).
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// The kind of every entry of π, in order.
    pub fn kinds(&self) -> Vec<ParameterKind> {
        let mut out = Vec::with_capacity(self.len());
        for b in &self.bodies {
            out.push(ParameterKind::Mass);
            let (h, i) = match b {
                BodySlots::Planar { .. } => (2, 1),
                BodySlots::Spatial { .. } => (3, 6),
            };
            out.extend(std::iter::repeat_n(ParameterKind::FirstMoment, h));
            out.extend(std::iter::repeat_n(ParameterKind::Inertia, i));
        }
        for j in &self.joints {
            if j.damping.is_some() {
                out.push(ParameterKind::Damping);
            }
            if j.spring.is_some() {
                out.push(ParameterKind::Stiffness);
                out.push(ParameterKind::StiffnessRest);
            }
        }
        out
    }

    /// The offset of each body's block in π.
    pub fn body_offsets(&self) -> Vec<usize> {
        let mut o = 0;
        self.bodies
            .iter()
            .map(|b| {
                let at = o;
                o += b.len();
                at
            })
            .collect()
    }

    /// π of a parameter set given by value lookup `get(index)`.
    pub fn standard(&self, get: impl Fn(usize) -> f64) -> Vec<f64> {
        let mut pi = Vec::with_capacity(self.len());
        for b in &self.bodies {
            match b {
                BodySlots::Planar {
                    mass, com, inertia, ..
                } => {
                    let m = get(*mass);
                    let c = [get(com[0]), get(com[1])];
                    pi.extend([
                        m,
                        m * c[0],
                        m * c[1],
                        get(*inertia) + m * (c[0] * c[0] + c[1] * c[1]),
                    ]);
                }
                BodySlots::Spatial {
                    mass, com, inertia, ..
                } => {
                    let m = get(*mass);
                    let c = [get(com[0]), get(com[1]), get(com[2])];
                    let ic = |r: usize, s: usize| {
                        0.5 * (get(inertia[3 * r + s]) + get(inertia[3 * s + r]))
                    };
                    let cc = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
                    pi.extend([m, m * c[0], m * c[1], m * c[2]]);
                    for (r, s) in SYM {
                        let delta = if r == s { cc } else { 0.0 };
                        pi.push(ic(r, s) + m * (delta - c[r] * c[s]));
                    }
                }
            }
        }
        for j in &self.joints {
            if let Some(d) = j.damping {
                pi.push(get(d));
            }
            if let Some((k, r)) = j.spring {
                pi.extend([get(k), get(k) * get(r)]);
            }
        }
        pi
    }

    /// Write π into a parameter set through `set(index, value)` (the DSL's
    /// names: mass, centre of mass c = (m·c)/m, inertia about the centre
    /// I_c = I_O − m(|c|²·1 − c cᵀ), rest = (k·s₀)/k). A zero mass or, for
    /// a joint with k·s₀ ≠ 0, a zero stiffness has no DSL form: an error.
    pub fn set_standard(
        &self,
        pi: &[f64],
        mut set: impl FnMut(usize, f64),
    ) -> Result<(), IdentifyError> {
        check_length("standard parameters", self.len(), pi.len())?;
        if let Some(i) = pi.iter().position(|x| !x.is_finite()) {
            return Err(IdentifyError::NonFinite {
                what: format!("standard parameter `{}`", self.names[i]),
            });
        }
        let mut at = 0;
        for b in &self.bodies {
            let m = pi[at];
            if m == 0.0 {
                return Err(IdentifyError::NoDslForm {
                    parameter: self.names[at].clone(),
                });
            }
            match b {
                BodySlots::Planar {
                    mass, com, inertia, ..
                } => {
                    let c = [pi[at + 1] / m, pi[at + 2] / m];
                    set(*mass, m);
                    set(com[0], c[0]);
                    set(com[1], c[1]);
                    set(*inertia, pi[at + 3] - m * (c[0] * c[0] + c[1] * c[1]));
                }
                BodySlots::Spatial {
                    mass, com, inertia, ..
                } => {
                    let c = [pi[at + 1] / m, pi[at + 2] / m, pi[at + 3] / m];
                    let cc = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
                    set(*mass, m);
                    for a in 0..3 {
                        set(com[a], c[a]);
                    }
                    for (k, (r, s)) in SYM.iter().enumerate() {
                        let delta = if r == s { cc } else { 0.0 };
                        let v = pi[at + 4 + k] - m * (delta - c[*r] * c[*s]);
                        set(inertia[3 * r + s], v);
                        set(inertia[3 * s + r], v);
                    }
                }
            }
            at += b.len();
        }
        for j in &self.joints {
            if let Some(d) = j.damping {
                set(d, pi[at]);
                at += 1;
            }
            if let Some((k, r)) = j.spring {
                let (kk, kr) = (pi[at], pi[at + 1]);
                set(k, kk);
                if kk != 0.0 {
                    set(r, kr / kk);
                } else if kr != 0.0 {
                    return Err(IdentifyError::NoDslForm {
                        parameter: self.names[at + 1].clone(),
                    });
                }
                at += 2;
            }
        }
        Ok(())
    }
}

/// The upper-triangle entries (r, s) of a symmetric 3 × 3 matrix, in the
/// order of the `inertia_o` parameters: xx, xy, xz, yy, yz, zz.
pub(crate) const SYM: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

/// One transition of a log: three consecutive positions and the inputs
/// held over the interval before (u_{k−1}, over [t_{k−1}, t_k]) and after
/// (u_k, over [t_k, t_{k+1}]) the middle sample. Empty input slices mean
/// no input.
#[derive(Clone, Copy, Debug)]
pub struct Transition<'a> {
    /// x_{k−1}, x_k, x_{k+1}.
    pub positions: [&'a [f64]; 3],
    /// u_{k−1}, u_k.
    pub inputs: [&'a [f64]; 2],
}

/// A source of regressor rows: the DEL residual of one transition as
/// Y·π − b, with π laid out as [`Structure`] says.
///
/// The generic implementation is [`DelRegressor`]; another engine (a
/// recursive pass with the parameters pulled out) plugs in by implementing
/// this trait with the same layout.
pub trait Regressor {
    /// The layout of π.
    fn structure(&self) -> &Structure;

    /// Number of generalized coordinates per sample.
    fn coordinates(&self) -> usize;

    /// Number of inputs per sample (0 for an unactuated mechanism).
    fn inputs(&self) -> usize;

    /// Rows per transition (coordinates minus loop equations).
    fn rows(&self) -> usize;

    /// π of the mechanism this regressor holds (its declared values).
    fn standard(&self) -> Vec<f64>;

    /// The (projected, multiplier-free) residual of a transition with the
    /// parameters π: equal to Y·π − b to rounding.
    fn residual(&self, t: &Transition<'_>, pi: &[f64]) -> Result<DVector<f64>, IdentifyError>;

    /// The rows (Y, b) of one transition: residual = Y·π − b for every π.
    fn transition(&self, t: &Transition<'_>)
    -> Result<(DMatrix<f64>, DVector<f64>), IdentifyError>;

    /// ∂(residual)/∂(x_{k−1}, x_k, x_{k+1}) at parameters π (rows × 3N):
    /// how position noise enters the residual, for the covariance
    /// ([`super::covariance`]). For a loop, the multipliers are held at
    /// their least-squares value λ̂ = (G Gᵀ)⁻¹G·r and the projection at
    /// x_k's: d(Zᵀr) = Zᵀ(dr − dGᵀλ) there, since ZᵀGᵀ = 0.
    fn noise_jacobian(&self, t: &Transition<'_>, pi: &[f64])
    -> Result<DMatrix<f64>, IdentifyError>;

    /// The residual at parameters π, before any projection (N rows: for a
    /// mechanism with loops the DEL residual without its multiplier term
    /// −G(x_k)ᵀλ), and its exact Jacobians with respect to x_{k−1}, x_k and
    /// x_{k+1} (each N × N): what a simulation with the parameters π needs
    /// (x_{k+1} solves residual = G(x_k)ᵀλ, g(x_{k+1}) = 0) and its
    /// derivatives by the implicit function theorem
    /// ([`super::output_error`]). The default, for a source of rows that
    /// cannot simulate, says so with [`IdentifyError::Layout`] (the
    /// regression needs none of it).
    #[allow(clippy::type_complexity)]
    fn position_jacobians(
        &self,
        t: &Transition<'_>,
        pi: &[f64],
    ) -> Result<(DVector<f64>, [DMatrix<f64>; 3]), IdentifyError> {
        let _ = (t, pi);
        Err(IdentifyError::Layout {
            message: "this regressor gives no position Jacobians, which output error needs".into(),
        })
    }

    /// The rows of [`Regressor::position_jacobians`]' residual, before any
    /// projection (N × P and N: residual = Y·π − b). Equal to
    /// [`Regressor::transition`] without loops (the default).
    fn unprojected_transition(
        &self,
        t: &Transition<'_>,
    ) -> Result<(DMatrix<f64>, DVector<f64>), IdentifyError> {
        self.transition(t)
    }

    /// The loop constraints at the configuration `x`: g(x) (C entries) and
    /// G(x) = ∂g/∂x (C × N); `None` for a mechanism without loops (the
    /// default).
    #[allow(clippy::type_complexity)]
    fn loop_constraints(
        &self,
        x: &[f64],
    ) -> Result<Option<(DVector<f64>, DMatrix<f64>)>, IdentifyError> {
        let _ = x;
        Ok(None)
    }

    /// Σ λ_i ∇²g_i(x) (N × N), the derivative of G(x)ᵀλ in x, for the
    /// sensitivities of a simulation with loops. The default (no loops):
    /// [`IdentifyError::Layout`].
    fn loop_curvature(&self, x: &[f64], lambda: &[f64]) -> Result<DMatrix<f64>, IdentifyError> {
        let _ = (x, lambda);
        Err(IdentifyError::Layout {
            message: "this regressor has no loop constraints".into(),
        })
    }
}

/// The rows (Y, b), or [`IdentifyError::NonFinite`] when an entry is NaN
/// or ∞.
pub(super) fn finite_rows(
    (y, b): (DMatrix<f64>, DVector<f64>),
) -> Result<(DMatrix<f64>, DVector<f64>), IdentifyError> {
    if y.iter().chain(b.iter()).any(|v| !v.is_finite()) {
        return Err(IdentifyError::NonFinite {
            what: "regressor rows".into(),
        });
    }
    Ok((y, b))
}

/// Central differences of a transition's residual in its 3N positions
/// (columns x_{k−1}, x_k, x_{k+1}), step 1e-6·(1 + |x|): truncation ≈ 1e-12
/// relative, rounding ≈ 1e-10; ample for a covariance
/// ([`Regressor::noise_jacobian`]). `residual(s, c, d)` is the residual
/// with coordinate c of sample s moved by d.
pub(crate) fn position_differences(
    positions: [&[f64]; 3],
    mut residual: impl FnMut(usize, usize, f64) -> Result<DVector<f64>, IdentifyError>,
) -> Result<DMatrix<f64>, IdentifyError> {
    let n = positions[0].len();
    let mut jac = DMatrix::zeros(0, 3 * n);
    for (s, x) in positions.iter().enumerate() {
        for c in 0..n {
            let h = 1e-6 * (1.0 + x[c].abs());
            let d = (residual(s, c, h)? - residual(s, c, -h)?) / (2.0 * h);
            if jac.nrows() != d.len() {
                jac = DMatrix::zeros(d.len(), 3 * n);
            }
            jac.set_column(s * n + c, &d);
        }
    }
    Ok(jac)
}

/// The regressor of the DEL residual of a mechanism (module docs), for the
/// first-order (α = 0) or the midpoint (α = ½) rule, obtained from the
/// residual itself through the mechanism's [`Parameters`].
#[derive(Clone, Debug)]
pub struct DelRegressor<M, const N: usize, const C: usize> {
    model: M,
    dt: f64,
    alpha: f64,
    structure: Structure,
    base: Vec<f64>,
    steps: Vec<f64>,
}

impl<M, const N: usize, const C: usize> DelRegressor<M, N, C>
where
    M: Mechanism<N, C> + Parameters + Copy,
{
    /// The regressor of the paper's first-order rule ([`crate::Variational::new`]).
    pub fn first_order(model: M, dt: f64) -> Result<Self, IdentifyError> {
        Self::new(model, dt, 0.0)
    }

    /// The regressor of the midpoint rule ([`crate::Variational::midpoint`]).
    pub fn midpoint(model: M, dt: f64) -> Result<Self, IdentifyError> {
        Self::new(model, dt, 0.5)
    }

    /// The regressor of the DEL residual with quadrature weight `alpha`
    /// ([`crate::del`]): 0 or ½.
    pub fn new(model: M, dt: f64, alpha: f64) -> Result<Self, IdentifyError> {
        check_time_step(dt)?;
        if !(alpha == 0.0 || alpha == 0.5) {
            return Err(IdentifyError::Layout {
                message: format!(
                    "quadrature weight α = {alpha}: only 0 and ½ are variational rules here"
                ),
            });
        }
        let structure = Structure::of::<M>()?;
        let get = |i: usize| model.parameter(i).unwrap_or(f64::NAN);
        let mut base = structure.standard(get);
        if let Some(i) = base.iter().position(|x| !x.is_finite()) {
            return Err(IdentifyError::NonFinite {
                what: format!("declared parameter `{}`", structure.names[i]),
            });
        }
        // The base point must have a DSL form: positive masses (c = h/m)
        // and non-zero stiffness (s₀ = k s₀ / k).
        let kinds = structure.kinds();
        for (x, k) in base.iter_mut().zip(&kinds) {
            if matches!(k, ParameterKind::Mass | ParameterKind::Stiffness) && *x <= 0.0 {
                *x = 1.0;
            }
        }
        // A positive step keeps masses and stiffnesses positive; its size
        // follows the entry so that rounding stays relative.
        let steps = base.iter().map(|x| 1.0 + x.abs()).collect();
        Ok(Self {
            model,
            dt,
            alpha,
            structure,
            base,
            steps,
        })
    }

    /// The mechanism with its declared parameters.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// The time step.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// The quadrature weight α (0: first order, ½: midpoint).
    pub fn alpha(&self) -> f64 {
        self.alpha
    }

    /// The mechanism with standard parameters π (lengths, gravity and
    /// everything else as declared).
    pub fn model_with(&self, pi: &[f64]) -> Result<M, IdentifyError> {
        let mut m = self.model;
        self.structure.set_standard(pi, |i, v| {
            if let Some(p) = m.parameter_mut(i) {
                *p = v;
            }
        })?;
        Ok(m)
    }

    /// One configuration as a vector: N finite entries.
    fn vector(&self, x: &[f64]) -> Result<SVector<f64, N>, IdentifyError> {
        check_finite_vector("positions", x, N)?;
        Ok(SVector::from_column_slice(x))
    }

    fn vectors(&self, t: &Transition<'_>) -> Result<[SVector<f64, N>; 3], IdentifyError> {
        let mut out = [SVector::zeros(); 3];
        for (o, x) in out.iter_mut().zip(t.positions) {
            *o = self.vector(x)?;
        }
        for u in t.inputs {
            if u.iter().any(|v| !v.is_finite()) {
                return Err(IdentifyError::NonFinite {
                    what: "inputs".into(),
                });
            }
        }
        Ok(out)
    }

    /// The DEL residual without the multiplier term, at model `m`.
    fn raw(&self, m: &M, x: &[SVector<f64, N>; 3], u: [&[f64]; 2]) -> SVector<f64, N> {
        let (dt, alpha) = (self.dt, self.alpha);
        let v0 = (x[1] - x[0]) / dt;
        let v1 = (x[2] - x[1]) / dt;
        let mut r = del::previous_momentum::<M, N, C>(m, dt, alpha, &x[0], &v0);
        if alpha != 0.0 && u[0].iter().any(|v| *v != 0.0) {
            let m0 = x[0] + v0 * (alpha * dt);
            r += m.input_force::<f64>(&m0, u[0]) * (alpha * dt);
        }
        r + del::del_terms_forced::<M, f64, N, C>(m, dt, alpha, &x[1], &v1, u[1])
    }

    /// [`Self::raw`] on any scalar: the residual through jets, for its
    /// exact Jacobians.
    fn raw_jet<D: Scalar>(&self, m: &M, x: &[SVector<D, N>; 3], u: [&[f64]; 2]) -> SVector<D, N> {
        let (dt, alpha) = (D::from(self.dt), self.alpha);
        let v0 = (x[1] - x[0]) / dt;
        let v1 = (x[2] - x[1]) / dt;
        let p0 = if alpha == 0.0 {
            del::momentum::<M, D, N, C>(m, &x[0], &v0)
        } else {
            let h = D::from(alpha * self.dt);
            let m0 = x[0] + v0 * h;
            let mut p = del::momentum::<M, D, N, C>(m, &m0, &v0)
                + del::force_terms::<M, D, N, C>(m, &m0, &v0) * h;
            if u[0].iter().any(|v| *v != 0.0) {
                p += m.input_force::<D>(&m0, u[0]) * h;
            }
            p
        };
        p0 + del::del_terms_forced::<M, D, N, C>(m, self.dt, alpha, &x[1], &v1, u[1])
    }

    /// An orthonormal basis (N × (N − C), as rows of the returned matrix)
    /// of the null space of G(x_k): the eigenvectors of GᵀG with the N − C
    /// smallest eigenvalues, which are exactly zero since rank G ≤ C.
    fn null_basis(&self, x1: &SVector<f64, N>) -> DMatrix<f64> {
        if C == 0 {
            return DMatrix::identity(N, N);
        }
        let g = self.model.constraint_jacobian(x1);
        let gtg: DMatrix<f64> =
            DMatrix::from_fn(N, N, |i, j| (0..C).map(|k| g[(k, i)] * g[(k, j)]).sum());
        let eig = gtg.symmetric_eigen();
        let mut order: Vec<usize> = (0..N).collect();
        order.sort_by(|a, b| eig.eigenvalues[*a].total_cmp(&eig.eigenvalues[*b]));
        let rows = N.saturating_sub(C);
        DMatrix::from_fn(rows, N, |i, j| eig.eigenvectors[(j, order[i])])
    }
}

impl<M, const N: usize, const C: usize> Regressor for DelRegressor<M, N, C>
where
    M: Mechanism<N, C> + Parameters + Copy,
{
    fn structure(&self) -> &Structure {
        &self.structure
    }

    fn coordinates(&self) -> usize {
        N
    }

    fn inputs(&self) -> usize {
        <M as vigp_core::Dynamics<N, C>>::INPUTS
    }

    fn rows(&self) -> usize {
        N.saturating_sub(C)
    }

    fn standard(&self) -> Vec<f64> {
        self.structure
            .standard(|i| self.model.parameter(i).unwrap_or(f64::NAN))
    }

    fn residual(&self, t: &Transition<'_>, pi: &[f64]) -> Result<DVector<f64>, IdentifyError> {
        let x = self.vectors(t)?;
        let m = self.model_with(pi)?;
        let z = self.null_basis(&x[1]);
        let r = self.raw(&m, &x, t.inputs);
        Ok(&z * DVector::from_column_slice(r.as_slice()))
    }

    fn noise_jacobian(
        &self,
        t: &Transition<'_>,
        pi: &[f64],
    ) -> Result<DMatrix<f64>, IdentifyError> {
        let x = self.vectors(t)?;
        let m = self.model_with(pi)?;
        let z = self.null_basis(&x[1]);
        let r = self.raw(&m, &x, t.inputs);
        let dyn_g = |xk: &SVector<f64, N>| {
            let g = self.model.constraint_jacobian(xk);
            DMatrix::from_fn(C, N, |i, j| g[(i, j)])
        };
        let lambda: DVector<f64> = if C > 0 {
            let g = dyn_g(&x[1]);
            let rv = DVector::from_column_slice(r.as_slice());
            (&g * g.transpose())
                .lu()
                .solve(&(&g * rv))
                .unwrap_or_else(|| DVector::zeros(C))
        } else {
            DVector::zeros(0)
        };
        // The raw residual minus the multiplier term, λ held.
        let full = |xs: &[SVector<f64, N>; 3]| {
            let mut v = DVector::from_column_slice(self.raw(&m, xs, t.inputs).as_slice());
            if C > 0 {
                v -= dyn_g(&xs[1]).transpose() * &lambda;
            }
            v
        };
        let jac = position_differences(t.positions, |s, c, d| {
            let mut xs = x;
            xs[s][c] += d;
            Ok(full(&xs))
        })?;
        Ok(&z * jac)
    }

    fn position_jacobians(
        &self,
        t: &Transition<'_>,
        pi: &[f64],
    ) -> Result<(DVector<f64>, [DMatrix<f64>; 3]), IdentifyError> {
        let x = self.vectors(t)?;
        let m = self.model_with(pi)?;
        let mut r = DVector::zeros(N);
        let jacs = [0, 1, 2].map(|s| {
            let (value, jac) = num_dual::jacobian(
                |xs: SVector<DualVec<f64, Const<N>>, N>| {
                    let mut xx = x.map(|v| v.map(DualVec::from_re));
                    xx[s] = xs;
                    self.raw_jet(&m, &xx, t.inputs)
                },
                &x[s],
            );
            r = DVector::from_column_slice(value.as_slice());
            DMatrix::from_column_slice(N, N, jac.as_slice())
        });
        if r.iter()
            .chain(jacs.iter().flat_map(|j| j.iter()))
            .any(|v| !v.is_finite())
        {
            return Err(IdentifyError::NonFinite {
                what: "residual or its Jacobian".into(),
            });
        }
        Ok((r, jacs))
    }

    fn transition(
        &self,
        t: &Transition<'_>,
    ) -> Result<(DMatrix<f64>, DVector<f64>), IdentifyError> {
        let x = self.vectors(t)?;
        let z = self.null_basis(&x[1]);
        let (y, b) = self.raw_rows(t, &x)?;
        finite_rows((&z * y, &z * b))
    }

    fn unprojected_transition(
        &self,
        t: &Transition<'_>,
    ) -> Result<(DMatrix<f64>, DVector<f64>), IdentifyError> {
        let x = self.vectors(t)?;
        finite_rows(self.raw_rows(t, &x)?)
    }

    fn loop_constraints(
        &self,
        x: &[f64],
    ) -> Result<Option<(DVector<f64>, DMatrix<f64>)>, IdentifyError> {
        if C == 0 {
            return Ok(None);
        }
        let x = self.vector(x)?;
        let g = self.model.constraints(&x);
        let gj = self.model.constraint_jacobian(&x);
        Ok(Some((
            DVector::from_column_slice(g.as_slice()),
            DMatrix::from_fn(C, N, |i, j| gj[(i, j)]),
        )))
    }

    fn loop_curvature(&self, x: &[f64], lambda: &[f64]) -> Result<DMatrix<f64>, IdentifyError> {
        check_length("multipliers", C, lambda.len())?;
        let x = self.vector(x)?;
        let k =
            vigp_core::Dynamics::constants(&self.model).map_err(|e| IdentifyError::Simulation {
                message: e.to_string(),
            })?;
        let mu = SVector::<f64, C>::from_column_slice(lambda);
        let h = vigp_core::Dynamics::constraint_hessian(&self.model, &k, &x, &mu);
        Ok(DMatrix::from_fn(N, N, |i, j| h[(i, j)]))
    }
}

impl<M, const N: usize, const C: usize> DelRegressor<M, N, C>
where
    M: Mechanism<N, C> + Parameters + Copy,
{
    /// The rows (Y, b) of the raw residual (before the projection onto
    /// G(x_k)'s null space), by differences in π: the residual is affine in
    /// π, so they are exact to rounding.
    fn raw_rows(
        &self,
        t: &Transition<'_>,
        x: &[SVector<f64, N>; 3],
    ) -> Result<(DMatrix<f64>, DVector<f64>), IdentifyError> {
        let x = *x;
        let p = self.structure.len();
        let m0 = self.model_with(&self.base)?;
        let r0 = self.raw(&m0, &x, t.inputs);
        let mut y = DMatrix::zeros(N, p);
        let mut pi = self.base.clone();
        for i in 0..p {
            pi[i] = self.base[i] + self.steps[i];
            let mi = self.model_with(&pi)?;
            let ri = self.raw(&mi, &x, t.inputs);
            pi[i] = self.base[i];
            let col = (ri - r0) / self.steps[i];
            y.set_column(i, &DVector::from_column_slice(col.as_slice()));
        }
        let r0 = DVector::from_column_slice(r0.as_slice());
        let b = &y * DVector::from_column_slice(&self.base) - r0;
        Ok((y, b))
    }
}
