//! The linear-time variational step of a [`Tree`]: kinematics, momentum,
//! the discrete Euler–Lagrange residual and the articulated-body solve,
//! each one recursive pass (or two) over the bodies.

// Loops over the six components of spatial vectors and over bodies by index
// follow the equations (parent and child bodies are read in one loop).
#![allow(clippy::needless_range_loop)]

use super::model::{InvalidTree, JointKind, Tree, validate};
use super::spatial::{
    Inertia6, M3, M6, V3, V6, add, axis_angle, congruence, cross, cross_force, cross_motion, dot6,
    lift3, lift33, mul_mm, mul_mv, mul6, scale, zero,
};
use crate::Real;

/// The workspace of one body: its pose, world axis and inertias at the
/// configuration being evaluated, its articulated-body factors, twists,
/// momenta and the per-coordinate numbers of the solve. A step needs
/// `tree.len()` of them (`core::mem::size_of::<BodyScratch>()` bytes each,
/// about 1 KB); they are overwritten by every call, so one slice serves
/// any number of steps and trees. A step leaves the poses at the state it
/// committed, as [`Engine::momentum_of`] and
/// [`Engine::momentum_derivatives`] leave them at theirs; the next step of
/// the same tree from exactly that state (bit for bit: q, v and p) reuses
/// them for its starting energy instead of recomputing them (every other
/// call clears that mark).
///
/// The kinematic and momentum fields are of the scalar `R`: `f64` for the
/// step, a jet ([`crate::Jet1`]) for [`Engine::terms`] with exact
/// derivatives; the solver's fields are always `f64`.
#[derive(Clone, Copy, Debug, Default)]
pub struct BodyScratch<R = f64> {
    rot: M3<R>,
    pos: V3<R>,
    s: V6<R>,
    inertia: Inertia6<R>,
    composite: Inertia6<R>,
    /// The solve's factors (module docs of [`Engine::factor`]): the
    /// articulated operator IA, m = IA·S, the left vector ℓ, the row
    /// vector e and the pivot δ.
    ia: M6,
    u6: V6,
    l: V6,
    e: V6,
    d: f64,
    vel: V6<R>,
    hc: V6<R>,
    pa: V6,
    acc: V6,
    /// a = S ×ₘ V, read by every pair of [`Engine::term_derivatives`]
    /// that the body is on.
    sv: V6,
    /// ∂V/∂q at `at` (gravity and spring).
    dv: R,
    // per coordinate: the committed state (q, v) and its momentum p, the
    // configuration `at` evaluated, the iterate `vn`, its momentum `pn`
    // and ∂T/∂q `dtq`, the residual `r`, the solve's `x` and the
    // generalized force `tau`
    q: f64,
    v: f64,
    p: f64,
    at: R,
    vn: R,
    pn: R,
    dtq: R,
    r: f64,
    x: f64,
    tau: f64,
    /// The first iteration's start of the step (the caller's guess, or v).
    guess: f64,
    // Anderson acceleration: the last iterate and step, and the last
    // differences of iterates and steps
    vprev: f64,
    fprev: f64,
    dvs: [f64; ANDERSON],
    dfs: [f64; ANDERSON],
    /// In the first body: the [`Engine`]'s fingerprint when the workspace
    /// holds the poses of that tree at the state its last step committed
    /// (0 otherwise): the next step from that state reuses them.
    tag: u64,
}

/// Memory of the Anderson acceleration of the chord iteration.
const ANDERSON: usize = 3;

/// The Anderson mixing of one iteration: `None`, the plain chord
/// step v ← v + f; `Some((m, γ))`, the Anderson-accelerated update (type
/// II, memory [`ANDERSON`]) of the chord map G(v) = v + K⁻¹r(v) ([`Engine::factor`]):
/// with ΔV, ΔF the last m differences of iterates and of steps
/// f = G(v) − v, γ = argmin ‖f − ΔFγ‖₂ (normal equations, at most 3×3) and
/// v ← v + f − (ΔV + ΔF)γ. On the nearly linear DEL residual near its root
/// this is GMRES in disguise; a singular Gram matrix falls back to the
/// plain step.
type Mixing = Option<(usize, [f64; ANDERSON])>;

/// Solves the m×m system g[..m][..m]·γ = g[..m][ANDERSON] by Gaussian
/// elimination with partial pivoting; `None` when a pivot is below 1e-12 of
/// the largest diagonal entry (differences that are linearly dependent).
fn solve_small(g: &mut [[f64; ANDERSON + 1]; ANDERSON], m: usize) -> Option<[f64; ANDERSON]> {
    let mut big = 0.0f64;
    for i in 0..m {
        big = big.max(g[i][i]);
    }
    if !(big > 0.0 && big.is_finite()) {
        return None;
    }
    for c in 0..m {
        // the largest |pivot| (NaN counts as largest; the last of equals)
        let mut p = c;
        for r in c + 1..m {
            if g[r][c].abs().total_cmp(&g[p][c].abs()) != core::cmp::Ordering::Less {
                p = r;
            }
        }
        if g[p][c].abs() <= 1e-12 * big {
            return None;
        }
        g.swap(c, p);
        for r in c + 1..m {
            let f = g[r][c] / g[c][c];
            for k in c..m {
                g[r][k] -= f * g[c][k];
            }
            g[r][ANDERSON] -= f * g[c][ANDERSON];
        }
    }
    let mut x = [0.0; ANDERSON];
    for c in (0..m).rev() {
        let mut s = g[c][ANDERSON];
        for k in c + 1..m {
            s -= g[c][k] * x[k];
        }
        x[c] = s / g[c][c];
    }
    Some(x)
}

impl<R: Real> BodyScratch<R> {
    /// A workspace of the scalar `R` (all zero).
    pub fn zeroed() -> Self {
        let z6 = [zero(); 6];
        Self {
            rot: [[zero(); 3]; 3],
            pos: [zero(); 3],
            s: z6,
            inertia: Inertia6::zero(),
            composite: Inertia6::zero(),
            ia: [[0.0; 6]; 6],
            u6: [0.0; 6],
            l: [0.0; 6],
            e: [0.0; 6],
            d: 0.0,
            vel: z6,
            hc: z6,
            pa: [0.0; 6],
            acc: [0.0; 6],
            sv: [0.0; 6],
            dv: zero(),
            q: 0.0,
            v: 0.0,
            p: 0.0,
            at: zero(),
            vn: zero(),
            pn: zero(),
            dtq: zero(),
            r: 0.0,
            x: 0.0,
            tau: 0.0,
            guess: 0.0,
            vprev: 0.0,
            fprev: 0.0,
            dvs: [0.0; ANDERSON],
            dfs: [0.0; ANDERSON],
            tag: 0,
        }
    }

    /// The body's world pose (rotation, origin) at the last evaluated
    /// configuration.
    pub fn pose(&self) -> (M3<R>, V3<R>) {
        (self.rot, self.pos)
    }
}

/// Options of the engine's step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EngineOptions {
    /// Convergence when max|r| / (max|p₀| + m̄) is below this, r the DEL
    /// residual, p₀ the momentum and m̄ the largest diagonal entry of M
    /// (the scaling of [`crate::Stepper`]). Default 1e-12.
    pub tolerance: f64,
    /// Iterations per sub-step before it counts as failed (default 50).
    pub max_iterations: usize,
    /// Largest number of halvings of a step that does not converge
    /// (default 10: down to Δt/1024). 0 turns the subdivision off.
    pub max_depth: u32,
    /// Largest contraction of the scaled residual by the first iteration
    /// (default 0.5): a step whose iteration contracts less is too long for
    /// the chord map to be a contraction around v₀ (the DEL equations
    /// then may have their root far away, or another root nearer), and is
    /// subdivided. Not tested when the first residual is already within
    /// 1000 × tolerance.
    pub max_contraction: f64,
    /// Largest energy jump of a sub-step, relative to the energy scale
    /// T₀ + T₁ + Σ m_i|g|·|c_i| (c_i the centres of mass from the world
    /// origin), after the work of inputs and damping over the sub-step
    /// (h·Σ(τ_i − d_i v₁_i)(v₀_i + v₁_i)/2, v₀ and v₁ the velocities
    /// before and after) is taken off; default 1e-3. A variational
    /// step's energy error is bounded and changes by O(Δt²) per step; a
    /// larger jump means Δt resolves the motion no more (the first-order
    /// rule's discrete flow turns unstable), and the step is subdivided.
    /// `f64::INFINITY` turns the test off.
    pub energy_tolerance: f64,
}

