//! Steps of the nominal integrator and the projections run without heap
//! allocation (fixed sizes only), as firmware-style callers need.

use nalgebra::SVector;
use vigp::prelude::*;
use vigp::projection::{consistent_state, project_velocity};
use vigp::systems::{DoublePendulum, Fourbar};

#[test]
fn variational_steps_do_not_allocate() {
    let dp = Variational::new(DoublePendulum::default().minimal(), 0.01).unwrap();
    let mut z = State::new([1.0, 0.3], [0.0, 0.0]);
    let info = allocation_counter::measure(|| {
        for _ in 0..100 {
            z = dp.step(&z).unwrap();
        }
    });
    assert_eq!(info.count_total, 0, "double pendulum steps allocated");

    let fb = Fourbar::default().minimal();
    let z0 = consistent_state(
        &fb,
        &SVector::from([0.9, -1.3, -0.4, 1.3]),
        &SVector::zeros(),
        0.01,
    )
    .unwrap();
    let vi = Variational::new(fb, 0.01).unwrap();
    let mut out = [z0; 50];
    let info = allocation_counter::measure(|| {
        vi.rollout_into(&z0, &mut out).unwrap();
        let _ = project_velocity(
            &fb,
            &out[49].q,
            &SVector::from([0.1, 0.2, 0.3, 0.4]),
            0.01,
            &StepOptions::default(),
        )
        .unwrap();
    });
    assert_eq!(
        info.count_total, 0,
        "fourbar rollout_into / projection allocated"
    );

    // std steps from a state in maximal coordinates keep their 24 KB
    // workspace per thread: the thread's first step of that size allocates
    // it, once; the steps after it do not allocate
    use vigp::Coordinates;
    let fbm = Variational::new(Fourbar::default().maximal(), 0.01).unwrap();
    let zf = Fourbar::default().minimal().to_maximal(&z0, 0.01);
    let first = allocation_counter::measure(|| {
        fbm.step(&zf).unwrap();
    });
    // (one allocation or two: the box, and the thread's list of them on its
    // first use; none would mean the step no longer keeps its workspace)
    assert!(
        (1..=2).contains(&first.count_total),
        "first step: {first:?}"
    );
    let info = allocation_counter::measure(|| {
        for _ in 0..10 {
            fbm.step(&zf).unwrap();
        }
    });
    assert_eq!(info.count_total, 0, "maximal fourbar std steps allocated");

    // the fixed-size core engine: the midpoint rule with sub-steps in
    // minimal coordinates, both rules in maximal coordinates (4 joint
    // constraints), and the fourth-order composition
    use vigp::embedded::{Composition, Stepper};
    let sys = DoublePendulum::default();
    let zm = State::new([1.0, 0.3], [0.0, 0.0]);
    let zx = sys.minimal().to_maximal(&zm, 0.01);
    let mid = Stepper::midpoint(sys.minimal(), 0.01)
        .and_then(|s| s.substeps(2))
        .unwrap();
    let max1 = Stepper::new(sys.maximal(), 0.01).unwrap();
    let max2 = Stepper::midpoint(sys.maximal(), 0.01).unwrap();
    let c4 = Composition::new(sys.minimal(), 0.01).unwrap();
    let mut outm = [zm; 20];
    let mut outx = [zx; 20];
    let mut ws = vigp::embedded::StepWorkspace::new();
    let info = allocation_counter::measure(|| {
        mid.rollout_into(&zm, &mut outm).unwrap();
        max1.rollout_into(&zx, &mut outx).unwrap();
        max2.rollout_into(&zx, &mut outx).unwrap();
        c4.steps_into(&zm, &mut outm).unwrap();
        // steps from states in a kept workspace
        for z in &outx[..10] {
            max1.step_in(z, &mut ws).unwrap();
        }
    });
    assert_eq!(
        info.count_total, 0,
        "midpoint / maximal / fourth-order fixed-size steps allocated"
    );
    assert!(outx[19].q.iter().all(|x| x.is_finite()));

    // the counter does see allocations
    let info = allocation_counter::measure(|| {
        let _ = vi.rollout(&z0, 3).unwrap();
    });
    assert!(info.count_total > 0);
}
