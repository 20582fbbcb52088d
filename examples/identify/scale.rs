//! The scale of π for logs of free motion.
//!
//! Without inputs the DEL residual is homogeneous in the standard
//! parameters: r(α·π) = α·r(π) for every α, so a log of free motion
//! determines π only up to a common factor, and every factor α > 0 predicts
//! the same motion (the residual's root does not move). The rows then have
//! nothing on their right-hand side (b = 0), and least squares shrinks the
//! estimate towards zero, which is no mechanism at all. The factor must
//! come from the prior, and [`ScaleFixed`] takes it from there: it holds
//! one linear combination ℓ·π at its declared value ℓ·π₀,
//!
//! ```text
//! residual(π) = r(h(π)),   h(π) = π + (ℓ·π₀ − ℓ·π)/(ℓ·d) · d,   d = S²ℓ,
//! ```
//!
//! (S² the prior's covariance), which is affine in π, so the rows become
//! Y·P and b − Y·d (ℓ·π₀)/(ℓ·d) with P = 1 − dℓᵀ/(ℓ·d): they now have a
//! right-hand side, and see nothing along d. Moving along d = S²ℓ, the
//! prior's own metric, the estimate's conditional mean keeps ℓ·π̂ = ℓ·π₀,
//! so h(π̂) = π̂ unless the consistency projection moved it; the identified
//! mechanism is h(π̂). With the scale of the prior (ℓ·π₀ instead of ℓ·π*,
//! some 10 % off on the paper's systems) it moves as the true-scale one
//! would.
//!
//! ℓ is the prior's own direction, c_p = π₀_p/s_p² (π₀ the declared values,
//! s_p the prior's standard deviations), made orthogonal to the structural
//! null space: the combinations that no position data can see (a
//! pendulum's mass about a fixed pivot; in a loop, combinations of the
//! links' masses and inertias). Otherwise a vector of that null space,
//! which moves nothing, could meet ℓ·π = ℓ·π₀ with every combination the
//! data see at zero: a mechanism without dynamics, which fits free motion
//! as well as the truth. [`scale_direction`] finds that null space from
//! arbitrary position triples, on which no mechanism's residual vanishes,
//! so that the scale direction is not null there.
//!
//! Appending a heavy row ℓ·π = ℓ·π₀ instead was tried first and fails: the
//! per-row noise estimate of `identify` sees no residual on such a row and
//! weights it some 10¹⁵ above the others, which the solve cannot keep apart
//! from rounding.

use nalgebra::{DMatrix, DVector};
use vigp::identify::{IdentifyError, Log, Noise, Prior, Regressor, Structure, Transition, stack};

/// The direction ℓ (module docs): `triples` are logs of three arbitrary
/// positions each (consistent with any loop constraints, not with any
/// dynamics), `prior` the identification's prior. The structural null
/// space is spanned by the right singular vectors of their rows (columns
/// scaled to unit norm) at or below 1e-8 of the largest singular value.
pub fn scale_direction<R: Regressor>(
    inner: &R,
    triples: &[Log],
    prior: &Prior,
) -> Result<DVector<f64>, IdentifyError> {
    let (rows, _) = stack(inner, triples, Noise::LeastSquares)?;
    let w = &rows.w;
    let p = w.ncols();
    if w.nrows() < p {
        return Err(IdentifyError::TooFewTransitions {
            rows: w.nrows(),
            needed: p,
        });
    }
    // W·x = 0 ⇔ x = v/‖Y_j‖ entrywise for v in the scaled null space; a
    // column that is rounding next to the largest (below 1e-12 of it, as
    // `Base` does at 1e-14) is zero, not a unit vector of rounding
    let norms: Vec<f64> = (0..p).map(|j| w.column(j).norm()).collect();
    let wmax = norms.iter().copied().fold(0.0, f64::max);
    let live: Vec<bool> = norms.iter().map(|&n| n > 1e-12 * wmax).collect();
    let norms: Vec<f64> = (0..p)
        .map(|j| if live[j] { norms[j] } else { 1.0 })
        .collect();
    let scaled = DMatrix::from_fn(w.nrows(), p, |i, j| {
        if live[j] { w[(i, j)] / norms[j] } else { 0.0 }
    });
    let svd = scaled.svd(false, true);
    let vt = svd.v_t.ok_or(IdentifyError::Singular)?;
    let top = svd.singular_values.amax();
    let null: Vec<DVector<f64>> = (0..p)
        .filter(|&k| svd.singular_values[k] <= 1e-8 * top)
        .map(|k| DVector::from_fn(p, |j, _| vt[(k, j)] / norms[j]))
        .collect();
    let declared = inner.standard();
    let sd = prior.sd(inner.structure(), &declared);
    let mut l = DVector::from_fn(p, |j, _| declared[j] / (sd[j] * sd[j]));
    if !null.is_empty() {
        let q = DMatrix::from_columns(&null).qr().q();
        l -= &q * (q.transpose() * &l);
    }
    let size = l.norm();
    if !(size.is_finite() && size > 0.0) {
        return Err(IdentifyError::NonFinite {
            what: "scale direction (the prior's direction lies in the structural null space)"
                .into(),
        });
    }
    Ok(l / size)
}

