//! Identified physical parameters as the prior of a learned model
//! ([`Prior::Identified`](super::Prior::Identified)): the standard
//! parameters π of [`crate::identify`] with their covariance, applied to a
//! mechanism through its [`Parameters`].

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::identify::{Identification, Structure};
use crate::system::Parameters;

/// One identified standard parameter: its name in π
/// ([`crate::identify::regressor`]: `links.<l>.mass`, `links.<l>.mcom.x`,
/// `links.<l>.inertia_o`, `joints.<j>.damping`, …) and its value (SI units).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IdentifiedValue {
    /// The standard parameter's name.
    pub name: String,
    /// Its identified value.
    pub value: f64,
}

/// Physical parameters identified from logs: the standard parameters π
/// of a mechanism (every body's mass, first moments m·c and inertia about
/// its frame origin, every joint's damping, stiffness and stiffness·rest;
/// [`crate::identify::regressor`]) by name, and their covariance.
///
/// Built from an [`Identification`] ([`IdentifiedParameters::from_identification`])
/// or from values and a covariance ([`IdentifiedParameters::new`]); always
/// valid once built (finite values, one per standard parameter of the
/// mechanism, a finite symmetric covariance with a non-negative
/// diagonal). [`IdentifiedParameters::apply`] writes them into a
/// mechanism in the DSL's names (centre of mass c = (m·c)/m, inertia
/// about it, rest = (k·s₀)/k); everything they do not cover (lengths,
/// gravity, joint axes) stays as the mechanism declares it.
///
/// Saved in a model file inside its prior, as
/// `{"mechanism": …, "parameters": [{"name": …, "value": …}, …],
/// "covariance": [[…], …]}` (the covariance row by row, in the order of
/// `parameters`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IdentifiedParameters {
    mechanism: String,
    parameters: Vec<IdentifiedValue>,
    covariance: Vec<Vec<f64>>,
}

/// Why identified parameters cannot be built or applied to a mechanism.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum IdentifiedError {
    /// They were identified for another mechanism.
    #[error("the parameters were identified for `{found}`, not `{expected}`")]
    Mechanism {
        /// The mechanism they are applied to.
        expected: String,
        /// The mechanism they name.
        found: String,
    },
    /// A standard parameter of the mechanism has no identified value.
    #[error("standard parameter `{0}` of the mechanism has no identified value")]
    MissingParameter(String),
    /// A value names no standard parameter of the mechanism.
    #[error("`{0}` is not a standard parameter of the mechanism")]
    UnknownParameter(String),
    /// A standard parameter appears twice.
    #[error("standard parameter `{0}` appears twice")]
    DuplicateParameter(String),
    /// A value is NaN or ±∞.
    #[error("identified value of `{0}` is not finite")]
    NonFinite(String),
    /// The covariance does not fit the values or is not a covariance.
    #[error("covariance: {0}")]
    Covariance(String),
    /// The mechanism's parameter names have no standard-parameter layout
    /// (no link with a mass).
    #[error("the mechanism has no standard parameters: {0}")]
    Layout(String),
    /// The values have no form in the DSL's parameters (a zero mass, or a
    /// zero stiffness with a non-zero stiffness·rest).
    #[error("`{0}` has no form in the DSL's parameters (zero mass or stiffness)")]
    NoDslForm(String),
    /// The mechanism with the identified parameters is not one that the
    /// integrators take (e.g. a negative inertia about the centre of mass).
    #[error("the mechanism with the identified parameters is invalid: {0}")]
    Invalid(String),
}

