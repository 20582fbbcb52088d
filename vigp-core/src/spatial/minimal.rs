//! Minimal coordinates of a spatial mechanism: one angle per revolute tree
//! joint, one slide per prismatic tree joint, a quaternion (w, x, y, z) per
//! spherical tree joint, position and quaternion per free joint, nothing
//! for a fixed joint; loop-closing joints and the quaternions' unit norms
//! become constraints g(q) = 0. Everything is generic over [`Real`], so the
//! std runtime evaluates it on dual numbers (its `Mechanism` views) and
//! this crate on jets.
//!
//! Coordinates follow the tree joints in declaration order; constraint rows
//! are the loop joints' rows in declaration order, then one row |u|² − 1
//! per quaternion (in coordinate order).

use super::geometry::{Motion3, Pose3, dot, dot_f, mul_mtv, mul_mv_f};
use super::model::{
    Joint3, JointType, Layout, Link3, Spatial, joint_coordinate, joint_rates, joint_residual,
    place_child,
};
use crate::real::Real;
use nalgebra::SVector;

/// The pose of the parent of joint `j` (the world frame for a world parent).
fn parent_of<R: Real, const B: usize>(j: &Joint3, poses: &[Pose3<R>; B]) -> Pose3<R> {
    match j.parent {
        Some(p) => poses[p],
        None => Pose3::identity(),
    }
}

/// The pose and motion of the parent of joint `j` (the world frame at
/// rest for a world parent).
#[inline]
fn parent_motion_of<R: Real, const B: usize>(
    j: &Joint3,
    poses: &[Pose3<R>; B],
    motions: &[Motion3<R>; B],
) -> (Pose3<R>, Motion3<R>) {
    match j.parent {
        Some(p) => (poses[p], motions[p]),
        None => (Pose3::identity(), Motion3::zero()),
    }
}

/// The rates of joint `j` ([`joint_rates`]) at the link poses and motions,
/// into `rates`; returns how many it has.
#[inline]
fn rates_of<R: Real, const B: usize>(
    j: &Joint3,
    poses: &[Pose3<R>; B],
    motions: &[Motion3<R>; B],
    rates: &mut [R; 3],
) -> usize {
    let (pp, pm) = parent_motion_of(j, poses, motions);
    joint_rates(j, (&pp, &pm), (&poses[j.child], &motions[j.child]), rates)
}

/// Whether an input drives a loop joint (one without a minimal coordinate).
#[inline]
fn inputs_drive_loops<const J: usize>(layout: &Layout<J>, inputs: &[usize]) -> bool {
    inputs.iter().any(|&k| layout.coordinate[k] == usize::MAX)
}

/// Link frame poses for minimal coordinates `q`, in link declaration order.
pub fn poses<S, R, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<R, N>,
) -> [Pose3<R>; B]
where
    S: Spatial<B, J>,
    R: Real,
{
    let joints = sys.joints();
    let layout = Layout::of::<S, B>(&joints);
    let mut out = [Pose3::identity(); B];
    for &t in &S::TREE {
        let j = &joints[t];
        let parent = parent_of(j, &out);
        let o = layout.coordinate[t];
        let c = &q.as_slice()[o..o + j.kind.coordinates()];
        out[j.child] = place_child(j, &parent, None, c, None).0;
    }
    out
}

/// Link frame poses and motions for minimal positions `q` and velocities
/// `v` (any velocity: continuous or discrete).
pub fn poses_and_motions<S, R, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<R, N>,
    v: &SVector<R, N>,
) -> ([Pose3<R>; B], [Motion3<R>; B])
where
    S: Spatial<B, J>,
    R: Real,
{
    let joints = sys.joints();
    let layout = Layout::of::<S, B>(&joints);
    let mut poses = [Pose3::identity(); B];
    let mut motions = [Motion3::zero(); B];
    for &t in &S::TREE {
        let j = &joints[t];
        let (parent, pm) = parent_motion_of(j, &poses, &motions);
        let o = layout.coordinate[t];
        let n = j.kind.coordinates();
        let c = &q.as_slice()[o..o + n];
        let r = &v.as_slice()[o..o + n];
        let (pose, motion) = place_child(j, &parent, Some(&pm), c, Some(r));
        poses[j.child] = pose;
        motions[j.child] = motion.unwrap_or(pm);
    }
    (poses, motions)
}

