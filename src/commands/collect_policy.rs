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
//! simulator branch of `rank` (and `simulate --policy`) runs it: the same
//! per-episode noise streams (master seed 0), action horizon and end at success
//! (Lift and Can with `--no-early-stop`: at the step limit, so that success lasts).
//! So the dataset is a pure function of the arguments, whatever `--jobs` is.
//!
//! Push-T episodes are written in Push-T's layout ([`super::collect`]); Lift and
//! Can episodes in the robosuite layout of [`super::collect_arm`] (agentview
//! frames, 7-D actions, the task's state columns, `data/success`).

use std::path::Path;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use engine::{Setup, Start, Timing, Trajectory, sim_branch};
use harness::replay::{EpisodeArrays, ReplayWriter};
use harness::task::Task;
use policies::dir::checkpoint_dirs;
use scenarios::pusht::rollout::{Episode, StepRow};
use scenarios::pusht::{Pose2, PushTConfig, PushTTask};
use scenarios::robosuite::task::{ArmEngine, RobosuiteTask};
use serde_json::{Value, json};

use super::collect::{dataset_attrs, episode_arrays, episode_attr, replay_spec};
use crate::cli::CollectArgs;
use crate::policy_kinds::{expectations, load_any};
use crate::progress;

/// Episodes advanced together per batched policy call.
const BATCH: usize = 100;

/// Runs every checkpoint under `dir` and writes their episodes, checkpoint by checkpoint.
pub fn run(args: &CollectArgs, dir: &Path, quiet: bool) -> Result<ExitCode> {
    let c = &args.common;
    if c.noise != 0.0 || c.lag != 0 {
        bail!("--noise and --lag perturb the scripted expert; they do not apply to --policy");
    }
    let scenario =
        scenarios::scenario(&c.scenario).with_context(|| format!("loading scenario {}", c.scenario))?;
    match scenario {
        scenarios::Scenario::PushT(cfg) => pusht(args, dir, *cfg, quiet),
        scenarios::Scenario::Lift(cfg) => {
            let task = RobosuiteTask::new(scenarios::lift::LiftSim::new(cfg).context("setting up Lift")?);
            arm_task(args, dir, &task, quiet)
        }
        scenarios::Scenario::Can(cfg) => {
            let task = RobosuiteTask::new(scenarios::can::CanSim::new(cfg).context("setting up Can")?);
            arm_task(args, dir, &task, quiet)
        }
    }
}

/// Appends one episode (of the named checkpoint); returns its (score, per-episode attribute).
type WriteEpisode<'a> = dyn FnMut(&Trajectory, &str) -> Result<(f64, Value)> + 'a;

/// The checkpoints under `dir`, each run on the seeds in the simulator, each episode
/// handed to `write` (with its checkpoint's name) as its batch ends; `write` appends it
/// and returns its (score, per-episode attribute). Returns the episodes' and the
/// checkpoints' attributes.
fn roll_out(
    args: &CollectArgs,
    dir: &Path,
    task: &dyn Task,
    max_steps: usize,
    write: &mut WriteEpisode<'_>,
    quiet: bool,
) -> Result<(Vec<Value>, Vec<Value>)> {
    let c = &args.common;
    let setup = Setup { task, master_seed: 0, max_steps, judge: None };
    let device = world_model::device::selected()?;
    let dirs = checkpoint_dirs(dir)?;
    let expect = expectations(task);
    let seeds: Vec<u64> = harness::seed::range(c.seed_start, c.episodes)?.collect();
    let pool =
        rayon::ThreadPoolBuilder::new().num_threads(c.jobs.max(1)).build().context("starting threads")?;
    let pb = progress::bar(dirs.len() as u64 * c.episodes, "collect", quiet);
    let (mut episodes, mut checkpoints) = (Vec::new(), Vec::new());
    for d in &dirs {
        let policy =
            load_any(d, &expect, &device, task).with_context(|| format!("loading policy {}", d.display()))?;
        let name = policy.name().to_string();
        let mut timing = Timing::default();
        let mut score = 0.0;
        for batch in seeds.chunks(BATCH) {
            let mut start = Start::new(&name, batch, &setup)?;
            start.trajectories = true;
            start.run_on = args.no_early_stop;
            let out = pool
                .install(|| sim_branch(policy.as_ref(), start, &setup, &mut timing))
                .with_context(|| format!("policy {name}"))?;
            for t in &out.episodes {
                let (s, attr) = write(t, &name).with_context(|| format!("policy {name}, seed {}", t.seed))?;
                score += s;
                episodes.push(attr);
            }
            pb.inc(batch.len() as u64);
        }
        let mean = score / seeds.len().max(1) as f64;
        tracing::info!("{name}: {} episodes, mean score {mean:.3}", seeds.len());
        checkpoints.push(json!({"name": name, "path": d, "episodes": seeds.len(), "mean_score": mean}));
    }
    pb.finish_and_clear();
    Ok((episodes, checkpoints))
}

