//! Base parameters: the combinations of standard parameters that the data
//! determine, by a rank-revealing QR decomposition with column pivoting.
//!
//! With the columns of the stacked regressor W scaled to unit norm (so that
//! units do not decide), Businger–Golub pivoting (at each step, the column
//! with the largest norm orthogonal to those already chosen) splits the
//! columns into r independent ones W₁ and dependent ones W₂ = W₁·β (to the
//! rank tolerance). Then W·π = W₁·(π₁ + β·π₂): the base parameters are
//! π_b = K·π with K = [1 β] (in the original order), each one independent
//! parameter plus named multiples of dependent ones. A standard parameter
//! is identifiable by itself when no null-space direction of W touches it.

use nalgebra::DMatrix;

/// The base parameters of a stacked regressor.
#[derive(Clone, Debug, PartialEq)]
pub struct Base {
    /// Indices (into π) of the independent columns, one per base parameter,
    /// in pivot order.
    pub independent: Vec<usize>,
    /// Indices of the dependent columns (including columns that are zero:
    /// parameters the residual does not involve at all).
    pub dependent: Vec<usize>,
    /// K (r × P): base parameters π_b = K·π.
    pub k: DMatrix<f64>,
    /// A basis of the null space of W (P × (P − r)): directions of π that
    /// the data cannot see.
    pub null: DMatrix<f64>,
    /// The pivots' norms relative to the first (scaled columns): the
    /// rank-revealing diagonal of R.
    pub pivots: Vec<f64>,
}

/// Entries of K or of the null basis below this are rounding: set to zero
/// so that the combinations read as the exact ones.
const CLEAN: f64 = 1e-10;

impl Base {
    /// The base parameters of the stacked regressor `w` (rows × P);
    /// columns whose pivot falls below `tolerance` (relative to the first,
    /// after scaling every column to unit norm) are dependent.
    pub fn new(w: &DMatrix<f64>, tolerance: f64) -> Self {
        let p = w.ncols();
        let norms: Vec<f64> = (0..p).map(|j| w.column(j).norm()).collect();
        let wmax = norms.iter().cloned().fold(0.0, f64::max);
        // Compress the rows first (R of an unpivoted QR has the same column
        // geometry as W), then scale.
        let r0 = if w.nrows() > p {
            w.clone().qr().r()
        } else {
            w.clone()
        };
        let mut a = r0.clone();
        let mut live = vec![false; p];
        for j in 0..p {
            // A column is zero when it is rounding next to the largest one.
            if norms[j] > 1e-14 * wmax && norms[j] > 0.0 {
                live[j] = true;
                let s = 1.0 / norms[j];
                a.column_mut(j).scale_mut(s);
            } else {
                a.column_mut(j).fill(0.0);
            }
        }
        // Modified Gram–Schmidt with column pivoting and one
        // re-orthogonalisation per step.
        let mut chosen = Vec::new();
        let mut pivots = Vec::new();
        let mut q: Vec<nalgebra::DVector<f64>> = Vec::new();
        let mut remaining: Vec<usize> = (0..p).filter(|j| live[*j]).collect();
        let mut first = 0.0;
        while !remaining.is_empty() {
            let (pos, best) = remaining
                .iter()
                .enumerate()
                .map(|(i, &j)| (i, a.column(j).norm()))
                .fold((0, -1.0), |acc, x| if x.1 > acc.1 { x } else { acc });
            if chosen.is_empty() {
                first = best;
            }
            if first == 0.0 || best <= tolerance * first {
                break;
            }
            let j = remaining.remove(pos);
            let qj = a.column(j) / best;
            for &k in &remaining {
                for _ in 0..2 {
                    let d = qj.dot(&a.column(k));
                    let upd = a.column(k) - &qj * d;
                    a.set_column(k, &upd);
                }
            }
            q.push(qj);
            chosen.push(j);
            pivots.push(best / first);
        }
        let dependent: Vec<usize> = (0..p).filter(|j| !chosen.contains(j)).collect();
        let r = chosen.len();
        // β from the unscaled compressed columns: W₁ β = W₂ in least squares.
        let w1 = DMatrix::from_fn(r0.nrows(), r, |i, c| r0[(i, chosen[c])]);
        let w2 = DMatrix::from_fn(r0.nrows(), dependent.len(), |i, c| r0[(i, dependent[c])]);
        let beta = if r > 0 && !dependent.is_empty() {
            let svd = w1.clone().svd(true, true);
            svd.solve(&w2, 0.0)
                .unwrap_or_else(|_| DMatrix::zeros(r, dependent.len()))
        } else {
            DMatrix::zeros(r, dependent.len())
        };
        let mut k = DMatrix::zeros(r, p);
        for (i, &j) in chosen.iter().enumerate() {
            k[(i, j)] = 1.0;
            for (d, &jd) in dependent.iter().enumerate() {
                let v = beta[(i, d)];
                k[(i, jd)] = v;
            }
        }
        // Null directions: n_d = e_{dep d} − Σ_i β_{i d} e_{ind i}.
        let mut null = DMatrix::zeros(p, dependent.len());
        for (d, &jd) in dependent.iter().enumerate() {
            null[(jd, d)] = 1.0;
            for (i, &j) in chosen.iter().enumerate() {
                null[(j, d)] = -beta[(i, d)];
            }
        }
        let clean = |m: &mut DMatrix<f64>| {
            for v in m.iter_mut() {
                if v.abs() < CLEAN {
                    *v = 0.0;
                }
            }
        };
        clean(&mut k);
        clean(&mut null);
        Base {
            independent: chosen,
            dependent,
            k,
            null,
            pivots,
        }
    }

    /// Number of base parameters.
    pub fn rank(&self) -> usize {
        self.independent.len()
    }

    /// Whether standard parameter `i` is identifiable by itself (no
    /// direction the data cannot see moves it).
    pub fn identifiable(&self, i: usize) -> bool {
        (0..self.null.ncols()).all(|d| self.null[(i, d)] == 0.0)
    }

    /// The base parameters as readable combinations of the standard names,
    /// e.g. `links.upper.inertia_o + 1·links.lower.mass`.
    pub fn names(&self, standard: &[String]) -> Vec<String> {
        (0..self.rank())
            .map(|i| {
                let mut s = standard[self.independent[i]].clone();
                for (j, name) in standard.iter().enumerate() {
                    let c = self.k[(i, j)];
                    if j == self.independent[i] || c == 0.0 {
                        continue;
                    }
                    let sign = if c < 0.0 { '−' } else { '+' };
                    s.push_str(&format!(" {sign} {}·{name}", fmt_coefficient(c.abs())));
                }
                s
            })
            .collect()
    }
}

fn fmt_coefficient(c: f64) -> String {
    let r = (c * 1e6).round() / 1e6;
    if (r - c).abs() <= 1e-9 * c.abs().max(1.0) {
        format!("{r}")
    } else {
        format!("{c:.6e}")
    }
}
