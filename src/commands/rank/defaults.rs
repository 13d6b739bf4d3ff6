//! `rank`'s flags as [`runner::defaults::Asked`]: the task's defaults are resolved in the
//! run layer (`runner::defaults`), from `checkpoints/<task>/` and its `rank.toml`.

use std::path::Path;

use anyhow::Result;
use harness::task::Task;
pub use runner::defaults::Resolved;

use crate::cli::RankArgs;

/// Resolves `a` for `task` from the shipped folder `root/<task>` (`checkpoints`), with the
/// global `--render-workers` when it was given.
///
/// # Errors
/// An unreadable or invalid `rank.toml`, naming it.
pub fn resolve_with(
    a: &RankArgs,
    render_workers: Option<usize>,
    task: &dyn Task,
    root: &Path,
) -> Result<Resolved> {
    let asked = runner::defaults::Asked {
        policies: a.policies.clone(),
        world_model: a.world_model.clone(),
        judge: a.judge.clone(),
        episodes: a.episodes,
        max_steps: a.max_steps,
        processes: a.processes,
        shard: a.shard.is_some(),
        render_workers,
    };
    Ok(runner::defaults::resolve(&asked, task, root)?)
}
