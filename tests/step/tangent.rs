//! Step derivatives in tangent coordinates (`vigp::embedded::Tangent`) for
//! mechanisms whose minimal view holds unit quaternions: Ã = ∂δ₁/∂δ₀ and
//! B̃ = ∂δ₁/∂u, 2·DoF × 2·DoF and 2·DoF × U, checked against central
//! differences through the chart: δ₁(±h) = local(z₁, step(retract(z₀,
//! ±h·e_j), u)). Also: retract and local are inverses, and a mechanism
//! without quaternions has the identity chart (Ã = A).

use nalgebra::{SMatrix, SVector, UnitQuaternion, Vector3};
use vigp::embedded::{Tangent, TangentError};
use vigp::projection::consistent_state;
use vigp::{Mechanism, State, Variational};

/// Declares the 3-D arm `$name` with the doc comment `$doc`: an upper
/// link on a ball joint at the origin (`$shoulder`: the joint's keys, in
/// braces, or nothing) and a lower link on an elbow about (0, 0.6, 0.8)
/// taking the keys `$elbow` after its axis.
macro_rules! ball_arm {
    (
        $(#[doc = $doc:tt])*
        $name:ident {
            shoulder: [$($shoulder:tt)*],
            elbow: [$($elbow:tt)*],
        }
    ) => {
        vigp::mechanism! {
            $(#[doc = $doc])*
            pub $name {
                gravity: [0.0, 0.0, -9.81],
                links {
                    upper: { mass: 1.2, length: 0.8, inertia: [0.001, 0.065, 0.065] },
                    lower: { mass: 0.7, length: 0.6, inertia: [0.0007, 0.021, 0.0215] },
                }
                joints {
                    shoulder: spherical(world, upper.start) $($shoulder)*,
                    elbow: revolute(upper.end, lower.start) { axis: [0.0, 0.6, 0.8], $($elbow)* },
                }
            }
        }
    };
}

ball_arm! {
    /// A 3-D arm: a ball-jointed shoulder and an actuated, sprung, damped
    /// elbow (5 coordinates: a quaternion and an angle, one unit-norm
    /// constraint; 4 DoF).
    BallArm {
        shoulder: [{ damping: 0.1 }],
        elbow: [damping: 0.2, stiffness: 1.5, rest: 0.2, actuated],
    }
}

vigp::mechanism! {
    /// A free-floating body (3 positions and a quaternion; 6 DoF) tied to
    /// an actuated pendulum link.
    pub FreeBody {
        gravity: [0.0, 0.0, -9.81],
        links {
            body: { mass: 2.0, inertia: [0.02, 0.03, 0.04] },
            arm: { mass: 0.5, length: 0.4, inertia: [0.0002, 0.0067, 0.0068] },
        }
        joints {
            float: free(world, body.com),
            hinge: revolute(body.com, arm.start) { axis: [0.0, 1.0, 0.0], actuated },
        }
    }
}

/// Worst relative difference between the tangent Jacobians and central
/// differences through the chart over `states`, with step `h`.
fn worst<M, const N: usize, const C: usize, const T: usize, const U: usize>(
    model: M,
    states: &[State<N>],
    u: &SVector<f64, U>,
    dt: f64,
    h: f64,
) -> f64
where
    M: Mechanism<N, C> + vigp::embedded::Dynamics<N, C> + Copy + vigp::Inputs<U>,
{
    let vi = Variational::new(model, dt).unwrap();
    let chart = Tangent::new(<M as vigp::embedded::Dynamics<N, C>>::KINDS, dt).unwrap();
    assert_eq!(chart.dim(), T);
    let mut worst: f64 = 0.0;
    for z0 in states {
        let (z1, d) = vi.step_derivatives(z0, u).unwrap();
        let td = chart.derivatives::<T, U>(z0, &z1, &d).unwrap();
        let delta1 = |z0: &State<N>, u: &SVector<f64, U>| {
            let z = vi.step_forced(z0, u).unwrap();
            let mut out = [0.0; T];
            chart.local(&z1, &z, &mut out).unwrap();
            SVector::<f64, T>::from(out)
        };
        let mut a_fd = SMatrix::<f64, T, T>::zeros();
        for j in 0..T {
            let mut e = [0.0; T];
            e[j] = h;
            let zp = chart.retract(z0, &e).unwrap();
            e[j] = -h;
            let zm = chart.retract(z0, &e).unwrap();
            a_fd.set_column(j, &((delta1(&zp, u) - delta1(&zm, u)) / (2.0 * h)));
        }
        let mut b_fd = SMatrix::<f64, T, U>::zeros();
        for j in 0..U {
            let mut du = *u;
            du[j] += h;
            let p = delta1(z0, &du);
            du[j] -= 2.0 * h;
            b_fd.set_column(j, &((p - delta1(z0, &du)) / (2.0 * h)));
        }
        let ea = (td.a - a_fd).amax() / td.a.amax().max(1.0);
        let eb = (td.b - b_fd).amax() / td.b.amax().max(1.0);
        worst = worst.max(ea).max(eb);
    }
    worst
}

/// A consistent state of `model` from a guess: unit quaternion blocks and
/// their discrete velocities projected (`consistent_state`).
fn consistent<M: Mechanism<N, C>, const N: usize, const C: usize>(
    model: &M,
    q: [f64; N],
    v: [f64; N],
    dt: f64,
) -> State<N> {
    consistent_state(model, &SVector::from(q), &SVector::from(v), dt).unwrap()
}

fn quat(axis: [f64; 3], angle: f64) -> [f64; 4] {
    let q =
        UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(Vector3::from(axis)), angle);
    [q.w, q.i, q.j, q.k]
}

/// Central differences with h = 1e-6: truncation O(h²) ≈ 1e-12, and each
/// differenced step is solved to Newton's relative tolerance 1e-12, which
/// the division by 2h amplifies to ≈ 1e-6 at worst (measured: 2.7e-8 and
/// 1.3e-8). The bound 1e-6 is the acceptance bound for tangent-space A and
/// B; a wrong chart term fails it by orders of magnitude (J_r replaced by
/// the identity: 3.3e-3 on the ball arm).
#[test]
fn tangent_derivatives_match_central_differences_through_the_chart() {
    let dt = 0.01;
    let arm = BallArm::default().minimal();
    let mut states = Vec::new();
    for (k, angle) in [0.3, 1.1, 2.4].into_iter().enumerate() {
        let q = quat([0.3, -0.5 + k as f64, 0.8], angle);
        let qd = quat([1.0, 0.2, -0.4], 0.7);
        // a velocity with a body rate: v = (q ⊗ Δq − q)/Δt
        let q0 = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]));
        let q1 = q0
            * UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                qd[0], qd[1], qd[2], qd[3],
            ))
            .powf(0.02);
        let v: Vec<f64> = [q1.w - q0.w, q1.i - q0.i, q1.j - q0.j, q1.k - q0.k]
            .iter()
            .map(|x| x / dt)
            .collect();
        states.push(consistent(
            &arm,
            [q[0], q[1], q[2], q[3], 0.4 - 0.3 * k as f64],
            [v[0], v[1], v[2], v[3], 1.5 - k as f64],
            dt,
        ));
    }
    let e = worst::<_, 5, 1, 8, 1>(arm, &states, &SVector::from([0.7]), dt, 1e-6);
    println!("ball arm: worst relative |Ã − FD|, |B̃ − FD| = {e:.1e}");
    assert!(e < 1e-6, "ball arm: {e:e}");

    let free = FreeBody::default().minimal();
    let q = quat([0.1, 0.9, -0.3], 0.8);
    let z = consistent(
        &free,
        [0.1, -0.2, 1.0, q[0], q[1], q[2], q[3], 0.5],
        [0.3, 0.0, -0.2, 0.4, -1.1, 0.6, 0.9, -0.8],
        dt,
    );
    let e = worst::<_, 8, 1, 14, 1>(free, &[z], &SVector::from([-0.4]), dt, 1e-6);
    println!("free body: worst relative |Ã − FD|, |B̃ − FD| = {e:.1e}");
    assert!(e < 1e-6, "free body: {e:e}");
}

