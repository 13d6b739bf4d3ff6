//! `rank --processes N`: one run split into N `rank --shard i/N --jobs 1` processes
//! running at once, joined with `merge`, then finished as one run (`--resume` over the
//! joined rows runs no batch and writes the report, the table and the gates).
//!
//! Why processes and not threads: Lift's and Can's frames come from MuJoCo's GL
//! renderer on Mesa's llvmpipe, which lets one thread of a process render at a time
//! (two at once crashed it; `scenarios::robosuite::episode`), so `--jobs` workers of
//! one process wait on each other's frames. Processes do not share the renderer. On
//! the Can CI size (9 policies × 20 episodes × 250 steps) three processes took 13.4
//! minutes where one took about 27 (BENCHMARKS.md, 2026-11-27). The rows are those of
//! one process, byte for byte (merge's contract).
//!
//! The shards are this program started again as `evalharness -q --render-workers 0
//! rank-shard FILE` ([`SHARD_COMMAND`]): the binary's hidden command that hands the file to
//! [`run_shard`].
//!
//! The shards share one claims folder (`OUT.shards/claims`, [`runner::claims`]): each
//! runs the next batch no shard has claimed, so a shard that drew short episodes takes
//! more batches instead of waiting for the others.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitCode, Stdio};
use std::time::{Duration, Instant};

use harness::results::RunTiming;
use harness::task::Task;
use runner::defaults::Resolved;
use runner::progress;

use crate::args::RankArgs;
use crate::error::{Context, RankError};
use crate::one::{Caller, PARENT_ENV, run_with};

type Result<T, E = RankError> = std::result::Result<T, E>;

/// Runs `a` (for `task`, resolved as `r`, its inputs found) as `r.processes` shard
/// processes, joins them into `a.out` and finishes the run there. The shards' folders
/// (`OUT.shards/shard-i`, with each one's stderr in `shard-i.log`) are removed once the
/// run is complete; an interrupted run keeps them, and the same command with `--resume`
/// continues each.
///
/// # Errors
/// An `--out` that exists without `--force` or `--resume`, a shard
/// that failed (exit 2 or a signal; its log's last lines are quoted), or what `merge`
/// and the finishing run report.
pub(crate) fn run(a: &RankArgs, task: Box<dyn Task>, r: &Resolved, caller: &Caller<'_>) -> Result<ExitCode> {
    let started = Instant::now();
    let parts = shards_folder(&a.out);
    // The whole run writes `--out` (and its shards beside it): its inputs are checked
    // and it is locked first, as any output is.
    let _lock = runner::output::Inputs::new()
        .scenario(&a.scenario)
        .add("--policies", &r.policies)
        .world_model("--world-model", &r.world_model)
        .maybe("--judge", r.judge.as_deref())
        .claim(&a.out, ".shards")?;
    if a.out.exists() && !a.force && !a.resume {
        runner::refuse!(
            "--out {} exists: pass --force to replace it or --resume to continue it",
            a.out.display()
        );
    }
    // Resuming a run that has rows but no shards (finished, or run in one process): the
    // one-process path continues it, checking every setting against its config.json
    // first, so a resume under other settings is refused, never run over it.
    if a.resume && a.out.join("episodes.jsonl").is_file() && std::fs::symlink_metadata(&parts).is_err() {
        tracing::info!("{} has no shards to resume; continuing it in this process", a.out.display());
        let mut one = a.clone();
        one.processes = Some(1);
        return run_with(&one, task, r, caller, None);
    }
    let dirs = policies::dir::checkpoint_dirs(&r.policies)?;
    let total = dirs.len() * r.episodes;
    // No more processes than batches: a shard without a batch would only start up.
    let batches = dirs.len() * r.episodes.div_ceil(a.batch.max(1));
    let n = r.processes.min(batches.max(1));
    if n < r.processes {
        tracing::info!("--processes {}: the run has {batches} batches, so {n} processes", r.processes);
    }
    if a.resume {
        check_split(&parts, n)?;
    }
    // `OUT.shards` is the tool's own folder: a user's folder of that name is refused, never cleared.
    runner::output::make_owned(&parts, "the shards of a `rank --processes` run", false)?;
    // A fresh run's shards start empty (`--force`), so claims left by an interrupted
    // one would hold batches nobody runs; a resumed run keeps them for their shards.
    let claims = parts.join("claims");
    if !a.resume && claims.exists() {
        std::fs::remove_dir_all(&claims)
            .with_context(|| format!("removing the old claims {}", claims.display()))?;
    }
    let exe = std::env::current_exe().context("finding this program to start the shard processes")?;
    let mut shards = Vec::with_capacity(n);
    for i in 0..n {
        let dir = parts.join(format!("shard-{i}"));
        let log = parts.join(format!("shard-{i}.log"));
        let resume = a.resume && dir.exists();
        let mut shard = Shard { i, dir, log, child: None, restarted: false };
        shard.start(&exe, a, n, resume, false)?;
        shards.push(shard);
    }
    let pb = progress::bar(total as u64, "rank", caller.invocation.quiet);
    let failed = wait_all(&mut shards, &exe, a, n, &pb)?;
    pb.finish_and_clear();
    if let Some((i, why)) = failed {
        let s = &shards[i];
        let log = tail(&s.log);
        // Nothing to resume (no shard finished a batch): the shards' folder goes, so
        // the corrected command runs as a fresh one.
        if shards.iter().all(|s| count_lines(&s.dir.join("episodes.jsonl")) == 0) {
            let _ = std::fs::remove_dir_all(&parts);
            let log = format!("before any batch was done; its log ended:\n{log}");
            return Err(RankError::Shard { index: i, count: n, why, log });
        }
        let log = format!("its folder is {}, its log {} ends:\n{log}", s.dir.display(), s.log.display());
        return Err(RankError::Shard { index: i, count: n, why, log });
    }
    let dirs: Vec<PathBuf> = shards.iter().map(|s| s.dir.clone()).collect();
    // The shards' thread times, summed by merge; the wall clock is this command's.
    let (_, summed) = runner::merge::join(&dirs, &a.out, true, true, false)?;
    // The frames each shard kept for the filmstrips, for the finishing run to pick from.
    runner::media::kept::gather(&dirs, &a.out)?;
    let timing = RunTiming {
        wall_seconds: started.elapsed().as_secs_f64(),
        note: format!(
            "{n} shard processes at once: wall clock of the whole run, thread times summed over the \
             shards (each a task's elapsed time, so with more processes than cores it includes waits for a core)"
        ),
        ..summed
    };
    let mut whole = a.clone();
    (whole.processes, whole.resume, whole.force) = (Some(1), true, false);
    let code = run_with(&whole, task, r, caller, Some(timing))?;
    std::fs::remove_dir_all(&parts)
        .with_context(|| format!("removing the joined shards {}", parts.display()))?;
    Ok(code)
}

