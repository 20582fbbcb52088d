//! A second thread for the posterior variance of an exact GP
//! ([`Gp::set_parallel_variance`](super::Gp::set_parallel_variance)).
//!
//! One isolated prediction with variance streams each output's stored L⁻¹
//! (N²/2 numbers, 1 MB at N = 512) once; on a two-core machine one core
//! streams about 60 GB/s from the shared cache, so two outputs take twice
//! as long as one. This helper takes the variance products of some outputs
//! while the calling thread does the others. The hand-off is a counter the
//! helper spins on: after each request it spins for [`SPIN`] before it
//! parks, so a stream of predictions (a control loop, a rollout with
//! bounds) hands over in well under a microsecond, where waking a parked
//! thread (or rayon's pool from outside it) costs several microseconds.
//! The price is a core busy-waiting for up to [`SPIN`] after each
//! prediction.
//!
//! The products are the same functions on the same numbers as the
//! sequential path's, so the results are bit for bit the same.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use crate::packed;

/// How long the helper spins for the next request before it parks.
pub(crate) const SPIN: Duration = Duration::from_micros(200);

/// One variance product ‖L⁻¹k‖² for the helper.
#[derive(Default)]
pub(crate) struct Task {
    /// L⁻¹ packed by rows (`None`: no task in this slot).
    pub linv: Option<Arc<Vec<f64>>>,
    /// k, the kernel row of the query point.
    pub k: Vec<f64>,
    /// Scratch of length N.
    tmp: Vec<f64>,
    /// The result ‖L⁻¹k‖².
    pub quad: f64,
    /// Visit L⁻¹'s rows last to first next time (alternates, see
    /// [`packed::lower_matvec_dir`]).
    reverse: bool,
}

impl Task {
    fn run(&mut self) {
        if let Some(linv) = &self.linv {
            self.tmp.resize(self.k.len(), 0.0);
            packed::lower_matvec_dir(linv, &self.k, &mut self.tmp, self.reverse);
            self.reverse = !self.reverse;
            self.quad = packed::norm2(&self.tmp);
        }
    }
}

/// What the caller and the helper thread share.
struct Shared {
    tasks: Mutex<Vec<Task>>,
    /// Requests posted (a generation counter).
    posted: AtomicU64,
    /// Requests done.
    done: AtomicU64,
    quit: AtomicBool,
}

/// The helper thread (see the module docs). Dropping it stops the thread.
pub(crate) struct Helper {
    shared: Arc<Shared>,
    /// Held by the one caller using the helper at a time.
    busy: AtomicBool,
    thread: Option<JoinHandle<()>>,
}

impl core::fmt::Debug for Helper {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Helper").finish_non_exhaustive()
    }
}

impl Helper {
    /// Starts the helper thread; `None` if the system cannot start one.
    pub(crate) fn spawn() -> Option<Self> {
        let shared = Arc::new(Shared {
            tasks: Mutex::new(Vec::new()),
            posted: AtomicU64::new(0),
            done: AtomicU64::new(0),
            quit: AtomicBool::new(false),
        });
        let s = Arc::clone(&shared);
        let thread = thread::Builder::new()
            .name("vigp-variance".into())
            .spawn(move || serve(&s))
            .ok()?;
        Some(Self {
            shared,
            busy: AtomicBool::new(false),
            thread: Some(thread),
        })
    }

    /// The helper for this caller, or `None` while another caller (a clone
    /// of the model on another thread) uses it or the thread has ended.
    pub(crate) fn claim(&self) -> Option<Claim<'_>> {
        if self.thread.as_ref().is_none_or(JoinHandle::is_finished) {
            return None;
        }
        self.busy
            .compare_exchange(false, true, Ordering::Acquire, Ordering::Relaxed)
            .ok()?;
        Some(Claim { helper: self })
    }
}

impl Drop for Helper {
    fn drop(&mut self) {
        self.shared.quit.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            t.thread().unpark();
            let _ = t.join();
        }
    }
}

/// One caller's use of the helper: fill the tasks, [`post`](Claim::post),
/// do the caller's own share, [`wait`](Claim::wait) for the results.
pub(crate) struct Claim<'a> {
    helper: &'a Helper,
}