/// Kinetic energy ½m|v_com|² + ½ω_bᵀJω_b of one link (ω_b = Rᵀω).
pub fn link_kinetic_energy<R: Real>(link: &Link3, pose: &Pose3<R>, motion: &Motion3<R>) -> R {
    let v = motion.point_velocity(pose, link.com);
    let wb = mul_mtv(&pose.rot, motion.omega);
    let jw = [
        dot_f(wb, link.inertia[0]),
        dot_f(wb, link.inertia[1]),
        dot_f(wb, link.inertia[2]),
    ];
    (dot(v, v) * link.mass + dot(wb, jw)) * 0.5
}

/// Potential energy −m·g·p_com of one link.
pub fn link_potential_energy<R: Real>(link: &Link3, gravity: [f64; 3], pose: &Pose3<R>) -> R {
    dot_f(pose.point(link.com), gravity) * (-link.mass)
}

/// Kinetic energy T(q, v).
pub fn kinetic_energy<S, R, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<R, N>,
    v: &SVector<R, N>,
) -> R
where
    S: Spatial<B, J>,
    R: Real,
{
    let (poses, motions) = poses_and_motions::<S, R, B, J, N>(sys, q, v);
    let links = sys.links();
    let mut t = R::from_f64(0.0);
    for i in 0..B {
        t = t + link_kinetic_energy(&links[i], &poses[i], &motions[i]);
    }
    t
}

/// Potential energy V(q): gravity, plus the joint springs
/// ([`spring_energy`]) when [`Spatial::ELASTIC`].
pub fn potential_energy<S, R, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<R, N>,
) -> R
where
    S: Spatial<B, J>,
    R: Real,
{
    let poses = poses::<S, R, B, J, N>(sys, q);
    let (links, g) = (sys.links(), sys.gravity());
    let mut v = R::from_f64(0.0);
    for i in 0..B {
        v = v + link_potential_energy(&links[i], g, &poses[i]);
    }
    if S::ELASTIC {
        v = v + spring_energy::<S, R, B, J, N>(sys, q, &poses);
    }
    v
}

/// The coordinate s_j(q) of joint `k` (revolute or prismatic): the minimal
/// coordinate itself for a tree joint, [`joint_coordinate`] of the link
/// poses (on the branch within π of `near`) for a loop joint.
fn coordinate_of<R: Real, const B: usize, const J: usize, const N: usize>(
    joints: &[Joint3; J],
    layout: &Layout<J>,
    k: usize,
    q: &SVector<R, N>,
    poses: &[Pose3<R>; B],
    near: f64,
) -> R {
    let j = &joints[k];
    let o = layout.coordinate[k];
    if o != usize::MAX {
        return match j.kind {
            JointType::Revolute | JointType::Prismatic => q[o],
            _ => R::from_f64(0.0),
        };
    }
    joint_coordinate(j, &parent_of(j, poses), &poses[j.child], near)
}

/// Spring energy Σ_j ½k_j(s_j − rest_j)² over the joints with springs
/// ([`Spatial::springs`]) at the link `poses` of `q`.
pub fn spring_energy<S, R, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<R, N>,
    poses: &[Pose3<R>; B],
) -> R
where
    S: Spatial<B, J>,
    R: Real,
{
    let joints = sys.joints();
    let layout = Layout::of::<S, B>(&joints);
    let mut v = R::from_f64(0.0);
    for (k, sp) in sys.springs().iter().enumerate() {
        if sp.stiffness == 0.0 {
            continue;
        }
        let s = coordinate_of::<R, B, J, N>(&joints, &layout, k, q, poses, sp.rest);
        let stretch = s - sp.rest;
        v = v + stretch * stretch * (0.5 * sp.stiffness);
    }
    v
}

/// Virtual work of the inputs W(q; u) = Σ_i u_i s_i(q) over the actuated
/// joints ([`Spatial::INPUT_JOINTS`]; missing entries of `u` count as 0):
/// the generalized input force is ∇W = B(q)u.
pub fn input_work<S, R, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<R, N>,
    u: &[f64],
) -> R
where
    S: Spatial<B, J>,
    R: Real,
{
    let joints = sys.joints();
    let layout = Layout::of::<S, B>(&joints);
    let loops = inputs_drive_loops(&layout, S::INPUT_JOINTS);
    let poses = if loops {
        poses::<S, R, B, J, N>(sys, q)
    } else {
        [Pose3::identity(); B]
    };
    let mut w = R::from_f64(0.0);
    for (i, &k) in S::INPUT_JOINTS.iter().enumerate() {
        let ui = u.get(i).copied().unwrap_or(0.0);
        if ui != 0.0 {
            w = w + coordinate_of::<R, B, J, N>(&joints, &layout, k, q, &poses, 0.0) * ui;
        }
    }
    w
}

