//! The median, shared by `#[path]` between the examples that time or
//! summarise repeated runs (`paper`, `work_precision`).

/// Median of a slice (sorted in place); NaN when it is empty.
pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}
