//! Export of a trained GP as Rust source for `no_std` prediction with
//! [`vigp_core::gp::ExportedGp`].
//!
//! [`Gp::to_rust_source`] writes `static` arrays (scaled training inputs,
//! weights α, and optionally the packed Cholesky factor) and one
//! `ExportedGp` per output with the hyperparameters and normalisation.
//! Floats are written with Rust's shortest round-trip representation
//! (`{:?}`), so every number parses back to the same bits; the text
//! depends only on the model (no time stamps, no hash-map order), so the
//! same model always gives the same file. The exported model reproduces
//! [`Gp::predict_mean_into`] bit for bit, because both evaluate the shared
//! kernels of `vigp_core::gp` on the same numbers.

use core::fmt::Write;

use vigp_core::gp::ExportedGp;

use crate::error::GpError;
use crate::mean::Resolved;
use crate::model::{Gp, Posterior};
use crate::packed;

/// One output of a trained [`Gp`] in the layout of
/// [`ExportedGp`](vigp_core::gp::ExportedGp), owning its arrays (what
/// [`Gp::to_rust_source`] writes out). [`as_exported`](Self::as_exported)
/// borrows it as an `ExportedGp`, e.g. to test an export without compiling
/// the generated file.
#[derive(Clone, Debug, PartialEq)]
pub struct ExportedArrays {
    /// Input dimension d.
    pub input_dim: usize,
    /// Scaled training inputs ((x − μ)/s_x)/ℓ, column-major d × N.
    pub inputs: Vec<f64>,
    /// Weights α in normalised units (length N).
    pub weights: Vec<f64>,
    /// Length scales ℓ (normalised units, length d).
    pub length_scales: Vec<f64>,
    /// Signal variance σ_f² (normalised units).
    pub signal_variance: f64,
    /// Input standardisation shift μ (length d).
    pub input_shift: Vec<f64>,
    /// Input standardisation scale s_x (length d).
    pub input_scale: Vec<f64>,
    /// Output scale s_y.
    pub output_scale: f64,
    /// Constant prior mean (0 for a zero prior).
    pub prior_mean: f64,
    /// Packed lower Cholesky factor (N(N+1)/2 numbers), if requested.
    pub cholesky: Option<Vec<f64>>,
}

impl ExportedArrays {
    /// Borrows these arrays as an [`ExportedGp`] with `D` = d.
    pub fn as_exported<const D: usize>(&self) -> Result<ExportedGp<'_, D>, GpError> {
        let arr = |what: &'static str, v: &[f64]| -> Result<[f64; D], GpError> {
            v.try_into().map_err(|_| GpError::DimensionMismatch {
                what,
                expected: D,
                got: v.len(),
            })
        };
        Ok(ExportedGp {
            inputs: &self.inputs,
            weights: &self.weights,
            length_scales: arr("length_scales (D)", &self.length_scales)?,
            signal_variance: self.signal_variance,
            input_shift: arr("input_shift (D)", &self.input_shift)?,
            input_scale: arr("input_scale (D)", &self.input_scale)?,
            output_scale: self.output_scale,
            prior_mean: self.prior_mean,
            cholesky: self.cholesky.as_deref(),
        })
    }
}

/// Options of [`Gp::to_rust_source`] (and of the learned model's export in
/// `vigp`, which adds the integrator's constants).
#[derive(Clone, Debug, PartialEq)]
pub struct ExportOptions {
    /// Prefix of every generated item (an upper-case identifier, default
    /// `"GP"`): `GP` (the array of `ExportedGp`s), `GP_N`, `GP_0_INPUTS`, ….
    pub name: String,
    /// Path under which the generated code names the `vigp_core` crate:
    /// `"vigp::embedded"` (default; works with and without vigp's `std`
    /// feature) or `"vigp_core"`.
    pub core_path: String,
    /// Also export the Cholesky factor (N(N+1)/2 numbers per output: 131 328
    /// at N = 512), needed for [`ExportedGp::predict`] (variances).
    pub cholesky: bool,
    /// Lines for the file header, e.g. how the file was generated (each
    /// becomes a `//` comment line).
    pub header: Vec<String>,
    /// GP inputs (original units, d numbers each) at which the std model's
    /// predictions are written as `<NAME>_CHECK_*` arrays, so that the
    /// compiled export can be checked against the model that produced it.
    pub check_points: Vec<Vec<f64>>,
}

