//! A spatial link's inertia tensor: principal moments or a symmetric
//! matrix, checked (symmetric, positive definite, physically realisable)
//! when the macro knows every entry.

use crate::ctxt::Ctxt;
use crate::desc::model::DefaultValue;
use crate::geom3::eigenvalues;
use crate::syntax::{Field, Value};

/// The inertia: three principal moments (link frame axes) or a symmetric
/// 3×3 matrix; positive definite and physically realisable (each principal
/// moment at most the sum of the other two).
pub fn inertia(cx: &mut Ctxt, f: &Field) -> Option<[[DefaultValue; 3]; 3]> {
    let v = &f.value;
    let zero = || DefaultValue::Known(0.0);
    let params = if let Some(d) = v.items(3) {
        let d: Vec<DefaultValue> = d.into_iter().map(DefaultValue::from).collect();
        [
            [d[0].clone(), zero(), zero()],
            [zero(), d[1].clone(), zero()],
            [zero(), zero(), d[2].clone()],
        ]
    } else if let Some(m) = v.matrix3() {
        m.map(|r| r.map(DefaultValue::from))
    } else {
        cx.push(
            v.span(),
            "`inertia` takes principal moments `[i1, i2, i3]` or a symmetric matrix `[[..], [..], [..]]` (kg·m², about the centre of mass, link frame)",
        );
        return None;
    };
    // Checked here when the macro knows every entry; otherwise the
    // generated model's run-time validation checks symmetry and
    // definiteness (a typed error).
    let mut m = [[0.0; 3]; 3];
    for (row, prow) in m.iter_mut().zip(&params) {
        for (x, p) in row.iter_mut().zip(prow) {
            match p.known() {
                Some(k) => *x = k,
                None => return Some(params),
            }
        }
    }
    if check_inertia(cx, v, &m) {
        Some(params)
    } else {
        None
    }
}

/// The compile-time checks of a known inertia tensor; `false` after
/// reporting a problem.
fn check_inertia(cx: &mut Ctxt, v: &Value, m: &[[f64; 3]; 3]) -> bool {
    let big = m.iter().flatten().fold(0.0f64, |a, x| a.max(x.abs()));
    let asym = (m[0][1] - m[1][0])
        .abs()
        .max((m[0][2] - m[2][0]).abs())
        .max((m[1][2] - m[2][1]).abs());
    if asym > 1e-12 * big {
        cx.push(v.span(), "`inertia` must be symmetric");
        return false;
    }
    let e = eigenvalues(m);
    let big = e.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    if !e.iter().all(|x| x.is_finite()) || e.iter().any(|&x| x <= 1e-12 * big) || big == 0.0 {
        cx.push(
            v.span(),
            format!(
                "`inertia` must be positive definite (principal moments {:.6e}, {:.6e}, {:.6e}): every rotation of a rigid link needs inertia",
                e[0], e[1], e[2]
            ),
        );
        return false;
    }
    for i in 0..3 {
        let others = e[(i + 1) % 3] + e[(i + 2) % 3];
        if e[i] > others * (1.0 + 1e-9) {
            cx.push(
                v.span(),
                format!(
                    "`inertia` is not physically realisable: principal moment {:.6e} exceeds the sum {:.6e} of the other two",
                    e[i], others
                ),
            );
            return false;
        }
    }
    true
}
