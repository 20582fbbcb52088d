//! Step derivatives of [`LieStepper`] in tangent coordinates, for
//! controllers (LQR, MPC).
//!
//! # The chart
//!
//! A maximal state z = (x_i, q_i, v_i, ω_i) per link has the tangent
//! coordinates δ = (δc, δν), each of length 6B in the layout of
//! [`pack`]: δc = (δx_i, δη_i) per link, a translation of the centre of
//! mass and a right (body-frame) rotation, and δν = (δv_i, δω_i), changes
//! of the discrete velocities. The [retraction](LieStepper::retract) is
//! x' = x + δx, q' = q ⊗ exp(δη), v' = v + δv, ω' = ω + δω, and the
//! [local map](LieStepper::local) its inverse. These are the perturbations
//! of the integrator itself (its variations q ↦ q ⊗ exp(η), its body
//! rates), 6 + 6 per link. They are not reduced to the 2·DoF of the
//! constraint manifold: the step is defined (and smooth) off it as well,
//! so the chart needs no constraint solve and a state's tangent
//! coordinates are cheap; a controller that wants 2·DoF coordinates
//! projects on the kernel of the constraint Jacobians.
//!
//! # The derivatives
//!
//! The step maps z₀ to z₁ = (x₀ + Δt·v₀, q₀ ⊗ exp(Δt·ω₀), ν) with ν the
//! solution of the DEL r(ν, λ) = 0 and c(ν) = g(x₂, q₂) = 0 (module docs of
//! [`super`]). Configuration k+1 moves with δ₀ as
//!
//! ```text
//! δx₁ = δx₀ + Δt·δv₀,     δη₁ = R(exp(Δt·ω₀))ᵀ·δη₀ + Δt·J_r(Δt·ω₀)·δω₀
//! ```
//!
//! and the implicit function theorem on the converged KKT system gives
//! dν from
//!
//! ```text
//! [ ∂r/∂ν  −G₁ᵀ ] [ dν ]     [ ∂r/∂θ ]
//! [ ∂c/∂ν    0  ] [ dλ ] = − [ ∂c/∂θ ],   θ ∈ {δc₁, δν₀, u}
//!
//! ∂r/∂δc₁ = −∂(G₁ᵀλ)/∂δc₁ + Δt·Σ u_i·∂(∇_ν ṡ_i)/∂δc₁ − Δt·∂(D·ν)/∂δc₁ − Δt·∂(∇V)/∂δc₁
//! ∂r/∂δν₀ = blockdiag(m I, ∂μ⁻/∂ω₀),   ∂r/∂u_i = Δt·∇_ν ṡ_i
//! ∂c/∂δc₁ = G(x₂, q₂)·blockdiag(I, R(exp(Δt·ω₁))ᵀ)
//! ```
//!
//! with D(c₁) = Σ_j d_j Σ_k ∇_ν ṡ_jk ∇_ν ṡ_jkᵀ the damping of the joints'
//! rates and V(c₁) = Σ_j ½k_j(s_j − rest_j)² the springs' potential.
//!
//! The curvature terms are exact: forward-mode second-order jets ([`Jet2`])
//! through each joint's residual with the orientation expanded to second
//! order, R·(I + η̂ + ½η̂²), plus the ½∇g·(ε × η) that composing two right
//! perturbations adds (exp(ε)·exp(η) = exp(ε + η + ½ε × η + …)); the
//! input and damped rates' mixed derivatives by jets in 12 configuration
//! and 12 velocity directions; the springs' by the potential's jets as the
//! constraints'. Checked against central differences through the
//! retraction in tests/step/tangent.rs.

use super::{LieStepper, SpatialState, constraints_and_jacobian, link_pose, pack, unpack};
use crate::error::StepError;
use crate::forced::{InputJacobian, StateJacobian};
use crate::real::Jet2;
use crate::spatial::geometry::{Motion3, Pose3, cross, mul_mv, mul_mv_f, sub};
use crate::spatial::model::{
    Joint3, Link3, Spatial, joint_coordinate, joint_rates, joint_residual,
};
use crate::spatial::so3;
use nalgebra::{Matrix3, SMatrix, SVector, UnitQuaternion, Vector3};