/// Refuses to resume shards split another way: a shard resumed as `i/m` over rows of
/// `i/n` would be refused by its own settings check, which says `--force` (and would
/// throw away finished batches); this names the count to resume with instead.
///
/// # Errors
/// A saved split of another count.
fn check_split(parts: &Path, n: usize) -> Result<()> {
    let saved = runner::shards::saved_split(&parts.join("shard-0").join("config.json"));
    match saved {
        Some(k) if k != n => runner::refuse!(
            "--resume: {} holds a run split into {k} processes, and this one would be {n}; \
             resume with --processes {k} (the shards keep their finished batches)",
            parts.display()
        ),
        _ => Ok(()),
    }
}

/// Where the shards of a run into `out` go: `OUT.shards` beside it.
pub fn shards_folder(out: &Path) -> PathBuf {
    let mut name = out.file_name().map_or_else(|| OsString::from("rank"), ToOwned::to_owned);
    name.push(".shards");
    out.with_file_name(name)
}

/// One shard process: its folder, its stderr log and, while it runs, the child.
struct Shard {
    i: usize,
    dir: PathBuf,
    log: PathBuf,
    child: Option<Child>,
    restarted: bool,
}

impl Shard {
    /// Starts (or, `again`, restarts) the shard: `--resume` when `resume`, else `--force`.
    fn start(&mut self, exe: &Path, a: &RankArgs, n: usize, resume: bool, again: bool) -> Result<()> {
        let log = std::fs::OpenOptions::new()
            .create(true)
            .write(true)
            .append(again)
            .truncate(!again)
            .open(&self.log)
            .with_context(|| format!("opening {}", self.log.display()))?;
        // The shard's arguments, typed, in a file beside its folder: every setting of the
        // run reaches it as the struct it is (no command line rebuilt flag by flag).
        let file = shard_file(&self.dir);
        let text = serde_json::to_string_pretty(&shard_args(a, self.i, n, &self.dir, resume))?;
        harness::runfile::write_atomic(&file, &text)?;
        // A shard renders its own frames: the processes are the parallelism.
        let child = Command::new(exe)
            .args(SHARD_COMMAND)
            .arg(&file)
            .env(PARENT_ENV, std::process::id().to_string())
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .with_context(|| format!("starting shard {}/{n} ({})", self.i, exe.display()))?;
        self.child = Some(child);
        Ok(())
    }
}

