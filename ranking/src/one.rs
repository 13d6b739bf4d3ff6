//! One process's `rank` ([`run_with`]): every policy checkpoint, many seeded episodes, two branches
//! (MuJoCo and the world model) from the same initial state; per-policy scores
//! with CIs and how well the world model's ranking agrees with MuJoCo's.
//!
//! Output folder: `config.json` (resolved arguments), `episodes.jsonl` (appended
//! as batches finish), `episodes.csv` and `episodes.parquet` (the same rows, sorted),
//! `results.json`. `--resume` skips episodes
//! already in `episodes.jsonl`; `--shard i/n` runs every n-th batch (with `--claims`,
//! the batches it claims first); `--judge`
//! scores the imagined frames with a learned judge instead of the task's own.

use std::path::Path;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use engine::Setup;
use harness::results::{EpisodeRow, FailedPolicy, RankResults, RunTiming};
use harness::summarise::summarise;
use harness::task::Task;
use policies::dir::{checkpoint_dirs, checkpoint_name};
use policies::kinds::{expectations, load_any};
use runner::command::{Invocation, write_json};
use runner::defaults::Resolved;
use runner::progress;

use crate::args::RankArgs;
use crate::error::{Context, RankError};
use crate::summary;

type Result<T, E = RankError> = std::result::Result<T, E>;

/// What the binary hands `rank` of its process: its command line (recorded in `config.json`)
/// and whether bars are hidden ([`Invocation`]), and where result lines go (`say`: stdout).
pub struct Caller<'a> {
    /// The process.
    pub invocation: &'a Invocation,
    /// Writes one result line.
    pub say: &'a dyn Fn(&str),
}

/// Parses `--shard i/n`.
fn parse_shard(s: Option<&str>) -> Result<(usize, usize)> {
    let Some(s) = s else { return Ok((0, 1)) };
    let (i, n) = s.split_once('/').with_context(|| format!("--shard {s}: expected i/n"))?;
    let (Ok(i), Ok(n)) = (i.parse::<usize>(), n.parse::<usize>()) else {
        runner::refuse!("--shard {s}: expected i/n, two whole numbers");
    };
    if n == 0 || i >= n {
        runner::refuse!("--shard {s}: need 0 <= i < n");
    }
    Ok((i, n))
}