/// The input matrix B(q) (N × U): column i is ∇s_i(q) of actuated joint
/// i (a unit vector for a tree joint; one first-order jet pass when an
/// input drives a loop joint).
pub fn input_matrix<S, const B: usize, const J: usize, const N: usize, const U: usize>(
    sys: &S,
    q: &SVector<f64, N>,
) -> nalgebra::SMatrix<f64, N, U>
where
    S: Spatial<B, J>,
{
    use crate::real::Jet1;
    let joints = sys.joints();
    let layout = Layout::of::<S, B>(&joints);
    let mut out = nalgebra::SMatrix::<f64, N, U>::zeros();
    let qj = seed1(q);
    let mut cached = None;
    for (i, &k) in S::INPUT_JOINTS.iter().enumerate().take(U) {
        let o = layout.coordinate[k];
        if o != usize::MAX {
            out[(o, i)] = 1.0;
            continue;
        }
        let p = *cached.get_or_insert_with(|| poses::<S, Jet1<N>, B, J, N>(sys, &qj));
        let s = coordinate_of::<Jet1<N>, B, J, N>(&joints, &layout, k, &qj, &p, 0.0);
        for l in 0..N {
            out[(l, i)] = s.g[l];
        }
    }
    out
}

/// ∂/∂q [B(q)u] = Σ_i u_i ∇²s_i(q): zero unless an input drives a loop
/// joint (one second-order jet pass then).
pub fn input_force_jacobian<S, const B: usize, const J: usize, const N: usize, const U: usize>(
    sys: &S,
    q: &SVector<f64, N>,
    u: &SVector<f64, U>,
) -> nalgebra::SMatrix<f64, N, N>
where
    S: Spatial<B, J>,
{
    let joints = sys.joints();
    let layout = Layout::of::<S, B>(&joints);
    let loops = inputs_drive_loops(&layout, S::INPUT_JOINTS);
    if !loops {
        return nalgebra::SMatrix::zeros();
    }
    hessian(&InputWork::<S, B, J, U> { sys, u }, q)
}

/// Lagrangian T − V (springs included) in one pass of the kinematics.
pub fn lagrangian<S, R, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<R, N>,
    v: &SVector<R, N>,
) -> R
where
    S: Spatial<B, J>,
    R: Real,
{
    let (poses, motions) = poses_and_motions::<S, R, B, J, N>(sys, q, v);
    let (links, g) = (sys.links(), sys.gravity());
    let mut l = R::from_f64(0.0);
    for i in 0..B {
        l = l + link_kinetic_energy(&links[i], &poses[i], &motions[i])
            - link_potential_energy(&links[i], g, &poses[i]);
    }
    if S::ELASTIC {
        l = l - spring_energy::<S, R, B, J, N>(sys, q, &poses);
    }
    l
}

/// Rayleigh dissipation ½·Σ_j c_j·|rate_j|² over every damped joint (tree
/// and loop), rates by [`joint_rates`].
pub fn dissipation<S, R, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<R, N>,
    v: &SVector<R, N>,
) -> R
where
    S: Spatial<B, J>,
    R: Real,
{
    let (poses, motions) = poses_and_motions::<S, R, B, J, N>(sys, q, v);
    let mut out = R::from_f64(0.0);
    for j in sys.joints().iter() {
        if j.damping == 0.0 {
            continue;
        }
        let mut rates = [R::from_f64(0.0); 3];
        let n = rates_of(j, &poses, &motions, &mut rates);
        for r in &rates[..n] {
            out = out + *r * *r * (0.5 * j.damping);
        }
    }
    out
}

