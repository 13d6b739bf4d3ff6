//! Starting `--render-workers`: this program, run as `evalharness render-worker`, N
//! times (`scenarios::robosuite::render_pool` renders Lift's and Can's frames there).

use anyhow::{Context, Result};

/// Starts `n` render workers for the rest of this process.
///
/// # Errors
/// This program's path cannot be found, or a worker cannot be started.
pub fn start(n: usize) -> Result<()> {
    let exe = std::env::current_exe().context("finding this program to start its render workers")?;
    scenarios::robosuite::render_pool::start(&exe, &["-q", "render-worker"], n)
        .with_context(|| format!("--render-workers {n}"))
}
