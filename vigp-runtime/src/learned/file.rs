//! One file for a whole learned model: [`SavedLearned`] (serde, written as
//! JSON by [`Learned::save`]) and the checks that loading makes.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{Encoding, Learned, Prior};
use crate::gp::{Gp, GpError, SavedGp};
use crate::mechanism::{CoordinateKind, Mechanism};
use crate::newton::StepOptions;
use crate::system::Parameters;
use crate::variational::Variational;

/// The `format` tag of a learned-model file.
pub const FORMAT: &str = "vigp-learned";
/// The version written by [`Learned::to_saved`]; loading accepts only it.
pub const VERSION: u32 = 1;

/// The serde form of a trained [`Learned`]: everything prediction needs and
/// everything loading must check. Written and read as JSON by
/// [`Learned::save`] / [`Learned::load`] (or with any serde format through
/// [`Learned::to_saved`] / [`Learned::from_saved`]).
///
/// Loading into a model checks, each with an error that names the field:
/// the `format` tag and `version`, the mechanism's `mechanism` name, its
/// `coordinates` (their names and so the view: minimal or maximal), their
/// `kinds`, the `inputs` (the actuated joints the GP takes), every parameter
/// name (values are restored from the file: the prior is the model the GP
/// was trained on), `dt`, the solver options, and the GP's dimensions
/// against the encoding and the number of coordinates.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedLearned {
    /// Always `"vigp-learned"`.
    pub format: String,
    /// File format version (1 for files written by this version of vigp).
    pub version: u32,
    /// The mechanism's name (`Parameters::NAME`, e.g. `"Cartpole"`).
    pub mechanism: String,
    /// Names of the model's coordinates, in order (minimal: joint names;
    /// maximal: `link.x`, `link.y`, `link.theta`).
    pub coordinates: Vec<String>,
    /// What each coordinate measures.
    pub kinds: Vec<SavedKind>,
    /// Names of the control inputs the GP takes after the encoded state
    /// (the actuated joints; empty for a model trained without inputs).
    pub inputs: Vec<String>,
    /// The GP input layout of a model with inputs: `true` for
    /// (enc(z), u_prev, u), the previous input (the one that produced z's
    /// velocity) before the current one, as [`Learned::train_forced`]
    /// trains; `false` for (enc(z), u). A file without the field reads as
    /// `false` and loads as that layout (its predictions ignore the
    /// previous input); the field is written only when `true`.
    #[serde(default, skip_serializing_if = "is_false")]
    pub previous_input: bool,
    /// Every run-time parameter of the nominal model, by name.
    pub parameters: BTreeMap<String, f64>,
    /// Time step Δt (s).
    pub dt: f64,
    /// GP input encoding.
    pub encoding: Encoding,
    /// Prior of the velocity map: `"nominal"`, `"constant"`, or
    /// `{"identified": {"mechanism", "parameters", "covariance"}}` with the
    /// identified standard parameters by name and their covariance
    /// ([`crate::learned::IdentifiedParameters`]); the identified values in
    /// the DSL's names are those of `parameters`, and loading checks that
    /// the two agree.
    pub prior: Prior,
    /// Whether predictions are projected onto the constraints.
    pub project: bool,
    /// Newton options of the nominal steps and the projection.
    pub newton: SavedNewton,
    /// The GP (its own format, see [`SavedGp`]).
    pub gp: SavedGp,
}

fn is_false(b: &bool) -> bool {
    !*b
}

/// A coordinate kind in a saved model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SavedKind {
    /// An angle (rad).
    Angle,
    /// A length (m).
    Length,
    /// A unit-quaternion component (spatial minimal coordinates).
    Quaternion,
}

impl From<CoordinateKind> for SavedKind {
    fn from(k: CoordinateKind) -> Self {
        match k {
            CoordinateKind::Angle => SavedKind::Angle,
            CoordinateKind::Length => SavedKind::Length,
            CoordinateKind::Quaternion => SavedKind::Quaternion,
        }
    }
}