/// Constraints g(q): loop rows, then |u|² − 1 per quaternion.
pub fn constraints<S, R, const B: usize, const J: usize, const N: usize, const C: usize>(
    sys: &S,
    q: &SVector<R, N>,
) -> SVector<R, C>
where
    S: Spatial<B, J>,
    R: Real,
{
    let joints = sys.joints();
    let layout = Layout::of::<S, B>(&joints);
    let mut g = SVector::<R, C>::from_element(R::from_f64(0.0));
    if layout.loop_rows > 0 {
        let poses = poses::<S, R, B, J, N>(sys, q);
        for (k, j) in joints.iter().enumerate() {
            let row = layout.row[k];
            if row == usize::MAX {
                continue;
            }
            let parent = parent_of(j, &poses);
            let mut out = [R::from_f64(0.0); 6];
            let n = joint_residual(j, &parent, &poses[j.child], &mut out);
            for (i, r) in out[..n].iter().enumerate() {
                g[row + i] = *r;
            }
        }
    }
    let mut row = layout.loop_rows;
    for (k, j) in joints.iter().enumerate() {
        let o = layout.coordinate[k];
        let first = match j.kind {
            JointType::Spherical if o != usize::MAX => o,
            JointType::Free if o != usize::MAX => o + 3,
            _ => continue,
        };
        let u = &q.as_slice()[first..first + 4];
        g[row] = u[0] * u[0] + u[1] * u[1] + u[2] * u[2] + u[3] * u[3] - 1.0;
        row += 1;
    }
    g
}

/// World position of each link's centre of mass for poses `poses`.
pub fn centres_of_mass<R: Real, const B: usize>(
    links: &[Link3; B],
    poses: &[Pose3<R>; B],
) -> [[R; 3]; B] {
    core::array::from_fn(|i| poses[i].point(links[i].com))
}

/// The direction of the link-frame vector `local` of link `i` (a helper for
/// readouts such as "where does the pendulum point").
pub fn direction<R: Real>(pose: &Pose3<R>, local: [f64; 3]) -> [R; 3] {
    mul_mv_f(&pose.rot, local)
}

/// The mechanical terms of the minimal view at one configuration, by
/// forward-mode jets through the generic kinematics (no dual numbers, no
/// allocation): what a fixed-size step needs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MinimalTerms<const N: usize> {
    /// Mass matrix M(q): T = ½ vᵀ M v.
    pub mass: nalgebra::SMatrix<f64, N, N>,
    /// ∂M/∂q_l for every l.
    pub dmass: [nalgebra::SMatrix<f64, N, N>; N],
    /// ∇V(q).
    pub dpotential: SVector<f64, N>,
    /// Damping matrix D(q): the dissipation is ½ vᵀ D v.
    pub damping: nalgebra::SMatrix<f64, N, N>,
}

fn seed1<const N: usize>(q: &SVector<f64, N>) -> SVector<crate::real::Jet1<N>, N> {
    SVector::from_fn(|i, _| crate::real::Jet1::variable(q[i], i))
}

fn constant1<const N: usize>(q: &SVector<f64, N>) -> SVector<crate::real::Jet1<N>, N> {
    q.map(crate::real::Jet1::constant)
}

/// One link's velocity column for one velocity direction: the centre of
/// mass velocity and the body angular velocity, as jets in q.
type Column<const N: usize> = ([crate::real::Jet1<N>; 3], [crate::real::Jet1<N>; 3]);

/// Per link, for velocity direction e_j: the centre-of-mass velocity and
/// the body angular velocity (columns j of J_v and J_ω) as jets in q, so
/// their gradients are ∂J/∂q, written into `cols[j][i]`.
///
/// The N·B columns hold 6·N·(N + 1) numbers per link (1.2 MB for the
/// 29-joint G1): they are written in place, never returned by value,
/// because an unoptimised build keeps a copy of a returned array in every
/// frame it passes through (`core::array::from_fn` nests several), which
/// overflowed the 8 MB main-thread stack.
fn velocity_columns<S, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<f64, N>,
    cols: &mut [[Column<N>; B]; N],
) where
    S: Spatial<B, J>,
{
    use crate::real::Jet1;
    let links = sys.links();
    let qj = seed1(q);
    for (j, col) in cols.iter_mut().enumerate() {
        let mut v = SVector::<Jet1<N>, N>::from_element(Jet1::constant(0.0));
        v[j] = Jet1::constant(1.0);
        let (poses, motions) = poses_and_motions::<S, Jet1<N>, B, J, N>(sys, &qj, &v);
        for (i, c) in col.iter_mut().enumerate() {
            *c = (
                motions[i].point_velocity(&poses[i], links[i].com),
                mul_mtv(&poses[i].rot, motions[i].omega),
            );
        }
    }
}

