//! Closed-form mechanics at compile time: trigonometric polynomials in the
//! generalized coordinates.
//!
//! Every quantity of a planar mechanism built from revolute and prismatic
//! joints — positions, the mass matrix, the potential, constraints, joint
//! coordinates and all their derivatives — is a finite sum
//!
//! ```text
//! e(q) = Σ_φ [ a_φ(p, q) · cos(φ·q) + b_φ(p, q) · sin(φ·q) ]
//! ```
//!
//! over integer frequency vectors φ (non-zero only on angle coordinates),
//! with coefficients a_φ, b_φ that are polynomials in the run-time
//! parameters p (masses, lengths, gravity, …) and in the coordinates that
//! enter polynomially (slides, maximal positions, relative angles). The set
//! is closed under sums, products (product-to-sum identities) and
//! differentiation, so the macro can form M(q), ∂M/∂q, ∇V, G(q) and their
//! second derivatives exactly and emit them as straight-line code. Grouping
//! by frequency is what a hand derivation does: the double pendulum's mass
//! matrix comes out as `a + b·cos q₂`, and ∂M/∂q₁ is structurally zero.
//!
//! Coefficients are exact rational combinations of the description's
//! numbers in f64 (halves from the product-to-sum identities are exact in
//! binary); terms whose coefficient cancels to zero are dropped.

use std::collections::BTreeMap;

/// A symbol of a polynomial coefficient.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Sym {
    /// Run-time parameter `i` of the mechanism's parameter table.
    Param(usize),
    /// Generalized coordinate q_k, where it enters polynomially.
    Coord(usize),
}

/// A product of symbols, sorted (repeated for powers).
pub type Monomial = Vec<Sym>;

/// A polynomial with f64 coefficients.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Poly {
    /// Monomial → coefficient (never 0).
    pub terms: BTreeMap<Monomial, f64>,
}

impl Poly {
    /// 0.
    pub fn zero() -> Self {
        Self::default()
    }

    /// A constant.
    pub fn constant(c: f64) -> Self {
        let mut p = Self::zero();
        p.add_term(Vec::new(), c);
        p
    }

    /// A single symbol.
    pub fn sym(s: Sym) -> Self {
        let mut p = Self::zero();
        p.add_term(vec![s], 1.0);
        p
    }

    /// `true` for the zero polynomial.
    pub fn is_zero(&self) -> bool {
        self.terms.is_empty()
    }

    fn add_term(&mut self, m: Monomial, c: f64) {
        use std::collections::btree_map::Entry;
        if c == 0.0 {
            return;
        }
        match self.terms.entry(m) {
            Entry::Occupied(mut o) => {
                *o.get_mut() += c;
                if *o.get() == 0.0 {
                    o.remove();
                }
            }
            Entry::Vacant(v) => {
                v.insert(c);
            }
        }
    }

    /// self + c·other.
    pub fn axpy(&mut self, c: f64, other: &Poly) {
        for (m, v) in &other.terms {
            self.add_term(m.clone(), c * v);
        }
    }

    /// self + other.
    pub fn add(&self, other: &Poly) -> Poly {
        let mut p = self.clone();
        p.axpy(1.0, other);
        p
    }

    /// c·self.
    pub fn scale(&self, c: f64) -> Poly {
        let mut p = Poly::zero();
        p.axpy(c, self);
        p
    }

    /// self·other.
    pub fn mul(&self, other: &Poly) -> Poly {
        let mut p = Poly::zero();
        for (m1, c1) in &self.terms {
            for (m2, c2) in &other.terms {
                let mut m: Monomial = m1.iter().chain(m2).copied().collect();
                m.sort();
                p.add_term(m, c1 * c2);
            }
        }
        p
    }

    /// ∂/∂ Coord(k).
    pub fn deriv(&self, k: usize) -> Poly {
        let s = Sym::Coord(k);
        let mut p = Poly::zero();
        for (m, c) in &self.terms {
            let n = m.iter().filter(|x| **x == s).count();
            if n == 0 {
                continue;
            }
            let mut rest = m.clone();
            let i = rest.iter().position(|x| *x == s).expect("counted above");
            rest.remove(i);
            p.add_term(rest, c * n as f64);
        }
        p
    }

