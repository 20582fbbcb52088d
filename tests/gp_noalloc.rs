//! `Gp::predict_into` and `Gp::predict_mean_into` do not allocate once the
//! model and workspace exist, for exact and sparse (SGPR) models, and with
//! the parallel variance's helper thread. A counting global allocator in this test
//! binary (its own process) observes every allocation; the test is the only
//! one in the binary, so no other thread allocates meanwhile.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use vigp::gp::{Gp, Method, PriorMean, SparseOptions, TrainOptions};

struct Counting;

static ALLOCS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator, only counting calls.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::SeqCst);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::SeqCst);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn single_point_prediction_does_not_allocate() {
    let (x, y) = data(100);
    let methods = [Method::Exact, Method::Sparse(SparseOptions::kmeans(20))];
    check(&x, &y, methods, 1);
    // N ≥ PARALLEL_VARIANCE_MIN_N with the default sequential variance
    let (x, y) = data(vigp::gp::PARALLEL_VARIANCE_MIN_N + 4);
    check(&x, &y, [Method::Exact], 0);
    // and with the opt-in parallel variance (a helper thread): after the
    // first call, which sizes the helper's buffers, neither thread allocates
    let (mut gp, _) = Gp::train(
        &x,
        2,
        &y,
        2,
        &TrainOptions {
            restarts: 0,
            ..Default::default()
        },
    )
    .unwrap();
    gp.set_parallel_variance(true);
    let mut ws = gp.workspace();
    let (mut m, mut v) = ([0.0; 2], [0.0; 2]);
    gp.predict_into(&[0.3, 0.2], &mut m, &mut v, &mut ws)
        .unwrap();
    let before = ALLOCS.load(Ordering::SeqCst);
    for i in 0..1000 {
        let q = [(i as f64 * 0.01).sin(), 0.5];
        gp.predict_into(&q, &mut m, &mut v, &mut ws).unwrap();
        assert!(v[0] >= 0.0 && v[1] >= 0.0);
    }
    assert_eq!(ALLOCS.load(Ordering::SeqCst) - before, 0);
}

/// n points on [−1, 1]² (d = 2) and two smooth targets (p = 2).
fn data(n: usize) -> (Vec<f64>, Vec<f64>) {
    let x: Vec<f64> = (0..n)
        .flat_map(|i| [(i as f64 * 0.37).sin(), (i as f64 * 0.11).cos()])
        .collect();
    let y: Vec<f64> = x
        .chunks(2)
        .flat_map(|r| [r[0] * r[1], r[0] - r[1]])
        .collect();
    (x, y)
}

fn check<const K: usize>(x: &[f64], y: &[f64], methods: [Method; K], restarts: usize) {
    for (mean, method) in [
        PriorMean::Constant,
        PriorMean::Zero,
        PriorMean::function(|x, m| {
            m[0] = x[0];
            m[1] = 0.0;
        }),
    ]
    .into_iter()
    .flat_map(|m| methods.clone().map(|method| (m.clone(), method)))
    {
        let opts = TrainOptions {
            mean,
            method,
            restarts,
            ..Default::default()
        };
        let (gp, _) = Gp::train(x, 2, y, 2, &opts).unwrap();
        let mut ws = gp.workspace();
        let (mut m, mut v) = ([0.0; 2], [0.0; 2]);
        let before = ALLOCS.load(Ordering::SeqCst);
        let mut acc = 0.0;
        for i in 0..1000 {
            let q = [(i as f64 * 0.01).sin(), 0.5];
            gp.predict_into(&q, &mut m, &mut v, &mut ws).unwrap();
            acc += m[0] + v[1];
            gp.predict_mean_into(&q, &mut m, &mut ws).unwrap();
            acc += m[1];
        }
        let after = ALLOCS.load(Ordering::SeqCst);
        assert!(acc.is_finite());
        assert_eq!(
            after - before,
            0,
            "predict_into allocated {} times",
            after - before
        );
        // The counter works: a batch prediction does allocate.
        let _ = gp.predict(&[0.1, 0.2]).unwrap();
        assert!(ALLOCS.load(Ordering::SeqCst) > after);
    }
}
