//! Cooperative stop for long jobs (training runs).
//!
//! The binary routes Ctrl-C and SIGTERM to [`flag`]; a trainer polls [`requested`]
//! between steps, like its `--max-minutes` deadline, so an interrupted run
//! finishes the step in progress, saves its checkpoint and provenance, and can be
//! continued with `--resume` — instead of losing everything since the last
//! periodic checkpoint. A second Ctrl-C exits at once (the binary arranges that).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

static FLAG: OnceLock<Arc<AtomicBool>> = OnceLock::new();

/// The process-wide stop flag, for signal handlers to set.
pub fn flag() -> Arc<AtomicBool> {
    FLAG.get_or_init(|| Arc::new(AtomicBool::new(false))).clone()
}

/// Whether a stop was requested.
pub fn requested() -> bool {
    FLAG.get().is_some_and(|f| f.load(Ordering::Relaxed))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn setting_the_shared_flag_is_seen_by_requested() {
        let f = flag();
        assert!(Arc::ptr_eq(&f, &flag()), "one flag per process");
        f.store(true, Ordering::Relaxed);
        assert!(requested());
        f.store(false, Ordering::Relaxed);
        assert!(!requested());
    }
}
