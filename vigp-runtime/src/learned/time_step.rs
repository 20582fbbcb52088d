//! The time step that transitions were formed with: consecutive
//! transitions of one run (recognised by z_{k+1}.v = v_next of z_k, bit for
//! bit) satisfy x_{k+1} = x_k + Δt·v_k, which gives Δt by least squares,
//! ((x_{k+1} − x_k)·v_k)/(v_k·v_k). Used by training (a Δt far from the
//! data's is an error) and by `vigp::data::check_transitions_dt` (tight).

use crate::mechanism::State;
use nalgebra::SVector;

/// The median of the per-pair estimates of Δt over consecutive pairs of
/// (z, v_next), with the index of the first transition of the pair it came
/// from; `None` when no pair belongs to one run or every such pair is at
/// rest.
pub(crate) fn estimate<'a, const N: usize>(
    pairs: impl Iterator<Item = (&'a State<N>, &'a SVector<f64, N>)>,
) -> Option<(f64, usize)> {
    let mut estimates: Vec<(f64, usize)> = Vec::new();
    let mut last: Option<(&State<N>, &SVector<f64, N>)> = None;
    for (i, (z1, v_next1)) in pairs.enumerate() {
        if let Some((z0, v_next)) = last {
            let same_run =
                z1.v.iter()
                    .zip(v_next.iter())
                    .all(|(a, b)| a.to_bits() == b.to_bits());
            let vv = z0.v.dot(&z0.v);
            if same_run && vv.is_finite() && vv > 0.0 {
                let est = (z1.q - z0.q).dot(&z0.v) / vv;
                if est.is_finite() && est > 0.0 {
                    estimates.push((est, i - 1));
                }
            }
        }
        last = Some((z1, v_next1));
    }
    if estimates.is_empty() {
        return None;
    }
    estimates.sort_by(|a, b| a.0.total_cmp(&b.0));
    Some(estimates[estimates.len() / 2])
}

/// A hint when `given` and `found` differ by a round factor.
pub(crate) fn factor_hint(given: f64, found: f64) -> &'static str {
    let ratio = given / found;
    let near = |r: f64| (ratio / r - 1.0).abs() < 1e-3;
    if near(1000.0) || near(1e-3) {
        " (a factor of 1000: milliseconds against seconds?)"
    } else if near(2.0) || near(0.5) {
        " (a factor of 2)"
    } else {
        ""
    }
}
