//! The mechanics of a validated [`Model`] as closed-form expressions
//! ([`crate::symbolic`]): kinematics of every body, the energies, joint
//! coordinates and constraints, in either coordinate view. [`crate::emit`]
//! turns them into the generated `Dynamics` implementations.
//!
//! Conventions are those of the DSL (and of the generated forward
//! kinematics, which the std runtime's dual-number reference evaluates): a
//! link's frame sits at its `start`, θ = 0 hangs straight down, a local
//! point (a, b) maps to `origin + a·(sin θ, −cos θ) + b·(cos θ, sin θ)`.

// Index loops over (symmetric) matrices of expressions read as the
// formulas they implement; iterator chains would hide the indices.
#![allow(clippy::needless_range_loop)]

use crate::desc::planar::{Anchor, JointKind, Model, Point};
use crate::symbolic::{Expr, Freq, Poly, Sym, Vec2};
use syn::ext::IdentExt;

/// Which coordinates the expressions are written in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum View {
    /// One coordinate per tree joint; loop joints are constraints.
    Minimal,
    /// (x, y, θ) of each link's centre of mass; every joint is a constraint.
    Maximal,
}

/// A run-time parameter the expressions refer to (`Sym::Param(i)` is entry
/// `i` of [`Mechanics::params`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Param {
    /// `gravity[i]`.
    Gravity(usize),
    /// `links.<link>.mass`.
    Mass(usize),
    /// `links.<link>.length`.
    Length(usize),
    /// `links.<link>.inertia`.
    Inertia(usize),
    /// `links.<link>.com[i]`.
    Com(usize, usize),
    /// `joints.<joint>.damping`.
    Damping(usize),
    /// `joints.<joint>.stiffness`.
    Stiffness(usize),
    /// `joints.<joint>.rest`.
    Rest(usize),
}

/// One rigid body.
#[derive(Clone, Debug)]
pub struct Body {
    /// Link index.
    pub link: usize,
    /// World position of the centre of mass.
    pub com: Vec2,
    /// Orientation θ (a polynomial: linear in the angle coordinates).
    pub theta: Expr,
}

/// A frame (link pose) during the construction.
#[derive(Clone, Debug)]
struct Frame {
    origin: Vec2,
    freq: Freq,
    theta: Expr,
    cos: Expr,
    sin: Expr,
}

impl Frame {
    fn new(origin: Vec2, freq: Freq) -> Self {
        let n = freq.len();
        let mut theta = Expr::zero(n);
        for (k, w) in freq.iter().enumerate() {
            if *w != 0 {
                theta.axpy(*w as f64, &Expr::coord(n, k));
            }
        }
        let (cos, sin) = if freq.iter().all(|w| *w == 0) {
            (Expr::constant(n, 1.0), Expr::zero(n))
        } else {
            (Expr::cos(freq.clone()), Expr::sin(freq.clone()))
        };
        Self {
            origin,
            freq,
            theta,
            cos,
            sin,
        }
    }

    /// World direction of a local direction.
    fn direction(&self, local: &[Expr; 2]) -> Vec2 {
        let [a, b] = local;
        Vec2 {
            x: a.mul(&self.sin).add(&b.mul(&self.cos)),
            y: b.mul(&self.sin).sub(&a.mul(&self.cos)),
        }
    }

    /// World position of a local point.
    fn point(&self, local: &[Expr; 2]) -> Vec2 {
        self.origin.add(&self.direction(local))
    }
}

/// Everything the generated `Dynamics` implementation needs, as
/// expressions in the coordinates of one [`View`].
#[derive(Clone, Debug)]
pub struct Mechanics {
    /// The view.
    pub view: View,
    /// Number of coordinates.
    pub n: usize,
    /// Parameters referenced by `Sym::Param`.
    pub params: Vec<Param>,
    /// `true` for angle coordinates.
    pub angle: Vec<bool>,
    /// Rigid bodies (one per link).
    pub bodies: Vec<Body>,
    /// Potential energy V(q).
    pub potential: Expr,
    /// Mass matrix M(q) (N × N, symmetric).
    pub mass: Vec<Vec<Expr>>,
    /// Damped joints: (damping parameter, joint coordinate s(q)).
    pub dampers: Vec<(usize, Expr)>,
    /// Constraint rows g(q) (loop joints in minimal coordinates, every
    /// joint in maximal coordinates).
    pub constraints: Vec<Expr>,
    /// Coordinates s(q) of the actuated joints, in declaration order: input
    /// i applies the generalized force u_i ∇s_i(q).
    pub inputs: Vec<Expr>,
}