/// One process's run of `a` for `task`, resolved as `r` (its inputs found). `shard_times`:
/// the times of the shard processes whose joined rows this run finishes (`--processes`),
/// which `results.json` reports instead of this process's own (it runs no batch); their
/// wall clock is counted up to this process's start.
pub(crate) fn run_with(
    a: &RankArgs,
    task: Box<dyn Task>,
    r: &Resolved,
    caller: &Caller<'_>,
    shard_times: Option<RunTiming>,
) -> Result<ExitCode> {
    let (shard, shards) = parse_shard(a.shard.as_deref())?;
    if shards > 1 {
        watch_parent();
    }
    check_flags(a, r)?;
    let seeds: Vec<u64> = harness::seed::range(a.seed_start, r.episodes as u64)?.collect();
    let device = nn::device::selected()?;
    let (wm, judge) = load_models(a, r, task.as_ref(), &device)?;
    let dirs = checkpoint_dirs(&r.policies)?;
    let parameters = task.parameters();
    // A policy or autoencoder that learned on frames of another scene (a changed rendering)
    // is named on stderr before the run.
    if let Some(now) = &parameters {
        let ae = wm.cfg.autoencoder.as_ref().map(|a| r.world_model.join(a));
        for line in
            runner::frames_seen::mismatches(now, &|r| task.recorded_parameters(r), &dirs, ae.as_deref())
        {
            tracing::warn!("{line}");
        }
    }
    let fingerprints = runner::inputs::fingerprints(
        Some((&r.world_model, &wm)),
        &dirs,
        r.judge.as_deref(),
        &a.scenario,
        parameters.as_ref(),
    )?;
    // Each checkpoint too: one linked into --policies lies elsewhere on disk.
    let listed = runner::output::Inputs::new()
        .scenario(&a.scenario)
        .add("--policies", &r.policies)
        .all("policy checkpoint", &dirs)
        .world_model("--world-model", &r.world_model)
        .maybe("--judge", r.judge.as_deref());
    let (out_dir, jsonl) = prepare_run(&a.out, &listed, a.resume, a.force)?;
    let command = caller.invocation.command_line.join(" ");
    let config =
        rank_config(a, r, command, (&wm, judge.as_ref()), (&dirs, fingerprints), (shard, shards), parameters);
    let config_file = a.out.join("config.json");
    if a.resume {
        runner::resume::check(&config_file, &config)?;
    }
    runner::config::write(&config_file, &config)?;
    let batches: Vec<&[u64]> = seeds.chunks(a.batch).collect();
    let rows: Vec<EpisodeRow> = harness::rows::resume_rows(&jsonl, |r| {
        harness::rows::whole_batches(r, &batches, runner::resume::rank_key, &runner::resume::RANK_KINDS)
    })?;
    let pool = rayon::ThreadPoolBuilder::new().num_threads(a.jobs.max(1)).build()?;
    let judge = judge.map(|j| std::sync::Arc::new(j) as std::sync::Arc<dyn harness::judge::Judge>);
    let mut setup = Setup {
        judge_every_frame: a.judge_every_frame,
        float_frames: a.float_frames,
        ..Setup::new(task.as_ref(), a.seed, r.max_steps, judge.as_ref())
    };
    let pb = progress::bar((dirs.len() * r.episodes) as u64, "rank", caller.invocation.quiet);
    let started = Instant::now();
    let (names, loaded, failed) = load_policies(&dirs, task.as_ref(), &device, &|| pb.inc(r.episodes as u64));
    let policies: Vec<&dyn harness::policy::Policy> = loaded.iter().map(|(_, p)| p.as_ref()).collect();
    // The report's filmstrips come from the run's own frames (`runner::media::kept`) when the
    // batches in flight can hold them; the shards of `--processes` (which use claims) keep
    // theirs for the run that joins them.
    setup.record = ((!a.no_report && shards == 1) || a.claims.is_some())
        && runner::media::recording_fits(&policies, &setup, a.batch, a.jobs);
    let plan = runner::batches::Batches {
        names: &names,
        loaded: &loaded,
        batches: &batches,
        shard: (shard, shards),
        claims: a.claims.as_deref(),
        jobs: a.jobs,
        out: &a.out,
        world_model: &r.world_model,
        judge: r.judge.as_deref(),
    };
    let kept_dir = plan.kept_dir();
    let ran = plan.run(rows, failed, &setup, &wm, &|n| pb.inc(n))?;
    let (mut rows, failed, timing, kept) = (ran.rows, ran.failed, ran.timing, ran.kept);
    pb.finish_and_clear();
    if a.resume {
        runner::resume::straight_order(&jsonl, &mut rows, &names, &batches)?;
    }
    let failed_names: Vec<&str> = failed.iter().map(|f| f.policy.as_str()).collect();
    let ok_names: Vec<String> =
        names.iter().filter(|n| !failed_names.contains(&n.as_str())).cloned().collect();
    let (policies, agreement) = summarise(&rows, &ok_names, a.bootstrap, a.seed);
    let res =
        results(a, r, task.as_ref(), (policies, agreement, failed.clone()), (shard_times, started, &timing));
    write_json(&a.out.join("results.json"), &res.to_json()?)?;
    reports::episode_tables::write_tables(&a.out, &rows)?;
    // The results are complete (the report can be made again from them with
    // `evalharness report`): a run this one replaced can go.
    out_dir.finish(true)?;
    // The policies that loaded and ran without failing, as the run loaded them.
    let named: Vec<(String, &dyn harness::policy::Policy)> = loaded
        .iter()
        .map(|(pi, p)| (names[*pi].clone(), p.as_ref()))
        .filter(|(n, _)| !failed_names.contains(&n.as_str()))
        .collect();
    let src = runner::media::Sources { rows: &rows, kept: &kept, batches: &batches, setup: &setup, wm: &wm };
    let html = report(a, shards, (&named, &src), &pool, &kept_dir)?;
    if let Some((text, true)) = reports::scene::scene_note(&res.policies, res.simulator()) {
        tracing::warn!("{text}");
    }
    summary::print(&res, &a.out, html.as_deref(), caller.say);
    Ok(summary::gates(a.min_pearson, a.max_inversions, &res))
}