    /// `true` when some monomial contains `Coord(k)` for any k.
    pub fn has_coords(&self) -> bool {
        self.terms
            .keys()
            .any(|m| m.iter().any(|s| matches!(s, Sym::Coord(_))))
    }

    /// Split by the coordinate part of each monomial: coordinate monomial →
    /// parameter polynomial (its coefficient).
    pub fn by_coordinates(&self) -> BTreeMap<Monomial, Poly> {
        let mut out: BTreeMap<Monomial, Poly> = BTreeMap::new();
        for (m, c) in &self.terms {
            let (coords, params): (Vec<Sym>, Vec<Sym>) =
                m.iter().partition(|s| matches!(s, Sym::Coord(_)));
            out.entry(coords).or_default().add_term(params, *c);
        }
        out
    }

    /// Numerical value for parameters `p` and coordinates `q`.
    pub fn eval(&self, p: &[f64], q: &[f64]) -> f64 {
        self.terms
            .iter()
            .map(|(m, c)| {
                m.iter().fold(*c, |acc, s| {
                    acc * match s {
                        Sym::Param(i) => p[*i],
                        Sym::Coord(k) => q[*k],
                    }
                })
            })
            .sum()
    }
}

/// An integer frequency vector over the coordinates, in canonical form:
/// its first non-zero entry is positive (cos is even and sin odd, so
/// −φ folds onto φ).
pub type Freq = Vec<i32>;

/// A trigonometric polynomial Σ_φ [a_φ cos(φ·q) + b_φ sin(φ·q)] (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct Expr {
    n: usize,
    /// Canonical frequency → (cos coefficient, sin coefficient); the zero
    /// frequency has no sin part; empty coefficient pairs are removed.
    pub terms: BTreeMap<Freq, (Poly, Poly)>,
}

impl Expr {
    /// 0 over `n` coordinates.
    pub fn zero(n: usize) -> Self {
        Self {
            n,
            terms: BTreeMap::new(),
        }
    }

    /// Number of coordinates.
    pub fn dim(&self) -> usize {
        self.n
    }

    /// A polynomial (zero frequency).
    pub fn poly(n: usize, p: Poly) -> Self {
        let mut e = Self::zero(n);
        e.add_trig(vec![0; n], &p, &Poly::zero());
        e
    }

    /// A constant.
    pub fn constant(n: usize, c: f64) -> Self {
        Self::poly(n, Poly::constant(c))
    }

    /// A parameter.
    pub fn param(n: usize, i: usize) -> Self {
        Self::poly(n, Poly::sym(Sym::Param(i)))
    }

    /// The coordinate q_k itself.
    pub fn coord(n: usize, k: usize) -> Self {
        Self::poly(n, Poly::sym(Sym::Coord(k)))
    }

    /// cos(φ·q).
    pub fn cos(phi: Freq) -> Self {
        let mut e = Self::zero(phi.len());
        e.add_trig(phi, &Poly::constant(1.0), &Poly::zero());
        e
    }

    /// sin(φ·q).
    pub fn sin(phi: Freq) -> Self {
        let mut e = Self::zero(phi.len());
        e.add_trig(phi, &Poly::zero(), &Poly::constant(1.0));
        e
    }

    /// `true` for 0.
    pub fn is_zero(&self) -> bool {
        self.terms.is_empty()
    }

    /// Add a·cos(φ·q) + b·sin(φ·q) for any φ (canonicalised here).
    fn add_trig(&mut self, mut phi: Freq, a: &Poly, b: &Poly) {
        let mut sin_sign = 1.0;
        if let Some(first) = phi.iter().find(|x| **x != 0)
            && *first < 0
        {
            phi.iter_mut().for_each(|x| *x = -*x);
            sin_sign = -1.0;
        }
        let zero_freq = phi.iter().all(|x| *x == 0);
        let entry = self
            .terms
            .entry(phi.clone())
            .or_insert_with(|| (Poly::zero(), Poly::zero()));
        entry.0.axpy(1.0, a);
        if !zero_freq {
            entry.1.axpy(sin_sign, b);
        }
        if entry.0.is_zero() && entry.1.is_zero() {
            self.terms.remove(&phi);
        }
    }