impl Claim<'_> {
    /// The task slots, to fill before [`post`](Claim::post) (resize as
    /// needed; the buffers are kept for the next request).
    pub(crate) fn tasks(&self) -> MutexGuard<'_, Vec<Task>> {
        lock(&self.helper.shared.tasks)
    }

    /// Hands the filled tasks to the helper; returns the request's number.
    pub(crate) fn post(&self) -> u64 {
        let g = self.helper.shared.posted.fetch_add(1, Ordering::AcqRel) + 1;
        if let Some(t) = &self.helper.thread {
            t.thread().unpark();
        }
        g
    }

    /// Waits for request `g` and returns the tasks with their results. If
    /// the helper thread has ended, runs the tasks on this thread.
    pub(crate) fn wait(&self, g: u64) -> MutexGuard<'_, Vec<Task>> {
        let shared = &self.helper.shared;
        let mut spins = 0u32;
        while shared.done.load(Ordering::Acquire) < g {
            spins = spins.wrapping_add(1);
            if spins % 1024 == 0 {
                if self
                    .helper
                    .thread
                    .as_ref()
                    .is_none_or(JoinHandle::is_finished)
                {
                    let mut tasks = lock(&shared.tasks);
                    tasks.iter_mut().for_each(Task::run);
                    return tasks;
                }
                thread::yield_now();
            }
            std::hint::spin_loop();
        }
        lock(&shared.tasks)
    }
}

impl Drop for Claim<'_> {
    fn drop(&mut self) {
        // no lingering reference to a model's L⁻¹ (an online update of the
        // model would otherwise copy it)
        for t in lock(&self.helper.shared.tasks).iter_mut() {
            t.linv = None;
        }
        self.helper.busy.store(false, Ordering::Release);
    }
}

/// The mutex's contents even if a panic poisoned it (the tasks hold plain
/// numbers, valid whatever the interrupted code did).
fn lock(m: &Mutex<Vec<Task>>) -> MutexGuard<'_, Vec<Task>> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The helper thread's loop: spin for a request, run it, report it.
fn serve(shared: &Shared) {
    let mut seen = 0u64;
    loop {
        let idle = Instant::now();
        let g = loop {
            if shared.quit.load(Ordering::Acquire) {
                return;
            }
            let g = shared.posted.load(Ordering::Acquire);
            if g != seen {
                break g;
            }
            if idle.elapsed() > SPIN {
                thread::park_timeout(Duration::from_millis(50));
            } else {
                std::hint::spin_loop();
            }
        };
        lock(&shared.tasks).iter_mut().for_each(Task::run);
        seen = g;
        shared.done.store(g, Ordering::Release);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A packed lower-triangular n × n matrix with entries of both signs.
    fn packed(n: usize, seed: f64) -> Vec<f64> {
        (0..n * (n + 1) / 2)
            .map(|i| ((i as f64 + seed) * 0.618_033_988_7).fract() - 0.4)
            .collect()
    }

    #[test]
    fn the_helper_computes_what_the_caller_would_and_serves_one_caller() {
        let n = 300;
        let helper = Helper::spawn().expect("a thread");
        let mats: Vec<Arc<Vec<f64>>> = (0..3).map(|s| Arc::new(packed(n, s as f64))).collect();
        for round in 0..50 {
            let k: Vec<f64> = (0..n).map(|i| ((i + round) as f64 * 0.37).sin()).collect();
            let claim = helper.claim().expect("free");
            assert!(helper.claim().is_none(), "one caller at a time");
            {
                let mut tasks = claim.tasks();
                tasks.resize_with(3, Task::default);
                for (t, m) in tasks.iter_mut().zip(&mats) {
                    t.linv = Some(Arc::clone(m));
                    t.k.clear();
                    t.k.extend_from_slice(&k);
                }
            }
            let g = claim.post();
            let tasks = claim.wait(g);
            for (t, m) in tasks.iter().zip(&mats) {
                let mut tmp = vec![0.0; n];
                packed::lower_matvec_dir(m, &k, &mut tmp, false);
                assert_eq!(t.quad.to_bits(), packed::norm2(&tmp).to_bits());
            }
            drop(tasks);
            drop(claim);
            // the claim released the matrices
            assert!(mats.iter().all(|m| Arc::strong_count(m) == 1));
        }
        // after a pause longer than the spin the parked helper still answers
        thread::sleep(SPIN * 5);
        let claim = helper.claim().expect("free again");
        {
            let mut tasks = claim.tasks();
            tasks.truncate(1);
            tasks[0].linv = Some(Arc::clone(&mats[0]));
            tasks[0].k = vec![1.0; n];
        }
        let g = claim.post();
        assert!(claim.wait(g)[0].quad > 0.0);
    }
}