impl Default for ExportOptions {
    fn default() -> Self {
        Self {
            name: "GP".into(),
            core_path: "vigp::embedded".into(),
            cholesky: false,
            header: Vec::new(),
            check_points: Vec::new(),
        }
    }
}

fn export_error(msg: impl Into<String>) -> GpError {
    GpError::Export(msg.into())
}

impl ExportOptions {
    fn validate(&self, d: usize) -> Result<(), GpError> {
        let mut chars = self.name.chars();
        let ok_name = chars
            .next()
            .is_some_and(|c| c.is_ascii_uppercase() || c == '_')
            && chars.all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_');
        if !ok_name {
            return Err(export_error(format!(
                "name {:?} is not an upper-case identifier",
                self.name
            )));
        }
        let ok_path = !self.core_path.is_empty()
            && self.core_path.split("::").all(|seg| {
                let mut c = seg.chars();
                c.next()
                    .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
                    && c.all(|c| c.is_ascii_alphanumeric() || c == '_')
            });
        if !ok_path {
            return Err(export_error(format!(
                "core_path {:?} is not a Rust path",
                self.core_path
            )));
        }
        if self.header.iter().any(|l| l.contains('\n')) {
            return Err(export_error("header lines must not contain newlines"));
        }
        for p in &self.check_points {
            if p.len() != d {
                return Err(GpError::DimensionMismatch {
                    what: "check point (input dimension)",
                    expected: d,
                    got: p.len(),
                });
            }
        }
        Ok(())
    }
}

/// Shortest round-trip decimal form of a finite f64, always a float
/// literal (`1.0`, `-2.5e-7`, `1e300`).
fn lit(v: f64) -> String {
    format!("{v:?}")
}

fn write_array(out: &mut String, values: &[f64], per_line: usize) {
    for chunk in values.chunks(per_line) {
        out.push_str("   ");
        for v in chunk {
            out.push(' ');
            out.push_str(&lit(*v));
            out.push(',');
        }
        out.push('\n');
    }
}

fn inline_array(values: &[f64]) -> String {
    let parts: Vec<String> = values.iter().map(|v| lit(*v)).collect();
    format!("[{}]", parts.join(", "))
}

/// Writes a blank line, the doc line `doc` and the `static` item `item`
/// (`NAME: [[f64; width]; rows]`) holding `rows`, one inline array a line.
fn write_table<'a>(out: &mut String, doc: &str, item: &str, rows: impl Iterator<Item = &'a [f64]>) {
    let _ = writeln!(out, "\n/// {doc}");
    let _ = writeln!(out, "{ITEM_ATTRS}pub static {item} = [");
    for row in rows {
        let _ = writeln!(out, "    {},", inline_array(row));
    }
    let _ = writeln!(out, "];");
}

/// Attributes on every generated item: the numbers are data (clippy would
/// flag a weight that happens to be close to π), and the layout is ours.
const ITEM_ATTRS: &str =
    "#[rustfmt::skip]\n#[allow(clippy::approx_constant, clippy::excessive_precision)]\n";