/// The step limit (`--max-steps`, else the task's), checked with `--episodes`.
fn step_limit(args: &CollectArgs, default: usize) -> Result<usize> {
    let max_steps = args.common.max_steps.map_or(default, |m| m as usize);
    if max_steps == 0 || args.common.episodes == 0 {
        bail!("--episodes and --max-steps must be at least 1");
    }
    Ok(max_steps)
}

/// Push-T: the dataset layout of `collect`'s scripted behaviours.
fn pusht(args: &CollectArgs, dir: &Path, cfg: PushTConfig, quiet: bool) -> Result<ExitCode> {
    let c = &args.common;
    super::collect::refuse_run_on_for_pusht(args.no_early_stop)?;
    let task = PushTTask::new(cfg.clone())?;
    let max_steps = step_limit(args, cfg.task.max_steps as usize)?;
    crate::output::check_apart(&args.out, &[("--policy", dir)])?;
    let mut writer = ReplayWriter::create(&args.out, replay_spec(cfg.render.size as usize), c.force)?;
    let mut write = |t: &Trajectory, name: &str| {
        let ep = episode(t)?;
        writer.append(&episode_arrays(&ep))?;
        Ok((ep.score, episode_attr(&ep, name)))
    };
    let (episodes, checkpoints) = roll_out(args, dir, &task, max_steps, &mut write, quiet)?;
    let (n, steps) = (episodes.len(), total_steps(&episodes));
    let source = json!({"policy": dir, "checkpoints": checkpoints, "noise": 0.0, "lag": 0});
    let attrs = dataset_attrs(&cfg, c.seed_start, source, max_steps, episodes);
    let path = writer.finish(&attrs)?;
    println!(
        "pusht dataset: {n} episodes of {} checkpoint(s), {steps} steps -> {}",
        checkpoints.len(),
        path.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// Lift and Can: the robosuite layout of `collect --scenario lift|can`.
fn arm_task<T: ArmEngine + 'static>(
    args: &CollectArgs,
    dir: &Path,
    task: &RobosuiteTask<T>,
    quiet: bool,
) -> Result<ExitCode> {
    let c = &args.common;
    let arm = task.sim();
    let max_steps = step_limit(args, arm.max_steps())?;
    crate::output::check_apart(&args.out, &[("--policy", dir)])?;
    let size = task.observation_spec().image_size;
    let columns = arm.state_columns().len();
    let spec = super::collect_arm::replay_spec(size, columns);
    let threshold = task.score_kind().threshold();
    let mut writer = ReplayWriter::create(&args.out, spec, c.force)?;
    let mut write = |t: &Trajectory, name: &str| {
        writer.append(&arm_arrays(t, size, columns, threshold)?)?;
        let attr = json!({"seed": t.seed, "behaviour": name, "steps": t.actions.len(), "success": t.success});
        Ok((t.score, attr))
    };
    let (episodes, checkpoints) = roll_out(args, dir, task, max_steps, &mut write, quiet)?;
    let (n, steps) = (episodes.len(), total_steps(&episodes));
    let source = json!({"policy": dir, "checkpoints": checkpoints, "no_early_stop": args.no_early_stop});
    let attrs = super::collect_arm::dataset_attrs(arm, c.seed_start, source, max_steps, episodes);
    let path = writer.finish(&attrs)?;
    println!(
        "{} dataset: {n} episodes of {} checkpoint(s), {steps} steps -> {}",
        arm.name(),
        checkpoints.len(),
        path.display()
    );
    Ok(ExitCode::SUCCESS)
}

fn total_steps(episodes: &[Value]) -> u64 {
    episodes.iter().filter_map(|e| e["steps"].as_u64()).sum()
}

/// A recorded robosuite episode's arrays: the frame and state before each action, the
/// action, and whether the task succeeded after it (raw score above `threshold`).
fn arm_arrays(t: &Trajectory, size: usize, columns: usize, threshold: f64) -> Result<EpisodeArrays> {
    let n = t.actions.len();
    if t.frames.len() < n || t.states.len() != n || t.raw.len() != n {
        bail!("{} frames, {} states, {} scores for {n} actions", t.frames.len(), t.states.len(), t.raw.len());
    }
    let mut arrays = EpisodeArrays::default();
    for (j, ((f, s), a)) in t.frames.iter().zip(&t.states).zip(&t.actions).enumerate() {
        if f.len() != size * size * 3 || s.len() != columns || a.len() != 7 {
            bail!(
                "step {j}: frame of {} bytes, state of {} entries or action of {}, expected {}, {columns} and 7",
                f.len(),
                s.len(),
                a.len(),
                size * size * 3
            );
        }
        arrays.img.extend_from_slice(f);
        arrays.state.extend(s.iter().map(|&v| v as f32));
        arrays.action.extend_from_slice(a);
    }
    arrays.extras.push(t.raw.iter().map(|&r| if r > threshold { 1.0 } else { 0.0 }).collect());
    Ok(arrays)
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