/// [`StepOptions`] in a saved model.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedNewton {
    /// See [`StepOptions::tolerance`].
    pub tolerance: f64,
    /// See [`StepOptions::max_iterations`].
    pub max_iterations: usize,
    /// See [`StepOptions::min_step`].
    pub min_step: f64,
    /// See [`StepOptions::stall_tolerance`].
    pub stall_tolerance: f64,
}

/// Why a learned-model file could not be loaded. Every variant names what
/// is at fault; loading never panics, whatever the bytes.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LoadError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The text is not a learned-model file: bad JSON, a truncated file, a
    /// missing or unknown field, or a value of the wrong type (serde's
    /// message names the field where it can).
    #[error("not a valid vigp model file (line {line}, column {column}): {message}")]
    Syntax {
        /// Line of the error (1-based; 0 if unknown).
        line: usize,
        /// Column of the error (1-based; 0 if unknown).
        column: usize,
        /// What is wrong.
        message: String,
    },
    /// A field holds a value that does not fit the model being loaded into
    /// or is out of its domain.
    #[error("field `{field}`: {reason}")]
    Field {
        /// Dotted path of the field (e.g. `gp.input_dim`).
        field: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The file belongs to another mechanism.
    #[error("field `mechanism`: the file is a model of `{found}`, not of `{expected}`")]
    Mechanism {
        /// The mechanism loaded into.
        expected: String,
        /// The mechanism named in the file.
        found: String,
    },
    /// The file's coordinates are not the model's (another mechanism, or the
    /// other coordinate view).
    #[error("field `coordinates`: the file has {found:?}, the model {expected:?}")]
    Coordinates {
        /// The model's coordinate names.
        expected: Vec<String>,
        /// The file's.
        found: Vec<String>,
    },
    /// The file's control inputs are not the model's.
    #[error("field `inputs`: the file has {found:?}, the model {expected:?}")]
    Inputs {
        /// The model's input names.
        expected: Vec<String>,
        /// The file's.
        found: Vec<String>,
    },
    /// A parameter of the model is missing from the file.
    #[error("field `parameters`: `{0}` is missing")]
    MissingParameter(String),
    /// The file has a parameter the model does not.
    #[error("field `parameters`: `{0}` is not a parameter of this mechanism")]
    UnknownParameter(String),
    /// The GP could not be rebuilt from its saved form.
    #[error("field `gp`: {0}")]
    Gp(#[from] GpError),
}

impl From<serde_json::Error> for LoadError {
    fn from(e: serde_json::Error) -> Self {
        LoadError::Syntax {
            line: e.line(),
            column: e.column(),
            message: e.to_string(),
        }
    }
}

fn field(field: impl Into<String>, reason: impl Into<String>) -> LoadError {
    LoadError::Field {
        field: field.into(),
        reason: reason.into(),
    }
}

fn expect_len(name: &str, got: usize, expected: usize, what: &str) -> Result<(), LoadError> {
    if got != expected {
        return Err(field(
            name,
            format!("expected {expected} {what}, found {got}"),
        ));
    }
    Ok(())
}

/// Checks a parameter value for its physical domain (by the naming
/// convention of `Parameters`), as the mechanism's own run-time check does
/// (so that every model `fit` writes loads): lengths > 0, masses, inertias
/// and damping ≥ 0, everything finite.
fn check_parameter(name: &str, value: f64) -> Result<(), LoadError> {
    let bad = |why: &str| {
        Err(field(
            format!("parameters.{name}"),
            format!("{value} {why}"),
        ))
    };
    if !value.is_finite() {
        return bad("is not finite");
    }
    if name.ends_with(".length") && value <= 0.0 {
        return bad("must be > 0");
    }
    if (name.ends_with(".mass") || name.ends_with(".inertia") || name.ends_with(".damping"))
        && value < 0.0
    {
        return bad("must be >= 0");
    }
    Ok(())
}

/// Checks the saved GP's dimensions against the model before the GP's own
/// checks run, so that errors name the field (`gp.input_dim`, …).
fn check_gp(saved: &SavedGp, d: usize, p: usize, prior: &Prior) -> Result<(), LoadError> {
    if saved.input_dim != d {
        return Err(field(
            "gp.input_dim",
            format!(
                "the encoding of this model's state and its inputs has {d} components, the file says {}",
                saved.input_dim
            ),
        ));
    }
    if saved.output_dim != p {
        return Err(field(
            "gp.output_dim",
            format!(
                "the model has {p} velocity components, the file says {}",
                saved.output_dim
            ),
        ));
    }
    if saved.inputs.is_empty() {
        return Err(field("gp.inputs", "no training inputs"));
    }
    if saved.inputs.len() % d != 0 {
        return Err(field(
            "gp.inputs",
            format!(
                "{} numbers is not a multiple of gp.input_dim = {d}",
                saved.inputs.len()
            ),
        ));
    }
    let n = saved.inputs.len() / d;
    expect_len(
        "gp.targets",
        saved.targets.len(),
        n * p,
        "numbers (N × gp.output_dim)",
    )?;
    expect_len(
        "gp.input_normaliser.shift",
        saved.input_normaliser.shift.len(),
        d,
        "numbers (gp.input_dim)",
    )?;
    expect_len(
        "gp.input_normaliser.scale",
        saved.input_normaliser.scale.len(),
        d,
        "numbers (gp.input_dim)",
    )?;
    expect_len(
        "gp.outputs",
        saved.outputs.len(),
        p,
        "outputs (gp.output_dim)",
    )?;
    for (j, o) in saved.outputs.iter().enumerate() {
        expect_len(
            &format!("gp.outputs[{j}].hyperparameters.length_scales"),
            o.hyperparameters.length_scales.len(),
            d,
            "numbers (gp.input_dim)",
        )?;
    }
    use crate::gp::SavedMean;
    match (&saved.mean, prior) {
        (SavedMean::Zero, Prior::Nominal | Prior::Identified(_)) => {}
        (SavedMean::Constant(c), Prior::Constant) => {
            expect_len("gp.mean", c.len(), p, "constants (gp.output_dim)")?
        }
        (m, prior) => {
            let prior = match prior {
                Prior::Nominal => "nominal",
                Prior::Constant => "constant",
                Prior::Identified(_) => "identified",
            };
            return Err(field(
                "gp.mean",
                format!(
                    "{m:?} does not fit prior {prior} (nominal and identified: Zero, constant: Constant)"
                ),
            ));
        }
    }
    Ok(())
}

/// Checks the identified prior of a file against the mechanism (names,
/// finite values, covariance) and against the file's `parameters`: the
/// parameters the identified values set must be the file's, to rounding
/// (1e-12 relative; the two are written from the same numbers, and exactly
/// equal for files that vigp wrote).
fn check_identified<M, const N: usize, const C: usize>(
    model: &M,
    parameters: &BTreeMap<String, f64>,
    identified: &super::IdentifiedParameters,
) -> Result<(), LoadError>
where
    M: Mechanism<N, C> + Parameters + Clone,
{
    let at = "prior.identified";
    let applied = identified
        .model(model)
        .map_err(|e| field(at, e.to_string()))?;
    for (i, name) in M::PARAMETER_NAMES.iter().enumerate() {
        let (Some(a), Some(&b)) = (applied.parameter(i), parameters.get(*name)) else {
            continue;
        };
        if (a - b).abs() > 1e-12 * a.abs().max(b.abs()) {
            return Err(field(
                at,
                format!("the identified values give {name} = {a}, but `parameters.{name}` is {b}"),
            ));
        }
    }
    Ok(())
}

impl<M, const N: usize, const C: usize> Learned<M, N, C>
where
    M: Mechanism<N, C> + Parameters + Clone,
{
    /// The serialisable form of this model (see [`SavedLearned`]).
    pub fn to_saved(&self) -> SavedLearned {
        let parameters = M::PARAMETER_NAMES
            .iter()
            .enumerate()
            .map(|(i, n)| (n.to_string(), self.model().parameter(i).unwrap_or(f64::NAN)))
            .collect();
        SavedLearned {
            format: FORMAT.into(),
            version: VERSION,
            mechanism: M::NAME.into(),
            coordinates: M::COORDINATES.iter().map(|s| s.to_string()).collect(),
            kinds: M::KINDS.iter().map(|k| SavedKind::from(*k)).collect(),
            inputs: M::INPUT_NAMES[..self.inputs.min(M::INPUT_NAMES.len())]
                .iter()
                .map(|s| s.to_string())
                .collect(),
            previous_input: self.previous_input,
            parameters,
            dt: self.nominal.dt(),
            encoding: self.encoding,
            prior: self.prior.clone(),
            project: self.project,
            newton: SavedNewton {
                tolerance: self.nominal.options().tolerance,
                max_iterations: self.nominal.options().max_iterations,
                min_step: self.nominal.options().min_step,
                stall_tolerance: self.nominal.options().stall_tolerance,
            },
            gp: self.gp.to_saved(),
        }
    }

    /// Rebuilds a learned model from its saved form. `model` supplies the
    /// mechanism type; its parameter values are replaced by the file's (the
    /// nominal prior the GP was trained on). Every mismatch is a
    /// [`LoadError`] naming the field; the rebuilt model predicts bit for
    /// bit as the one saved. Cost: one O(N³) Cholesky per velocity
    /// component.
    pub fn from_saved(mut model: M, saved: &SavedLearned) -> Result<Self, LoadError> {
        if saved.format != FORMAT {
            return Err(field(
                "format",
                format!("{:?} is not {FORMAT:?}", saved.format),
            ));
        }
        if saved.version != VERSION {
            return Err(field(
                "version",
                format!(
                    "version {} is not supported (this build reads {VERSION})",
                    saved.version
                ),
            ));
        }
        if saved.mechanism != M::NAME {
            return Err(LoadError::Mechanism {
                expected: M::NAME.into(),
                found: saved.mechanism.clone(),
            });
        }
        if saved.coordinates.len() != N
            || saved
                .coordinates
                .iter()
                .zip(M::COORDINATES)
                .any(|(a, b)| a != b)
        {
            return Err(LoadError::Coordinates {
                expected: M::COORDINATES.iter().map(|s| s.to_string()).collect(),
                found: saved.coordinates.clone(),
            });
        }
        let kinds: Vec<SavedKind> = M::KINDS.iter().map(|k| SavedKind::from(*k)).collect();
        if saved.kinds != kinds {
            return Err(field(
                "kinds",
                format!("the file has {:?}, the model {kinds:?}", saved.kinds),
            ));
        }
        // no inputs (a model trained without them), or exactly the model's
        if !saved.inputs.is_empty()
            && (saved.inputs.len() != M::INPUT_NAMES.len()
                || saved.inputs.iter().zip(M::INPUT_NAMES).any(|(a, b)| a != b))
        {
            return Err(LoadError::Inputs {
                expected: M::INPUT_NAMES.iter().map(|s| s.to_string()).collect(),
                found: saved.inputs.clone(),
            });
        }
        // a length of 0: a 3-D link declared without one, if the
        // mechanism's own check takes it (a planar link's must be > 0)
        let mut zero_length = None;
        for (i, name) in M::PARAMETER_NAMES.iter().enumerate() {
            let Some(&value) = saved.parameters.get(*name) else {
                return Err(LoadError::MissingParameter(name.to_string()));
            };
            if name.ends_with(".length") && value == 0.0 {
                zero_length.get_or_insert(*name);
            } else {
                check_parameter(name, value)?;
            }
            match model.parameter_mut(i) {
                Some(slot) => *slot = value,
                None => return Err(LoadError::MissingParameter(name.to_string())),
            }
        }
        if let Some(name) = zero_length
            && vigp_core::Dynamics::constants(&model).is_err()
        {
            return Err(field(format!("parameters.{name}"), "0 must be > 0"));
        }
        if let Some(extra) = saved
            .parameters
            .keys()
            .find(|k| !M::PARAMETER_NAMES.contains(&k.as_str()))
        {
            return Err(LoadError::UnknownParameter(extra.clone()));
        }
        if !(saved.dt.is_finite() && saved.dt > 0.0) {
            return Err(field("dt", format!("{} must be finite and > 0", saved.dt)));
        }
        let s = &saved.newton;
        let options = StepOptions {
            tolerance: s.tolerance,
            max_iterations: s.max_iterations,
            min_step: s.min_step,
            stall_tolerance: s.stall_tolerance,
        };
        options
            .validate()
            .map_err(|e| field("newton", e.to_string()))?;
        if saved.project && C == 0 {
            return Err(field("project", "true, but the model has no constraints"));
        }
        if saved.previous_input && saved.inputs.is_empty() {
            return Err(field(
                "previous_input",
                "true, but the model takes no inputs",
            ));
        }
        let tail = if saved.previous_input {
            2 * saved.inputs.len()
        } else {
            saved.inputs.len()
        };
        let d = saved.encoding.dim(&M::KINDS) + tail;
        if let Prior::Identified(p) = &saved.prior {
            check_identified(&model, &saved.parameters, p)?;
        }
        check_gp(&saved.gp, d, N, &saved.prior)?;
        let gp = Gp::from_saved(&saved.gp, None)?;
        let nominal = Variational::new(model.clone(), saved.dt)
            .and_then(|vi| vi.with_options(options))
            .map_err(|e| {
                let at = match e {
                    crate::newton::StepError::InvalidTimeStep { .. } => "dt",
                    _ => "parameters",
                };
                field(at, e.to_string())
            })?;
        Ok(Self {
            nominal,
            prior: saved.prior.clone(),
            encoding: saved.encoding,
            project: saved.project,
            gp,
            inputs: saved.inputs.len(),
            previous_input: saved.previous_input,
        })
    }

    /// This model as JSON text (floats written to round-trip exactly).
    pub fn to_json(&self) -> String {
        // A SavedLearned holds only strings, numbers, maps and sequences:
        // serialising it cannot fail (non-finite numbers become `null`,
        // which loading rejects).
        serde_json::to_string_pretty(&self.to_saved()).unwrap_or_default()
    }

    /// A model from JSON text ([`Learned::to_json`]); see
    /// [`Learned::from_saved`] for `model` and the checks.
    pub fn from_json(model: M, json: &str) -> Result<Self, LoadError> {
        let saved: SavedLearned = serde_json::from_str(json)?;
        Self::from_saved(model, &saved)
    }

    /// Writes this model to `path` as JSON.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), LoadError> {
        let path = path.as_ref();
        std::fs::write(path, self.to_json()).map_err(|source| LoadError::Io {
            path: path.to_path_buf(),
            source,
        })
    }

    /// Reads a model saved with [`Learned::save`]; see
    /// [`Learned::from_saved`] for `model` and the checks.
    pub fn load(path: impl AsRef<Path>, model: M) -> Result<Self, LoadError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| LoadError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_json(model, &text)
    }
}

impl SavedLearned {
    /// Parses a learned-model file's JSON without loading it into a model
    /// (e.g. to see which mechanism and coordinates it is for).
    pub fn from_json(json: &str) -> Result<Self, LoadError> {
        Ok(serde_json::from_str(json)?)
    }

    /// Reads and parses a learned-model file ([`SavedLearned::from_json`]).
    pub fn read(path: impl AsRef<Path>) -> Result<Self, LoadError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| LoadError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_json(&text)
    }
}