impl IdentifiedParameters {
    /// Identified values of mechanism `mechanism` (its
    /// [`Parameters::NAME`]): standard-parameter `names` and `values`, and
    /// the covariance of the values (`names.len()` square, in the same
    /// order). The covariance is symmetrised, (Σ + Σᵀ)/2.
    ///
    /// Errors: lengths that differ, a name twice, NaN or ∞, a negative
    /// variance.
    pub fn new(
        mechanism: impl Into<String>,
        names: &[String],
        values: &[f64],
        covariance: &DMatrix<f64>,
    ) -> Result<Self, IdentifiedError> {
        let p = names.len();
        if values.len() != p {
            return Err(IdentifiedError::Covariance(format!(
                "{p} names but {} values",
                values.len()
            )));
        }
        if covariance.nrows() != p || covariance.ncols() != p {
            return Err(IdentifiedError::Covariance(format!(
                "{} × {} for {p} parameters",
                covariance.nrows(),
                covariance.ncols()
            )));
        }
        let covariance = (0..p)
            .map(|i| {
                (0..p)
                    .map(|j| 0.5 * (covariance[(i, j)] + covariance[(j, i)]))
                    .collect()
            })
            .collect();
        let out = IdentifiedParameters {
            mechanism: mechanism.into(),
            parameters: names
                .iter()
                .zip(values)
                .map(|(n, v)| IdentifiedValue {
                    name: n.clone(),
                    value: *v,
                })
                .collect(),
            covariance,
        };
        out.validate()?;
        Ok(out)
    }

    /// The estimate π̂ of an identification of mechanism `M`
    /// ([`Identification::estimate`]) and its covariance
    /// ([`Identification::covariance`]).
    ///
    /// Errors: an identification of another layout than `M`'s, NaN or ∞.
    pub fn from_identification<M: Parameters>(
        id: &Identification,
    ) -> Result<Self, IdentifiedError> {
        let structure = structure_of::<M>()?;
        if structure.names != id.structure.names {
            return Err(IdentifiedError::Layout(format!(
                "the identification's standard parameters {:?} are not `{}`'s {:?}",
                id.structure.names,
                M::NAME,
                structure.names
            )));
        }
        Self::new(M::NAME, &id.structure.names, &id.estimate, &id.covariance)
    }

    /// The mechanism's name ([`Parameters::NAME`]).
    pub fn mechanism(&self) -> &str {
        &self.mechanism
    }

    /// The identified standard parameters, in order.
    pub fn parameters(&self) -> &[IdentifiedValue] {
        &self.parameters
    }

    /// The value of standard parameter `name`.
    pub fn value(&self, name: &str) -> Option<f64> {
        self.parameters
            .iter()
            .find(|p| p.name == name)
            .map(|p| p.value)
    }

    /// The covariance of the values (in the order of
    /// [`parameters`](Self::parameters)).
    pub fn covariance(&self) -> DMatrix<f64> {
        let p = self.parameters.len();
        DMatrix::from_fn(p, p, |i, j| self.covariance[i][j])
    }

    /// The standard deviation of every value, √Σ_ii.
    pub fn std_devs(&self) -> Vec<f64> {
        (0..self.parameters.len())
            .map(|i| self.covariance[i][i].sqrt())
            .collect()
    }

    /// Checks what [`IdentifiedParameters::new`] guarantees (a value read
    /// from a file was not built by it).
    pub fn validate(&self) -> Result<(), IdentifiedError> {
        let p = self.parameters.len();
        for (i, v) in self.parameters.iter().enumerate() {
            if self.parameters[..i].iter().any(|w| w.name == v.name) {
                return Err(IdentifiedError::DuplicateParameter(v.name.clone()));
            }
            if !v.value.is_finite() {
                return Err(IdentifiedError::NonFinite(v.name.clone()));
            }
        }
        if self.covariance.len() != p {
            return Err(IdentifiedError::Covariance(format!(
                "{} rows for {p} parameters",
                self.covariance.len()
            )));
        }
        if let Some(i) = self.covariance.iter().position(|r| r.len() != p) {
            return Err(IdentifiedError::Covariance(format!(
                "row {i} has {} entries for {p} parameters",
                self.covariance[i].len()
            )));
        }
        let scale = self
            .covariance
            .iter()
            .flatten()
            .fold(0.0f64, |m, x| m.max(x.abs()));
        for i in 0..p {
            let s = self.covariance[i][i];
            if !(s.is_finite() && s >= 0.0) {
                return Err(IdentifiedError::Covariance(format!(
                    "the variance of `{}` is {s}",
                    self.parameters[i].name
                )));
            }
            for j in 0..i {
                let (a, b) = (self.covariance[i][j], self.covariance[j][i]);
                if !(a.is_finite() && b.is_finite()) {
                    return Err(IdentifiedError::Covariance(format!(
                        "entry ({i}, {j}) is not finite"
                    )));
                }
                // symmetric up to the rounding of a written and re-read
                // number (exact with round-trip floats)
                if (a - b).abs() > 1e-12 * scale {
                    return Err(IdentifiedError::Covariance(format!(
                        "not symmetric: entry ({i}, {j}) is {a}, ({j}, {i}) is {b}"
                    )));
                }
            }
        }
        Ok(())
    }