/// local(z, retract(z, δ)) = δ to rounding, and retract(z, 0) = z on a
/// consistent state.
#[test]
fn retract_and_local_are_inverses() {
    let dt = 0.01;
    let arm = BallArm::default().minimal();
    let q = quat([0.3, -0.5, 0.8], 1.2);
    let z = consistent(
        &arm,
        [q[0], q[1], q[2], q[3], 0.4],
        [0.5, -0.3, 0.2, 0.1, 1.5],
        dt,
    );
    let chart = Tangent::new(
        <vigp::systems::PendulumMinimal as vigp::embedded::Dynamics<1, 0>>::KINDS,
        dt,
    )
    .unwrap();
    assert_eq!(chart.dim(), 2);
    let chart = Tangent::new(
        <BallArmMinimal as vigp::embedded::Dynamics<5, 1>>::KINDS,
        dt,
    )
    .unwrap();
    assert_eq!((chart.dof(), chart.dim()), (4, 8));
    let delta = [0.05, -0.02, 0.03, 0.1, 0.4, -0.7, 0.2, 0.3];
    let moved = chart.retract(&z, &delta).unwrap();
    let mut back = [0.0; 8];
    chart.local(&z, &moved, &mut back).unwrap();
    for (a, b) in delta.iter().zip(back) {
        assert!((a - b).abs() < 1e-13, "{delta:?} vs {back:?}");
    }
    let same = chart.retract(&z, &[0.0; 8]).unwrap();
    assert!((same.q - z.q).amax() < 1e-15 && (same.v - z.v).amax() < 1e-12);
    // the moved state is on the unit sphere at both ends of its step
    let (q0, q1) = (
        moved.q.fixed_rows::<4>(0),
        moved.q.fixed_rows::<4>(0) + moved.v.fixed_rows::<4>(0) * dt,
    );
    assert!((q0.norm() - 1.0).abs() < 1e-15 && (q1.norm() - 1.0).abs() < 1e-14);
    // wrong lengths and states are typed errors
    assert_eq!(
        chart.retract(&z, &[0.0; 3]).unwrap_err(),
        TangentError::Dimension {
            expected: 8,
            got: 3
        }
    );
    let mut bad = z;
    bad.q[1] = f64::NAN;
    assert_eq!(
        chart.retract(&bad, &delta).unwrap_err(),
        TangentError::NonFinite
    );
    assert!(matches!(
        Tangent::<5>::new(
            <BallArmMinimal as vigp::embedded::Dynamics<5, 1>>::KINDS,
            0.0
        ),
        Err(TangentError::TimeStep(_))
    ));
}