    /// self + c·other.
    pub fn axpy(&mut self, c: f64, other: &Expr) {
        debug_assert_eq!(self.n, other.n);
        for (phi, (a, b)) in &other.terms {
            self.add_trig(phi.clone(), &a.scale(c), &b.scale(c));
        }
    }

    /// self + other.
    pub fn add(&self, other: &Expr) -> Expr {
        let mut e = self.clone();
        e.axpy(1.0, other);
        e
    }

    /// self − other.
    pub fn sub(&self, other: &Expr) -> Expr {
        let mut e = self.clone();
        e.axpy(-1.0, other);
        e
    }

    /// c·self.
    pub fn scale(&self, c: f64) -> Expr {
        let mut e = Expr::zero(self.n);
        e.axpy(c, self);
        e
    }

    /// self·other (product-to-sum identities).
    pub fn mul(&self, other: &Expr) -> Expr {
        debug_assert_eq!(self.n, other.n);
        let mut e = Expr::zero(self.n);
        for (phi, (a, b)) in &self.terms {
            for (psi, (c, d)) in &other.terms {
                let sum: Freq = phi.iter().zip(psi).map(|(x, y)| x + y).collect();
                let diff: Freq = phi.iter().zip(psi).map(|(x, y)| x - y).collect();
                let (ac, bd, ad, bc) = (a.mul(c), b.mul(d), a.mul(d), b.mul(c));
                // cos(φ+ψ): ½(ac − bd)   sin(φ+ψ): ½(ad + bc)
                // cos(φ−ψ): ½(ac + bd)   sin(φ−ψ): ½(bc − ad)
                let mut c_sum = ac.scale(0.5);
                c_sum.axpy(-0.5, &bd);
                let mut s_sum = ad.scale(0.5);
                s_sum.axpy(0.5, &bc);
                let mut c_diff = ac.scale(0.5);
                c_diff.axpy(0.5, &bd);
                let mut s_diff = bc.scale(0.5);
                s_diff.axpy(-0.5, &ad);
                e.add_trig(sum, &c_sum, &s_sum);
                e.add_trig(diff, &c_diff, &s_diff);
            }
        }
        e
    }

    /// ∂/∂q_k.
    pub fn deriv(&self, k: usize) -> Expr {
        let mut e = Expr::zero(self.n);
        for (phi, (a, b)) in &self.terms {
            let w = phi[k] as f64;
            // d/dq_k [a cos + b sin] = a' cos + b' sin + w(b cos − a sin)
            let mut ca = a.deriv(k);
            let mut cb = b.deriv(k);
            if w != 0.0 {
                ca.axpy(w, b);
                cb.axpy(-w, a);
            }
            e.add_trig(phi.clone(), &ca, &cb);
        }
        e
    }

    /// `true` when the expression does not depend on q at all.
    pub fn is_constant(&self) -> bool {
        self.terms
            .iter()
            .all(|(phi, (a, b))| phi.iter().all(|x| *x == 0) && !a.has_coords() && !b.has_coords())
    }

    /// The largest |coefficient| (NaN if any is NaN): the description's
    /// numbers must keep it finite with room for derivatives.
    pub fn max_abs_coefficient(&self) -> f64 {
        let mut m = 0.0f64;
        for (a, b) in self.terms.values() {
            for c in a.terms.values().chain(b.terms.values()) {
                if c.is_nan() {
                    return f64::NAN;
                }
                m = m.max(c.abs());
            }
        }
        m
    }

    /// Numerical value for parameters `p` and coordinates `q`.
    pub fn eval(&self, p: &[f64], q: &[f64]) -> f64 {
        self.terms
            .iter()
            .map(|(phi, (a, b))| {
                let x: f64 = phi.iter().zip(q).map(|(w, q)| *w as f64 * q).sum();
                a.eval(p, q) * x.cos() + b.eval(p, q) * x.sin()
            })
            .sum()
    }
}

/// A planar vector of expressions.
#[derive(Clone, Debug, PartialEq)]
pub struct Vec2 {
    /// x component.
    pub x: Expr,
    /// y component.
    pub y: Expr,
}