impl Default for EngineOptions {
    fn default() -> Self {
        Self {
            tolerance: 1e-12,
            max_iterations: 50,
            max_depth: 10,
            max_contraction: 0.5,
            energy_tolerance: 1e-3,
        }
    }
}

/// Why the engine refused or failed a step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum EngineError {
    /// The tree does not describe a mechanism.
    InvalidTree(InvalidTree),
    /// Options that cannot work (the message says which).
    InvalidOptions(&'static str),
    /// A slice has the wrong length.
    WrongLength {
        /// Which slice.
        what: &'static str,
        /// Length required.
        expected: usize,
        /// Length given.
        got: usize,
    },
    /// Δt is not finite and > 0, or Δt² is not a normal number.
    InvalidTimeStep {
        /// The offending Δt.
        dt: f64,
    },
    /// The state or momentum holds NaN or ±∞.
    NonFiniteState,
    /// A generalized force holds NaN or ±∞.
    NonFiniteInput,
    /// The mass matrix (plus Δt·damping) is singular at this configuration:
    /// the subtree of `body` has no inertia along its joint (e.g. a
    /// massless leaf).
    SingularMass {
        /// The body (= coordinate) whose articulated inertia vanished.
        body: usize,
    },
    /// The Newton matrix of a converged sub-step is singular (or its
    /// solve not finite), so the step has no derivatives there
    /// ([`Engine::step_derivatives`]).
    SingularNewtonMatrix,
    /// The sub-steps converged, but down to `substep_dt` one still changed
    /// the energy by more than [`EngineOptions::energy_tolerance`].
    EnergyJump {
        /// Halvings made (the options' `max_depth`).
        depth: u32,
        /// The sub-step (s).
        substep_dt: f64,
        /// Its relative energy jump.
        jump: f64,
    },
    /// No sub-step converged: the step was halved `depth` times down to
    /// `substep_dt` and the iteration still failed there.
    NotConverged {
        /// Halvings made (the options' `max_depth`).
        depth: u32,
        /// The sub-step that failed (s).
        substep_dt: f64,
        /// Iterations of that last attempt.
        iterations: usize,
        /// Its scaled residual (NaN: the iterate blew up).
        residual: f64,
    },
}

impl core::fmt::Display for EngineError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::InvalidTree(e) => write!(f, "{e}"),
            Self::InvalidOptions(why) => write!(f, "invalid engine options: {why}"),
            Self::WrongLength {
                what,
                expected,
                got,
            } => write!(f, "{what} has length {got}, expected {expected}"),
            Self::InvalidTimeStep { dt } => write!(
                f,
                "invalid time step dt = {dt:e} (must be finite and > 0, with dt² a normal number)"
            ),
            Self::NonFiniteState => write!(f, "non-finite state or momentum"),
            Self::NonFiniteInput => write!(f, "non-finite generalized force"),
            Self::SingularMass { body } => write!(
                f,
                "singular mass matrix: the subtree of body {body} has no inertia along its joint"
            ),
            Self::SingularNewtonMatrix => write!(
                f,
                "the Newton matrix of a converged sub-step is singular: the step has no derivatives there"
            ),
            Self::EnergyJump {
                depth,
                substep_dt,
                jump,
            } => write!(
                f,
                "halved {depth} times down to dt = {substep_dt:e}, a sub-step still changed the energy by {jump:.3e} of its scale"
            ),
            Self::NotConverged {
                depth,
                substep_dt,
                iterations,
                residual,
            } => write!(
                f,
                "no sub-step converged: halved {depth} times down to dt = {substep_dt:e}, \
                 still not converged after {iterations} iterations (scaled residual {residual:.3e})"
            ),
        }
    }
}

impl core::error::Error for EngineError {}

impl From<InvalidTree> for EngineError {
    fn from(e: InvalidTree) -> Self {
        Self::InvalidTree(e)
    }
}

/// Diagnostics of a step (sums and maxima over its sub-steps).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct EngineReport {
    /// Chord iterations (solves with the factored Newton matrix) over all sub-steps,
    /// failed attempts included.
    pub iterations: usize,
    /// Sub-steps that converged (1 when the step was not subdivided).
    pub substeps: usize,
    /// Halvings: the step's sub-step is Δt/2^depth.
    pub depth: u32,
    /// Largest final scaled residual of a sub-step.
    pub residual: f64,
}

/// A failed sub-step.
enum SubFail {
    NotConverged { iterations: usize, residual: f64 },
    EnergyJump { iterations: usize, jump: f64 },
    Singular(usize),
}

/// The variational integrator of a [`Tree`] in minimal coordinates, O(N)
/// per residual and per solve.
///
/// # The step
///
/// L(q, v) = ½vᵀM(q)v − V(q), V = gravity + joint springs; the first-order
/// rule L_d(a, b) = Δt·L(a, (b − a)/Δt). From (q₀, v₀) with momentum
/// p₀ = M(q₀)v₀, q₁ = q₀ + Δt·v₀ and v₁ solves
///
/// ```text
/// r(v₁) = p₀ − M(q₁)v₁ + Δt·(∂T/∂q(q₁, v₁) − ∇V(q₁) − D·v₁ + τ) = 0,
/// ```
///
/// D = diag(damping), τ the generalized forces. The momentum carried is
/// p₁ = M(q₁)v₁ — the equations of [`crate::Stepper::new`].
///
/// # The passes
///
/// With world-frame joint axes S_i (unit twists), body twists
/// V_i = V_λ(i) + S_i v_i, body momenta I_i V_i and composite momenta
/// h_i = Σ_{j ∈ subtree(i)} I_j V_j (one backward pass):
/// p_i = S_i·h_i, ∂T/∂q_i = (V_i ×ₘ S_i)·h_i (the axis moves as
/// Ṡ_i = V_i ×ₘ S_i), ∂V/∂q_i = −S_i·W_i with W_i the gravity wrench of
/// subtree i, plus k_i(q_i − rest_i). q₁ is fixed during a step, so the
/// kinematics, the composite inertias and ∇V are evaluated once per
/// sub-step; each residual is a forward and a backward pass.
///
/// # The iteration: a chord method on the Newton matrix, in O(N)
///
/// The Newton matrix of the residual is −K, K = M + Δt·D − Δt·C with
/// C = ∂(∂T/∂q)/∂v. The engine iterates v ← v + K⁻¹ r(v) with K factored
/// once per sub-step at the iterate it starts from (the caller's guess or
/// v), by a leaves-first elimination that is the articulated-body
/// algorithm with a non-symmetric rank-one update per body. With I_b and
/// h_b the composite inertia and momentum of b's subtree, V_b its twist
/// and w_b = V_b ×ₘ S_b, the entries of C are S_jᵀ(S_b ×* h_b + I_b w_b)
/// for j on b's path and w_jᵀ I_b S_b for j strictly above b, and one
/// backward pass of 6×6 operators gives
///
/// ```text
/// IA_b = I_b(own) + Σ_children (IA_c − m_c ℓ_cᵀ/δ_c),   m_b = IA_b S_b,   e_b = S_b − Δt·w_b,
/// ℓ_b = IA_bᵀ e_b − Δt·(S_b ×* h_b),   δ_b = e_bᵀ m_b + Δt·d_b;
/// ```
///
/// each solve is then a backward pass ρ_b = r_b − e_bᵀ g_b,
/// g_parent += g_b + m_b ρ_b/δ_b and a forward pass
/// x_b = (ρ_b − ℓ_bᵀ Y_parent)/δ_b, Y_b = Y_parent + S_b x_b, on
/// 6-vectors (at Δt·C = 0 this is the articulated-body algorithm for
/// M + Δt·D). Near the root this chord
/// map contracts by about Δt·|C(v₁) − C(v_start)|, which a good start
/// makes small (the map with M + Δt·D alone contracts by Δt·|C| ~ Δt·|ω|).
/// Where a pivot of K is not positive (Δt·|ω| large), the factors are
/// those of M + Δt·D. From the second iteration on the map is
/// Anderson-accelerated (memory 3), which on the nearly linear residual
/// near its root acts as GMRES. It converges to the scaled residual of
/// [`crate::Stepper`] (module docs of [`EngineOptions::tolerance`]). Where
/// it does not (the first iteration contracts less than
/// [`EngineOptions::max_contraction`], a scaled residual grows fourfold
/// above its best, NaN, or `max_iterations`), the sub-step counts as failed
/// and the step is halved; so is a converged sub-step whose energy jumps
/// ([`EngineOptions::energy_tolerance`]).
///
/// # Adaptive sub-steps
///
/// A step that fails is redone as two steps of Δt/2 from the same state
/// (the variational integrator at Δt/2: the velocity of the state is then
/// the discrete velocity of the last sub-step), recursively up to
/// `max_depth` halvings; once halved, the rest of the step keeps the finer
/// sub-step. [`EngineReport`] says how deep a step went.
#[derive(Clone, Copy, Debug)]
pub struct Engine<T: Tree> {
    tree: T,
    options: EngineOptions,
    /// A hash of what the poses depend on (never 0).
    fingerprint: u64,
    /// Whether the derivatives solve J in the tree's pattern
    /// (`model::branched`).
    pub(super) branched: bool,
    /// Whether every body's parent is the one before it (then every pair
    /// of bodies is on one path, and no entry of the term derivatives is
    /// structurally zero).
    chain: bool,
}

