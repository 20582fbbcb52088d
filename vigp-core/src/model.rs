//! The fixed-size model interface that `mechanism!` implements for every
//! mechanism (minimal coordinates), and the mechanical terms computed from
//! it with jets: mass matrix M(q), its derivatives ∂M/∂q_i, the potential
//! gradient ∇V(q), the damping matrix D(q) and the energy.
//!
//! Every planar mechanism of the DSL has L(q, v) = ½ vᵀM(q)v − V(q) and a
//! Rayleigh function R = ½ vᵀD(q)v, so these terms determine the dynamics.
//! One evaluation of the kinematics on [`Jet2`] gives all of them exactly
//! (no finite differences, no nested duals).

use crate::dynamics::Terms;
use crate::kinematics::Point2;
use crate::real::{Jet1, Jet2, Real};
use crate::state::CoordinateKind;
use nalgebra::{SMatrix, SVector};

/// One rigid body as the kinematics sees it at some q.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Body<R> {
    /// Mass (kg).
    pub mass: f64,
    /// Rotational inertia about the centre of mass (kg·m²).
    pub inertia: f64,
    /// World position of the centre of mass.
    pub com: Point2<R>,
    /// Orientation.
    pub theta: R,
}

/// A planar mechanism in `N` minimal coordinates with `C` loop constraints,
/// described by its bodies, dampers and constraints as functions of q for
/// any [`Real`]. Implemented by `mechanism!` for the parameter struct.
pub trait Model<const N: usize, const C: usize> {
    /// What each coordinate measures.
    const KINDS: [CoordinateKind; N];
    /// `true` when some joint declares damping.
    const DISSIPATIVE: bool;

    /// Gravitational acceleration (m/s²).
    fn gravity(&self) -> [f64; 2];

    /// Calls `visit` with every body at configuration `q`.
    fn for_each_body<R: Real>(&self, q: &SVector<R, N>, visit: &mut impl FnMut(Body<R>));

    /// Calls `visit(c, s)` for every joint with damping coefficient `c` and
    /// joint coordinate `s(q)` (its rate is ∇s·v). Default: none.
    fn for_each_damper<R: Real>(&self, q: &SVector<R, N>, visit: &mut impl FnMut(f64, R)) {
        let _ = (q, visit);
    }

    /// Loop constraints g(q) (empty for a tree).
    fn constraints<R: Real>(&self, q: &SVector<R, N>) -> SVector<R, C> {
        let _ = q;
        SVector::from_element(R::from_f64(0.0))
    }
}

fn seed1<const N: usize>(q: &SVector<f64, N>) -> SVector<Jet1<N>, N> {
    SVector::from_fn(|i, _| Jet1::variable(q[i], i))
}

fn seed2<const N: usize>(q: &SVector<f64, N>) -> SVector<Jet2<N>, N> {
    SVector::from_fn(|i, _| Jet2::variable(q[i], i))
}