struct Builder<'m> {
    m: &'m Model,
    n: usize,
    params: Vec<Param>,
}

impl Builder<'_> {
    fn param_index(&mut self, p: Param) -> usize {
        match self.params.iter().position(|q| *q == p) {
            Some(i) => i,
            None => {
                self.params.push(p);
                self.params.len() - 1
            }
        }
    }

    fn param(&mut self, p: Param) -> Expr {
        let i = self.param_index(p);
        Expr::poly(self.n, Poly::sym(Sym::Param(i)))
    }

    fn constant(&self, c: f64) -> Expr {
        Expr::constant(self.n, c)
    }

    fn pair(&self, p: [f64; 2]) -> [Expr; 2] {
        [self.constant(p[0]), self.constant(p[1])]
    }

    /// Local coordinates of an anchor on `link`.
    fn anchor(&mut self, link: usize, anchor: Anchor) -> [Expr; 2] {
        match anchor {
            Anchor::Start => self.pair([0.0, 0.0]),
            Anchor::End => [self.param(Param::Length(link)), self.constant(0.0)],
            Anchor::Center => [
                self.param(Param::Length(link)).scale(0.5),
                self.constant(0.0),
            ],
            Anchor::At(p) => self.pair(p),
        }
    }

    fn com(&mut self, link: usize) -> [Expr; 2] {
        [
            self.param(Param::Com(link, 0)),
            self.param(Param::Com(link, 1)),
        ]
    }

    /// World position of a point, given the frames built so far.
    fn point(&mut self, frames: &[Option<Frame>], p: Point) -> Vec2 {
        match p {
            Point::World(w) => Vec2 {
                x: self.constant(w[0]),
                y: self.constant(w[1]),
            },
            Point::Link { link, anchor } => {
                let local = self.anchor(link, anchor);
                frames[link].as_ref().expect("frame built").point(&local)
            }
        }
    }

    /// Orientation expression of the body a point is on (world: 0).
    fn theta(&self, frames: &[Option<Frame>], p: Point) -> Expr {
        match p.link() {
            None => Expr::zero(self.n),
            Some(l) => frames[l].as_ref().expect("frame built").theta.clone(),
        }
    }

    /// World direction of a prismatic axis fixed in the parent.
    fn axis(&self, frames: &[Option<Frame>], parent: Point, axis: [f64; 2]) -> Vec2 {
        match parent.link() {
            None => Vec2 {
                x: self.constant(axis[0]),
                y: self.constant(axis[1]),
            },
            Some(l) => frames[l]
                .as_ref()
                .expect("frame built")
                .direction(&self.pair(axis)),
        }
    }

    /// The coordinate of joint `j` (relative angle or slide) from the frames.
    fn joint_coordinate(&mut self, frames: &[Option<Frame>], j: usize) -> Expr {
        let joint = self.m.joints[j].clone();
        match joint.kind {
            JointKind::Revolute => self
                .theta(frames, joint.child)
                .sub(&self.theta(frames, joint.parent)),
            JointKind::Prismatic { axis } => {
                let gap = self
                    .point(frames, joint.child)
                    .sub(&self.point(frames, joint.parent));
                gap.dot(&self.axis(frames, joint.parent, axis))
            }
        }
    }

    /// The two constraint rows of joint `j` (as the generated
    /// `constraints` of the dual-number views: revolute `parent − child`;
    /// prismatic `(child − parent) × axis` and the relative angle).
    fn joint_rows(&mut self, frames: &[Option<Frame>], j: usize) -> [Expr; 2] {
        let joint = self.m.joints[j].clone();
        let (pp, cp) = (
            self.point(frames, joint.parent),
            self.point(frames, joint.child),
        );
        match joint.kind {
            JointKind::Revolute => {
                let gap = pp.sub(&cp);
                [gap.x, gap.y]
            }
            JointKind::Prismatic { axis } => {
                let gap = cp.sub(&pp);
                let dir = self.axis(frames, joint.parent, axis);
                let turn = self
                    .theta(frames, joint.child)
                    .sub(&self.theta(frames, joint.parent));
                [gap.cross(&dir), turn]
            }
        }
    }

    /// Link frames in minimal coordinates (forward kinematics).
    fn minimal_frames(&mut self) -> Vec<Option<Frame>> {
        let n = self.n;
        let mut frames: Vec<Option<Frame>> = vec![None; self.m.links.len()];
        for &l in &self.m.order.clone() {
            let j = self.m.placed_by[l];
            let joint = self.m.joints[j].clone();
            let k = self
                .m
                .coordinate_of(j)
                .expect("tree joint has a coordinate");
            let Point::Link { anchor, .. } = joint.child else {
                unreachable!("a tree joint's child is a link")
            };
            let local = self.anchor(l, anchor);
            let parent_at = self.point(&frames, joint.parent);
            let parent_freq = match joint.parent.link() {
                None => vec![0; n],
                Some(p) => frames[p].as_ref().expect("parent first").freq.clone(),
            };
            let (freq, at) = match joint.kind {
                JointKind::Revolute => {
                    let mut f = parent_freq;
                    f[k] += 1;
                    (f, parent_at)
                }
                JointKind::Prismatic { axis } => {
                    let dir = self.axis(&frames, joint.parent, axis);
                    let slide = dir.times(&Expr::coord(n, k));
                    (parent_freq, parent_at.add(&slide))
                }
            };
            let mut frame = Frame::new(Vec2::zero(n), freq);
            frame.origin = at.sub(&frame.direction(&local));
            frames[l] = Some(frame);
        }
        frames
    }

    /// Link frames in maximal coordinates: (x, y, θ) of each centre of mass.
    fn maximal_frames(&mut self) -> Vec<Option<Frame>> {
        let n = self.n;
        (0..self.m.links.len())
            .map(|l| {
                let mut freq = vec![0; n];
                freq[3 * l + 2] = 1;
                let mut frame = Frame::new(Vec2::zero(n), freq);
                let com = self.com(l);
                let at = Vec2 {
                    x: Expr::coord(n, 3 * l),
                    y: Expr::coord(n, 3 * l + 1),
                };
                frame.origin = at.sub(&frame.direction(&com));
                Some(frame)
            })
            .collect()
    }
}

