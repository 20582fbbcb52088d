//! A trained [`Learned`] as Rust source for the `no_std`
//! [`vigp_core::LearnedStepper`]: the GP arrays and one `LearnedModel`
//! static naming the mechanism, its parameters, Δt, encoding, prior and
//! control inputs.

use core::fmt::Write;

use super::{Encoding, Learned, Prior};
use crate::gp::{ExportOptions, GpError};
use crate::mechanism::Mechanism;
use crate::system::Parameters;

/// Options of [`Learned::to_embedded_source`].
#[derive(Clone, Debug, PartialEq)]
pub struct EmbeddedExport {
    /// Name of the generated `LearnedModel` static (an upper-case
    /// identifier, default `"LEARNED"`); the GP items are prefixed
    /// `<NAME>_GP`.
    pub name: String,
    /// Path of the `vigp_core` crate in the generated code (default
    /// `"vigp::embedded"`).
    pub core_path: String,
    /// Also write the Cholesky factors (N(N+1)/2 numbers per velocity
    /// component), needed only for posterior variances on the target.
    pub variance: bool,
    /// Comment lines for the file header.
    pub header: Vec<String>,
}

impl Default for EmbeddedExport {
    fn default() -> Self {
        Self {
            name: "LEARNED".into(),
            core_path: "vigp::embedded".into(),
            variance: false,
            header: Vec::new(),
        }
    }
}

/// What an export holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ExportSize {
    /// Points in the exported arrays: the training points N of an exact
    /// GP, the inducing points M of a sparse one.
    pub n: usize,
    /// GP inputs d.
    pub input_dim: usize,
    /// Velocity components (one GP each).
    pub outputs: usize,
    /// f64 numbers in the exported arrays.
    pub numbers: usize,
    /// Bytes of those numbers in the target's memory (8 each).
    pub data_bytes: usize,
    /// Bytes of the generated source text.
    pub source_bytes: usize,
}

impl EmbeddedExport {
    /// The GP part of an export of `gp` under these options: its Rust
    /// source (items named `<NAME>_GP`, with the Cholesky factors when
    /// [`EmbeddedExport::variance`]) and that name.
    pub(crate) fn gp_source(&self, gp: &crate::gp::Gp) -> Result<(String, String), GpError> {
        let gp_name = format!("{}_GP", self.name);
        let gp_opts = ExportOptions {
            name: gp_name.clone(),
            core_path: self.core_path.clone(),
            cholesky: self.variance,
            header: self.header.clone(),
            check_points: Vec::new(),
        };
        Ok((gp.to_rust_source(&gp_opts)?, gp_name))
    }
}

/// The names of `encoding` and `prior` in the generated code's
/// `Encoding::…` and `Prior::…`. An identified prior is `Nominal` there:
/// the identified parameters are the exported model's own (a mechanism's
/// `parameters`, a robot's bodies).
pub(crate) fn source_names(encoding: &Encoding, prior: &Prior) -> (&'static str, &'static str) {
    let encoding = match encoding {
        Encoding::Raw => "Raw",
        Encoding::SinCos => "SinCos",
    };
    let prior = match prior {
        Prior::Nominal | Prior::Identified(_) => "Nominal",
        Prior::Constant => "Constant",
    };
    (encoding, prior)
}

impl ExportSize {
    /// The size of an export of `gp` (with the Cholesky factors when
    /// `variance`) written in `source_bytes` bytes.
    pub(crate) fn of(gp: &crate::gp::Gp, variance: bool, source_bytes: usize) -> Self {
        let (n, d, p) = (gp.posterior_points(), gp.input_dim(), gp.output_dim());
        let mut numbers = p * (n * (d + 1) + 3 * d + 3);
        if variance {
            numbers += p * n * (n + 1) / 2;
        }
        ExportSize {
            n,
            input_dim: d,
            outputs: p,
            numbers,
            data_bytes: 8 * numbers,
            source_bytes,
        }
    }
}