/// M(q), ∂M/∂q, ∇V(q) and D(q) in one [`Jet2`] pass of the kinematics
/// (plus one [`Jet1`] pass of the damped joints if dissipative).
///
/// Cost: the kinematics on `N`-direction second-order jets, plus `O(N³)`
/// per body for ∂M.
pub fn terms<M: Model<N, C>, const N: usize, const C: usize>(
    model: &M,
    q: &SVector<f64, N>,
) -> Terms<N> {
    let g = model.gravity();
    let mut t = Terms {
        mass: SMatrix::zeros(),
        dmass: [SMatrix::zeros(); N],
        dpotential: SVector::zeros(),
        damping: SMatrix::zeros(),
    };
    // tt[j][l][k] = Σ_bodies m(∂²x/∂q_j∂q_l ∂x/∂q_k + same for y)
    // + I ∂²θ/∂q_j∂q_l ∂θ/∂q_k, symmetric in (j, l): only j ≤ l is formed.
    // Then ∂M_jk/∂q_l = tt[j][l][k] + tt[k][l][j]. Scaling the gradients by
    // m and I once per body makes every entry three products.
    let mut tt = [[[0.0f64; N]; N]; N];
    model.for_each_body(&seed2(q), &mut |b: Body<Jet2<N>>| {
        let ([x, y], th, m, i) = (b.com, b.theta, b.mass, b.inertia);
        let (mut mx, mut my, mut it) = ([0.0f64; N], [0.0f64; N], [0.0f64; N]);
        for k in 0..N {
            (mx[k], my[k], it[k]) = (m * x.g[k], m * y.g[k], i * th.g[k]);
        }
        for j in 0..N {
            t.dpotential[j] -= g[0] * mx[j] + g[1] * my[j];
            // M is symmetric: accumulate k ≥ j only.
            for k in j..N {
                t.mass[(j, k)] += x.g[j] * mx[k] + y.g[j] * my[k] + th.g[j] * it[k];
            }
            // Indexed on purpose: the iterator form (enumerate/skip over
            // tt[j]) measured 9% more instructions per double-pendulum step.
            #[allow(clippy::needless_range_loop)]
            for l in j..N {
                let (hx, hy, ht) = (x.h[j][l], y.h[j][l], th.h[j][l]);
                for k in 0..N {
                    tt[j][l][k] += hx * mx[k] + hy * my[k] + ht * it[k];
                }
            }
        }
    });
    let t_at = |j: usize, l: usize, k: usize| {
        if j <= l { tt[j][l][k] } else { tt[l][j][k] }
    };
    for j in 0..N {
        for k in j..N {
            for (l, dm) in t.dmass.iter_mut().enumerate() {
                let v = t_at(j, l, k) + t_at(k, l, j);
                dm[(j, k)] = v;
                dm[(k, j)] = v;
            }
        }
        for k in 0..j {
            t.mass[(j, k)] = t.mass[(k, j)];
        }
    }
    if M::DISSIPATIVE {
        model.for_each_damper(&seed1(q), &mut |c: f64, s: Jet1<N>| {
            for j in 0..N {
                for k in 0..N {
                    t.damping[(j, k)] += c * s.g[j] * s.g[k];
                }
            }
        });
    }
    t
}

/// Mass matrix M(q) (one [`Jet1`] pass).
pub fn mass_matrix<M: Model<N, C>, const N: usize, const C: usize>(
    model: &M,
    q: &SVector<f64, N>,
) -> SMatrix<f64, N, N> {
    let mut mass = SMatrix::zeros();
    model.for_each_body(&seed1(q), &mut |b: Body<Jet1<N>>| {
        let ([x, y], th) = (b.com, b.theta);
        for j in 0..N {
            let (mx, my, it) = (b.mass * x.g[j], b.mass * y.g[j], b.inertia * th.g[j]);
            // symmetric: k ≥ j only
            for k in j..N {
                mass[(j, k)] += mx * x.g[k] + my * y.g[k] + it * th.g[k];
            }
        }
    });
    for j in 0..N {
        for k in 0..j {
            mass[(j, k)] = mass[(k, j)];
        }
    }
    mass
}

/// Total energy ½ vᵀM(q)v + V(q), with V = −Σ m g·p_com.
pub fn energy<M: Model<N, C>, const N: usize, const C: usize>(
    model: &M,
    q: &SVector<f64, N>,
    v: &SVector<f64, N>,
) -> f64 {
    let g = model.gravity();
    let mut e = 0.0;
    model.for_each_body(&seed1(q), &mut |b: Body<Jet1<N>>| {
        let ([x, y], th) = (b.com, b.theta);
        let rate = |j: &Jet1<N>| j.g.iter().zip(v.iter()).map(|(a, b)| a * b).sum::<f64>();
        let (vx, vy, w) = (rate(&x), rate(&y), rate(&th));
        e += 0.5 * b.mass * (vx * vx + vy * vy) + 0.5 * b.inertia * w * w
            - b.mass * (g[0] * x.v + g[1] * y.v);
    });
    e
}

/// Loop constraints g(q) and their Jacobian G(q) (one [`Jet1`] pass).
pub fn constraints_and_jacobian<M: Model<N, C>, const N: usize, const C: usize>(
    model: &M,
    q: &SVector<f64, N>,
) -> (SVector<f64, C>, SMatrix<f64, C, N>) {
    let gj = model.constraints(&seed1(q));
    (
        SVector::from_fn(|r, _| gj[r].v),
        SMatrix::from_fn(|r, k| gj[r].g[k]),
    )
}
