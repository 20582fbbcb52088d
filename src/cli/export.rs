//! `vigp export`: the Rust source of a learned model for no_std firmware.

use std::io::Write;

use super::args::ExportArgs;
use super::{CliError, check_out_dir, io_error, w};
use crate::learned::{EmbeddedExport, Learned};
use crate::{Mechanism, Parameters};

pub(super) fn export<M, const N: usize, const C: usize>(
    a: &ExportArgs,
    learned: &Learned<M, N, C>,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    M: Mechanism<N, C> + Parameters + Clone,
{
    let opts = EmbeddedExport {
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
    };
    check_out_dir(&a.out)?;
    let (src, size) = learned.to_embedded_source(&opts)?;
    let sparse = learned.gp().is_sparse();
    std::fs::write(&a.out, &src).map_err(io_error(&a.out))?;
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
            if learned.inputs() > 0 {
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
            },
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
