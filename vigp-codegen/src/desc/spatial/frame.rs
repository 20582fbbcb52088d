//! A spatial link's reference frame: its axes in world coordinates,
//! checked (non-zero, orthogonal, right-handed) and re-orthonormalised.

use crate::ctxt::Ctxt;
use crate::desc::checks;
use crate::geom3::{cross, dot, unit};
use crate::syntax::Field;

/// Tolerance on the orthogonality (cosine between axes) of a `frame`.
const FRAME_TOL: f64 = 1e-6;

/// `frame: [[x axis], [y axis], [z axis]]`: the link's axes in world
/// coordinates in the reference configuration (rows normalised, mutually
/// orthogonal to 1e-6, right-handed), as the rotation R⁰ (columns = axes),
/// re-orthonormalised exactly.
pub fn frame(cx: &mut Ctxt, f: &Field) -> Option<[[f64; 3]; 3]> {
    let v = &f.value;
    let Some(items) = v.matrix3() else {
        cx.push(
            v.span(),
            "`frame` takes the link's axes in world coordinates `[[x axis], [y axis], [z axis]]`",
        );
        return None;
    };
    let mut rows = [[0.0; 3]; 3];
    for (row, r) in rows.iter_mut().zip(items) {
        *row = checks::known(cx, r, "`frame`")?;
    }
    let mut axes = [[0.0; 3]; 3];
    for (i, r) in rows.iter().enumerate() {
        match unit(*r) {
            Some(u) => axes[i] = u,
            None => {
                cx.push(v.span(), "`frame` axes must not be zero");
                return None;
            }
        }
    }
    let worst = dot(axes[0], axes[1])
        .abs()
        .max(dot(axes[0], axes[2]).abs())
        .max(dot(axes[1], axes[2]).abs());
    if worst > FRAME_TOL {
        cx.push(
            v.span(),
            format!(
                "`frame` axes must be mutually orthogonal (largest cosine {worst:.3e} > {FRAME_TOL:e})"
            ),
        );
        return None;
    }
    if dot(cross(axes[0], axes[1]), axes[2]) <= 0.0 {
        cx.push(
            v.span(),
            "`frame` must be right-handed: x axis × y axis = z axis",
        );
        return None;
    }
    // Gram–Schmidt: x, then y ⊥ x, then z = x × y
    let x = axes[0];
    let y = unit({
        let d = dot(axes[1], x);
        [
            axes[1][0] - d * x[0],
            axes[1][1] - d * x[1],
            axes[1][2] - d * x[2],
        ]
    })?;
    let z = cross(x, y);
    // columns are the axes
    Some([[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]])
}