impl<M, const N: usize, const C: usize> Learned<M, N, C>
where
    M: Mechanism<N, C> + Parameters + Clone,
{
    /// This model as Rust source for [`vigp_core::LearnedStepper`]: static
    /// arrays of what the GP mean needs (scaled training inputs and weights
    /// α: N·(d + 1) numbers per velocity component; with
    /// [`EmbeddedExport::variance`] also the Cholesky factor) and a
    /// `LearnedModel` static. The text compiles in a `#![no_std]` crate and
    /// is deterministic; floats round-trip exactly.
    ///
    /// A model trained with inputs ([`Learned::train_forced`]) records
    /// their names (`inputs: &["rail"]`, the mechanism's
    /// `Dynamics::INPUT_NAMES`); its GPs take the encoded state followed by
    /// the previous and the current input, (enc(z), u_prev, u), so the GP
    /// input dimension `D` is the encoding's plus twice the inputs (a model
    /// loaded from a file with the layout (enc(z), u) keeps it: plus once;
    /// `LearnedStepper::new` tells the two apart by `D`), and on the target
    /// it steps with `LearnedStepper::step_forced`. A model trained without
    /// inputs writes `inputs: &[]`.
    ///
    /// Models in either coordinate view export; `LearnedStepper::new` then
    /// takes the same view (`sys.minimal()` or the parameter struct for a
    /// minimal-coordinate model, `sys.maximal()` for a maximal one; the GP
    /// input dimension it checks differs between the views).
    pub fn to_embedded_source(
        &self,
        opts: &EmbeddedExport,
    ) -> Result<(String, ExportSize), GpError> {
        let (mut s, gp_name) = opts.gp_source(&self.gp)?;
        let core = &opts.core_path;
        let d = self.gp.input_dim();
        let lit = |v: f64| format!("{v:?}");
        let coords: Vec<String> = M::COORDINATES.iter().map(|c| format!("{c:?}")).collect();
        if self.inputs > M::INPUT_NAMES.len() {
            return Err(GpError::Export(format!(
                "the model takes {} inputs, the mechanism names {}",
                self.inputs,
                M::INPUT_NAMES.len()
            )));
        }
        let inputs: Vec<String> = M::INPUT_NAMES[..self.inputs]
            .iter()
            .map(|c| format!("{c:?}"))
            .collect();
        let mut params = String::new();
        for (i, name) in M::PARAMETER_NAMES.iter().enumerate() {
            let value = self.model().parameter(i).unwrap_or(f64::NAN);
            if !value.is_finite() {
                return Err(GpError::Export(format!("parameter {name} is not finite")));
            }
            let _ = writeln!(params, "        ({name:?}, {}),", lit(value));
        }
        let (encoding, prior) = source_names(&self.encoding, &self.prior);
        let name = &opts.name;
        let _ = write!(
            s,
            "\n/// The learned model of `{mech}` (Δt = {dt} s, {encoding} encoding, {prior} prior{with_inputs}):\n\
             /// step it in the view it was trained in (`coordinates` below):\n\
             /// `{core}::LearnedStepper::new({mech}::default(), &{name})` in minimal coordinates,\n\
             /// `{core}::LearnedStepper::new({mech}::default().maximal(), &{name})` in maximal ones.\n\
             #[rustfmt::skip]\n\
             pub static {name}: {core}::learned::LearnedModel<'static, {N}, {d}> = {core}::learned::LearnedModel {{\n\
             \x20   mechanism: {mech:?},\n\
             \x20   coordinates: [{coords}],\n\
             \x20   inputs: &[{inputs}],\n\
             \x20   parameters: &[\n{params}    ],\n\
             \x20   dt: {dtl},\n\
             \x20   encoding: {core}::learned::Encoding::{encoding},\n\
             \x20   prior: {core}::learned::Prior::{prior},\n\
             \x20   project: {project},\n\
             \x20   options: {core}::StepOptions {{ tolerance: {tol}, max_iterations: {iters}, min_step: {min_step}, stall_tolerance: {stall} }},\n\
             \x20   gps: &{gp_name},\n\
             }};\n",
            mech = M::NAME,
            dt = self.nominal.dt(),
            dtl = lit(self.nominal.dt()),
            coords = coords.join(", "),
            inputs = inputs.join(", "),
            with_inputs = if inputs.is_empty() {
                String::new()
            } else if self.previous_input {
                format!(
                    ", inputs {}; GP input (enc(z), u_prev, u)",
                    inputs.join(", ")
                )
            } else {
                format!(", inputs {}", inputs.join(", "))
            },
            project = self.project,
            tol = lit(self.nominal.options().tolerance),
            iters = self.nominal.options().max_iterations,
            min_step = lit(self.nominal.options().min_step),
            stall = lit(self.nominal.options().stall_tolerance),
        );
        let size = ExportSize::of(&self.gp, opts.variance, s.len());
        Ok((s, size))
    }
}