    /// The values in the order of `M`'s standard parameters, after checking
    /// the mechanism's name and that the names are exactly its standard
    /// parameters.
    fn ordered<M: Parameters>(&self) -> Result<(Structure, Vec<f64>), IdentifiedError> {
        self.validate()?;
        if self.mechanism != M::NAME {
            return Err(IdentifiedError::Mechanism {
                expected: M::NAME.into(),
                found: self.mechanism.clone(),
            });
        }
        let structure = structure_of::<M>()?;
        if let Some(extra) = self
            .parameters
            .iter()
            .find(|v| !structure.names.contains(&v.name))
        {
            return Err(IdentifiedError::UnknownParameter(extra.name.clone()));
        }
        let values = structure
            .names
            .iter()
            .map(|n| {
                self.value(n)
                    .ok_or_else(|| IdentifiedError::MissingParameter(n.clone()))
            })
            .collect::<Result<Vec<f64>, _>>()?;
        Ok((structure, values))
    }

    /// Writes the identified values into `p`'s parameters (DSL names:
    /// mass, `com` = (m·c)/m, `inertia` about the centre of mass, `damping`,
    /// `stiffness`, `rest` = (k·s₀)/k); its other parameters stay. `p` is
    /// left unchanged on error. No check of the result's physics (see
    /// [`IdentifiedParameters::apply`] for a mechanism).
    ///
    /// Errors: another mechanism ([`IdentifiedError::Mechanism`]), names
    /// that are not exactly its standard parameters, a zero mass or
    /// stiffness where the DSL needs to divide by it.
    pub fn write_to<P: Parameters>(&self, p: &mut P) -> Result<(), IdentifiedError> {
        let (structure, values) = self.ordered::<P>()?;
        let mut new = Vec::new();
        structure
            .set_standard(&values, |i, v| new.push((i, v)))
            .map_err(|e| match e {
                crate::identify::IdentifyError::NoDslForm { parameter } => {
                    IdentifiedError::NoDslForm(parameter)
                }
                e => IdentifiedError::Invalid(e.to_string()),
            })?;
        for (i, v) in new {
            if let Some(slot) = p.parameter_mut(i) {
                *slot = v;
            }
        }
        Ok(())
    }

    /// Writes the identified values into `model`
    /// ([`IdentifiedParameters::write_to`]) and checks that the mechanism
    /// takes them (its own check of its parameters, as an integrator
    /// makes). `model` is left unchanged on error.
    ///
    /// Errors: those of `write_to`, and a result that the mechanism's own
    /// check refuses ([`IdentifiedError::Invalid`], e.g. a negative inertia
    /// about the centre of mass).
    pub fn apply<M, const N: usize, const C: usize>(
        &self,
        model: &mut M,
    ) -> Result<(), IdentifiedError>
    where
        M: Parameters + vigp_core::Dynamics<N, C> + Clone,
    {
        let mut m = model.clone();
        self.write_to(&mut m)?;
        m.constants()
            .map_err(|e| IdentifiedError::Invalid(format!("{e}")))?;
        *model = m;
        Ok(())
    }

    /// `model` with the identified values ([`IdentifiedParameters::apply`]).
    pub fn model<M, const N: usize, const C: usize>(&self, model: &M) -> Result<M, IdentifiedError>
    where
        M: Parameters + vigp_core::Dynamics<N, C> + Clone,
    {
        let mut m = model.clone();
        self.apply(&mut m)?;
        Ok(m)
    }
}

fn structure_of<M: Parameters>() -> Result<Structure, IdentifiedError> {
    Structure::of::<M>().map_err(|e| IdentifiedError::Layout(e.to_string()))
}