/// FNV-1a over 64-bit words: the fingerprint of a tree's geometry and
/// masses (what the poses and first moments depend on), so that a
/// workspace stepped by one engine is not mistaken for another's.
fn fingerprint<T: Tree>(tree: &T) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |x: u64| {
        for byte in x.to_le_bytes() {
            h ^= u64::from(byte);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    };
    eat(tree.len() as u64);
    for i in 0..tree.len() {
        let b = tree.body(i);
        eat(b.parent.map_or(0, |p| p as u64 + 1));
        eat(match b.joint {
            JointKind::Revolute => 1,
            JointKind::Prismatic => 2,
        });
        let words = b
            .axis
            .iter()
            .chain(b.rotation.iter().flatten())
            .chain(&b.translation)
            .chain(&b.com)
            .chain(core::iter::once(&b.mass));
        for x in words {
            eat(x.to_bits());
        }
    }
    h | 1
}

/// The ranges [`Engine::with_options`] accepts.
fn check_options(options: &EngineOptions) -> Result<(), EngineError> {
    if !(options.tolerance.is_finite() && options.tolerance > 0.0) {
        return Err(EngineError::InvalidOptions(
            "tolerance must be finite and > 0",
        ));
    }
    if options.max_iterations == 0 {
        return Err(EngineError::InvalidOptions("max_iterations must be >= 1"));
    }
    if !(options.max_contraction > 0.0 && options.max_contraction <= 1.0) {
        return Err(EngineError::InvalidOptions(
            "max_contraction must be in (0, 1]",
        ));
    }
    if options.energy_tolerance.is_nan() || options.energy_tolerance <= 0.0 {
        return Err(EngineError::InvalidOptions("energy_tolerance must be > 0"));
    }
    if options.max_depth > 30 {
        return Err(EngineError::InvalidOptions("max_depth must be <= 30"));
    }
    Ok(())
}

/// Δt must be finite and > 0 with Δt² a normal number (the step divides
/// by it); else [`EngineError::InvalidTimeStep`].
pub(super) fn check_time_step(dt: f64) -> Result<(), EngineError> {
    if dt.is_finite() && dt > 0.0 && (dt * dt).is_normal() {
        Ok(())
    } else {
        Err(EngineError::InvalidTimeStep { dt })
    }
}

pub(super) fn check_len(
    what: &'static str,
    got: usize,
    expected: usize,
) -> Result<(), EngineError> {
    if got == expected {
        Ok(())
    } else {
        Err(EngineError::WrongLength {
            what,
            expected,
            got,
        })
    }
}

/// The outputs of [`Engine::term_derivatives`]: five row-major N × N
/// matrices (N² entries each).
#[derive(Debug)]
pub struct TermDerivatives<'a> {
    /// ∂p/∂q, p = M(q)v the momentum.
    pub p_q: &'a mut [f64],
    /// ∂p/∂v = M(q).
    pub p_v: &'a mut [f64],
    /// ∂(∂T/∂q)/∂q.
    pub t_q: &'a mut [f64],
    /// ∂(∂T/∂q)/∂v.
    pub t_v: &'a mut [f64],
    /// ∂(∇V)/∂q (gravity and springs).
    pub v_q: &'a mut [f64],
}

impl<'a> TermDerivatives<'a> {
    /// The five outputs as consecutive N × N blocks of `buf` (at least
    /// 5N² numbers), in the order of the fields.
    pub fn split(buf: &'a mut [f64], n: usize) -> Self {
        let (p_q, rest) = buf.split_at_mut(n * n);
        let (p_v, rest) = rest.split_at_mut(n * n);
        let (t_q, rest) = rest.split_at_mut(n * n);
        let (t_v, rest) = rest.split_at_mut(n * n);
        Self {
            p_q,
            p_v,
            t_q,
            t_v,
            v_q: &mut rest[..n * n],
        }
    }
}

/// a − b for spatial vectors.
#[inline(always)]
fn sub6(a: &V6, b: &V6) -> V6 {
    core::array::from_fn(|c| a[c] - b[c])
}

/// max |x_i| over the bodies' `field`, NaN when any is NaN or ±∞.
#[inline(always)]
fn max_abs(ws: &[BodyScratch], field: impl Fn(&BodyScratch) -> f64) -> f64 {
    let (mut m, mut poison) = (0.0f64, 0.0f64);
    for b in ws {
        let x = field(b);
        m = m.max(x.abs());
        poison += x * 0.0;
    }
    m + poison
}

impl<T: Tree> Engine<T> {
    /// The engine of `tree` with default options; the tree is validated.
    pub fn new(tree: T) -> Result<Self, EngineError> {
        Self::with_options(tree, EngineOptions::default())
    }

    /// The engine with the given options.
    pub fn with_options(tree: T, options: EngineOptions) -> Result<Self, EngineError> {
        validate(&tree)?;
        check_options(&options)?;
        let fingerprint = fingerprint(&tree);
        let branched = super::model::branched(&tree);
        let chain = (0..tree.len()).all(|i| tree.body(i).parent == i.checked_sub(1));
        Ok(Self {
            tree,
            options,
            fingerprint,
            branched,
            chain,
        })
    }

    /// An engine over this one's tree, borrowed, with other options: no
    /// copy of the tree and no second validation (the tree was validated
    /// when `self` was made), so it is cheap enough to make per call.
    pub fn with_options_borrowed(&self, options: EngineOptions) -> Result<Engine<&T>, EngineError> {
        check_options(&options)?;
        Ok(Engine {
            tree: &self.tree,
            options,
            fingerprint: self.fingerprint,
            branched: self.branched,
            chain: self.chain,
        })
    }

    /// The tree.
    pub fn tree(&self) -> &T {
        &self.tree
    }

    /// The options.
    pub fn options(&self) -> &EngineOptions {
        &self.options
    }

    /// Number of coordinates.
    pub fn dof(&self) -> usize {
        self.tree.len()
    }

