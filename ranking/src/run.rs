//! `rank` from its arguments: the flags checked, the task loaded and its defaults resolved,
//! then the run made in this process ([`crate::one`]) or in shard processes
//! ([`crate::processes`]); and `rank-shard FILE`, one shard process's side.

use std::path::Path;
use std::process::ExitCode;

use harness::task::Task;
use runner::defaults::Resolved;

use crate::args::RankArgs;
use crate::error::{Context, RankError};
use crate::one::{Caller, run_with};
use crate::processes;

type Result<T, E = RankError> = std::result::Result<T, E>;

/// `evalharness rank`: the run `a` asks for, in this process or in shard processes; its exit
/// code says whether the gates passed. `render_workers` is the global `--render-workers` when
/// given (the binary started them); otherwise the task's `rank.toml` may ask for some, which
/// are this program started again as `evalharness -q render-worker`.
///
/// # Errors
/// A flag or input refused, or what the run layer, the engine, the task or a shard process
/// reports, in context.
pub fn run(a: &RankArgs, render_workers: Option<usize>, caller: &Caller<'_>) -> Result<ExitCode> {
    match (a.processes, &a.shard) {
        (Some(0), _) => runner::refuse!("--processes 0: must be at least 1"),
        (Some(n), Some(_)) if n > 1 => {
            runner::refuse!("--processes {n} runs the shards itself: give it without --shard")
        }
        _ => {}
    }
    // Every input is checked before the output folder is touched.
    let task =
        scenarios::load_task(&a.scenario).with_context(|| format!("loading scenario {}", a.scenario))?;
    let r = resolve(a, render_workers, task.as_ref(), Path::new("checkpoints"))?;
    let missing = r.missing(&a.scenario);
    if !missing.is_empty() {
        runner::refuse!("--scenario {}: missing inputs:\n  {}", a.scenario, missing.join("\n  "));
    }
    if r.processes > 1 {
        return processes::run(a, task, &r, caller);
    }
    // The task's default render workers (a one-process run); the global flag, when
    // given, started them (or not) already.
    if r.render_workers > 0 && render_workers.is_none() {
        let exe = std::env::current_exe().context("finding this program to start its render workers")?;
        scenarios::robosuite::render_pool::start(&exe, &RENDER_WORKER_COMMAND, r.render_workers)
            .with_context(|| format!("--render-workers {} (the task's rank.toml)", r.render_workers))?;
    }
    run_with(a, task, &r, caller, None)
}

/// This program's command line of a render worker process (the binary's hidden
/// `render-worker` command).
pub const RENDER_WORKER_COMMAND: [&str; 2] = ["-q", "render-worker"];

/// `a`'s flags as [`runner::defaults::Asked`], resolved for `task` from the shipped folder
/// `root/<task>` (`checkpoints`) and its `rank.toml`, with the global `--render-workers` when
/// it was given.
///
/// # Errors
/// An unreadable or invalid `rank.toml`, naming it.
pub fn resolve(
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

/// `evalharness rank-shard FILE`: one shard process of `rank --processes`, its
/// arguments read from the file its parent wrote.
///
/// # Errors
/// A file that cannot be read or is not `rank`'s arguments (naming it), or what the
/// shard's run returns.
pub fn run_shard(file: &Path, render_workers: Option<usize>, caller: &Caller<'_>) -> Result<ExitCode> {
    let text = std::fs::read_to_string(file).with_context(|| format!("reading {}", file.display()))?;
    let args: RankArgs = serde_json::from_str(&text)
        .with_context(|| format!("{}: not a rank shard's arguments", file.display()))?;
    if args.shard.is_none() {
        runner::refuse!("{}: not a rank shard's arguments (no shard)", file.display());
    }
    run(&args, render_workers, caller)
}