/// A regressor with ℓ·π held at its declared value (module docs).
pub struct ScaleFixed<'a, R> {
    inner: &'a R,
    /// ℓ.
    l: DVector<f64>,
    /// d/(ℓ·d), d = S²ℓ.
    d: DVector<f64>,
    /// ℓ·π₀.
    target: f64,
}

impl<'a, R: Regressor> ScaleFixed<'a, R> {
    /// `inner` with ℓ·π held (`l` from [`scale_direction`] with the same
    /// `prior`).
    pub fn new(inner: &'a R, l: DVector<f64>, prior: &Prior) -> Self {
        let declared = inner.standard();
        let sd = prior.sd(inner.structure(), &declared);
        let d = DVector::from_fn(l.len(), |j, _| sd[j] * sd[j] * l[j]);
        let d = &d / l.dot(&d);
        let target = l.dot(&DVector::from_vec(declared));
        Self {
            inner,
            l,
            d,
            target,
        }
    }

    /// The rows (Y, b) of the inner regressor as rows of this one:
    /// Y·P and b − Y·d (ℓ·π₀)/(ℓ·d) (module docs).
    fn held(&self, (y, b): (DMatrix<f64>, DVector<f64>)) -> (DMatrix<f64>, DVector<f64>) {
        let yd = &y * &self.d;
        (&y - &yd * self.l.transpose(), b - yd * self.target)
    }

    /// h(π): `pi` moved along d onto ℓ·π = ℓ·π₀, the parameters the rows
    /// of this regressor describe.
    pub fn hold(&self, pi: &[f64]) -> Vec<f64> {
        let pi = DVector::from_column_slice(pi);
        let shift = self.target - self.l.dot(&pi);
        (pi + &self.d * shift).iter().copied().collect()
    }
}

impl<R: Regressor> Regressor for ScaleFixed<'_, R> {
    fn structure(&self) -> &Structure {
        self.inner.structure()
    }

    fn coordinates(&self) -> usize {
        self.inner.coordinates()
    }

    fn inputs(&self) -> usize {
        self.inner.inputs()
    }

    fn rows(&self) -> usize {
        self.inner.rows()
    }

    fn standard(&self) -> Vec<f64> {
        self.inner.standard()
    }

    fn residual(&self, t: &Transition<'_>, pi: &[f64]) -> Result<DVector<f64>, IdentifyError> {
        self.inner.residual(t, &self.hold(pi))
    }

    fn transition(
        &self,
        t: &Transition<'_>,
    ) -> Result<(DMatrix<f64>, DVector<f64>), IdentifyError> {
        self.inner.transition(t).map(|rows| self.held(rows))
    }

    fn noise_jacobian(
        &self,
        t: &Transition<'_>,
        pi: &[f64],
    ) -> Result<DMatrix<f64>, IdentifyError> {
        self.inner.noise_jacobian(t, &self.hold(pi))
    }

    // what output error simulates: the inner mechanism at h(π), its rows
    // held as `transition`'s are, its loops its own

    fn position_jacobians(
        &self,
        t: &Transition<'_>,
        pi: &[f64],
    ) -> Result<(DVector<f64>, [DMatrix<f64>; 3]), IdentifyError> {
        self.inner.position_jacobians(t, &self.hold(pi))
    }

    fn unprojected_transition(
        &self,
        t: &Transition<'_>,
    ) -> Result<(DMatrix<f64>, DVector<f64>), IdentifyError> {
        self.inner
            .unprojected_transition(t)
            .map(|rows| self.held(rows))
    }

    fn loop_constraints(
        &self,
        x: &[f64],
    ) -> Result<Option<(DVector<f64>, DMatrix<f64>)>, IdentifyError> {
        self.inner.loop_constraints(x)
    }

    fn loop_curvature(&self, x: &[f64], lambda: &[f64]) -> Result<DMatrix<f64>, IdentifyError> {
        self.inner.loop_curvature(x, lambda)
    }
}