/// This program's command line of a shard process, before its arguments' file: quiet, its
/// frames rendered by itself (the processes are the parallelism), the hidden `rank-shard`.
pub const SHARD_COMMAND: [&str; 4] = ["-q", "--render-workers", "0", "rank-shard"];

/// Waits for every shard, counting their episodes on `pb` (each `episodes.jsonl` row is
/// one branch of one episode). A shard killed by a signal (a crash inside the system's
/// GL driver, say) keeps its finished batches and is resumed once. A shard that ends with
/// exit 2 or more, or by a signal again, stops the others (their finished batches stay;
/// `--resume` continues them) and is returned with why. Exit 1 (rows written, but a
/// policy failed or the shard held fewer than two policies) counts as done: the joined
/// run reports it.
fn wait_all(
    shards: &mut [Shard],
    exe: &Path,
    a: &RankArgs,
    n: usize,
    pb: &indicatif::ProgressBar,
) -> Result<Option<(usize, String)>> {
    let mut failed = None;
    while failed.is_none() && shards.iter().any(|s| s.child.is_some()) {
        for s in shards.iter_mut() {
            let Some(child) = s.child.as_mut() else { continue };
            let Some(status) = child.try_wait().with_context(|| format!("waiting for shard {}", s.i))? else {
                continue;
            };
            s.child = None;
            match status.code() {
                Some(0 | 1) => {}
                None if !s.restarted => {
                    tracing::warn!("shard {}/{n} ended with {status}; resuming it once", s.i);
                    s.restarted = true;
                    s.start(exe, a, n, true, true)?;
                }
                _ => {
                    failed = Some((s.i, format!("ended with {status}")));
                    break;
                }
            }
        }
        // The rows are counted only for a bar that shows.
        if !pb.is_hidden() {
            let rows: u64 = shards.iter().map(|s| count_lines(&s.dir.join("episodes.jsonl"))).sum();
            pb.set_position(rows / 2);
        }
        std::thread::sleep(Duration::from_millis(300));
    }
    for s in shards.iter_mut() {
        if let Some(mut child) = s.child.take() {
            // Already gone is fine: the wait reaps it either way.
            let _ = child.kill();
            child.wait().with_context(|| format!("waiting for shard {}", s.i))?;
        }
    }
    Ok(failed)
}

/// Lines in `path` (0 when it is not there yet).
fn count_lines(path: &Path) -> u64 {
    std::fs::read(path).map_or(0, |b| b.iter().filter(|&&c| c == b'\n').count() as u64)
}

/// The last 20 lines of a shard's log.
fn tail(log: &Path) -> String {
    let text = std::fs::read_to_string(log).unwrap_or_default();
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(20)..].join("\n")
}

/// The file of shard `dir`'s arguments: `OUT.shards/shard-I.args.json`.
pub fn shard_file(dir: &Path) -> PathBuf {
    let mut name = dir.file_name().map_or_else(|| OsString::from("shard"), ToOwned::to_owned);
    name.push(".args.json");
    dir.with_file_name(name)
}

/// The arguments of shard `i` of `n` into `dir`: every setting of the run (the
/// finishing `--resume` refuses the joined rows if one differed; a field `rank` gains
/// reaches the shards by this struct update without being named here), one worker, its
/// shard and the shards' shared claims folder, no processes of its own, no report and
/// no gates (they belong to the whole run); `--resume` or `--force`.
pub fn shard_args(a: &RankArgs, i: usize, n: usize, dir: &Path, resume: bool) -> RankArgs {
    let claims = dir.parent().map_or_else(|| PathBuf::from("claims"), |p| p.join("claims"));
    RankArgs {
        jobs: 1,
        shard: Some(format!("{i}/{n}")),
        claims: Some(claims),
        out: dir.to_path_buf(),
        processes: None,
        min_pearson: None,
        max_inversions: None,
        no_report: true,
        resume,
        force: !resume,
        ..a.clone()
    }
}