impl Gp {
    /// Output `j` in the exported layout; `cholesky` adds the packed
    /// Cholesky factor (O(N²) numbers). A sparse GP exports its M inducing
    /// points as the "training inputs" and its weights u as α, so the
    /// exported mean is the sparse mean (O(M·d) per point); it has no
    /// exported variance (`cholesky = true` is an [`GpError::Export`]).
    ///
    /// Errors: `j` out of range, or a model with a function prior mean
    /// (the exported predictor has only a constant mean: export the GP of
    /// the residual, trained with a zero mean, and add the function in the
    /// embedded code, as vigp's learned model with its nominal prior does).
    pub fn export_output(&self, j: usize, cholesky: bool) -> Result<ExportedArrays, GpError> {
        let o = self.outputs.get(j).ok_or(GpError::DimensionMismatch {
            what: "output index (< output dimension)",
            expected: self.p,
            got: j,
        })?;
        let prior_mean = match &self.mean {
            Resolved::Zero => 0.0,
            Resolved::Constant(c) => c[j],
            Resolved::Function(_) => {
                return Err(export_error(
                    "a function prior mean cannot be exported (train the residual with a zero mean)",
                ));
            }
        };
        let n = o.alpha.len();
        let cholesky = match (&o.post, cholesky) {
            (_, false) => None,
            (Posterior::Exact { l, .. }, true) => Some(packed::to_column_packed(l, n)),
            (Posterior::Sparse { .. }, true) => {
                return Err(export_error(
                    "a sparse GP exports its mean only (its variance needs two M × M factors, \
                     which ExportedGp does not hold): export with cholesky = false",
                ));
            }
        };
        Ok(ExportedArrays {
            input_dim: self.d,
            inputs: o.xs_cols.clone(),
            weights: o.alpha.clone(),
            length_scales: o.hp.length_scales.clone(),
            signal_variance: o.hp.signal_variance,
            input_shift: self.input_norm.shift.clone(),
            input_scale: self.input_norm.scale.clone(),
            output_scale: o.output_scale,
            prior_mean,
            cholesky,
        })
    }