impl Mechanics {
    /// The mechanics of `m` in coordinates `view`.
    pub fn new(m: &Model, view: View) -> Self {
        let n = match view {
            View::Minimal => m.dof(),
            View::Maximal => 3 * m.links.len(),
        };
        let mut b = Builder {
            m,
            n,
            params: Vec::new(),
        };
        let frames = match view {
            View::Minimal => b.minimal_frames(),
            View::Maximal => b.maximal_frames(),
        };
        let angle = match view {
            View::Minimal => m
                .tree
                .iter()
                .map(|&j| m.joints[j].kind == JointKind::Revolute)
                .collect(),
            View::Maximal => (0..n).map(|i| i % 3 == 2).collect(),
        };

        // bodies and energies
        let (gx, gy) = (b.param(Param::Gravity(0)), b.param(Param::Gravity(1)));
        let mut bodies = Vec::new();
        let mut potential = Expr::zero(n);
        for l in 0..m.links.len() {
            let frame = frames[l].clone().expect("every link placed");
            let com_local = b.com(l);
            let com = frame.point(&com_local);
            let mass = b.param(Param::Mass(l));
            let height = com.x.mul(&gx).add(&com.y.mul(&gy));
            potential = potential.sub(&height.mul(&mass));
            bodies.push(Body {
                link: l,
                com,
                theta: frame.theta.clone(),
            });
        }
        let mut mass = vec![vec![Expr::zero(n); n]; n];
        for body in &bodies {
            let l = body.link;
            let (mb, ib) = (b.param(Param::Mass(l)), b.param(Param::Inertia(l)));
            let jp: Vec<Vec2> = (0..n).map(|k| body.com.deriv(k)).collect();
            let jt: Vec<Expr> = (0..n).map(|k| body.theta.deriv(k)).collect();
            for j in 0..n {
                for k in j..n {
                    let e = jp[j].dot(&jp[k]).mul(&mb).add(&jt[j].mul(&jt[k]).mul(&ib));
                    mass[j][k] = mass[j][k].add(&e);
                }
            }
        }
        for j in 0..n {
            for k in 0..j {
                mass[j][k] = mass[k][j].clone();
            }
        }

        // joint coordinates s_j(q), for dampers, springs and inputs
        let mut coordinates: Vec<Option<Expr>> = vec![None; m.joints.len()];
        let mut joint_coordinate = |b: &mut Builder, j: usize| {
            coordinates[j]
                .get_or_insert_with(|| match (view, m.coordinate_of(j)) {
                    (View::Minimal, Some(k)) => Expr::coord(n, k),
                    _ => b.joint_coordinate(&frames, j),
                })
                .clone()
        };

        // dampers
        let mut dampers = Vec::new();
        if m.dissipative() {
            for j in 0..m.joints.len() {
                let s = joint_coordinate(&mut b, j);
                dampers.push((b.param_index(Param::Damping(j)), s));
            }
        }

        // springs: V += ½ k_j (s_j − r_j)² for every joint (run-time k, r)
        if m.elastic() {
            for j in 0..m.joints.len() {
                let s = joint_coordinate(&mut b, j);
                let (k, r) = (b.param(Param::Stiffness(j)), b.param(Param::Rest(j)));
                let stretch = s.sub(&r);
                potential = potential.add(&stretch.mul(&stretch).mul(&k).scale(0.5));
            }
        }

        // inputs
        let inputs: Vec<Expr> = m
            .inputs()
            .into_iter()
            .map(|j| joint_coordinate(&mut b, j))
            .collect();

        // constraints
        let joints: Vec<usize> = match view {
            View::Minimal => m.loops.clone(),
            View::Maximal => (0..m.joints.len()).collect(),
        };
        let mut constraints = Vec::new();
        for j in joints {
            constraints.extend(b.joint_rows(&frames, j));
        }

        Mechanics {
            view,
            n,
            params: b.params,
            angle,
            bodies,
            potential,
            mass,
            dampers,
            constraints,
            inputs,
        }
    }

