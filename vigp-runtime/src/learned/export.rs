//! A learned model as Rust source for `no_std` prediction: the GP's
//! arrays ([`Gp::to_rust_source`](crate::gp::Gp::to_rust_source)) plus the
//! integrator's constants (Δt, the input encoding, the prior).

use core::fmt::Write;

use super::{Encoding, Learned, Prior};
use crate::gp::{ExportOptions, GpError};
use crate::integrator::Integrator;
use crate::mechanism::{CoordinateKind, Mechanism};

impl<M: Mechanism<N, C> + Clone, const N: usize, const C: usize> Learned<M, N, C> {
    /// The learned velocity map's GP as Rust source ([`Gp::to_rust_source`](crate::gp::Gp::to_rust_source)),
    /// plus what embedded code needs to use it: `<NAME>_DT`, the input
    /// encoding (`<NAME>_ENCODING`, documented component by component) and
    /// the prior (`<NAME>_PRIOR`: with `"nominal"` the GP predicts
    /// v_{k+1} − v̄(z_k), to be added to the nominal variational step
    /// v̄(z_k); with `"constant"` the GP mean is the velocity itself). A
    /// model with an identified prior says `"nominal"`: its nominal step is
    /// that of the mechanism with the identified parameters
    /// ([`Learned::model`]).
    /// The projection onto constraints (C > 0) is not exported.
    pub fn to_rust_source(&self, opts: &ExportOptions) -> Result<String, GpError> {
        let mut s = self.gp().to_rust_source(opts)?;
        let name = &opts.name;
        let mut components = Vec::new();
        for (i, kind) in M::KINDS.iter().enumerate() {
            if self.encoding() == Encoding::SinCos && *kind == CoordinateKind::Angle {
                components.push(format!("sin q{i}"));
                components.push(format!("cos q{i}"));
            } else {
                components.push(format!("q{i}"));
            }
        }
        components.extend((0..N).map(|i| format!("v{i}")));
        let (encoding, prior) = (
            match self.encoding() {
                Encoding::Raw => "raw",
                Encoding::SinCos => "sincos",
            },
            match self.prior() {
                Prior::Nominal | Prior::Identified(_) => "nominal",
                Prior::Constant => "constant",
            },
        );
        let dt = Integrator::dt(self);
        let _ = writeln!(
            s,
            "\n/// Time step of the learned integrator (s).\npub const {name}_DT: f64 = {dt:?};\n\
             /// GP input encoding of a state z = (q, v): [{}].\npub const {name}_ENCODING: &str = \"{encoding}\";\n\
             /// Prior of the velocity map: \"nominal\" (GP = v_next - nominal VI step) or \"constant\" (GP = v_next).\n\
             pub const {name}_PRIOR: &str = \"{prior}\";",
            components.join(", ")
        );
        Ok(s)
    }
}