impl Vec2 {
    /// (0, 0) over `n` coordinates.
    pub fn zero(n: usize) -> Self {
        Self {
            x: Expr::zero(n),
            y: Expr::zero(n),
        }
    }

    /// a + b.
    pub fn add(&self, o: &Vec2) -> Vec2 {
        Vec2 {
            x: self.x.add(&o.x),
            y: self.y.add(&o.y),
        }
    }

    /// a − b.
    pub fn sub(&self, o: &Vec2) -> Vec2 {
        Vec2 {
            x: self.x.sub(&o.x),
            y: self.y.sub(&o.y),
        }
    }

    /// s·a for a scalar expression s.
    pub fn times(&self, s: &Expr) -> Vec2 {
        Vec2 {
            x: self.x.mul(s),
            y: self.y.mul(s),
        }
    }

    /// a·b.
    pub fn dot(&self, o: &Vec2) -> Expr {
        self.x.mul(&o.x).add(&self.y.mul(&o.y))
    }

    /// a × b = a_x b_y − a_y b_x.
    pub fn cross(&self, o: &Vec2) -> Expr {
        self.x.mul(&o.y).sub(&self.y.mul(&o.x))
    }

    /// ∂/∂q_k.
    pub fn deriv(&self, k: usize) -> Vec2 {
        Vec2 {
            x: self.x.deriv(k),
            y: self.y.deriv(k),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) {
        assert!((a - b).abs() <= 1e-13 * (1.0 + b.abs()), "{a} vs {b}");
    }

    /// Products, sums and derivatives of trigonometric polynomials agree
    /// with the same operations on their numerical values (the product by
    /// evaluating both factors; the derivative by central differences).
    #[test]
    fn algebra_matches_numbers() {
        let n = 3;
        let p = [0.7f64, -1.3];
        let q = [0.4f64, -1.1, 0.25];
        // e1 = p0·cos(q0 + q1) + q2·sin(q1)
        let mut e1 = Expr::cos(vec![1, 1, 0]).mul(&Expr::param(n, 0));
        e1 = e1.add(&Expr::sin(vec![0, 1, 0]).mul(&Expr::coord(n, 2)));
        // e2 = p1 − sin(q0 − q1) + cos(2 q0)
        let e2 = Expr::param(n, 1)
            .sub(&Expr::sin(vec![1, -1, 0]))
            .add(&Expr::cos(vec![2, 0, 0]));
        let v1 = p[0] * (q[0] + q[1]).cos() + q[2] * q[1].sin();
        let v2 = p[1] - (q[0] - q[1]).sin() + (2.0 * q[0]).cos();
        close(e1.eval(&p, &q), v1);
        close(e2.eval(&p, &q), v2);
        close(e1.mul(&e2).eval(&p, &q), v1 * v2);
        close(e1.mul(&e1).eval(&p, &q), v1 * v1);
        let prod = e1.mul(&e2);
        for k in 0..n {
            let h = 1e-6;
            let (mut qp, mut qm) = (q, q);
            qp[k] += h;
            qm[k] -= h;
            let fd = (prod.eval(&p, &qp) - prod.eval(&p, &qm)) / (2.0 * h);
            let d = prod.deriv(k).eval(&p, &q);
            assert!((d - fd).abs() < 1e-8, "k = {k}: {d} vs {fd}");
        }
    }

    /// sin² + cos² collapses to the constant 1: frequencies are grouped and
    /// cancelled terms disappear.
    #[test]
    fn pythagoras_is_exact() {
        let (c, s) = (Expr::cos(vec![1, 1]), Expr::sin(vec![1, 1]));
        let one = c.mul(&c).add(&s.mul(&s));
        assert_eq!(one, Expr::constant(2, 1.0));
        assert!(one.deriv(0).is_zero());
    }

    /// A negative leading frequency folds onto its canonical form.
    #[test]
    fn frequencies_are_canonical() {
        let a = Expr::sin(vec![-1, 2]);
        let b = Expr::sin(vec![1, -2]).scale(-1.0);
        assert_eq!(a, b);
        assert_eq!(Expr::cos(vec![0, -1]), Expr::cos(vec![0, 1]));
        assert!(Expr::sin(vec![0, 0]).is_zero());
    }
}
