//! Per-thread solver scratch for the std integrators.
//!
//! [`crate::Variational::step`] is a step from a state: without a kept
//! workspace every call would zero the fixed-size solver's scratch
//! ([`vigp_core::StepWorkspace`], 24 KB for 12 coordinates, a sixth of
//! a maximal-coordinate step). Each thread keeps one workspace per workspace
//! type (one per coordinate count and constraint count) here, allocated on
//! the thread's first step of that size and reused afterwards, so that
//! `Variational` stays `Copy`, `Send` and `Sync` and its steps need no
//! `&mut`. A workspace holds no result between calls: the step resets what
//! it reads (`StepWorkspace::reset`), and the state equals a
//! step in a fresh workspace bit for bit.

use std::any::Any;
use std::cell::RefCell;

/// Workspaces from this size on are kept; smaller ones are zeroed about as
/// fast as a kept one is fetched. Measured with `cargo bench --bench step`
/// (std steps from a state, 2026-11-24): fetching costs ≈ 20–50 ns, which
/// made the 250-byte workspace of the two-coordinate double pendulum's
/// 160 ns step 30 % slower and left the 1.5 KB one of the minimal fourbar
/// 2 % slower, while the 4 KB ones of the maximal double pendulum and
/// cartpole gained 8–11 % and the 24 KB one of the maximal fourbar 12 %.
const KEEP_FROM_BYTES: usize = 2048;

thread_local! {
    // a handful of entries at most (one per mechanism size a thread steps)
    static KEPT: RefCell<Vec<Box<dyn Any>>> = const { RefCell::new(Vec::new()) };
}

/// Run `f` on this thread's kept `W` (`Some`) when `W` is large enough to
/// be worth keeping and the `std` feature is on, else on nothing (`None`:
/// the caller steps in a fresh workspace). The one place that decides.
#[inline(always)]
pub(crate) fn with_workspace<W: Any + Default, R>(f: impl FnOnce(Option<&mut W>) -> R) -> R {
    if cfg!(feature = "std") && size_of::<W>() >= KEEP_FROM_BYTES {
        with_kept(|w| f(Some(w)))
    } else {
        f(None)
    }
}

/// Run `f` on this thread's kept `W`, creating it on first use. The
/// workspace is taken out for the call and put back after it, so a step
/// called from inside a step (or during the thread's teardown) runs on a
/// fresh `W` instead: the same result, only slower.
fn with_kept<W: Any + Default, R>(f: impl FnOnce(&mut W) -> R) -> R {
    let taken = KEPT
        .try_with(|cell| {
            let mut all = cell.try_borrow_mut().ok()?;
            let i = all.iter().position(|w| w.is::<W>())?;
            Some(all.swap_remove(i))
        })
        .ok()
        .flatten();
    let mut w: Box<W> = taken.and_then(|w| w.downcast().ok()).unwrap_or_default();
    let r = f(&mut w);
    // back in its place (no reallocation: the slot was there); it replaces
    // the one a nested call may have put there meanwhile
    let _ = KEPT.try_with(|cell| {
        if let Ok(mut all) = cell.try_borrow_mut() {
            match all.iter().position(|x| x.is::<W>()) {
                Some(i) => all[i] = w,
                None => all.push(w),
            }
        }
    });
    r
}

#[cfg(test)]
mod tests {
    use super::with_kept;

    #[derive(Default)]
    struct Counter(u32);

    #[test]
    fn a_thread_keeps_one_workspace_per_type_and_nested_calls_get_a_fresh_one() {
        assert_eq!(
            with_kept(|c: &mut Counter| {
                c.0 += 1;
                c.0
            }),
            1
        );
        assert_eq!(
            with_kept(|c: &mut Counter| {
                c.0 += 1;
                c.0
            }),
            2
        );
        // another type: its own workspace
        assert_eq!(
            with_kept(|v: &mut Vec<u8>| {
                v.push(1);
                v.len()
            }),
            1
        );
        // nested: the outer call holds the kept one, the inner gets a fresh one
        let inner = with_kept(|c: &mut Counter| {
            c.0 += 1;
            with_kept(|d: &mut Counter| {
                d.0 += 1;
                d.0
            })
        });
        assert_eq!(inner, 1);
        assert_eq!(with_kept(|c: &mut Counter| c.0), 3);
        // another thread starts from its own
        let other = std::thread::spawn(|| {
            with_kept(|c: &mut Counter| {
                c.0 += 1;
                c.0
            })
        })
        .join()
        .unwrap();
        assert_eq!(other, 1);
    }
}