/// Without quaternions the chart is the identity: Ã = A and B̃ = B.
#[test]
fn without_quaternions_the_tangent_jacobians_are_a_and_b() {
    use vigp::systems::Cartpole;
    let dt = 0.01;
    let m = Cartpole::default().minimal();
    let vi = Variational::new(m, dt).unwrap();
    let z = State::new([0.1, 2.0], [0.3, -0.4]);
    let u = SVector::<f64, 0>::zeros();
    let (z1, d) = vi.step_derivatives(&z, &u).unwrap();
    let chart = Tangent::new(
        <vigp::systems::CartpoleMinimal as vigp::embedded::Dynamics<2, 0>>::KINDS,
        dt,
    )
    .unwrap();
    let td = chart.derivatives::<4, 0>(&z, &z1, &d).unwrap();
    assert!((td.a - d.a.matrix::<4>()).amax() < 1e-14);
    assert_eq!(
        chart.derivatives::<6, 0>(&z, &z1, &d).unwrap_err(),
        TangentError::Dimension {
            expected: 4,
            got: 6
        }
    );
}

// ---- the maximal view: `LieStepper::step_derivatives` in its tangent
// ---- chart (6 + 6 coordinates per link), against central differences
// ---- through `LieStepper::retract` and `LieStepper::local`.