/// M(q), ∂M/∂q, ∇V(q) and D(q) (see [`MinimalTerms`]). Cost: N + 1 passes
/// of the kinematics on N-direction first-order jets (plus N for damping).
pub fn terms<S, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<f64, N>,
) -> MinimalTerms<N>
where
    S: Spatial<B, J>,
{
    use crate::real::Jet1;
    use nalgebra::SMatrix;
    let links = sys.links();
    let zero = Jet1::<N>::constant(0.0);
    let mut cols = [[([zero; 3], [zero; 3]); B]; N];
    velocity_columns::<S, B, J, N>(sys, q, &mut cols);
    let mut mass = SMatrix::<f64, N, N>::zeros();
    let mut dmass = [SMatrix::<f64, N, N>::zeros(); N];
    for (i, link) in links.iter().enumerate() {
        // inertia times the angular columns: I·J_ω[:, k] as jets
        let iw: [[Jet1<N>; 3]; N] = core::array::from_fn(|k| {
            let w = cols[k][i].1;
            [
                dot_f(w, link.inertia[0]),
                dot_f(w, link.inertia[1]),
                dot_f(w, link.inertia[2]),
            ]
        });
        for j in 0..N {
            for k in j..N {
                let e = dot(cols[j][i].0, cols[k][i].0) * link.mass + dot(cols[j][i].1, iw[k]);
                mass[(j, k)] += e.v;
                for (l, dm) in dmass.iter_mut().enumerate() {
                    dm[(j, k)] += e.g[l];
                }
            }
        }
    }
    for j in 0..N {
        for k in 0..j {
            mass[(j, k)] = mass[(k, j)];
            for dm in dmass.iter_mut() {
                dm[(j, k)] = dm[(k, j)];
            }
        }
    }
    let v = potential_energy::<S, Jet1<N>, B, J, N>(sys, &seed1(q));
    let dpotential = SVector::<f64, N>::from_fn(|l, _| v.g[l]);
    let damping = damping_matrix::<S, B, J, N>(sys, q);
    MinimalTerms {
        mass,
        dmass,
        dpotential,
        damping,
    }
}

/// The rate rows of every damped joint at q: each rate is b·v with b the
/// returned row (as a jet in q when `R` is a jet); `visit(c, b)`.
// `j` is the velocity direction: it fills the innermost index of `rows`.
#[allow(clippy::needless_range_loop)]
fn damping_rows<S, R, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<R, N>,
    visit: &mut impl FnMut(f64, [R; N]),
) where
    S: Spatial<B, J>,
    R: Real,
{
    // the rates are linear in v: evaluate them at v = e_j for every j
    let joints = sys.joints();
    let mut rows = [[[R::from_f64(0.0); N]; 3]; J];
    let mut counts = [0usize; J];
    for j in 0..N {
        let v = SVector::<R, N>::from_fn(|i, _| R::from_f64(if i == j { 1.0 } else { 0.0 }));
        let (poses, motions) = poses_and_motions::<S, R, B, J, N>(sys, q, &v);
        for (k, jt) in joints.iter().enumerate() {
            if jt.damping == 0.0 {
                continue;
            }
            let mut r = [R::from_f64(0.0); 3];
            let n = rates_of(jt, &poses, &motions, &mut r);
            counts[k] = n;
            for (row, rate) in r[..n].iter().enumerate() {
                rows[k][row][j] = *rate;
            }
        }
    }
    for (k, jt) in joints.iter().enumerate() {
        for row in &rows[k][..counts[k]] {
            visit(jt.damping, *row);
        }
    }
}

/// D(q) = Σ_j c_j b_j b_jᵀ over the rate rows b_j.
pub fn damping_matrix<S, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<f64, N>,
) -> nalgebra::SMatrix<f64, N, N>
where
    S: Spatial<B, J>,
{
    let mut d = nalgebra::SMatrix::<f64, N, N>::zeros();
    if !S::DISSIPATIVE {
        return d;
    }
    damping_rows::<S, f64, B, J, N>(sys, q, &mut |c, b| {
        for i in 0..N {
            for k in 0..N {
                d[(i, k)] += c * b[i] * b[k];
            }
        }
    });
    d
}