    fn scratch<'w, R>(
        &self,
        ws: &'w mut [BodyScratch<R>],
    ) -> Result<&'w mut [BodyScratch<R>], EngineError> {
        let n = self.tree.len();
        if ws.len() < n {
            return Err(EngineError::WrongLength {
                what: "workspace",
                expected: n,
                got: ws.len(),
            });
        }
        Ok(&mut ws[..n])
    }

    /// Pose, world axis and centre of mass of body `i` at the configuration
    /// `ws[i].at` (its parent's pose already placed): writes `rot`, `pos`
    /// and `s`, returns the centre of mass in world coordinates.
    #[inline(always)]
    fn place<R: Real>(&self, i: usize, ws: &mut [BodyScratch<R>]) -> V3<R> {
        let b = self.tree.body(i);
        // the joint frame (the root's parent is the world: no product)
        let (rj, pj) = match b.parent {
            Some(p) => {
                let (rp, pp) = (ws[p].rot, ws[p].pos);
                (
                    mul_mm(&rp, &lift33(&b.rotation)),
                    add(pp, mul_mv(&rp, lift3(b.translation))),
                )
            }
            None => (lift33(&b.rotation), lift3(b.translation)),
        };
        let w = &mut ws[i];
        let axis = mul_mv(&rj, lift3(b.axis));
        match b.joint {
            JointKind::Revolute => {
                w.rot = mul_mm(&rj, &axis_angle(b.axis, w.at));
                w.pos = pj;
                let m = cross(pj, axis);
                w.s = [axis[0], axis[1], axis[2], m[0], m[1], m[2]];
            }
            JointKind::Prismatic => {
                w.rot = rj;
                w.pos = add(pj, scale(axis, w.at));
                w.s = [zero(), zero(), zero(), axis[0], axis[1], axis[2]];
            }
        }
        add(w.pos, mul_mv(&w.rot, lift3(b.com)))
    }

    /// Poses, axes, inertias, composite inertias and ∇V at the
    /// configuration `ws[i].at`; also the articulated inertias' start
    /// values.
    fn kinematics<R: Real>(&self, ws: &mut [BodyScratch<R>]) {
        let t = &self.tree;
        let g = t.gravity();
        for i in 0..ws.len() {
            let c = self.place(i, ws);
            let b = t.body(i);
            let w = &mut ws[i];
            let ic = congruence(&w.rot, &lift33(&b.inertia));
            w.inertia = Inertia6::from_com(R::from_f64(b.mass), c, &ic);
            w.composite = w.inertia;
        }
        for i in (0..ws.len()).rev() {
            let b = t.body(i);
            let w = &mut ws[i];
            w.dv = -dot6(&w.s, &w.composite.gravity_wrench(g)) + (w.at - b.rest) * b.stiffness;
            if let Some(p) = b.parent {
                let c = ws[i].composite;
                ws[p].composite = ws[p].composite.add(&c);
            }
        }
    }

    /// The part of [`Engine::kinematics`] the energy reads: poses and the
    /// first moments m·c (`inertia.first`, as [`Inertia6::from_com`] forms
    /// them) at `ws[i].at`; the rotational inertias, composites and ∇V are
    /// left stale.
    fn poses(&self, ws: &mut [BodyScratch]) {
        for i in 0..ws.len() {
            let c = self.place(i, ws);
            ws[i].inertia.first = scale(c, self.tree.body(i).mass);
        }
    }

    /// m̄, the largest diagonal entry of M (after [`Engine::kinematics`]).
    fn mass_scale(&self, ws: &[BodyScratch]) -> f64 {
        ws.iter()
            .map(|w| dot6(&w.s, &w.composite.mul(&w.s)))
            .fold(0.0, f64::max)
    }

    /// Factorisation of the Newton matrix of the residual at the current
    /// iterate (after kinematics and [`Engine::iterate_forward`]), for the
    /// chord iteration v ← v + K⁻¹r(v) of the sub-step:
    /// K = −∂r/∂v = M + h·D − h·C, C = ∂(∂T/∂q)/∂v, in O(N).
    ///
    /// With u_b = I_b S_b (I_b the composite inertia of b's subtree, h_b its
    /// composite momentum, V_b b's twist and w_b = V_b × S_b), the entries
    /// of C are C_bj = S_jᵀ(S_b ×* h_b + I_b w_b) for j on b's path and
    /// C_jb = w_jᵀ u_b for j strictly above b ([`Engine::term_derivatives`]),
    /// so K_bj = S_jᵀ a_b (a_b = u_b − h·(S_b ×* h_b + I_b w_b)),
    /// K_jb = e_jᵀ u_b (e_j = S_j − h·w_j) and K_bb = e_bᵀ u_b + h·d_b.
    /// Eliminating leaves first, as the articulated-body algorithm does
    /// for M (to which this reduces at h·C = 0), each body's subtree sends
    /// its parent the operator IA − m ℓᵀ/δ with
    ///
    /// ```text
    /// IA_b = I_b(own) + Σ_children (IA_c − m_c ℓ_cᵀ/δ_c),   m_b = IA_b S_b,
    /// ℓ_b = IA_bᵀ e_b − h·(S_b ×* h_b),   δ_b = e_bᵀ m_b + h·d_b,
    /// ```
    ///
    /// and the solve is a backward pass ρ_b = r_b − e_bᵀ g_b,
    /// g_parent += g_b + m_b ρ_b/δ_b, then a forward pass
    /// x_b = (ρ_b − ℓ_bᵀ Y_parent)/δ_b, Y_b = Y_parent + S_b x_b. Checked
    /// against a dense solve with K from [`Engine::term_derivatives`]
    /// (unit tests). K is that of the iterate the sub-step starts from
    /// (the guess); near the root the chord iteration contracts by
    /// h·|C(v) − C(v_start)|, against h·|C| for M + h·D alone.
    ///
    /// Where a pivot δ is not positive (K is far from M, h·|v| large:
    /// the DEL may have no root near the start), the factors are those of
    /// M + h·D (e = ℓ = S, the articulated-body algorithm), whose
    /// iteration then decides, by its contraction, whether to subdivide.
    /// `Err(body)` when M + h·D itself is singular there.
    fn factor(&self, h: f64, mbar: f64, ws: &mut [BodyScratch]) -> Result<(), usize> {
        if self.factor_with(h, mbar, true, ws).is_ok() {
            return Ok(());
        }
        self.factor_with(h, mbar, false, ws)
    }

    /// [`Engine::factor`] of K (`newton`) or of M + h·D.
    fn factor_with(
        &self,
        h: f64,
        mbar: f64,
        newton: bool,
        ws: &mut [BodyScratch],
    ) -> Result<(), usize> {
        let t = &self.tree;
        let hn = if newton { h } else { 0.0 };
        for w in ws.iter_mut() {
            w.ia = w.inertia.matrix();
            // the composite momenta, in `acc` (the solve's forward pass
            // overwrites it)
            w.acc = w.hc;
        }
        for i in (0..ws.len()).rev() {
            let b = t.body(i);
            let w = &mut ws[i];
            let s = w.s;
            let wv = cross_motion(&w.vel, &s);
            let sh = cross_force(&s, &w.acc);
            let e: V6 = core::array::from_fn(|c| s[c] - hn * wv[c]);
            let m = mul6(&w.ia, &s);
            let l: V6 = core::array::from_fn(|c| {
                (0..6).map(|r| w.ia[r][c] * e[r]).sum::<f64>() - hn * sh[c]
            });
            let d = dot6(&e, &m) + h * b.damping;
            // NaN fails this test too
            if d.is_nan() || d <= 1e-13 * mbar {
                return Err(i);
            }
            (w.u6, w.l, w.e, w.d) = (m, l, e, d);
            if let Some(p) = b.parent {
                // the parent gains IA − m·ℓᵀ/δ
                let (ia, acc, dinv) = (w.ia, w.acc, 1.0 / d);
                let wp = &mut ws[p];
                for r in 0..6 {
                    let mr = m[r] * dinv;
                    for c in 0..6 {
                        wp.ia[r][c] += ia[r][c] - mr * l[c];
                    }
                }
                for c in 0..6 {
                    wp.acc[c] += acc[c];
                }
            }
        }
        Ok(())
    }

    /// The solve of [`Engine::factor`] at configuration q (as the
    /// evaluated `at`) and iterate v for the right-hand side `rhs`, into
    /// `x`: x = K⁻¹·rhs, K = M + h·D − h·∂(∂T/∂q)/∂v (unit tests compare it
    /// with a dense solve).
    #[cfg(test)]
    pub(super) fn newton_solve(
        &self,
        q: &[f64],
        v: &[f64],
        h: f64,
        rhs: &[f64],
        x: &mut [f64],
        ws: &mut [BodyScratch],
    ) -> Result<(), usize> {
        let t = &self.tree;
        let ws = &mut ws[..t.len()];
        for (i, w) in ws.iter_mut().enumerate() {
            (w.at, w.vn) = (q[i], v[i]);
        }
        self.kinematics(ws);
        let mbar = self.mass_scale(ws);
        self.iterate_forward(None, ws);
        self.factor_with(h, mbar, true, ws)?;
        for i in (0..ws.len()).rev() {
            let w = &mut ws[i];
            let u = rhs[i] - dot6(&w.e, &w.pa);
            w.x = u;
            if let Some(p) = t.body(i).parent {
                let (pa, u6, k) = (w.pa, w.u6, u / w.d);
                for c in 0..6 {
                    ws[p].pa[c] += pa[c] + u6[c] * k;
                }
            }
        }
        self.solve_forward(0, ws);
        for (x, w) in x.iter_mut().zip(ws.iter()) {
            *x = w.x;
        }
        Ok(())
    }

    /// Twists, composite momenta, p = M v and ∂T/∂q for v = `ws[i].vn`
    /// (after kinematics).
    fn momentum<R: Real>(&self, ws: &mut [BodyScratch<R>]) {
        let t = &self.tree;
        for i in 0..ws.len() {
            let vp = match t.body(i).parent {
                Some(p) => ws[p].vel,
                None => [zero(); 6],
            };
            let w = &mut ws[i];
            for c in 0..6 {
                w.vel[c] = vp[c] + w.s[c] * w.vn;
            }
            w.hc = w.inertia.mul(&w.vel);
        }
        for i in (0..ws.len()).rev() {
            let w = &mut ws[i];
            w.pn = dot6(&w.s, &w.hc);
            w.dtq = dot6(&cross_motion(&w.vel, &w.s), &w.hc);
            if let Some(p) = t.body(i).parent {
                let h = w.hc;
                let hp = &mut ws[p].hc;
                for c in 0..6 {
                    hp[c] = hp[c] + h[c];
                }
            }
        }
    }

    /// The forward pass of an iteration: moves the iterate by the last
    /// solve's step `x` (`update`: `None` leaves it, `Some(None)` the plain
    /// step, `Some(Some((m, γ)))` the Anderson-mixed step of
    /// [`Engine::solve_forward`]), then twists and body momenta at it, and
    /// clears the solve's articulated forces.
    #[inline(always)]
    fn iterate_forward(&self, update: Option<Mixing>, ws: &mut [BodyScratch]) {
        let t = &self.tree;
        for i in 0..ws.len() {
            let vp = match t.body(i).parent {
                Some(p) => ws[p].vel,
                None => [0.0; 6],
            };
            let w = &mut ws[i];
            if let Some(mix) = update {
                let mut step = w.x;
                if let Some((m, gm)) = mix {
                    for a in 0..m {
                        step -= (w.dvs[a] + w.dfs[a]) * gm[a];
                    }
                }
                w.vn += step;
            }
            for c in 0..6 {
                w.vel[c] = vp[c] + w.s[c] * w.vn;
            }
            w.hc = w.inertia.mul(&w.vel);
            w.pa = [0.0; 6];
        }
    }

    /// The backward pass of an iteration (after
    /// [`Engine::iterate_forward`]): composite momenta, p = M v and ∂T/∂q,
    /// the residual r (sub-step h) and the backward half of the
    /// solve of K·x = r ([`Engine::factor`]); returns max|r| (NaN when
    /// any is NaN or ±∞).
    #[inline(always)]
    fn iterate_backward(&self, h: f64, ws: &mut [BodyScratch]) -> f64 {
        let t = &self.tree;
        let (mut big, mut poison) = (0.0f64, 0.0f64);
        for i in (0..ws.len()).rev() {
            let b = t.body(i);
            let w = &mut ws[i];
            w.pn = dot6(&w.s, &w.hc);
            w.dtq = dot6(&cross_motion(&w.vel, &w.s), &w.hc);
            w.r = w.p - w.pn + h * (w.dtq - w.dv - b.damping * w.vn + w.tau);
            big = big.max(w.r.abs());
            poison += w.r * 0.0;
            let u = w.r - dot6(&w.e, &w.pa);
            w.x = u;
            if let Some(p) = b.parent {
                let (hc, pa, u6, k) = (w.hc, w.pa, w.u6, u / w.d);
                let wp = &mut ws[p];
                for c in 0..6 {
                    wp.hc[c] += hc[c];
                    wp.pa[c] += pa[c] + u6[c] * k;
                }
            }
        }
        big + poison
    }

    /// The forward half of the solve (x = K⁻¹ r into `ws[i].x`, after
    /// [`Engine::iterate_backward`]), with the bookkeeping of the Anderson
    /// acceleration after the `k`-th iteration (k = 0, 1, …; module docs of
    /// [`Mixing`]); returns the mixing of the next
    /// [`Engine::iterate_forward`].
    #[inline(always)]
    fn solve_forward(&self, k: usize, ws: &mut [BodyScratch]) -> Mixing {
        let t = &self.tree;
        // iteration 0: the plain step; then the differences of iterates
        // and steps and their normal equations
        let (slot, m) = match k {
            0 => (0, 0),
            _ => ((k - 1) % ANDERSON, k.min(ANDERSON)),
        };
        let mut g = [[0.0f64; ANDERSON + 1]; ANDERSON];
        for i in 0..ws.len() {
            let ap = match t.body(i).parent {
                Some(p) => ws[p].acc,
                None => [0.0; 6],
            };
            let w = &mut ws[i];
            w.x = (w.x - dot6(&w.l, &ap)) / w.d;
            for c in 0..6 {
                w.acc[c] = ap[c] + w.s[c] * w.x;
            }
            if k > 0 {
                w.dvs[slot] = w.vn - w.vprev;
                w.dfs[slot] = w.x - w.fprev;
                for a in 0..m {
                    for b in 0..m {
                        g[a][b] += w.dfs[a] * w.dfs[b];
                    }
                    g[a][ANDERSON] += w.dfs[a] * w.x;
                }
            }
            w.vprev = w.vn;
            w.fprev = w.x;
        }
        if k == 0 {
            return None;
        }
        solve_small(&mut g, m).map(|gm| (m, gm))
    }

    /// The residual at the iterate `vn`, sub-step h; returns max|r|.
    fn residual_in(&self, h: f64, ws: &mut [BodyScratch]) -> f64 {
        self.momentum(ws);
        let t = &self.tree;
        for (i, w) in ws.iter_mut().enumerate() {
            let b = t.body(i);
            w.r = w.p - w.pn + h * (w.dtq - w.dv - b.damping * w.vn + w.tau);
        }
        max_abs(ws, |w| w.r)
    }

    /// One sub-step of h from the committed (q, v, p) in `ws`; commits on
    /// success and returns (iterations, scaled residual).
    fn substep(
        &self,
        h: f64,
        guessed: bool,
        e0: &mut (f64, f64),
        ws: &mut [BodyScratch],
    ) -> Result<(usize, f64), SubFail> {
        for w in ws.iter_mut() {
            w.at = w.q + h * w.v;
            w.vn = if guessed { w.guess } else { w.v };
        }
        self.kinematics(ws);
        let mbar = self.mass_scale(ws);
        self.iterate_forward(None, ws);
        self.factor(h, mbar, ws).map_err(SubFail::Singular)?;
        let scale = max_abs(ws, |w| w.p) + mbar;
        let tol = self.options.tolerance;
        let mut best = f64::INFINITY;
        let mut first = f64::NAN;
        let mut iterations = 0;
        loop {
            let res = self.iterate_backward(h, ws) / scale;
            if res.is_nan() {
                return Err(SubFail::NotConverged {
                    iterations,
                    residual: f64::NAN,
                });
            }
            if res <= tol {
                if self.options.energy_tolerance.is_finite() {
                    let (e_start, t_start) = *e0;
                    let (e1, t1, work, grav) = self.energy_terms(h, ws);
                    let jump =
                        (e1 - e_start - work).abs() / (t_start + t1 + grav + f64::MIN_POSITIVE);
                    if jump.is_nan() || jump > self.options.energy_tolerance {
                        return Err(SubFail::EnergyJump { iterations, jump });
                    }
                    *e0 = (e1, t1);
                }
                for w in ws.iter_mut() {
                    w.q = w.at;
                    w.v = w.vn;
                    w.p = w.pn;
                }
                return Ok((iterations, res));
            }
            if iterations == 0 {
                first = res;
            }
            let slow =
                iterations == 1 && first > 1e3 * tol && res > self.options.max_contraction * first;
            if slow || iterations >= self.options.max_iterations || res > 4.0 * best {
                return Err(SubFail::NotConverged {
                    iterations,
                    residual: res,
                });
            }
            best = best.min(res);
            let mixing = self.solve_forward(iterations, ws);
            self.iterate_forward(Some(mixing), ws);
            iterations += 1;
        }
    }

    fn load<R: Real>(
        &self,
        q: &[R],
        v: &[R],
        ws: &mut [BodyScratch<R>],
    ) -> Result<(), EngineError> {
        if let Some(w) = ws.first_mut() {
            w.tag = 0;
        }
        let n = self.tree.len();
        check_len("q", q.len(), n)?;
        check_len("v", v.len(), n)?;
        if !q.iter().chain(v).all(|x| x.value().is_finite()) {
            return Err(EngineError::NonFiniteState);
        }
        for (w, (&a, &b)) in ws.iter_mut().zip(q.iter().zip(v)) {
            w.q = a.value();
            w.v = b.value();
            w.at = a;
            w.vn = b;
        }
        Ok(())
    }

    /// p = M(q)v (into `p`).
    pub fn momentum_of(
        &self,
        q: &[f64],
        v: &[f64],
        p: &mut [f64],
        ws: &mut [BodyScratch],
    ) -> Result<(), EngineError> {
        let ws = self.scratch(ws)?;
        check_len("p", p.len(), ws.len())?;
        self.momentum_pass(q, v, ws)?;
        self.commit_start(p, ws);
        Ok(())
    }

    /// After a momentum pass at (q, v): p = M(q)v out, and the workspace
    /// marked as holding the poses of the committed state (q, v, p), as a
    /// step leaves it, so that a step from there reuses them.
    fn commit_start(&self, p: &mut [f64], ws: &mut [BodyScratch]) {
        for (x, w) in p.iter_mut().zip(ws.iter_mut()) {
            *x = w.pn;
            w.p = w.pn;
        }
        if let Some(w) = ws.first_mut() {
            w.tag = self.fingerprint;
        }
    }

    /// Loads (q, v), then the kinematics and momentum passes: what
    /// [`Engine::momentum_of`] and [`Engine::terms`] read their outputs from.
    fn momentum_pass<R: Real>(
        &self,
        q: &[R],
        v: &[R],
        ws: &mut [BodyScratch<R>],
    ) -> Result<(), EngineError> {
        self.load(q, v, ws)?;
        self.kinematics(ws);
        self.momentum(ws);
        Ok(())
    }

    /// At (q, v): the momentum M(q)v, ∂T/∂q and ∇V(q) (gravity and
    /// springs), each O(N). Generic over the scalar: with jets
    /// ([`crate::Jet1`]) in q and v, the outputs carry their exact
    /// derivatives (the step derivatives of `vigp::Robot` are built on
    /// this).
    pub fn terms<R: Real>(
        &self,
        q: &[R],
        v: &[R],
        p: &mut [R],
        dtdq: &mut [R],
        dvdq: &mut [R],
        ws: &mut [BodyScratch<R>],
    ) -> Result<(), EngineError> {
        let ws = self.scratch(ws)?;
        let n = ws.len();
        check_len("p", p.len(), n)?;
        check_len("dtdq", dtdq.len(), n)?;
        check_len("dvdq", dvdq.len(), n)?;
        self.momentum_pass(q, v, ws)?;
        for (i, w) in ws.iter().enumerate() {
            p[i] = w.pn;
            dtdq[i] = w.dtq;
            dvdq[i] = w.dv;
        }
        Ok(())
    }

    /// The first derivatives of the terms of [`Engine::terms`] at (q, v),
    /// row-major N × N into `out` (row i: the term of coordinate i; column
    /// j: the derivative by q_j or v_j), in closed form over pairs of
    /// bodies on one path from the root: O(N) passes, then O(1) per pair,
    /// O(N²) in all (O(N·depth) for a branching tree).
    ///
    /// With S the world axes, V the twists, Iᶜ the composite inertias, hᶜ
    /// the composite momenta, Gᶜ = Iᶜ·(0, g) the subtrees' gravity wrenches,
    /// a_j = S_j ×ₘ V_j, w_i = V_i ×ₘ S_i, and ×* the force cross product
    /// (∂S_i/∂q_j = S_j ×ₘ S_i and ∂I_k/∂q_j = S_j ×* I_k − I_k S_j ×ₘ for j
    /// on the path to i or k), for j on the path from the root to i:
    ///
    /// ```text
    /// ∂p_i/∂q_j = −S_i·Iᶜ_i a_j        ∂p_i/∂v_j = S_i·Iᶜ_i S_j
    /// ∂(∂T/∂q)_i/∂q_j = −(a_j ×ₘ S_i)·hᶜ_i − w_i·Iᶜ_i a_j
    /// ∂(∂T/∂q)_i/∂v_j = (S_j ×ₘ S_i)·hᶜ_i + w_i·Iᶜ_i S_j
    /// ∂(∇V)_i/∂q_j = S_i·Iᶜ_i (S_j ×ₘ (0, g)) (+ k_i when j = i)
    /// ```
    ///
    /// and for i strictly above j, with F_j = S_j ×* hᶜ_j − Iᶜ_j a_j and
    /// E_j = S_j ×* Gᶜ_j − Iᶜ_j (S_j ×ₘ (0, g)):
    ///
    /// ```text
    /// ∂p_i/∂q_j = S_i·F_j     ∂(∂T/∂q)_i/∂q_j = w_i·F_j     ∂(∇V)_i/∂q_j = −S_i·E_j
    /// ∂p_i/∂v_j = S_i·Iᶜ_j S_j     ∂(∂T/∂q)_i/∂v_j = w_i·Iᶜ_j S_j
    /// ```
    ///
    /// Every other entry is zero. Checked against the same terms on jets
    /// (unit tests of this module).
    pub fn term_derivatives(
        &self,
        q: &[f64],
        v: &[f64],
        out: TermDerivatives<'_>,
        ws: &mut [BodyScratch],
    ) -> Result<(), EngineError> {
        let ws = self.scratch(ws)?;
        let n = ws.len();
        let mut out = out;
        check_len("p_q", out.p_q.len(), n * n)?;
        check_len("p_v", out.p_v.len(), n * n)?;
        check_len("t_q", out.t_q.len(), n * n)?;
        check_len("t_v", out.t_v.len(), n * n)?;
        check_len("v_q", out.v_q.len(), n * n)?;
        self.momentum_pass(q, v, ws)?;
        self.loaded_term_derivatives(&mut out, ws);
        Ok(())
    }

    /// [`Engine::term_derivatives`] at the (q, v) whose kinematics and
    /// momenta `ws` already holds (its momentum pass, or the last
    /// iterate of a converged sub-step, which equals it bit for bit),
    /// into `out` (blocks of N × N, lengths checked by the caller).
    pub(super) fn loaded_term_derivatives(
        &self,
        out: &mut TermDerivatives<'_>,
        ws: &mut [BodyScratch],
    ) {
        let rest = (&mut *out.t_q, &mut *out.t_v, &mut *out.v_q);
        self.pair_derivatives(ws, out.p_q, out.p_v, Some(rest));
    }

    /// p = M(q)v, ∂p/∂q and ∂p/∂v = M at (q, v): the part of
    /// [`Engine::term_derivatives`] a step's start needs (row-major N × N
    /// into `p_q` and `p_v`), by the same closed forms.
    pub fn momentum_derivatives(
        &self,
        q: &[f64],
        v: &[f64],
        p: &mut [f64],
        p_q: &mut [f64],
        p_v: &mut [f64],
        ws: &mut [BodyScratch],
    ) -> Result<(), EngineError> {
        let ws = self.scratch(ws)?;
        let n = ws.len();
        check_len("p", p.len(), n)?;
        check_len("p_q", p_q.len(), n * n)?;
        check_len("p_v", p_v.len(), n * n)?;
        self.momentum_pass(q, v, ws)?;
        self.pair_derivatives(ws, p_q, p_v, None);
        self.commit_start(p, ws);
        Ok(())
    }

    /// The closed forms of [`Engine::term_derivatives`] after its momentum
    /// pass: ∂p/∂q and ∂p/∂v, and with `rest` ∂(∂T/∂q)/∂q, ∂(∂T/∂q)/∂v and
    /// ∂(∇V)/∂q.
    #[allow(clippy::type_complexity)]
    fn pair_derivatives(
        &self,
        ws: &mut [BodyScratch],
        p_q: &mut [f64],
        p_v: &mut [f64],
        mut rest: Option<(&mut [f64], &mut [f64], &mut [f64])>,
    ) {
        let n = ws.len();
        // on a chain every entry is written below
        if !self.chain {
            p_q.fill(0.0);
            p_v.fill(0.0);
            if let Some((t_q, t_v, v_q)) = rest.as_mut() {
                t_q.fill(0.0);
                t_v.fill(0.0);
                v_q.fill(0.0);
            }
        }
        let g = self.tree.gravity();
        let ag = [0.0, 0.0, 0.0, g[0], g[1], g[2]];
        for w in ws.iter_mut() {
            w.sv = cross_motion(&w.s, &w.vel);
        }
        let ws = &*ws;
        // Every pair (b, j) is a few dot products of per-body vectors:
        // the composite inertia I_b is symmetric, s·(I_b x) = (I_b s)·x,
        // and the motion and force cross products are dual,
        // (x × y)·f = −y·(x ×* f). With a = S × V (w = V × S = −a),
        // u_b = I_b S_b and f_b = S_b ×* h_b − I_b a_b:
        //   (a_j × S_b)·h_b + w_b·(I_b a_j) = a_j·f_b,
        //   (S_j × S_b)·h_b + w_b·(I_b S_j) = S_j·f_b,
        //   S_b·(I_b (S_j × a_g)) = S_j·(a_g ×* u_b).
        for b in 0..n {
            let wb = &ws[b];
            let (sb, hb, ib, a_b) = (wb.s, wb.hc, wb.composite, wb.sv);
            let u_b = ib.mul(&sb);
            let f_b = sub6(&cross_force(&sb, &hb), &ib.mul(&a_b));
            // the gravity terms, for the rest
            let gravity = rest.as_ref().map(|_| {
                let sg_b = cross_motion(&sb, &ag);
                let e_b = sub6(&cross_force(&sb, &ib.mul(&ag)), &ib.mul(&sg_b));
                (cross_force(&ag, &u_b), e_b)
            });
            // j runs over b and its ancestors: (row b, column j) with j on
            // b's path; (row j, column b) with j strictly above b
            let mut at = Some(b);
            while let Some(j) = at {
                let wj = &ws[j];
                let (sj, a_j) = (wj.s, wj.sv);
                let (ua, us, sf) = (dot6(&u_b, &a_j), dot6(&u_b, &sj), dot6(&sj, &f_b));
                let bj = b * n + j;
                p_q[bj] = -ua;
                p_v[bj] = us;
                if j != b {
                    let jb = j * n + b;
                    p_q[jb] = sf;
                    p_v[jb] = us;
                }
                if let (Some((t_q, t_v, v_q)), Some((g_b, e_b))) = (rest.as_mut(), gravity.as_ref())
                {
                    let af = dot6(&a_j, &f_b);
                    t_q[bj] = -af;
                    v_q[bj] = dot6(&sj, g_b);
                    t_v[bj] = sf;
                    if j != b {
                        let jb = j * n + b;
                        t_q[jb] = -af;
                        v_q[jb] = -dot6(&sj, e_b);
                        t_v[jb] = -ua;
                    }
                }
                at = self.tree.body(j).parent;
            }
            if let Some((_, _, v_q)) = rest.as_mut() {
                v_q[b * n + b] += self.tree.body(b).stiffness;
            }
        }
    }

    /// The bias forces of the equations of motion M(q)q̈ + b(q, q̇) = τ at
    /// (q, v): b = Ṁv − ∂T/∂q + ∇V, by the recursive Newton–Euler pass with
    /// zero acceleration (Ṁv − ∂T/∂q = Σ_j∈subtree S_i·(I_j c_j + V_j ×* I_j V_j),
    /// c_j the velocity-product acceleration). The "nonlinear effects" of
    /// other libraries (plus the spring forces, which they do not model).
    pub fn bias_forces(
        &self,
        q: &[f64],
        v: &[f64],
        out: &mut [f64],
        ws: &mut [BodyScratch],
    ) -> Result<(), EngineError> {
        let ws = self.scratch(ws)?;
        check_len("out", out.len(), ws.len())?;
        self.load(q, v, ws)?;
        self.kinematics(ws);
        let t = &self.tree;
        for i in 0..ws.len() {
            let (vp, ap) = match t.body(i).parent {
                Some(p) => (ws[p].vel, ws[p].acc),
                None => ([0.0; 6], [0.0; 6]),
            };
            let w = &mut ws[i];
            for c in 0..6 {
                w.vel[c] = vp[c] + w.s[c] * w.vn;
            }
            let sd = cross_motion(&w.vel, &w.s);
            for c in 0..6 {
                w.acc[c] = ap[c] + sd[c] * w.vn;
            }
            let h = w.inertia.mul(&w.vel);
            let f = w.inertia.mul(&w.acc);
            let x = cross_force(&w.vel, &h);
            for c in 0..6 {
                w.hc[c] = f[c] + x[c];
            }
        }
        for i in (0..ws.len()).rev() {
            out[i] = dot6(&ws[i].s, &ws[i].hc) + ws[i].dv;
            if let Some(p) = t.body(i).parent {
                let h = ws[i].hc;
                for c in 0..6 {
                    ws[p].hc[c] += h[c];
                }
            }
        }
        Ok(())
    }

    /// The mass matrix M(q), row-major into `out` (N² entries): N momentum
    /// passes, O(N²). For tests and inspection; the step never forms M.
    pub fn mass_matrix(
        &self,
        q: &[f64],
        out: &mut [f64],
        ws: &mut [BodyScratch],
    ) -> Result<(), EngineError> {
        let ws = self.scratch(ws)?;
        let n = ws.len();
        check_len("out", out.len(), n * n)?;
        self.load(q, q, ws)?;
        self.kinematics(ws);
        for j in 0..n {
            for (k, w) in ws.iter_mut().enumerate() {
                w.vn = if k == j { 1.0 } else { 0.0 };
            }
            self.momentum(ws);
            for (i, w) in ws.iter().enumerate() {
                out[i * n + j] = w.pn;
            }
        }
        Ok(())
    }

    /// The DEL residual r(v₁) of a step of `dt` from (q₀, v₀) with momentum
    /// p₀ and generalized forces τ (module docs of [`Engine`]), into `out`.
    #[allow(clippy::too_many_arguments)]
    pub fn residual(
        &self,
        q0: &[f64],
        v0: &[f64],
        p0: &[f64],
        tau: &[f64],
        v1: &[f64],
        dt: f64,
        out: &mut [f64],
        ws: &mut [BodyScratch],
    ) -> Result<(), EngineError> {
        let ws = self.scratch(ws)?;
        let n = ws.len();
        check_len("p0", p0.len(), n)?;
        check_len("tau", tau.len(), n)?;
        check_len("v1", v1.len(), n)?;
        check_len("out", out.len(), n)?;
        self.load(q0, v0, ws)?;
        for (i, w) in ws.iter_mut().enumerate() {
            w.at = w.q + dt * w.v;
            w.p = p0[i];
            w.tau = tau[i];
            w.vn = v1[i];
        }
        self.kinematics(ws);
        self.residual_in(dt, ws);
        for (x, w) in out.iter_mut().zip(ws.iter()) {
            *x = w.r;
        }
        Ok(())
    }

    /// Energy T + V at (q, v): kinetic, gravity and spring.
    pub fn energy(&self, q: &[f64], v: &[f64], ws: &mut [BodyScratch]) -> Result<f64, EngineError> {
        let ws = self.scratch(ws)?;
        self.load(q, v, ws)?;
        self.kinematics(ws);
        self.momentum(ws);
        Ok(self.energy_loaded(ws))
    }

    /// (E, T, W, Σ m|g||c|) at the iterate (after kinematics and
    /// momentum), W = h·Σ(τ − d·v₁)·(v₀ + v₁)/2 the work of the inputs and
    /// the damping over the sub-step: the DEL changes the momentum by
    /// h·(τ − d·v₁) between the intervals of v₀ and v₁, which for a
    /// constant M changes T by exactly W (with v₁ alone in place of the
    /// mean the balance is off by h²·F·M⁻¹F/2, which strong inputs on light
    /// links turn into refused steps).
    fn energy_terms(&self, h: f64, ws: &[BodyScratch]) -> (f64, f64, f64, f64) {
        let g = self.tree.gravity();
        let gn = libm::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
        let (mut t, mut work, mut grav) = (0.0, 0.0, 0.0);
        for (i, w) in ws.iter().enumerate() {
            let b = self.tree.body(i);
            t += 0.5 * w.vn * w.pn;
            work += h * (w.tau - b.damping * w.vn) * 0.5 * (w.v + w.vn);
            let f = w.inertia.first;
            grav += gn * libm::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]);
        }
        (self.energy_loaded(ws), t, work, grav)
    }

    /// T = ½ Σ vn·pn of a workspace after momentum (as
    /// [`Engine::energy_terms`] sums it).
    fn kinetic(&self, ws: &[BodyScratch]) -> f64 {
        let mut t = 0.0;
        for w in ws {
            t += 0.5 * w.vn * w.pn;
        }
        t
    }

    /// T + V from a workspace after kinematics and momentum.
    fn energy_loaded(&self, ws: &[BodyScratch]) -> f64 {
        let g = self.tree.gravity();
        let mut e = 0.0;
        for (i, w) in ws.iter().enumerate() {
            let b = self.tree.body(i);
            let dq = w.at - b.rest;
            e += 0.5 * w.vn * w.pn
                - (g[0] * w.inertia.first[0]
                    + g[1] * w.inertia.first[1]
                    + g[2] * w.inertia.first[2])
                + 0.5 * b.stiffness * dq * dq;
        }
        e
    }

    /// One step of `dt` in place: (q, v) → (q₁, v₁), with the momentum `p`
    /// carried (p must be M(q)v for the state, from
    /// [`Engine::momentum_of`] or the previous step) and generalized forces
    /// `tau` held over the step. Subdivides itself when the iteration fails
    /// (type docs). No allocation: `ws` holds at least N bodies.
    pub fn step(
        &self,
        q: &mut [f64],
        v: &mut [f64],
        p: &mut [f64],
        tau: &[f64],
        dt: f64,
        ws: &mut [BodyScratch],
    ) -> Result<EngineReport, EngineError> {
        self.step_guessed(q, v, p, tau, dt, None, ws)
    }

    /// [`Engine::step`] with the iteration of the full step started at
    /// `guess` instead of v (a rollout passes an extrapolation of the last
    /// velocities; the converged step is the same to the tolerance).
    /// A non-finite guess is ignored.
    #[allow(clippy::too_many_arguments)]
    pub fn step_guessed(
        &self,
        q: &mut [f64],
        v: &mut [f64],
        p: &mut [f64],
        tau: &[f64],
        dt: f64,
        guess: Option<&[f64]>,
        ws: &mut [BodyScratch],
    ) -> Result<EngineReport, EngineError> {
        check_time_step(dt)?;
        let ws = self.scratch(ws)?;
        let n = ws.len();
        check_len("p", p.len(), n)?;
        check_len("tau", tau.len(), n)?;
        // the workspace already holds the poses at q when its last step
        // (of this tree) committed exactly this state
        let warm = ws.first().is_some_and(|w| w.tag == self.fingerprint)
            && ws
                .iter()
                .zip(q.iter().zip(v.iter()).zip(p.iter()))
                .all(|(w, ((a, b), c))| {
                    w.q.to_bits() == a.to_bits()
                        && w.v.to_bits() == b.to_bits()
                        && w.p.to_bits() == c.to_bits()
                });
        self.load(q, v, ws)?;
        if !p.iter().all(|x| x.is_finite()) {
            return Err(EngineError::NonFiniteState);
        }
        if !tau.iter().all(|x| x.is_finite()) {
            return Err(EngineError::NonFiniteInput);
        }
        let mut guessed = false;
        if let Some(g) = guess {
            check_len("guess", g.len(), n)?;
            guessed = g.iter().all(|x| x.is_finite());
            for (w, &x) in ws.iter_mut().zip(g) {
                w.guess = x;
            }
        }
        for (i, w) in ws.iter_mut().enumerate() {
            w.p = p[i];
            w.tau = tau[i];
        }
        let mut e0 = (0.0, 0.0);
        if self.options.energy_tolerance.is_finite() {
            // the energy at the start (the committed q, v and p)
            for w in ws.iter_mut() {
                w.at = w.q;
                w.vn = w.v;
                w.pn = w.p;
            }
            if !warm {
                self.poses(ws);
            }
            let (e, t) = (self.energy_loaded(ws), self.kinetic(ws));
            e0 = (e, t);
        }
        let mut report = EngineReport::default();
        let (mut depth, mut done, mut total) = (0u32, 0usize, 1usize);
        while done < total {
            let h = dt / total as f64;
            match self.substep(h, guessed && total == 1, &mut e0, ws) {
                Ok((it, res)) => {
                    report.iterations += it;
                    report.substeps += 1;
                    report.residual = report.residual.max(res);
                    done += 1;
                }
                Err(SubFail::Singular(body)) => return Err(EngineError::SingularMass { body }),
                Err(SubFail::EnergyJump { iterations, jump }) => {
                    report.iterations += iterations;
                    if depth >= self.options.max_depth || !(h * 0.5 * h * 0.5).is_normal() {
                        return Err(EngineError::EnergyJump {
                            depth,
                            substep_dt: h,
                            jump,
                        });
                    }
                    depth += 1;
                    done *= 2;
                    total *= 2;
                }
                Err(SubFail::NotConverged {
                    iterations,
                    residual,
                }) => {
                    report.iterations += iterations;
                    if depth >= self.options.max_depth || !(h * 0.5 * h * 0.5).is_normal() {
                        return Err(EngineError::NotConverged {
                            depth,
                            substep_dt: h,
                            iterations,
                            residual,
                        });
                    }
                    depth += 1;
                    done *= 2;
                    total *= 2;
                }
            }
        }
        report.depth = depth;
        for (i, w) in ws.iter().enumerate() {
            q[i] = w.q;
            v[i] = w.v;
            p[i] = w.p;
        }
        if let Some(w) = ws.first_mut() {
            w.tag = self.fingerprint;
        }
        Ok(report)
    }
}
