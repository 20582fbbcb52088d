//! `vigp export`: the Rust source of a learned model for no_std firmware
//! (a declared mechanism's, or a learned robot's: [`export_robot`]).

use std::io::Write;

use super::args::ExportArgs;
use super::{CliError, check_out_dir, io_error, w};
use crate::learned::{EmbeddedExport, ExportSize, Learned};
use crate::{Mechanism, Parameters};

/// The export options of the arguments.
fn options(a: &ExportArgs) -> EmbeddedExport {
    EmbeddedExport {
        name: a.name.clone(),
        core_path: a.core_path.clone(),
        variance: a.variance,
        header: vec![format!(
            "exported by `vigp export` from {}",
            a.model.file_name().map_or_else(
                || a.model.display().to_string(),
                |f| f.to_string_lossy().into()
            )
        )],
    }
}

pub(super) fn export<M, const N: usize, const C: usize>(
    a: &ExportArgs,
    learned: &Learned<M, N, C>,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    M: Mechanism<N, C> + Parameters + Clone,
{
    check_out_dir(&a.out)?;
    let (src, size) = learned.to_embedded_source(&options(a))?;
    std::fs::write(&a.out, &src).map_err(io_error(&a.out))?;
    let inputs = if learned.inputs() > 0 {
        format!(
            " (state, then control inputs {}{})",
            M::INPUT_NAMES[..learned.inputs().min(M::INPUT_NAMES.len())].join(", "),
            if learned.takes_previous_input() {
                ", previous then current"
            } else {
                ""
            }
        )
    } else {
        String::new()
    };
    report(a, &size, learned.gp().is_sparse(), &inputs, out)
}

/// `export` of a learned robot's model (`fit --urdf`): the GP arrays, the
/// prior's bodies and a `LearnedTree` static for
/// `vigp::embedded::tree::LearnedTreeStepper`.
pub(super) fn export_robot(a: &ExportArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let learned = super::robot::load_learned(&a.model)?;
    check_out_dir(&a.out)?;
    let (src, size) = learned.to_embedded_source(&options(a))?;
    std::fs::write(&a.out, &src).map_err(io_error(&a.out))?;
    let inputs = learned.robot().input_names();
    let inputs = if inputs.is_empty() {
        String::new()
    } else {
        format!(
            " (state, then inputs {}, previous then current)",
            inputs.join(", ")
        )
    };
    report(a, &size, learned.gp().is_sparse(), &inputs, out)?;
    w(
        out,
        format_args!(
            "the robot's {} bodies are in {}_BODIES; `{}::tree::LearnedTreeStepper::new(&{})` steps it",
            learned.robot().dof(),
            a.name,
            a.core_path,
            a.name
        ),
    )
}

/// What was written: the GPs' sizes.
fn report(
    a: &ExportArgs,
    size: &ExportSize,
    sparse: bool,
    inputs: &str,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    w(
        out,
        format_args!(
            "wrote {}: {} GPs on {} = {} {}points, d = {} inputs{}: {} numbers = {} bytes of f64 \
             data ({}), {} bytes of source",
            a.out.display(),
            size.outputs,
            if sparse { "M" } else { "N" },
            size.n,
            if sparse { "inducing " } else { "" },
            size.input_dim,
            inputs,
            size.numbers,
            size.data_bytes,
            if a.variance {
                "mean and variance"
            } else if sparse {
                "mean only: a sparse model exports no variance"
            } else {
                "mean only; --variance adds the Cholesky factors"
            },
            size.source_bytes
        ),
    )
}