/// ∂/∂q [½ vᵀ ∂M/∂q v − ∇V − D(q) v] at fixed v: the Hessian of T − V in
/// q at fixed v (one second-order jet pass) minus ∂(D v)/∂q.
pub fn force_jacobian<S, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<f64, N>,
    v: &SVector<f64, N>,
) -> nalgebra::SMatrix<f64, N, N>
where
    S: Spatial<B, J>,
{
    use crate::real::Jet1;
    let mut out = hessian(&LagrangianAt::<S, B, J, N> { sys, v }, q);
    if S::DISSIPATIVE {
        // D v = Σ c b (b·v): ∂/∂q_l = Σ c (∂b/∂q_l (b·v) + b ∂(b·v)/∂q_l)
        damping_rows::<S, Jet1<N>, B, J, N>(sys, &seed1(q), &mut |c, b| {
            let bv = (0..N).fold(Jet1::<N>::constant(0.0), |acc, i| acc + b[i] * v[i]);
            for i in 0..N {
                for l in 0..N {
                    out[(i, l)] -= c * (b[i].g[l] * bv.v + b[i].v * bv.g[l]);
                }
            }
        });
    }
    out
}

/// The largest N whose Hessians come from one second-order jet pass
/// ([`Jet2`](crate::real::Jet2): N² + N + 1 numbers per scalar, 1.3 KB at
/// N = 12). Above it they come column by column
/// ([`JetDir`](crate::real::JetDir): 2(N + 1) numbers), about three times
/// the arithmetic but a stack that grows as N instead of N²: one Jet2 pass
/// of the 29-joint G1's kinematics holds several MB of jets.
pub const ONE_PASS_HESSIAN: usize = 12;

/// A scalar function of the minimal coordinates, on any [`Real`]: what
/// [`hessian`] differentiates twice.
pub(crate) trait OfCoordinates<const N: usize> {
    /// f(q).
    fn at<R: Real>(&self, q: &SVector<R, N>) -> R;
}

/// ∇²f(q): one second-order jet pass up to [`ONE_PASS_HESSIAN`]
/// coordinates, N column passes above.
pub(crate) fn hessian<F: OfCoordinates<N>, const N: usize>(
    f: &F,
    q: &SVector<f64, N>,
) -> nalgebra::SMatrix<f64, N, N> {
    if N <= ONE_PASS_HESSIAN {
        hessian_one_pass(f, q)
    } else {
        hessian_by_columns(f, q)
    }
}

/// ∇²f(q) by one second-order jet pass.
pub(crate) fn hessian_one_pass<F: OfCoordinates<N>, const N: usize>(
    f: &F,
    q: &SVector<f64, N>,
) -> nalgebra::SMatrix<f64, N, N> {
    use crate::real::Jet2;
    let y = f.at(&SVector::<Jet2<N>, N>::from_fn(|i, _| {
        Jet2::variable(q[i], i)
    }));
    nalgebra::SMatrix::from_fn(|i, k| y.hessian(i, k))
}

/// ∇²f(q) by N passes of [`JetDir`](crate::real::JetDir), column l from
/// the pass along q_l.
pub(crate) fn hessian_by_columns<F: OfCoordinates<N>, const N: usize>(
    f: &F,
    q: &SVector<f64, N>,
) -> nalgebra::SMatrix<f64, N, N> {
    use crate::real::JetDir;
    let mut out = nalgebra::SMatrix::<f64, N, N>::zeros();
    for l in 0..N {
        let y = f.at(&SVector::<JetDir<N>, N>::from_fn(|i, _| {
            JetDir::variable(q[i], i, l)
        }));
        for i in 0..N {
            out[(i, l)] = y.dx.g[i];
        }
    }
    out
}

/// The Lagrangian at fixed velocities, as a function of q.
pub(crate) struct LagrangianAt<'a, S, const B: usize, const J: usize, const N: usize> {
    /// The mechanism.
    pub sys: &'a S,
    /// The fixed velocities.
    pub v: &'a SVector<f64, N>,
}

impl<S, const B: usize, const J: usize, const N: usize> OfCoordinates<N>
    for LagrangianAt<'_, S, B, J, N>
where
    S: Spatial<B, J>,
{
    fn at<R: Real>(&self, q: &SVector<R, N>) -> R {
        let v = self.v.map(R::from_f64);
        lagrangian::<S, R, B, J, N>(self.sys, q, &v)
    }
}

