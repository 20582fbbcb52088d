//! Straight-line Rust for the closed-form mechanics of one view
//! ([`Mechanics`]): the `vigp::embedded::Dynamics` implementation every
//! integrator runs on.
//!
//! Each function computes the sines and cosines it needs once (angle sums
//! by the addition theorems from angles already at hand), multiplies them
//! by parameter products precomputed in `constants` (indexed `k[i]`), and
//! writes every entry of its result. Entries that are structurally zero
//! are written as `0.0`; derivatives that vanish identically are not
//! computed at all.

// Index loops over (symmetric) matrices of expressions read as the
// formulas they implement; iterator chains would hide the indices.
#![allow(clippy::needless_range_loop)]

use crate::desc::planar::Model;
use crate::mechanics::{Mechanics, Param};
use crate::symbolic::{Expr, Freq, Monomial, Poly, Sym};
use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};
use std::cell::Cell;
use std::collections::BTreeMap;
use syn::Ident;

/// An f64 literal (callers put the sign).
fn lit(x: f64) -> TokenStream {
    let l = Literal::f64_unsuffixed(x.abs());
    if x < 0.0 { quote!(-#l) } else { quote!(#l) }
}

fn index(i: usize) -> Literal {
    Literal::usize_unsuffixed(i)
}

/// Tokens reading a parameter from `sys` (the parameter struct).
fn param_tokens(m: &Model, p: &Param) -> TokenStream {
    let link = |l: usize, field: &str| {
        let (n, f) = (&m.links[l].name, format_ident!("{}", field));
        quote!(sys.links.#n.#f)
    };
    let joint = |j: usize, field: &str| {
        let (n, f) = (&m.joints[j].name, format_ident!("{}", field));
        quote!(sys.joints.#n.#f)
    };
    match *p {
        Param::Gravity(i) => {
            let i = index(i);
            quote!(sys.gravity[#i])
        }
        Param::Mass(l) => link(l, "mass"),
        Param::Length(l) => link(l, "length"),
        Param::Inertia(l) => link(l, "inertia"),
        Param::Com(l, i) => {
            let (n, i) = (&m.links[l].name, index(i));
            quote!(sys.links.#n.com[#i])
        }
        Param::Damping(j) => joint(j, "damping"),
        Param::Stiffness(j) => joint(j, "stiffness"),
        Param::Rest(j) => joint(j, "rest"),
    }
}

type PolyKey = Vec<(Monomial, u64)>;

fn key(p: &Poly) -> PolyKey {
    p.terms
        .iter()
        .map(|(m, c)| (m.clone(), c.to_bits()))
        .collect()
}

/// The table of parameter products `k[i]`.
#[derive(Default)]
struct Constants {
    polys: Vec<Poly>,
    index: BTreeMap<PolyKey, usize>,
}

impl Constants {
    /// `(index, negated)` of a parameter polynomial (shared with its negation).
    fn get(&mut self, p: &Poly) -> (usize, bool) {
        if let Some(&i) = self.index.get(&key(p)) {
            return (i, false);
        }
        if let Some(&i) = self.index.get(&key(&p.scale(-1.0))) {
            return (i, true);
        }
        self.polys.push(p.clone());
        self.index.insert(key(p), self.polys.len() - 1);
        (self.polys.len() - 1, false)
    }
}

/// What a function body read, so that unused arguments get a `_` name.
#[derive(Default)]
struct Uses {
    q: Cell<bool>,
    k: Cell<bool>,
}

/// Sines and cosines of the frequencies one function needs.
struct Trig {
    names: BTreeMap<Freq, (Ident, Ident)>,
    lets: Vec<TokenStream>,
}

fn freq_name(phi: &Freq) -> String {
    let parts: Vec<String> = phi
        .iter()
        .enumerate()
        .filter(|(_, w)| **w != 0)
        .map(|(k, w)| match *w {
            1 => format!("q{k}"),
            -1 => format!("mq{k}"),
            w if w > 0 => format!("{w}q{k}"),
            w => format!("m{}q{k}", -w),
        })
        .collect();
    parts.join("_")
}

/// φ·q as tokens.
fn angle_tokens(phi: &Freq) -> TokenStream {
    let mut out = TokenStream::new();
    for (k, w) in phi.iter().enumerate() {
        if *w == 0 {
            continue;
        }
        let kk = index(k);
        let term = match w.abs() {
            1 => quote!(q[#kk]),
            a => {
                let a = lit(a as f64);
                quote!(#a * q[#kk])
            }
        };
        out = match (out.is_empty(), *w > 0) {
            (true, true) => term,
            (true, false) => quote!(-#term),
            (false, true) => quote!(#out + #term),
            (false, false) => quote!(#out - #term),
        };
    }
    out
}

impl Trig {
    /// Lets for every non-zero frequency in `freqs`: `sincos` of the angle,
    /// or the addition theorem from two frequencies already computed.
    fn new(freqs: impl IntoIterator<Item = Freq>) -> Self {
        let mut list: Vec<Freq> = freqs
            .into_iter()
            .filter(|phi| phi.iter().any(|w| *w != 0))
            .collect();
        list.sort_by_key(|phi| (phi.iter().map(|w| w.abs()).sum::<i32>(), phi.clone()));
        list.dedup();
        let mut trig = Trig {
            names: BTreeMap::new(),
            lets: Vec::new(),
        };
        for phi in list {
            let name = freq_name(&phi);
            let (s, c) = (format_ident!("sin_{}", name), format_ident!("cos_{}", name));
            let derived = trig.sum_of_known(&phi);
            let value = match derived {
                Some((a, sa, b, sb)) => {
                    // sin(±α ± β), cos(±α ± β) from sin/cos of α and β
                    let (sin_a, cos_a) = trig.names[&a].clone();
                    let (sin_b, cos_b) = trig.names[&b].clone();
                    let sa = if sa < 0.0 {
                        quote!((-#sin_a))
                    } else {
                        quote!(#sin_a)
                    };
                    let sb = if sb < 0.0 {
                        quote!((-#sin_b))
                    } else {
                        quote!(#sin_b)
                    };
                    quote!((#sa * #cos_b + #cos_a * #sb, #cos_a * #cos_b - #sa * #sb))
                }
                None => {
                    let angle = angle_tokens(&phi);
                    quote!(::vigp::embedded::dynamics::sincos(#angle))
                }
            };
            trig.lets.push(quote!(let (#s, #c) = #value;));
            trig.names.insert(phi, (s, c));
        }
        trig
    }

    /// φ = sa·α + sb·β for known canonical α, β and signs sa, sb = ±1.
    fn sum_of_known(&self, phi: &Freq) -> Option<(Freq, f64, Freq, f64)> {
        let known: Vec<&Freq> = self.names.keys().collect();
        for a in &known {
            for b in &known {
                for (sa, sb) in [(1, 1), (1, -1), (-1, 1)] {
                    let f: Freq = a
                        .iter()
                        .zip(b.iter())
                        .map(|(x, y)| sa * x + sb * y)
                        .collect();
                    if &f == phi {
                        return Some(((*a).clone(), sa as f64, (*b).clone(), sb as f64));
                    }
                }
            }
        }
        None
    }

    fn lets(&self) -> TokenStream {
        let lets = &self.lets;
        quote!(#(#lets)*)
    }
}

/// Writes expressions as tokens over `q`, `k[i]` and the trig lets.
struct Writer<'a> {
    constants: &'a mut Constants,
    uses: Uses,
}

impl Writer<'_> {
    /// Tokens of one expression (`0.0` for zero).
    fn expr(&mut self, e: &Expr, trig: &Trig) -> TokenStream {
        // (negative?, term) in a stable order
        let mut terms: Vec<(bool, TokenStream)> = Vec::new();
        for (phi, (a, b)) in &e.terms {
            let zero = phi.iter().all(|w| *w == 0);
            for (poly, is_sin) in [(a, false), (b, true)] {
                if poly.is_zero() {
                    continue;
                }
                let factor = if zero {
                    None
                } else {
                    let (s, c) = &trig.names[phi];
                    Some(if is_sin { quote!(#s) } else { quote!(#c) })
                };
                for (coords, p) in poly.by_coordinates() {
                    terms.push(self.term(&coords, &p, factor.clone()));
                }
            }
        }
        if terms.is_empty() {
            return quote!(0.0);
        }
        let mut out = TokenStream::new();
        for (i, (neg, t)) in terms.into_iter().enumerate() {
            out = match (i == 0, neg) {
                (true, false) => t,
                (true, true) => quote!(-#t),
                (false, false) => quote!(#out + #t),
                (false, true) => quote!(#out - #t),
            };
        }
        out
    }

    /// One product: coefficient × trig factor × coordinate monomial.
    fn term(
        &mut self,
        coords: &Monomial,
        p: &Poly,
        factor: Option<TokenStream>,
    ) -> (bool, TokenStream) {
        let mut factors: Vec<TokenStream> = Vec::new();
        let numeric = p.terms.len() == 1 && p.terms.keys().next().is_some_and(Vec::is_empty);
        let neg = if numeric {
            let c = *p.terms.values().next().expect("one term");
            if c.abs() != 1.0 || (factor.is_none() && coords.is_empty()) {
                factors.push(lit(c.abs()));
            }
            c < 0.0
        } else {
            let (i, neg) = self.constants.get(p);
            let i = index(i);
            self.uses.k.set(true);
            factors.push(quote!(k[#i]));
            neg
        };
        factors.extend(factor);
        for s in coords {
            let Sym::Coord(c) = s else {
                unreachable!("coordinate part")
            };
            let c = index(*c);
            self.uses.q.set(true);
            factors.push(quote!(q[#c]));
        }
        let mut t = TokenStream::new();
        for (i, f) in factors.iter().enumerate() {
            t = if i == 0 { f.clone() } else { quote!(#t * #f) };
        }
        (neg, t)
    }
}

/// Assignments `target = expr;` sharing one set of trig lets, then
/// `extra`; returns the body and whether it read `q` and `k`.
fn assign_body(
    constants: &mut Constants,
    outputs: &[(TokenStream, &Expr)],
    extra: TokenStream,
) -> (TokenStream, bool, bool) {
    let trig = Trig::new(freqs(outputs.iter().map(|(_, e)| *e)));
    let mut w = Writer {
        constants,
        uses: Uses::default(),
    };
    let assigns: Vec<TokenStream> = outputs
        .iter()
        .map(|(target, e)| {
            let v = w.expr(e, &trig);
            quote!(#target = #v;)
        })
        .collect();
    let lets = trig.lets();
    let uses_q = w.uses.q.get() || !trig.lets.is_empty();
    let uses_k = w.uses.k.get();
    (quote!(#lets #(#assigns)* #extra), uses_q, uses_k)
}

/// The Hessians ∇²f_i of `count` functions of the `n` coordinates from
/// their gradients, `grad(i, a)` = ∂f_i/∂q_a.
fn hessians<'e>(
    count: usize,
    n: usize,
    grad: impl Fn(usize, usize) -> &'e Expr,
) -> Vec<Vec<Vec<Expr>>> {
    (0..count)
        .map(|i| {
            (0..n)
                .map(|a| (0..n).map(|b| grad(i, a).deriv(b)).collect())
                .collect()
        })
        .collect()
}

/// The statements `h[(a, b)] = Σ_r (hess_r)_ab · w[r]` (upper triangle,
/// mirrored) of a weighted sum of symmetric n × n Hessians with weights
/// named `weight` (Σ μ_r ∇²g_r, Σ u_i ∇²s_i), skipping structural zeros;
/// with the trig lets they need and whether they read q and k.
fn weighted_hessian(
    constants: &mut Constants,
    hess: &[Vec<Vec<Expr>>],
    n: usize,
    weight: &str,
) -> (TokenStream, Vec<TokenStream>, bool, bool) {
    let weight = format_ident!("{}", weight);
    let all = hess
        .iter()
        .flat_map(|h| (0..n).flat_map(move |a| (a..n).map(move |b| &h[a][b])));
    let trig = Trig::new(freqs(all));
    let mut w = Writer {
        constants,
        uses: Uses::default(),
    };
    let mut assigns = Vec::new();
    for a in 0..n {
        for b in a..n {
            let mut sum = TokenStream::new();
            for (r, h) in hess.iter().enumerate() {
                if h[a][b].is_zero() {
                    continue;
                }
                let ri = index(r);
                let x = w.expr(&h[a][b], &trig);
                sum = if sum.is_empty() {
                    quote!((#x) * #weight[#ri])
                } else {
                    quote!(#sum + (#x) * #weight[#ri])
                };
            }
            if sum.is_empty() {
                continue;
            }
            let t = ij(a, b);
            assigns.push(quote!(h[#t] = #sum;));
            if a != b {
                let tt = ij(b, a);
                assigns.push(quote!(h[#tt] = h[#t];));
            }
        }
    }
    let uses_q = w.uses.q.get() || !trig.lets.is_empty();
    (trig.lets(), assigns, uses_q, w.uses.k.get())
}

/// The tokens `(i, j)` of a matrix index.
fn ij(i: usize, j: usize) -> TokenStream {
    let (i, j) = (index(i), index(j));
    quote!((#i, #j))
}

fn freqs<'a>(exprs: impl IntoIterator<Item = &'a Expr>) -> Vec<Freq> {
    let mut out: Vec<Freq> = exprs
        .into_iter()
        .flat_map(|e| e.terms.keys().cloned())
        .collect();
    out.sort();
    out.dedup();
    out
}

/// The `Dynamics` implementation for `ty` (a view struct with field `sys`).
pub fn emit_dynamics(
    m: &Model,
    mech: &Mechanics,
    ty: &Ident,
    kinds: &[TokenStream],
) -> TokenStream {
    let n = mech.n;
    let c = mech.c();
    let nn = index(n);
    let cc = index(c);
    let svector = quote!(::vigp::__private::nalgebra::SVector);
    let smatrix = quote!(::vigp::__private::nalgebra::SMatrix);
    let dissipative = !mech.dampers.is_empty();
    let constant_mass = mech.constant_mass();
    let mut constants = Constants::default();

    let arg = |used: bool, name: &str| {
        if used {
            format_ident!("{}", name)
        } else {
            format_ident!("_{}", name)
        }
    };

    // mass(q)
    let mut outs = Vec::new();
    let mut mirror = Vec::new();
    for j in 0..n {
        for l in j..n {
            let t = ij(j, l);
            outs.push((quote!(m[#t]), &mech.mass[j][l]));
            if l != j {
                let tt = ij(l, j);
                mirror.push(quote!(m[#tt] = m[#t];));
            }
        }
    }
    let (body, uq, uk) = assign_body(&mut constants, &outs, quote!(#(#mirror)*));
    let (q_arg, k_arg) = (arg(uq, "q"), arg(uk, "k"));
    let mass_fn = quote! {
        fn mass(&self, #k_arg: &Self::Constants, #q_arg: &#svector<f64, #nn>) -> #smatrix<f64, #nn, #nn> {
            let mut m = #smatrix::<f64, #nn, #nn>::zeros();
            #body
            m
        }
    };

    // potential(q)
    let (body, uq, uk) = assign_body(
        &mut constants,
        &[(quote!(let v), &mech.potential)],
        quote!(),
    );
    let (q_arg, k_arg) = (arg(uq, "q"), arg(uk, "k"));
    let potential_fn = quote! {
        fn potential(&self, #k_arg: &Self::Constants, #q_arg: &#svector<f64, #nn>) -> f64 {
            #body
            v
        }
    };

    // terms(q)
    let grad_v = mech.potential_gradient();
    let damping = mech.damping_matrix();
    let dmass: Vec<Vec<Vec<Expr>>> = if constant_mass {
        Vec::new()
    } else {
        (0..n)
            .map(|l| {
                (0..n)
                    .map(|j| (0..n).map(|k| mech.mass[j][k].deriv(l)).collect())
                    .collect()
            })
            .collect()
    };
    let pattern: Vec<TokenStream> = (0..n)
        .map(|l| {
            let rows = (0..n).map(|j| {
                let cells = (0..n).map(|k| !constant_mass && !dmass[l][j][k].is_zero());
                quote!([#(#cells),*])
            });
            quote!([#(#rows),*])
        })
        .collect();
    let pattern_const = if constant_mass {
        quote!(const DMASS_PATTERN: [[[bool; #nn]; #nn]; #nn] = [[[false; #nn]; #nn]; #nn];)
    } else {
        quote!(const DMASS_PATTERN: [[[bool; #nn]; #nn]; #nn] = [#(#pattern),*];)
    };
    // kinetic(t, v) and quadratic_max(t, dv): the contractions of ∂M/∂q
    // with the velocity, straight-line over its structural non-zeros
    let contractions = if constant_mass {
        quote!()
    } else {
        let nz = |l: usize, j: usize, k: usize| !dmass[l][j][k].is_zero();
        let mut kin = Vec::new();
        let mut quad = Vec::new();
        let mut used_slices = Vec::new();
        for l in 0..n {
            if !(0..n).any(|j| (0..n).any(|k| nz(l, j, k))) {
                continue;
            }
            let li = index(l);
            let mut f_terms = Vec::new();
            for j in 0..n {
                let row: Vec<TokenStream> = (0..n)
                    .filter(|&k| nz(l, j, k))
                    .map(|k| {
                        let (jj, kk) = (index(j), index(k));
                        quote!(t.dmass[#li][(#jj, #kk)] * v[#kk])
                    })
                    .collect();
                if row.is_empty() {
                    continue;
                }
                let (jj, name) = (index(j), format_ident!("q_{}_{}", l, j));
                kin.push(quote!(let #name = #(#row)+*; q[(#li, #jj)] = #name;));
                f_terms.push(quote!(#name * v[#jj]));
            }
            kin.push(quote!(f[#li] = 0.5 * (#(#f_terms)+*);));
            // dvᵀ A dv over the upper triangle (A symmetric)
            let mut qt = Vec::new();
            for j in 0..n {
                for k in j..n {
                    if !nz(l, j, k) {
                        continue;
                    }
                    let (jj, kk) = (index(j), index(k));
                    qt.push(if j == k {
                        quote!(t.dmass[#li][(#jj, #jj)] * (dv[#jj] * dv[#jj]))
                    } else {
                        quote!(2.0 * t.dmass[#li][(#jj, #kk)] * (dv[#jj] * dv[#kk]))
                    });
                }
            }
            let name = format_ident!("s_{}", l);
            quad.push(quote!(let #name = (#(#qt)+*).abs();));
            used_slices.push(name);
        }
        let worst = used_slices.iter().skip(1).fold(
            used_slices.first().map_or(quote!(0.0), |s| quote!(#s)),
            |acc, s| quote!(#acc.max(#s)),
        );
        quote! {
            #[inline(always)]
            fn kinetic(t: &::vigp::embedded::Terms<#nn>, v: &#svector<f64, #nn>) -> (#smatrix<f64, #nn, #nn>, #svector<f64, #nn>) {
                let mut q = #smatrix::<f64, #nn, #nn>::zeros();
                let mut f = #svector::<f64, #nn>::zeros();
                #(#kin)*
                (q, f)
            }
            #[inline(always)]
            fn quadratic_max(t: &::vigp::embedded::Terms<#nn>, dv: &#svector<f64, #nn>) -> f64 {
                #(#quad)*
                #worst
            }
        }
    };
    // mass_times(t, v) and damping_times(t, v): M·v and D·v straight-line
    // over the structural non-zeros (M is diagonal in maximal coordinates)
    let sparse_times = |name: &str, field: TokenStream, a: &[Vec<Expr>]| {
        let rows = (0..n).filter_map(|j| {
            let terms: Vec<TokenStream> = (0..n)
                .filter(|&k| !a[j.min(k)][j.max(k)].is_zero())
                .map(|k| {
                    let (jj, kk) = (index(j), index(k));
                    quote!(t.#field[(#jj, #kk)] * v[#kk])
                })
                .collect();
            let jj = index(j);
            (!terms.is_empty()).then(|| quote!(r[#jj] = #(#terms)+*;))
        });
        let name = format_ident!("{}", name);
        quote! {
            #[inline(always)]
            fn #name(t: &::vigp::embedded::Terms<#nn>, v: &#svector<f64, #nn>) -> #svector<f64, #nn> {
                let mut r = #svector::<f64, #nn>::zeros();
                #(#rows)*
                r
            }
        }
    };
    let mass_times = sparse_times("mass_times", quote!(mass), &mech.mass);
    let damping_times = if dissipative {
        sparse_times("damping_times", quote!(damping), &damping)
    } else {
        quote!()
    };
    let mut outs = Vec::new();
    let mut mirror = Vec::new();
    for j in 0..n {
        for l in j..n {
            let t = ij(j, l);
            outs.push((quote!(out.mass[#t]), &mech.mass[j][l]));
            if l != j {
                let tt = ij(l, j);
                mirror.push(quote!(out.mass[#tt] = out.mass[#t];));
            }
        }
    }
    for (l, dm) in dmass.iter().enumerate() {
        let li = index(l);
        for j in 0..n {
            for k in j..n {
                let t = ij(j, k);
                outs.push((quote!(out.dmass[#li][#t]), &dm[j][k]));
                if k != j {
                    let tt = ij(k, j);
                    mirror.push(quote!(out.dmass[#li][#tt] = out.dmass[#li][#t];));
                }
            }
        }
    }
    for (k, g) in grad_v.iter().enumerate() {
        let kk = index(k);
        outs.push((quote!(out.dpotential[#kk]), g));
    }
    if dissipative {
        for j in 0..n {
            for k in j..n {
                let t = ij(j, k);
                outs.push((quote!(out.damping[#t]), &damping[j][k]));
                if k != j {
                    let tt = ij(k, j);
                    mirror.push(quote!(out.damping[#tt] = out.damping[#t];));
                }
            }
        }
    }
    let (body, uq, uk) = assign_body(&mut constants, &outs, quote!(#(#mirror)*));
    let (q_arg, k_arg) = (arg(uq, "q"), arg(uk, "k"));
    let terms_fn = quote! {
        fn terms(&self, #k_arg: &Self::Constants, #q_arg: &#svector<f64, #nn>, out: &mut ::vigp::embedded::Terms<#nn>) {
            #body
        }
    };

    // force_jacobian(q, v) = ∂/∂q [½ vᵀ∂M/∂q v − ∇V − D(q) v]
    let mut fj: Vec<Vec<Expr>> = vec![vec![Expr::zero(n); n]; n];
    let mut v_terms: Vec<Vec<Vec<(usize, usize, Expr)>>> = vec![vec![Vec::new(); n]; n];
    for i in 0..n {
        for l in i..n {
            fj[i][l] = grad_v[i].deriv(l).scale(-1.0);
            if !constant_mass {
                for j in 0..n {
                    for k in j..n {
                        let e = dmass[i][j][k].deriv(l);
                        if !e.is_zero() {
                            let w = if j == k { 0.5 } else { 1.0 };
                            v_terms[i][l].push((j, k, e.scale(w)));
                        }
                    }
                }
            }
        }
    }
    // damping: −Σ_j ∂D_ij/∂q_l v_j (not symmetric in i, l)
    let mut d_terms: Vec<Vec<Vec<(usize, Expr)>>> = vec![vec![Vec::new(); n]; n];
    if dissipative {
        for i in 0..n {
            for l in 0..n {
                for j in 0..n {
                    let e = damping[i][j].deriv(l);
                    if !e.is_zero() {
                        d_terms[i][l].push((j, e.scale(-1.0)));
                    }
                }
            }
        }
    }
    let force_jacobian_fn = {
        let mut all: Vec<&Expr> = Vec::new();
        for i in 0..n {
            for l in i..n {
                all.push(&fj[i][l]);
                all.extend(v_terms[i][l].iter().map(|(_, _, e)| e));
            }
        }
        for row in &d_terms {
            for cell in row {
                all.extend(cell.iter().map(|(_, e)| e));
            }
        }
        let trig = Trig::new(freqs(all.iter().copied()));
        let mut w = Writer {
            constants: &mut constants,
            uses: Uses::default(),
        };
        let mut assigns = Vec::new();
        let mut uses_v = false;
        for i in 0..n {
            for l in i..n {
                let t = ij(i, l);
                let mut value = w.expr(&fj[i][l], &trig);
                let mut nonzero = !fj[i][l].is_zero();
                for (j, k, e) in &v_terms[i][l] {
                    let (jj, kk) = (index(*j), index(*k));
                    let x = w.expr(e, &trig);
                    value = if nonzero {
                        quote!(#value + (#x) * (v[#jj] * v[#kk]))
                    } else {
                        quote!((#x) * (v[#jj] * v[#kk]))
                    };
                    nonzero = true;
                    uses_v = true;
                }
                assigns.push(quote!(f[#t] = #value;));
                if l != i {
                    let tt = ij(l, i);
                    assigns.push(quote!(f[#tt] = f[#t];));
                }
            }
        }
        for (i, row) in d_terms.iter().enumerate() {
            for (l, cell) in row.iter().enumerate() {
                if cell.is_empty() {
                    continue;
                }
                let t = ij(i, l);
                let mut sum = TokenStream::new();
                for (j, e) in cell {
                    let jj = index(*j);
                    let x = w.expr(e, &trig);
                    sum = if sum.is_empty() {
                        quote!((#x) * v[#jj])
                    } else {
                        quote!(#sum + (#x) * v[#jj])
                    };
                }
                uses_v = true;
                assigns.push(quote!(f[#t] += #sum;));
            }
        }
        let lets = trig.lets();
        let q_arg = arg(w.uses.q.get() || !trig.lets.is_empty(), "q");
        let k_arg = arg(w.uses.k.get(), "k");
        let v_arg = arg(uses_v, "v");
        quote! {
            fn force_jacobian(&self, #k_arg: &Self::Constants, #q_arg: &#svector<f64, #nn>, #v_arg: &#svector<f64, #nn>) -> #smatrix<f64, #nn, #nn> {
                let mut f = #smatrix::<f64, #nn, #nn>::zeros();
                #lets
                #(#assigns)*
                f
            }
        }
    };

    // constraints
    let (constraint_const, constraint_fns) = if c == 0 {
        (quote!(), quote!())
    } else {
        let rows = &mech.constraints;
        let outs: Vec<(TokenStream, &Expr)> = rows
            .iter()
            .enumerate()
            .map(|(r, e)| {
                let r = index(r);
                (quote!(g[#r]), e)
            })
            .collect();
        let (body, uq, uk) = assign_body(&mut constants, &outs, quote!());
        let (q_arg, k_arg) = (arg(uq, "q"), arg(uk, "k"));
        let g_fn = quote! {
            fn constraint_values(&self, #k_arg: &Self::Constants, #q_arg: &#svector<f64, #nn>) -> #svector<f64, #cc> {
                let mut g = #svector::<f64, #cc>::zeros();
                #body
                g
            }
        };
        let jac: Vec<Vec<Expr>> = rows
            .iter()
            .map(|e| (0..n).map(|k| e.deriv(k)).collect())
            .collect();
        let mut outs: Vec<(TokenStream, &Expr)> = Vec::new();
        for (r, e) in rows.iter().enumerate() {
            let ri = index(r);
            outs.push((quote!(g[#ri]), e));
            for k in 0..n {
                let t = ij(r, k);
                outs.push((quote!(jac[#t]), &jac[r][k]));
            }
        }
        let (body, uq, uk) = assign_body(&mut constants, &outs, quote!());
        let (q_arg, k_arg) = (arg(uq, "q"), arg(uk, "k"));
        let jac_fn = quote! {
            fn constraints_and_jacobian(&self, #k_arg: &Self::Constants, #q_arg: &#svector<f64, #nn>) -> (#svector<f64, #cc>, #smatrix<f64, #cc, #nn>) {
                let mut g = #svector::<f64, #cc>::zeros();
                let mut jac = #smatrix::<f64, #cc, #nn>::zeros();
                #body
                (g, jac)
            }
        };
        // Σ μ_r ∇²g_r
        let hess = hessians(jac.len(), n, |r, a| &jac[r][a]);
        let (lets, assigns, uq, uk) = weighted_hessian(&mut constants, &hess, n, "mu");
        let (q_arg, k_arg) = (arg(uq, "q"), arg(uk, "k"));
        let mu_arg = arg(!assigns.is_empty(), "mu");
        let hess_fn = quote! {
            fn constraint_hessian(&self, #k_arg: &Self::Constants, #q_arg: &#svector<f64, #nn>, #mu_arg: &#svector<f64, #cc>) -> #smatrix<f64, #nn, #nn> {
                let mut h = #smatrix::<f64, #nn, #nn>::zeros();
                #lets
                #(#assigns)*
                h
            }
        };
        // G's structural zeros, for the Schur complement of the step
        let pattern = jac.iter().map(|row| {
            let cells = row.iter().map(|e| !e.is_zero());
            quote!([#(#cells),*])
        });
        (
            quote!(const CONSTRAINT_PATTERN: [[bool; #nn]; #cc] = [#(#pattern),*];),
            quote!(#g_fn #jac_fn #hess_fn),
        )
    };

    // inputs (emitted last: the constants of the other functions keep
    // their indices, so an actuated mechanism's terms are those of the
    // same mechanism without `actuated`)
    let (inputs_const, input_fns, inputs_impl) = if mech.inputs.is_empty() {
        (quote!(), quote!(), quote!())
    } else {
        let u = mech.inputs.len();
        let uu = index(u);
        let bm = mech.input_matrix();
        let mut outs: Vec<(TokenStream, &Expr)> = Vec::new();
        for (k, row) in bm.iter().enumerate() {
            for (i, e) in row.iter().enumerate() {
                let t = ij(k, i);
                outs.push((quote!(b[#t]), e));
            }
        }
        let (body, uq, uk) = assign_body(&mut constants, &outs, quote!());
        let (q_arg, k_arg) = (arg(uq, "q"), arg(uk, "k"));
        // U = 0 is the input-free step (no force): the derivatives of the
        // unforced step need it for an actuated mechanism too
        let assert_u = quote! {
            const { ::core::assert!(U == #uu || U == 0, "the input vector's length U must equal Dynamics::INPUTS (or 0: no input)") };
        };
        let b_fn = quote! {
            fn input_matrix<const U: usize>(&self, #k_arg: &Self::Constants, #q_arg: &#svector<f64, #nn>) -> #smatrix<f64, #nn, U> {
                #assert_u
                let mut b = #smatrix::<f64, #nn, U>::zeros();
                if U == 0 {
                    return b;
                }
                #body
                b
            }
        };
        // Σ_i u_i ∇²s_i (symmetric)
        let hess = hessians(u, n, |i, a| &bm[a][i]);
        let (lets, assigns, uq, uk) = weighted_hessian(&mut constants, &hess, n, "u");
        let (q_arg, k_arg) = (arg(uq, "q"), arg(uk, "k"));
        let u_arg = arg(!assigns.is_empty(), "u");
        let h_fn = quote! {
            fn input_force_jacobian<const U: usize>(&self, #k_arg: &Self::Constants, #q_arg: &#svector<f64, #nn>, #u_arg: &#svector<f64, U>) -> #smatrix<f64, #nn, #nn> {
                #assert_u
                #[allow(unused_mut)]
                let mut h = #smatrix::<f64, #nn, #nn>::zeros();
                if U == 0 {
                    return h;
                }
                #lets
                #(#assigns)*
                h
            }
        };
        let names = m
            .inputs()
            .into_iter()
            .map(|j| syn::ext::IdentExt::unraw(&m.joints[j].name).to_string());
        (
            quote! {
                const INPUTS: usize = #uu;
                const INPUT_NAMES: &'static [&'static str] = &[#(#names),*];
            },
            quote!(#b_fn #h_fn),
            quote! {
                #[doc = " Forced steps take input vectors of its number of inputs (and of length 0)."]
                impl ::vigp::embedded::Inputs<#uu> for #ty {}
            },
        )
    };

    // constants(): validation of every parameter, then the products
    let nk = index(constants.polys.len());
    let checks = validation(m);
    let products: Vec<TokenStream> = constants
        .polys
        .iter()
        .map(|p| poly_tokens(m, mech, p))
        .collect();
    // parameter products mix spans from the description (field names) with
    // the macro's own (operators): clippy would read a line break inside
    // each product and suspect a missing comma in the array
    let constants_fn = quote! {
        #[allow(clippy::possible_missing_comma)]
        fn constants(&self) -> ::core::result::Result<[f64; #nk], ::vigp::embedded::StepError> {
            let sys = &self.sys;
            #(#checks)*
            ::vigp::embedded::dynamics::check_constants([#(#products),*])
        }
    };

    quote! {
        impl ::vigp::embedded::Dynamics<#nn, #cc> for #ty {
            const KINDS: [::vigp::CoordinateKind; #nn] = [#(#kinds),*];
            const DISSIPATIVE: bool = #dissipative;
            const CONSTANT_MASS: bool = #constant_mass;
            #pattern_const
            #constraint_const
            #inputs_const
            type Constants = [f64; #nk];

            #constants_fn
            #mass_fn
            #potential_fn
            #terms_fn
            #contractions
            #mass_times
            #damping_times
            #force_jacobian_fn
            #constraint_fns
            #input_fns
        }
        #inputs_impl
    }
}

/// A parameter polynomial as tokens over `sys`.
fn poly_tokens(m: &Model, mech: &Mechanics, p: &Poly) -> TokenStream {
    let mut out = TokenStream::new();
    for (i, (mono, c)) in p.terms.iter().enumerate() {
        let mut factors: Vec<TokenStream> = mono
            .iter()
            .map(|s| match s {
                Sym::Param(j) => param_tokens(m, &mech.params[*j]),
                Sym::Coord(_) => unreachable!("parameter polynomial"),
            })
            .collect();
        if c.abs() != 1.0 || factors.is_empty() {
            factors.push(lit(c.abs()));
        }
        let mut t = TokenStream::new();
        for (j, f) in factors.iter().enumerate() {
            t = if j == 0 { f.clone() } else { quote!(#t * #f) };
        }
        out = match (i == 0, *c < 0.0) {
            (true, false) => t,
            (true, true) => quote!(-#t),
            (false, false) => quote!(#out + #t),
            (false, true) => quote!(#out - #t),
        };
    }
    out
}

/// The sign a run-time parameter must have (besides being finite): the
/// variant of `vigp::embedded::dynamics::ParameterSign` the generated check
/// names, and what its message says.
#[derive(Clone, Copy)]
enum Sign {
    Any,
    NonNegative,
    Positive,
}

impl Sign {
    /// The generated `ParameterSign` variant.
    fn variant(self) -> TokenStream {
        match self {
            Sign::Any => quote!(Any),
            Sign::NonNegative => quote!(NonNegative),
            Sign::Positive => quote!(Positive),
        }
    }

    /// What the message adds to "must be finite".
    fn bound(self) -> &'static str {
        match self {
            Sign::Any => "",
            Sign::NonNegative => " and >= 0",
            Sign::Positive => " and > 0",
        }
    }
}

/// Checks of every run-time parameter, naming it in the error.
fn validation(m: &Model) -> Vec<TokenStream> {
    let mut out = Vec::new();
    // parameter `p`, called `what` in the message, must be finite and of
    // the sign `s`, which the message states
    let mut check = |p: Param, s: Sign, what: String| {
        let value = param_tokens(m, &p);
        let msg = format!("{what} must be finite{}", s.bound());
        let s = s.variant();
        out.push(quote!(::vigp::embedded::dynamics::check_parameter(
            #value,
            ::vigp::embedded::dynamics::ParameterSign::#s,
            #msg
        )?;));
    };
    for i in 0..2 {
        check(Param::Gravity(i), Sign::Any, format!("gravity[{i}]"));
    }
    for (l, link) in m.links.iter().enumerate() {
        let name = syn::ext::IdentExt::unraw(&link.name).to_string();
        for (p, s, field) in [
            (Param::Mass(l), Sign::NonNegative, "mass"),
            (Param::Length(l), Sign::Positive, "length"),
            (Param::Inertia(l), Sign::NonNegative, "inertia"),
            (Param::Com(l, 0), Sign::Any, "com[0]"),
            (Param::Com(l, 1), Sign::Any, "com[1]"),
        ] {
            check(p, s, format!("link `{name}`: {field}"));
        }
    }
    // all joints' dampings, then each joint's spring
    type Field = (fn(usize) -> Param, Sign, &'static str);
    let damping: &[Field] = &[(Param::Damping, Sign::NonNegative, "damping")];
    let spring: &[Field] = &[
        (Param::Stiffness, Sign::NonNegative, "stiffness"),
        (Param::Rest, Sign::Any, "rest"),
    ];
    for (fields, present) in [(damping, m.dissipative()), (spring, m.elastic())] {
        if !present {
            continue;
        }
        for (j, joint) in m.joints.iter().enumerate() {
            let name = syn::ext::IdentExt::unraw(&joint.name).to_string();
            for &(p, s, field) in fields {
                check(p(j), s, format!("joint `{name}`: {field}"));
            }
        }
    }
    out
}