    /// `false` when a coefficient of the closed forms is not finite or so
    /// large (> 1e300) that its derivatives could overflow: the
    /// description's literal numbers (anchors, world points) are too large.
    pub fn coefficients_are_finite(&self) -> bool {
        let ok = |e: &Expr| e.max_abs_coefficient() <= 1e300;
        self.mass.iter().flatten().all(ok)
            && ok(&self.potential)
            && self.constraints.iter().all(ok)
            && self.dampers.iter().all(|(_, s)| ok(s))
            && self.inputs.iter().all(ok)
    }

    /// The input matrix B(q) (N × U): column i is ∇s_i of actuated joint i.
    pub fn input_matrix(&self) -> Vec<Vec<Expr>> {
        (0..self.n)
            .map(|k| self.inputs.iter().map(|s| s.deriv(k)).collect())
            .collect()
    }

    /// Number of constraint rows.
    pub fn c(&self) -> usize {
        self.constraints.len()
    }

    /// `true` when M does not depend on q.
    pub fn constant_mass(&self) -> bool {
        self.mass.iter().flatten().all(Expr::is_constant)
    }

    /// ∇V.
    pub fn potential_gradient(&self) -> Vec<Expr> {
        (0..self.n).map(|k| self.potential.deriv(k)).collect()
    }

    /// D(q) = Σ c_j ∇s_j ∇s_jᵀ.
    pub fn damping_matrix(&self) -> Vec<Vec<Expr>> {
        let n = self.n;
        let mut d = vec![vec![Expr::zero(n); n]; n];
        for (c, s) in &self.dampers {
            let grad: Vec<Expr> = (0..n).map(|k| s.deriv(k)).collect();
            let c = Expr::poly(n, Poly::sym(Sym::Param(*c)));
            for j in 0..n {
                for k in j..n {
                    d[j][k] = d[j][k].add(&grad[j].mul(&grad[k]).mul(&c));
                }
            }
        }
        for j in 0..n {
            for k in 0..j {
                d[j][k] = d[k][j].clone();
            }
        }
        d
    }

    /// The Rust path (relative to the parameter struct) and a readable name
    /// of parameter `i`, e.g. `links.upper.mass`.
    pub fn param_path(&self, m: &Model, i: usize) -> String {
        let link = |l: usize| m.links[l].name.unraw().to_string();
        match self.params[i] {
            Param::Gravity(k) => format!("gravity[{k}]"),
            Param::Mass(l) => format!("links.{}.mass", link(l)),
            Param::Length(l) => format!("links.{}.length", link(l)),
            Param::Inertia(l) => format!("links.{}.inertia", link(l)),
            Param::Com(l, k) => format!("links.{}.com[{k}]", link(l)),
            Param::Damping(j) => format!("joints.{}.damping", m.joints[j].name.unraw()),
            Param::Stiffness(j) => format!("joints.{}.stiffness", m.joints[j].name.unraw()),
            Param::Rest(j) => format!("joints.{}.rest", m.joints[j].name.unraw()),
        }
    }
}
