//! `evalharness collect --policy DIR`: a dataset of policy checkpoints' closed-loop
//! MuJoCo rollouts, in the same zarr layout as the scripted behaviours.
//!
//! Why: a world model trained only on expert and random-exploration episodes has
//! never seen a weak policy nudge the block without bringing it home, and that is
//! most of what a ranking run asks it to imagine. Rollouts of checkpoints *outside*
//! the ranked set (other epochs, other training seeds) fill that gap without
//! leaking the ranked policies' own behaviour into the model.
//!
//! Each checkpoint runs `--episodes` episodes from `--seed-start`, exactly as the
//! MuJoCo branch of `rank` (and `simulate --policy`) runs it: the same per-episode
//! noise streams (master seed 0), action horizon and end at success. So the
//! dataset is a pure function of the arguments, whatever `--jobs` is.

use std::path::Path;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use engine::{Setup, Start, Timing, Trajectory, sim_branch};
use harness::replay::ReplayWriter;
use policies::dir::checkpoint_dirs;
use scenarios::pusht::rollout::{Episode, StepRow};
use scenarios::pusht::{Pose2, PushTTask};
use serde_json::json;

use super::collect::{dataset_attrs, episode_arrays, episode_attr, replay_spec};
use crate::cli::CollectArgs;
use crate::policy_kinds::{expectations, load_any};
use crate::progress;
use crate::scenario::load_pusht;

/// Episodes advanced together per batched policy call.
const BATCH: usize = 100;

/// Runs every checkpoint under `dir` and writes their episodes, checkpoint by checkpoint.
pub fn run(args: &CollectArgs, dir: &Path, quiet: bool) -> Result<ExitCode> {
    let c = &args.common;
    if c.noise != 0.0 || c.lag != 0 {
        bail!("--noise and --lag perturb the scripted expert; they do not apply to --policy");
    }
    let cfg = load_pusht(&c.scenario)?;
    let task = PushTTask::new(cfg.clone())?;
    let max_steps = c.max_steps.map_or(cfg.task.max_steps as usize, |m| m as usize);
    if max_steps == 0 || c.episodes == 0 {
        bail!("--episodes and --max-steps must be at least 1");
    }
    let setup = Setup { task: &task, master_seed: 0, max_steps, judge: None };
    let device = world_model::device::selected()?;
    let dirs = checkpoint_dirs(dir)?;
    let size = cfg.render.size as usize;
    let expect = expectations(&task);
    crate::output::check_apart(&args.out, &[("--policy", dir)])?;
    let seeds: Vec<u64> = harness::seed::range(c.seed_start, c.episodes)?.collect();
    let mut writer = ReplayWriter::create(&args.out, replay_spec(size), c.force)?;
    let pool =
        rayon::ThreadPoolBuilder::new().num_threads(c.jobs.max(1)).build().context("starting threads")?;
    let pb = progress::bar(dirs.len() as u64 * c.episodes, "collect", quiet);
    let (mut episodes, mut checkpoints) = (Vec::new(), Vec::new());
    for d in &dirs {
        let policy = load_any(d, &expect, &device, &task)
            .with_context(|| format!("loading policy {}", d.display()))?;
        let name = policy.name().to_string();
        let mut timing = Timing::default();
        let mut score = 0.0;
        for batch in seeds.chunks(BATCH) {
            let mut start = Start::new(&name, batch, &setup)?;
            start.trajectories = true;
            let out = pool
                .install(|| sim_branch(policy.as_ref(), start, &setup, &mut timing))
                .with_context(|| format!("policy {name}"))?;
            for t in &out.episodes {
                let ep = episode(t).with_context(|| format!("policy {name}, seed {}", t.seed))?;
                writer.append(&episode_arrays(&ep))?;
                score += ep.score;
                episodes.push(episode_attr(&ep, &name));
            }
            pb.inc(batch.len() as u64);
        }
        let mean = score / seeds.len().max(1) as f64;
        tracing::info!("{name}: {} episodes, mean score {mean:.3}", seeds.len());
        checkpoints.push(json!({"name": name, "path": d, "episodes": seeds.len(), "mean_score": mean}));
    }
    pb.finish_and_clear();
    let n = episodes.len();
    let steps: u64 = episodes.iter().filter_map(|e| e["steps"].as_u64()).sum();
    let source = json!({"policy": dir, "checkpoints": checkpoints, "noise": 0.0, "lag": 0});
    let attrs = dataset_attrs(&cfg, c.seed_start, source, max_steps, episodes);
    let path = writer.finish(&attrs)?;
    println!(
        "pusht dataset: {n} episodes of {} checkpoint(s), {steps} steps -> {}",
        dirs.len(),
        path.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// A recorded Push-T episode in the dataset layout of `collect`: each step's state
/// (agent x, y, block x, y, θ) before the action, the action and the coverage after it.
fn episode(t: &Trajectory) -> Result<Episode> {
    let g = t.goal.context("the episode has no goal pose")?;
    let rows = t
        .states
        .iter()
        .zip(&t.actions)
        .zip(&t.raw)
        .enumerate()
        .map(|(j, ((s, a), &coverage))| match (&s[..], &a[..]) {
            (&[ax, ay, bx, by, bth], &[x, y]) => Ok(StepRow {
                step: j as u32,
                agent: [ax, ay],
                block: Pose2::new(bx, by, bth),
                action: [f64::from(x), f64::from(y)],
                coverage,
            }),
            _ => bail!("step {j}: state of {} entries or action of {}, expected 5 and 2", s.len(), a.len()),
        })
        .collect::<Result<_>>()?;
    let (seed, score, success) = (t.seed, t.score, t.success);
    Ok(Episode { seed, goal: Pose2::new(g[0], g[1], g[2]), rows, frames: t.frames.clone(), score, success })
}