/// Refuses flags that contradict each other or the resolved run, before anything is loaded.
///
/// # Errors
/// A zero step limit or batch, or `--judge-persist` without a judge or of 0.
fn check_flags(a: &RankArgs, r: &Resolved) -> Result<()> {
    if r.max_steps == 0 || a.batch == 0 {
        runner::refuse!("--max-steps and --batch must be positive");
    }
    match (a.judge_persist, &r.judge) {
        (Some(0), _) => runner::refuse!("--judge-persist 0: must be at least 1 frame"),
        (Some(_), None) => {
            runner::refuse!(
                "--judge-persist: there is no judge folder to apply it to (the task judges its own frames)"
            )
        }
        _ => {}
    }
    Ok(())
}

/// The world model and the learned judge (when given, with `--judge-persist` applied) the
/// run reads.
///
/// # Errors
/// A model or judge that does not load or does not fit the task, or `--float-frames` with a
/// goal-free world model.
fn load_models(
    a: &RankArgs,
    r: &Resolved,
    task: &dyn Task,
    device: &burn::tensor::Device,
) -> Result<(world_model::model::WorldModel, Option<judges::folder::FrameJudge>)> {
    let wm = runner::inputs::load_world_model(&r.world_model, a.alpha, a.noise_scale, device)?;
    if a.float_frames && wm.cfg.is_goal_free() {
        runner::refuse!(
            "--float-frames: world model {} is goal-free (its frames get the goal drawn back as bytes); use a world model of whole frames",
            r.world_model.display()
        );
    }
    let mut judge = r.judge.as_deref().map(|d| runner::inputs::load_judge(d, task, device)).transpose()?;
    if let (Some(k), Some(j)) = (a.judge_persist, judge.as_mut()) {
        j.file.persist_frames = k;
    }
    Ok((wm, judge))
}

/// The run's `config.json`: its resolved settings and the task's parameters, the checkpoints
/// and every input's fingerprint, and the judge's settings when one was given.
fn rank_config(
    a: &RankArgs,
    r: &Resolved,
    command: String,
    (wm, judge): (&world_model::model::WorldModel, Option<&judges::folder::FrameJudge>),
    (dirs, fingerprints): (&[std::path::PathBuf], std::collections::BTreeMap<String, String>),
    (shard, shards): (usize, usize),
    scenario_parameters: Option<serde_json::Value>,
) -> runner::RankConfig {
    runner::RankConfig {
        command,
        scenario: a.scenario.clone(),
        scenario_parameters,
        policies: r.policies.clone(),
        world_model: r.world_model.clone(),
        world_model_config: wm.cfg.clone(),
        episodes: r.episodes,
        seed_start: a.seed_start,
        max_steps: r.max_steps,
        batch: a.batch,
        seed: a.seed,
        bootstrap: a.bootstrap,
        shard: (shard, shards),
        checkpoints: dirs.to_vec(),
        fingerprints,
        judge: r.judge.as_ref().zip(judge).map(|(dir, j)| runner::JudgeSettings {
            path: dir.clone(),
            label: j.file.label,
            threshold: j.file.threshold,
            persist_frames: j.file.persist_frames,
            heldout: j.file.heldout,
        }),
        judge_every_frame: a.judge_every_frame,
        float_frames: a.float_frames,
        merged_from: Vec::new(),
    }
}

/// A loaded checkpoint with its index among the run's.
type Loaded = (usize, Box<dyn harness::policy::Policy>);

/// Loads every checkpoint of `dirs` for `task`; one that fails is reported and left out
/// (`skipped` is called for it). Returns every checkpoint's name, the loaded ones with their
/// index, and the failures.
fn load_policies(
    dirs: &[std::path::PathBuf],
    task: &dyn Task,
    device: &burn::tensor::Device,
    skipped: &dyn Fn(),
) -> (Vec<String>, Vec<Loaded>, Vec<FailedPolicy>) {
    let expect = expectations(task);
    let (mut names, mut loaded, mut failed) = (Vec::new(), Vec::new(), Vec::new());
    for (pi, dir) in dirs.iter().enumerate() {
        let name = checkpoint_name(dir);
        names.push(name.clone());
        match load_any(dir, &expect, device, task) {
            Ok(p) => loaded.push((pi, p)),
            Err(e) => {
                tracing::error!("{e}; continuing with the other policies");
                failed.push(FailedPolicy { policy: name, error: e.to_string() });
                skipped();
            }
        }
    }
    (names, loaded, failed)
}