/// R·(I + ε̂ + s·ε̂²) with ε the jet variables `base..base + 3`.
fn jet_rot<const K: usize>(r: &[[f64; 3]; 3], base: usize, s: f64) -> [[Jet2<K>; 3]; 3] {
    let e = [
        Jet2::<K>::variable(0.0, base),
        Jet2::variable(0.0, base + 1),
        Jet2::variable(0.0, base + 2),
    ];
    let z = Jet2::constant(0.0);
    let eh = [[z, -e[2], e[1]], [e[2], z, -e[0]], [-e[1], e[0], z]];
    let mut m = eh;
    for (i, row) in m.iter_mut().enumerate() {
        for (c, x) in row.iter_mut().enumerate() {
            let mut sq = Jet2::constant(0.0);
            for (k, ehk) in eh.iter().enumerate() {
                sq = sq + eh[i][k] * ehk[c];
            }
            *x = *x + sq * s;
            if i == c {
                *x = *x + 1.0;
            }
        }
    }
    core::array::from_fn(|i| {
        core::array::from_fn(|c| m[0][c] * r[i][0] + m[1][c] * r[i][1] + m[2][c] * r[i][2])
    })
}

/// The pose of `link` at (x, R) with its centre of mass moved by the jet
/// variables `base..base + 3` and its orientation by `base + 3..base + 6`
/// (to second order when `s` = ½).
fn jet_pose2<const K: usize>(
    link: &Link3,
    pose: &Pose3<f64>,
    x: &Vector3<f64>,
    base: usize,
    s: f64,
) -> Pose3<Jet2<K>> {
    let rot = jet_rot::<K>(&pose.rot, base + 3, s);
    let c = mul_mv_f(&rot, link.com);
    let origin = core::array::from_fn(|i| Jet2::variable(x[i], base + i) - c[i]);
    Pose3 { origin, rot }
}

fn constant_pose2<const K: usize>() -> Pose3<Jet2<K>> {
    let p = Pose3::<f64>::identity();
    Pose3 {
        origin: p.origin.map(Jet2::constant),
        rot: p.rot.map(|r| r.map(Jet2::constant)),
    }
}

/// Adds the 12 × 12 block `m` (rows and columns over the parent's and the
/// child's six coordinates) into `out`.
fn scatter_block<const N: usize>(out: &mut SMatrix<f64, N, N>, j: &Joint3, m: &[[f64; 12]; 12]) {
    let col = |k: usize| -> Option<usize> {
        if k < 6 {
            j.parent.map(|p| 6 * p + k)
        } else {
            Some(6 * j.child + k - 6)
        }
    };
    for (a, row) in m.iter().enumerate() {
        let Some(ia) = col(a) else { continue };
        for (b, x) in row.iter().enumerate() {
            if let Some(ib) = col(b) {
                out[(ia, ib)] += *x;
            }
        }
    }
}

/// M[a][b] = ∂/∂ε_b ∂/∂ξ_a of φ(c ⊕ ε ⊕ ξ) from φ's jets in ζ (orientation
/// to second order): the Hessian plus ½∇φ·(e_b × e_a) within each link's
/// rotation block.
fn mixed_from_hessian(phi: &Jet2<12>) -> [[f64; 12]; 12] {
    let mut m = [[0.0; 12]; 12];
    for (a, row) in m.iter_mut().enumerate() {
        for (b, x) in row.iter_mut().enumerate() {
            *x = phi.hessian(a, b);
        }
    }
    for base in [3usize, 9] {
        let g = [phi.g[base], phi.g[base + 1], phi.g[base + 2]];
        for a in 0..3 {
            for b in 0..3 {
                let mut ea = [0.0; 3];
                let mut eb = [0.0; 3];
                ea[a] = 1.0;
                eb[b] = 1.0;
                let c = cross(eb, ea);
                m[base + a][base + b] += 0.5 * (g[0] * c[0] + g[1] * c[1] + g[2] * c[2]);
            }
        }
    }
    m
}