    /// The model as Rust source: `static` arrays and one
    /// `ExportedGp<'static, d>` per output in `<NAME>: [ExportedGp; p]`,
    /// plus `<NAME>_INPUT_DIM`, `<NAME>_OUTPUT_DIM`, `<NAME>_N` and, with
    /// check points, `<NAME>_CHECK_POINTS` / `<NAME>_CHECK_MEANS` (and
    /// `<NAME>_CHECK_VARIANCES` with the Cholesky factor) holding this
    /// model's predictions. The text compiles in a `#![no_std]` crate as a
    /// module or through `include!`; it is deterministic and its floats
    /// round-trip exactly.
    ///
    /// Size: p·N·(d + 1) numbers, plus p·N(N+1)/2 with the factor.
    ///
    /// ```
    /// use vigp_gp::{ExportOptions, Gp, TrainOptions};
    /// let x: Vec<f64> = (0..10).map(|i| i as f64 * 0.3).collect();
    /// let y: Vec<f64> = x.iter().map(|v| v.sin()).collect();
    /// let (gp, _) = Gp::train(&x, 1, &y, 1, &TrainOptions::default())?;
    /// let src = gp.to_rust_source(&ExportOptions::default())?;
    /// assert!(src.contains("pub static GP: [vigp::embedded::gp::ExportedGp<'static, 1>; 1]"));
    /// # Ok::<(), vigp_gp::GpError>(())
    /// ```
    pub fn to_rust_source(&self, opts: &ExportOptions) -> Result<String, GpError> {
        let (d, p) = (self.d, self.p);
        let n = self.posterior_points();
        opts.validate(d)?;
        let outputs = (0..p)
            .map(|j| self.export_output(j, opts.cholesky))
            .collect::<Result<Vec<_>, _>>()?;
        let name = &opts.name;
        let ty = format!("{}::gp::ExportedGp<'static, {d}>", opts.core_path);
        let mut s = String::new();
        // `write!` into a String cannot fail.
        let _ = writeln!(
            s,
            "// @generated by vigp-runtime {} (Gp::to_rust_source). Do not edit.",
            env!("CARGO_PKG_VERSION")
        );
        for l in &opts.header {
            let _ = writeln!(s, "// {l}");
        }
        let _ = writeln!(
            s,
            "//\n// A Gaussian process with {p} output(s) on {d} input(s), N = {n} training points,\n\
             // ARD squared-exponential kernel; predict with {}::gp::ExportedGp.\n\
             // Hyperparameters are in normalised units (see the ExportedGp docs).",
            opts.core_path
        );
        if self.is_sparse() {
            let _ = writeln!(
                s,
                "// Sparse GP (SGPR) trained on {} samples: the {n} \"training points\" below\n\
                 // are its inducing points, the weights its predictive weights u.",
                self.n
            );
        }
        for (j, o) in self.outputs.iter().enumerate() {
            let _ = writeln!(
                s,
                "// output {j}: noise variance {}, jitter {}, log marginal likelihood {}",
                lit(o.hp.noise_variance),
                lit(o.jitter),
                lit(o.lml)
            );
        }
        let _ = writeln!(
            s,
            "\n/// Input dimension d.\npub const {name}_INPUT_DIM: usize = {d};\n\
             /// Number of outputs p (one GP each).\npub const {name}_OUTPUT_DIM: usize = {p};\n\
             /// Number of training points N.\npub const {name}_N: usize = {n};\n"
        );
        let _ = writeln!(s, "/// The GP of every output.");
        let _ = writeln!(s, "{ITEM_ATTRS}pub static {name}: [{ty}; {p}] = [");
        for (j, a) in outputs.iter().enumerate() {
            let _ = writeln!(s, "    {}::gp::ExportedGp {{", opts.core_path);
            let _ = writeln!(s, "        inputs: &{name}_{j}_INPUTS,");
            let _ = writeln!(s, "        weights: &{name}_{j}_WEIGHTS,");
            let _ = writeln!(
                s,
                "        length_scales: {},",
                inline_array(&a.length_scales)
            );
            let _ = writeln!(s, "        signal_variance: {},", lit(a.signal_variance));
            let _ = writeln!(s, "        input_shift: {},", inline_array(&a.input_shift));
            let _ = writeln!(s, "        input_scale: {},", inline_array(&a.input_scale));
            let _ = writeln!(s, "        output_scale: {},", lit(a.output_scale));
            let _ = writeln!(s, "        prior_mean: {},", lit(a.prior_mean));
            if a.cholesky.is_some() {
                let _ = writeln!(s, "        cholesky: Some(&{name}_{j}_CHOLESKY),");
            } else {
                let _ = writeln!(s, "        cholesky: None,");
            }
            let _ = writeln!(s, "    }},");
        }
        let _ = writeln!(s, "];");
        for (j, a) in outputs.iter().enumerate() {
            let _ = writeln!(
                s,
                "\n/// Output {j}: scaled training inputs ((x - shift)/scale)/length_scale, \
                 column-major {d} x {n} (one block of {n} per input dimension)."
            );
            let _ = writeln!(
                s,
                "{ITEM_ATTRS}pub static {name}_{j}_INPUTS: [f64; {}] = [",
                n * d
            );
            for (c, col) in a.inputs.chunks(n).enumerate() {
                let _ = writeln!(s, "    // input dimension {c}");
                write_array(&mut s, col, 4);
            }
            let _ = writeln!(s, "];");
            let _ = writeln!(
                s,
                "\n/// Output {j}: weights alpha = (K + noise I)^-1 r (normalised units)."
            );
            let _ = writeln!(
                s,
                "{ITEM_ATTRS}pub static {name}_{j}_WEIGHTS: [f64; {n}] = ["
            );
            write_array(&mut s, &a.weights, 4);
            let _ = writeln!(s, "];");
            if let Some(l) = &a.cholesky {
                let _ = writeln!(
                    s,
                    "\n/// Output {j}: lower Cholesky factor of K + noise I, packed column by column."
                );
                let _ = writeln!(
                    s,
                    "{ITEM_ATTRS}pub static {name}_{j}_CHOLESKY: [f64; {}] = [",
                    l.len()
                );
                write_array(&mut s, l, 4);
                let _ = writeln!(s, "];");
            }
        }
        if !opts.check_points.is_empty() {
            let k = opts.check_points.len();
            let flat: Vec<f64> = opts.check_points.concat();
            let pred = self.predict(&flat)?;
            write_table(
                &mut s,
                "GP inputs (original units) at which the exporting std model was evaluated.",
                &format!("{name}_CHECK_POINTS: [[f64; {d}]; {k}]"),
                opts.check_points.iter().map(Vec::as_slice),
            );
            write_table(
                &mut s,
                "The std model's posterior means at the check points (one per output).",
                &format!("{name}_CHECK_MEANS: [[f64; {p}]; {k}]"),
                pred.mean.chunks(p),
            );
            if opts.cholesky {
                write_table(
                    &mut s,
                    "The std model's latent variances at the check points (one per output).",
                    &format!("{name}_CHECK_VARIANCES: [[f64; {p}]; {k}]"),
                    pred.variance.chunks(p),
                );
            }
        }
        Ok(s)
    }
}