/// Σ_i μ_i g_i(q), the constraints weighted by multipliers.
pub(crate) struct WeightedConstraints<'a, S, const B: usize, const J: usize, const C: usize> {
    /// The mechanism.
    pub sys: &'a S,
    /// The weights μ.
    pub mu: &'a SVector<f64, C>,
}

impl<S, const B: usize, const J: usize, const N: usize, const C: usize> OfCoordinates<N>
    for WeightedConstraints<'_, S, B, J, C>
where
    S: Spatial<B, J>,
{
    fn at<R: Real>(&self, q: &SVector<R, N>) -> R {
        let g = constraints::<S, R, B, J, N, C>(self.sys, q);
        (0..C).fold(R::from_f64(0.0), |s, i| s + g[i] * self.mu[i])
    }
}

/// The work of the inputs, Σ u_k s_k(q), as a function of q.
pub(crate) struct InputWork<'a, S, const B: usize, const J: usize, const U: usize> {
    /// The mechanism.
    pub sys: &'a S,
    /// The inputs.
    pub u: &'a SVector<f64, U>,
}

impl<S, const B: usize, const J: usize, const N: usize, const U: usize> OfCoordinates<N>
    for InputWork<'_, S, B, J, U>
where
    S: Spatial<B, J>,
{
    fn at<R: Real>(&self, q: &SVector<R, N>) -> R {
        input_work::<S, R, B, J, N>(self.sys, q, self.u.as_slice())
    }
}

/// g(q) and G(q) = ∂g/∂q (one first-order jet pass).
pub fn constraints_and_jacobian<S, const B: usize, const J: usize, const N: usize, const C: usize>(
    sys: &S,
    q: &SVector<f64, N>,
) -> (SVector<f64, C>, nalgebra::SMatrix<f64, C, N>)
where
    S: Spatial<B, J>,
{
    let g = constraints::<S, crate::real::Jet1<N>, B, J, N, C>(sys, &seed1(q));
    (
        SVector::from_fn(|r, _| g[r].v),
        nalgebra::SMatrix::from_fn(|r, k| g[r].g[k]),
    )
}

/// Σ_i μ_i ∇²g_i(q) (one second-order jet pass, or N column passes
/// above [`ONE_PASS_HESSIAN`]).
pub fn constraint_hessian<S, const B: usize, const J: usize, const N: usize, const C: usize>(
    sys: &S,
    q: &SVector<f64, N>,
    mu: &SVector<f64, C>,
) -> nalgebra::SMatrix<f64, N, N>
where
    S: Spatial<B, J>,
{
    hessian(&WeightedConstraints::<S, B, J, C> { sys, mu }, q)
}

/// Potential energy V(q) in f64.
pub fn potential<S, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<f64, N>,
) -> f64
where
    S: Spatial<B, J>,
{
    potential_energy::<S, f64, B, J, N>(sys, q)
}

/// Mass matrix M(q) alone (one pass per velocity direction, values only).
pub fn mass_matrix<S, const B: usize, const J: usize, const N: usize>(
    sys: &S,
    q: &SVector<f64, N>,
) -> nalgebra::SMatrix<f64, N, N>
where
    S: Spatial<B, J>,
{
    use crate::real::Jet1;
    // velocities as jets at fixed q: the centre-of-mass velocity and body
    // rate of each link have J_v, J_ω as gradients
    let links = sys.links();
    let qc = constant1(q);
    let v = SVector::<Jet1<N>, N>::from_fn(|i, _| Jet1::variable(0.0, i));
    let (poses, motions) = poses_and_motions::<S, Jet1<N>, B, J, N>(sys, &qc, &v);
    let mut m = nalgebra::SMatrix::<f64, N, N>::zeros();
    for (i, link) in links.iter().enumerate() {
        let vc = motions[i].point_velocity(&poses[i], link.com);
        let wb = mul_mtv(&poses[i].rot, motions[i].omega);
        for j in 0..N {
            for k in 0..N {
                let mut e = link.mass
                    * (vc[0].g[j] * vc[0].g[k] + vc[1].g[j] * vc[1].g[k] + vc[2].g[j] * vc[2].g[k]);
                for a in 0..3 {
                    for b in 0..3 {
                        e += wb[a].g[j] * link.inertia[a][b] * wb[b].g[k];
                    }
                }
                m[(j, k)] += e;
            }
        }
    }
    m
}