/// The run's `results.json`: per-policy statistics, agreement, failures and timing (the
/// shard processes' when this run joins them, else this process's).
fn results(
    a: &RankArgs,
    r: &Resolved,
    task: &dyn Task,
    (policies, agreement, failed): (
        Vec<harness::results::PolicyResult>,
        harness::results::AgreementSummary,
        Vec<FailedPolicy>,
    ),
    (shard_times, started, timing): (Option<RunTiming>, Instant, &engine::Timing),
) -> RankResults {
    RankResults {
        schema_version: harness::results::RESULTS_SCHEMA,
        scenario: a.scenario.clone(),
        world_model: r.world_model.clone(),
        episodes: r.episodes,
        seed_start: a.seed_start,
        max_steps: r.max_steps,
        scoring: Some(task.score_kind().describe()),
        simulator: Some(task.simulator().to_string()),
        policies,
        agreement,
        failed_policies: failed,
        timing: match shard_times {
            Some(t) => RunTiming { wall_seconds: t.wall_seconds + started.elapsed().as_secs_f64(), ..t },
            None => RunTiming {
                wall_seconds: started.elapsed().as_secs_f64(),
                sim_seconds: timing.sim_s,
                world_model_seconds: timing.world_model_s,
                world_model_ms_per_frame: 1e3 * timing.world_model_s / timing.frames.max(1) as f64,
                policy_seconds: timing.policy_s,
                note: "this process only (a resumed run times its own part)".into(),
            },
        },
    }
}

/// The run's report (unless `--no-report`) with its filmstrips from `src` for the policies
/// `named` (a shard writes none: the run that joins the shards does), then the kept frames
/// removed; returns the report's path.
///
/// # Errors
/// A filmstrip or the report that cannot be written, or kept frames that cannot be removed.
fn report(
    a: &RankArgs,
    shards: usize,
    (named, src): (&[(String, &dyn harness::policy::Policy)], &runner::media::Sources<'_>),
    pool: &rayon::ThreadPool,
    kept_dir: &Path,
) -> Result<Option<std::path::PathBuf>> {
    let html = if a.no_report {
        None
    } else {
        if shards == 1 {
            runner::media::write_filmstrips(&a.out.join("filmstrips"), named, src, pool)?;
        }
        Some(runner::report::write_report(&a.out)?)
    };
    if shards == 1 && kept_dir.exists() {
        // The filmstrips are written (or not asked for): the kept frames are done with.
        std::fs::remove_dir_all(kept_dir).with_context(|| format!("removing {}", kept_dir.display()))?;
    }
    Ok(html)
}

/// Checks that `out` stays apart from every input `listed` (every folder of
/// [`runner::inputs::fingerprints`] among them), then prepares it for a run that appends rows (see
/// [`runner::output::RunDir::prepare_episodes`]); returns it and its `episodes.jsonl`.
///
/// # Errors
/// An `out` that overlaps an input, or one `--resume` / `--force` cannot take.
pub fn prepare_run(
    out: &Path,
    listed: &runner::output::Inputs,
    resume: bool,
    force: bool,
) -> Result<(runner::output::RunDir, std::path::PathBuf), runner::output::OutputError> {
    let dir = runner::output::RunDir::prepare_episodes(out, listed, resume, force)?;
    Ok((dir, out.join("episodes.jsonl")))
}

/// The environment variable naming a shard's parent process ([`watch_parent`]).
pub(crate) const PARENT_ENV: &str = "EVALHARNESS_PARENT_PID";

/// In a shard started by `rank --processes`: a thread that ends this process once
/// the parent is gone (killed with `kill -9`, say), so that no shard goes on running
/// (and claiming batches) for a run nobody will finish. The batches it finished are
/// on disk whole; `--resume` continues from them. A shard started by hand has no
/// such parent and is not watched.
fn watch_parent() {
    let Some(parent) = std::env::var(PARENT_ENV).ok().and_then(|p| p.parse::<u32>().ok()) else { return };
    std::thread::spawn(move || {
        loop {
            // Once the parent dies the shard is re-parented (to init or a subreaper).
            if std::os::unix::process::parent_id() != parent {
                tracing::error!("the rank --processes parent {parent} is gone; this shard stops");
                std::process::exit(2);
            }
            std::thread::sleep(Duration::from_millis(500));
        }
    });
}
