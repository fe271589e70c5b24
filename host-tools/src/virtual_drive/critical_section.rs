//! The critical section the drive application takes (the `critical-section` crate), for the
//! host: a lock held by one thread at a time, re-entrant within it.
//!
//! Not the crate's own `std` feature: enabling it in this workspace would also give the drive
//! application's tests that implementation (Cargo unifies features), where they install
//! their own, which measures how long the link side holds the section.

use std::sync::atomic::{AtomicUsize, Ordering};

/// The holder's token (an address unique to its thread), 0 when free.
static HOLDER: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    static TOKEN: u8 = const { 0 };
}

fn this_thread() -> usize {
    TOKEN.with(|t| t as *const u8 as usize)
}

struct HostCriticalSection;
critical_section::set_impl!(HostCriticalSection);

// SAFETY: `acquire` returns only once this thread holds the lock (or already held it: then
// it says so, and the matching `release` leaves it held); `release` frees it only for the
// outermost acquisition.
unsafe impl critical_section::Impl for HostCriticalSection {
    unsafe fn acquire() -> critical_section::RawRestoreState {
        let me = this_thread();
        if HOLDER.load(Ordering::Acquire) == me {
            return true;
        }
        while HOLDER.compare_exchange_weak(0, me, Ordering::Acquire, Ordering::Relaxed).is_err() {
            std::thread::yield_now();
        }
        false
    }

    unsafe fn release(nested: critical_section::RawRestoreState) {
        if !nested {
            HOLDER.store(0, Ordering::Release);
        }
    }
}
