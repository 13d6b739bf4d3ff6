//! Starting `--render-workers`: this program, run as `evalharness render-worker`, N
//! times (`scenarios::robosuite::render_pool` renders Lift's and Can's frames there).

use anyhow::{Context, Result};

/// Starts `n` render workers for the rest of this process.
///
/// # Errors
/// This program's path cannot be found, or a worker cannot be started.
pub fn start(n: usize) -> Result<()> {
    let exe = std::env::current_exe().context("finding this program to start its render workers")?;
    scenarios::robosuite::render_pool::start(&exe, &ranking::run::RENDER_WORKER_COMMAND, n)
        .with_context(|| format!("--render-workers {n}"))
}

/// Ends the render workers, if any were started: each is waited for, so none outlives this
/// process and their CPU time counts as this process's children's (what `/usr/bin/time`
/// reports). A worker that failed is a warning: the results are already written.
pub fn stop() {
    if let Err(e) = scenarios::robosuite::render_pool::stop() {
        tracing::warn!("{e}");
    }
}