impl<S: Spatial<B, J>, const B: usize, const J: usize, const N: usize, const C: usize>
    LieStepper<S, B, J, N, C>
{
    /// The retraction of the tangent chart (module docs): `z` moved by the
    /// configuration perturbation `dc` and the velocity perturbation `dnu`
    /// (layout of [`pack`]).
    pub fn retract(
        &self,
        z: &SpatialState<B>,
        dc: &SVector<f64, N>,
        dnu: &SVector<f64, N>,
    ) -> SpatialState<B> {
        let (dv, dw) = unpack::<B, N>(dnu);
        SpatialState {
            x: core::array::from_fn(|i| z.x[i] + dc.fixed_rows::<3>(6 * i)),
            q: core::array::from_fn(|i| {
                UnitQuaternion::new_normalize(
                    z.q[i].quaternion()
                        * so3::exp(&dc.fixed_rows::<3>(6 * i + 3).into_owned()).quaternion(),
                )
            }),
            v: core::array::from_fn(|i| z.v[i] + dv[i]),
            w: core::array::from_fn(|i| z.w[i] + dw[i]),
        }
    }

    /// The local map of the chart: the tangent coordinates (δc, δν) of `z`
    /// relative to `base` (the inverse of [`Self::retract`]).
    pub fn local(
        &self,
        base: &SpatialState<B>,
        z: &SpatialState<B>,
    ) -> (SVector<f64, N>, SVector<f64, N>) {
        let mut dc = SVector::<f64, N>::zeros();
        for i in 0..B {
            dc.fixed_rows_mut::<3>(6 * i)
                .copy_from(&(z.x[i] - base.x[i]));
            dc.fixed_rows_mut::<3>(6 * i + 3)
                .copy_from(&so3::log(&(base.q[i].inverse() * z.q[i])));
        }
        let dnu = pack::<B, N>(&z.v, &z.w) - pack::<B, N>(&base.v, &base.w);
        (dc, dnu)
    }

    /// One forced step (as [`Self::step_forced`]; `U` = 0 for none) with its
    /// exact derivatives in the tangent chart (module docs): the
    /// [`StateJacobian`]'s blocks are ∂δc₁/∂δc₀ (`q_q`), ∂δc₁/∂δν₀ (`q_v`),
    /// ∂δν₁/∂δc₀ (`v_q`), ∂δν₁/∂δν₀ (`v_v`), each 6B × 6B, so
    /// A = `a.matrix::<{12B}>()`; the [`InputJacobian`] holds ∂δν₁/∂u
    /// (`q_u` is zero: the inputs act from configuration k+1 on). Errors:
    /// the step's, as [`Self::step_forced`]'s.
    #[allow(clippy::type_complexity)]
    pub fn step_derivatives<const U: usize>(
        &self,
        z: &SpatialState<B>,
        u: &SVector<f64, U>,
    ) -> Result<(SpatialState<B>, StateJacobian<N>, InputJacobian<N, U>), StepError>
    where
        S: crate::Inputs<U>,
    {
        let inputs = S::INPUT_JOINTS.len();
        if U != inputs && U != 0 {
            return Err(StepError::InvalidOptions(
                "the input vector's length is not the number of inputs",
            ));
        }
        z.validate()?;
        if !u.iter().all(|x| x.is_finite()) {
            return Err(StepError::NonFiniteInput { step: None });
        }
        let h = self.dt;
        let (z1, _, lambda) = self.solve_full(z, &pack(&z.v, &z.w), u.as_slice())?;
        let d = self.prepare(z, u.as_slice());
        let nu = pack::<B, N>(&z1.v, &z1.w);
        let kkt = self.factor(&d, &nu).ok_or(StepError::singular(0))?;
        let poses: [Pose3<f64>; B] =
            core::array::from_fn(|i| link_pose(&self.links[i], &d.x1[i], &d.q1[i]));

        // δc₁ = P δc₀ + Q δν₀
        let mut p = SMatrix::<f64, N, N>::zeros();
        let mut q = SMatrix::<f64, N, N>::zeros();
        let mut r_nu0 = SMatrix::<f64, N, N>::zeros();
        for i in 0..B {
            let hw = z.w[i] * h;
            let rt = so3::exp(&hw).to_rotation_matrix().matrix().transpose();
            p.fixed_view_mut::<3, 3>(6 * i, 6 * i)
                .copy_from(&Matrix3::identity());
            p.fixed_view_mut::<3, 3>(6 * i + 3, 6 * i + 3)
                .copy_from(&rt);
            q.fixed_view_mut::<3, 3>(6 * i, 6 * i)
                .copy_from(&(Matrix3::identity() * h));
            q.fixed_view_mut::<3, 3>(6 * i + 3, 6 * i + 3)
                .copy_from(&(so3::right_jacobian(&hw) * h));
            r_nu0
                .fixed_view_mut::<3, 3>(6 * i, 6 * i)
                .copy_from(&(Matrix3::identity() * self.links[i].mass));
            r_nu0
                .fixed_view_mut::<3, 3>(6 * i + 3, 6 * i + 3)
                .copy_from(&so3::momentum_jacobian(&self.inertia[i], &z.w[i], h, -1.0));
        }

        // ∂r/∂δc₁ = −∂(G₁ᵀλ)/∂δc₁ + Δt Σ u_i ∂(∇_ν ṡ_i)/∂δc₁
        let mut r_c = SMatrix::<f64, N, N>::zeros();
        let mut row = 0;
        for j in &self.joints {
            let (parent, child) = self.pose_jets2(&poses, &d.x1, j);
            let mut out = [Jet2::constant(0.0); 6];
            let n = joint_residual(j, &parent, &child, &mut out);
            if n == 0 {
                continue;
            }
            let mut phi = Jet2::<12>::constant(0.0);
            for (k, g) in out[..n].iter().enumerate() {
                phi = phi + *g * lambda[row + k];
            }
            row += n;
            let m = mixed_from_hessian(&phi).map(|r| r.map(|x| -x));
            scatter_block(&mut r_c, j, &m);
        }
        let mut r_u = SMatrix::<f64, N, U>::zeros();
        for (col, &k) in S::INPUT_JOINTS.iter().enumerate().take(U) {
            let j = &self.joints[k];
            let rate = self.rate_jets2(&poses, &d.x1, j).0[0];
            let ui = u[col];
            let mut m = [[0.0; 12]; 12];
            let mut grad = [0.0; 12];
            for (a, row) in m.iter_mut().enumerate() {
                grad[a] = rate.g[12 + a];
                for (b, x) in row.iter_mut().enumerate() {
                    *x = h * ui * rate.hessian(12 + a, b);
                }
            }
            scatter_block(&mut r_c, j, &m);
            let mut g = SVector::<f64, N>::zeros();
            super::scatter(&mut g, j, &grad, h);
            r_u.set_column(col, &g);
        }

        // damping, r −= Δt·D(c₁)·ν with D = Σ_j d_j Σ_k ∇_ν ṡ_k ∇_ν ṡ_kᵀ:
        // −Δt·d_j Σ_k (∂(∇_ν ṡ_k)/∂δc₁·ṡ_k + ∇_ν ṡ_k ⊗ ∂ṡ_k/∂δc₁), ṡ_k
        // being linear in ν
        if self.dissipative {
            for j in &self.joints {
                if j.damping == 0.0 {
                    continue;
                }
                let (rates, n) = self.rate_jets2(&poses, &d.x1, j);
                let nu_local: [f64; 12] = core::array::from_fn(|a| {
                    if a < 6 {
                        j.parent.map_or(0.0, |p| nu[6 * p + a])
                    } else {
                        nu[6 * j.child + a - 6]
                    }
                });
                let mut m = [[0.0; 12]; 12];
                for rate in &rates[..n] {
                    let grad: [f64; 12] = core::array::from_fn(|a| rate.g[12 + a]);
                    let sdot: f64 = grad.iter().zip(&nu_local).map(|(g, v)| g * v).sum();
                    let dsdot: [f64; 12] = core::array::from_fn(|b| {
                        (0..12).map(|e| rate.hessian(12 + e, b) * nu_local[e]).sum()
                    });
                    for (a, row) in m.iter_mut().enumerate() {
                        for (b, x) in row.iter_mut().enumerate() {
                            *x -= h
                                * j.damping
                                * (rate.hessian(12 + a, b) * sdot + grad[a] * dsdot[b]);
                        }
                    }
                }
                scatter_block(&mut r_c, j, &m);
            }
        }
        // springs, r −= Δt·∇V(c₁) with V = ½k(s − rest)²: the chart's
        // second derivative of Δt·V, as for the constraints' λ·g
        if self.elastic {
            for (j, spring) in self.joints.iter().zip(&self.springs) {
                if spring.stiffness == 0.0 {
                    continue;
                }
                let (parent, child) = self.pose_jets2(&poses, &d.x1, j);
                let e = joint_coordinate(j, &parent, &child, spring.rest) - spring.rest;
                let potential = e * e * (0.5 * h * spring.stiffness);
                let m = mixed_from_hessian(&potential).map(|r| r.map(|x| -x));
                scatter_block(&mut r_c, j, &m);
            }
        }

        // ∂c/∂δc₁ = G(x₂, q₂)·blockdiag(I, R(exp(Δt ω₁))ᵀ)
        let mut c_c = SMatrix::<f64, C, N>::zeros();
        if C > 0 {
            let (x2, q2) = self.config2(&d, &nu);
            let g = constraints_and_jacobian::<B, N, C>(&self.links, &self.joints, &x2, &q2).1;
            for i in 0..B {
                let rt = so3::exp(&(z1.w[i] * h))
                    .to_rotation_matrix()
                    .matrix()
                    .transpose();
                c_c.fixed_view_mut::<C, 3>(0, 6 * i)
                    .copy_from(&g.fixed_view::<C, 3>(0, 6 * i));
                let rot = g.fixed_view::<C, 3>(0, 6 * i + 3) * rt;
                c_c.fixed_view_mut::<C, 3>(0, 6 * i + 3).copy_from(&rot);
            }
        }

        let solve = |dr: SVector<f64, N>, dc: SVector<f64, C>| kkt.solve(&(-dr), &(-dc)).0;
        let (rc_p, cc_p) = (r_c * p, c_c * p);
        let (rc_q, cc_q) = (r_c * q + r_nu0, c_c * q);
        let mut v_q = SMatrix::<f64, N, N>::zeros();
        let mut v_v = SMatrix::<f64, N, N>::zeros();
        for k in 0..N {
            v_q.set_column(
                k,
                &solve(rc_p.column(k).into_owned(), cc_p.column(k).into_owned()),
            );
            v_v.set_column(
                k,
                &solve(rc_q.column(k).into_owned(), cc_q.column(k).into_owned()),
            );
        }
        let mut v_u = SMatrix::<f64, N, U>::zeros();
        for k in 0..U {
            v_u.set_column(k, &solve(r_u.column(k).into_owned(), SVector::zeros()));
        }
        Ok((
            z1,
            StateJacobian {
                q_q: p,
                q_v: q,
                v_q,
                v_v,
            },
            InputJacobian {
                q_u: SMatrix::zeros(),
                v_u,
            },
        ))
    }

    /// The poses of joint `j`'s parent (directions 0..6) and child (6..12)
    /// as jets to second order in their (δx, η) (module docs).
    fn pose_jets2(
        &self,
        poses: &[Pose3<f64>; B],
        x: &[Vector3<f64>; B],
        j: &Joint3,
    ) -> (Pose3<Jet2<12>>, Pose3<Jet2<12>>) {
        let child = jet_pose2::<12>(&self.links[j.child], &poses[j.child], &x[j.child], 6, 0.5);
        let parent = match j.parent {
            Some(p) => jet_pose2::<12>(&self.links[p], &poses[p], &x[p], 0, 0.5),
            None => constant_pose2(),
        };
        (parent, child)
    }

    /// The rates of joint `j` (and how many it has) as jets in the
    /// parent's and child's configuration (directions 0..12, first order
    /// in the orientation) and velocities (12..24).
    fn rate_jets2(
        &self,
        poses: &[Pose3<f64>; B],
        x: &[Vector3<f64>; B],
        j: &Joint3,
    ) -> ([Jet2<24>; 3], usize) {
        let pm = |i: usize, cbase: usize, vbase: usize| {
            let pose = jet_pose2::<24>(&self.links[i], &poses[i], &x[i], cbase, 0.0);
            let wb = [
                Jet2::<24>::variable(0.0, vbase + 3),
                Jet2::variable(0.0, vbase + 4),
                Jet2::variable(0.0, vbase + 5),
            ];
            let omega = mul_mv(&pose.rot, wb);
            let vcom = [
                Jet2::variable(0.0, vbase),
                Jet2::variable(0.0, vbase + 1),
                Jet2::variable(0.0, vbase + 2),
            ];
            let arm = mul_mv_f(&pose.rot, self.links[i].com);
            let velocity = sub(vcom, cross(omega, arm));
            (pose, Motion3 { velocity, omega })
        };
        let (cp, cm) = pm(j.child, 6, 18);
        let (pp, pmo) = match j.parent {
            Some(p) => pm(p, 0, 12),
            None => (constant_pose2(), Motion3::zero()),
        };
        let mut out = [Jet2::constant(0.0); 3];
        let n = joint_rates(j, (&pp, &pmo), (&cp, &cm), &mut out);
        (out, n)
    }
}