spatial_four_bar! {
    /// An R-S-U-R four-bar with an actuated crank, no damping or springs:
    /// a loop, a ball joint and a Hooke joint (17 maximal constraint rows
    /// on 3 links, 1 DoF).
    DrivenRsur {
        crankshaft: [actuated],
        ball: ball,
        cardan: universal(rocker.end, coupler.end) { axes: [[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] },
    }
}

ball_arm! {
    /// A ball-jointed upper arm with an actuated, undamped elbow whose
    /// axis is neither parallel nor perpendicular to anything (a chain:
    /// 8 constraint rows on 2 links).
    DrivenBallArm {
        shoulder: [],
        elbow: [actuated],
    }
}

/// Worst difference, relative to the largest entry, between the tangent
/// A (then B) of `LieStepper::step_derivatives` at `z0` and central
/// differences with step `h` through the chart: δ₁(±h) = local(z₁,
/// step(retract(z₀, ±h·e_j), u)).
fn lie_worst<S, const B: usize, const J: usize, const N: usize, const C: usize, const U: usize>(
    st: &vigp::spatial::LieStepper<S, B, J, N, C>,
    z0: &vigp::spatial::SpatialState<B>,
    u: &SVector<f64, U>,
    h: f64,
) -> (f64, f64)
where
    S: vigp::spatial::Spatial<B, J> + vigp::Inputs<U>,
{
    let (z1, a, b) = st.step_derivatives(z0, u).unwrap();
    let plain = st.step_forced(z0, u).unwrap();
    assert_eq!(z1, plain, "the derivatives' step is the step");
    let column = |k: usize| -> (SVector<f64, N>, SVector<f64, N>) {
        if k < N {
            (a.q_q.column(k).into_owned(), a.v_q.column(k).into_owned())
        } else {
            (
                a.q_v.column(k - N).into_owned(),
                a.v_v.column(k - N).into_owned(),
            )
        }
    };
    let scale_a = crate::common::jacobian_amax(&a);
    let mut worst_a = 0.0f64;
    for k in 0..2 * N {
        let mut e = SVector::<f64, N>::zeros();
        e[k % N] = h;
        let zero = SVector::<f64, N>::zeros();
        let (plus, minus) = if k < N {
            (st.retract(z0, &e, &zero), st.retract(z0, &(-e), &zero))
        } else {
            (st.retract(z0, &zero, &e), st.retract(z0, &zero, &(-e)))
        };
        let (cp, np) = st.local(&z1, &st.step_forced(&plus, u).unwrap());
        let (cm, nm) = st.local(&z1, &st.step_forced(&minus, u).unwrap());
        let (dc, dn) = ((cp - cm) / (2.0 * h), (np - nm) / (2.0 * h));
        let (ec, en) = column(k);
        worst_a = worst_a.max((dc - ec).amax().max((dn - en).amax()) / scale_a);
    }
    let scale_b = b.v_u.amax().max(1e-300);
    let mut worst_b = 0.0f64;
    for k in 0..U {
        let mut du = SVector::<f64, U>::zeros();
        du[k] = h;
        let (cp, np) = st.local(&z1, &st.step_forced(z0, &(u + du)).unwrap());
        let (cm, nm) = st.local(&z1, &st.step_forced(z0, &(u - du)).unwrap());
        let (dc, dn) = ((cp - cm) / (2.0 * h), (np - nm) / (2.0 * h));
        worst_b = worst_b.max(
            (dc - b.q_u.column(k))
                .amax()
                .max((dn - b.v_u.column(k)).amax())
                / scale_b,
        );
    }
    (worst_a, worst_b)
}

/// [`lie_worst`] at three states 15, 30 and 45 forced steps from `z0`
/// (so that neither rates nor multipliers vanish), printed under `name`
/// and required to be at most 1e-6.
fn along_a_motion<
    S,
    const B: usize,
    const J: usize,
    const N: usize,
    const C: usize,
    const U: usize,
>(
    st: &vigp::spatial::LieStepper<S, B, J, N, C>,
    z0: vigp::spatial::SpatialState<B>,
    u: &SVector<f64, U>,
    name: &str,
) where
    S: vigp::spatial::Spatial<B, J> + vigp::Inputs<U>,
{
    let mut z = z0;
    let mut worst = (0.0f64, 0.0f64);
    for _ in 0..3 {
        for _ in 0..15 {
            z = st.step_forced(&z, u).unwrap();
        }
        let (a, b) = lie_worst(st, &z, u, 1e-6);
        worst = (worst.0.max(a), worst.1.max(b));
    }
    println!(
        "{name} maximal tangent A, B vs central differences: {:.2e}, {:.2e}",
        worst.0, worst.1
    );
    assert!(worst.0 <= 1e-6 && worst.1 <= 1e-6, "{name}: {worst:?}");
}

/// The maximal view's A and B in the tangent chart (12·links × 12·links
/// and 12·links × U) reproduce central differences through the
/// retraction to 1e-6 of their largest entry, on a loop with ball and
/// Hooke joints and on a chain, under a non-zero input, at states along a
/// forced motion (so neither rates nor multipliers vanish). Solver
/// tolerance 1e-14 and h = 1e-6: the differences' noise is then about
/// 1e-14/1e-6 = 1e-8 and their truncation h² ≈ 1e-12, both far below the
/// 1e-6 asked. Each curvature term is seen: without the constraints'
/// ½∇g·(ε × η) the four-bar's A is off by 8.5e-5, without the input's
/// curvature the arm's (elbow torque 3 N·m) by 6.4e-3.
#[test]
fn lie_stepper_tangent_derivatives_match_finite_differences() {
    use vigp::spatial::LieStepper;
    let dt = 0.01;
    let tight = crate::common::tight();
    let u = SVector::<f64, 1>::from([0.4]);

    let sys = DrivenRsur::default();
    let m = sys.minimal();
    let mut v = SVector::<f64, 6>::zeros();
    v[0] = 2.5;
    let z = consistent_state(&m, &m.reference(), &v, dt).unwrap();
    let st = LieStepper::with_options(sys.maximal(), dt, tight).unwrap();
    along_a_motion(&st, m.to_maximal(&z, dt), &u, "R-S-U-R");

    // a strong elbow torque, so that the input's curvature term matters
    let u = SVector::<f64, 1>::from([3.0]);
    let sys = DrivenBallArm::default();
    let m = sys.minimal();
    let q = SVector::<f64, 5>::from([0.9, 0.2, -0.3, 0.25, 0.7]);
    let qn = {
        let mut q = q;
        let n = q.fixed_rows::<4>(0).norm();
        for i in 0..4 {
            q[i] /= n;
        }
        q
    };
    let v = SVector::<f64, 5>::from([0.0, 0.4, -0.2, 0.3, 1.5]);
    let z = consistent_state(&m, &qn, &v, dt).unwrap();
    let st = LieStepper::with_options(sys.maximal(), dt, tight).unwrap();
    along_a_motion(&st, m.to_maximal(&z, dt), &u, "ball arm");

    // damped (ball joint 0.1, elbow 0.2 N·m·s/rad) and sprung (elbow
    // k = 1.5 N·m/rad, rest 0.2 rad) as well
    let sys = BallArm::default();
    let m = sys.minimal();
    let z = consistent_state(&m, &qn, &v, dt).unwrap();
    let st = LieStepper::with_options(sys.maximal(), dt, tight).unwrap();
    along_a_motion(&st, m.to_maximal(&z, dt), &u, "damped, sprung ball arm");
}
