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
//! Episodes are written by [`super::record::Sink`] in the task's own dataset layout, as
//! its scripted `collect` writes them.

use std::path::Path;

use crate::error::{Context, Result, SimError, refuse};
use crate::{Invocation, say};
use engine::{Setup, Start, Timing, sim_branch};
use harness::replay::attrs::{CheckpointEntry, EpisodeEntry, Source, total_steps};
use harness::task::Task;
use policies::dir::checkpoint_dirs;

use crate::args::CollectArgs;
use crate::collect::{load_task, refuse_no_early_stop, scripted_of};
use crate::record::Sink;
use policies::kinds::{expectations, load_any};

/// Episodes advanced together per batched policy call.
const BATCH: usize = 100;

/// Runs every checkpoint under `dir` and writes their episodes, checkpoint by checkpoint.
pub fn run(args: &CollectArgs, dir: &Path, inv: &Invocation, say: &mut dyn FnMut(&str)) -> Result<bool> {
    let c = &args.common;
    if c.noise != 0.0 || c.lag != 0 {
        refuse!("--noise and --lag perturb the scripted expert; they do not apply to --policy");
    }
    let task = load_task(&c.scenario)?;
    refuse_no_early_stop(task.as_ref(), args.no_early_stop)?;
    let max_steps = c.max_steps.map_or(task.max_steps(), |m| m as usize);
    if c.episodes == 0 {
        refuse!("--episodes must be at least 1");
    }
    let inputs = runner::output::Inputs::new().scenario(&c.scenario).add("--policy", dir);
    let mut sink = Sink::create(task.as_ref(), &args.out, c.force, &inputs)?;
    let (episodes, checkpoints) = roll_out(args, dir, task.as_ref(), max_steps, &mut sink, inv.quiet)?;
    let (n, steps) = (episodes.len(), total_steps(&episodes));
    // The scripted datasets' source fields, with no perturbation: --noise and --lag are
    // refused above.
    let n_checkpoints = checkpoints.len();
    let source = Source {
        policy: Some(dir.display().to_string()),
        checkpoints: Some(checkpoints),
        noise: Some(0.0),
        lag: Some(0),
        no_early_stop: scripted_of(task.as_ref())?.early_stop_optional().then_some(args.no_early_stop),
        ..Source::default()
    };
    let path = sink.finish(c.seed_start, source, max_steps, episodes)?;
    say!(
        say,
        "{} dataset: {n} episodes of {} checkpoint(s), {steps} steps -> {}",
        task.name(),
        n_checkpoints,
        path.display()
    );
    Ok(true)
}

/// The checkpoints under `dir`, each run on the seeds in the simulator, each episode
/// appended to `sink` (labelled with its checkpoint's name) as its batch ends.
/// Returns the episodes' and the checkpoints' attributes.
fn roll_out(
    args: &CollectArgs,
    dir: &Path,
    task: &dyn Task,
    max_steps: usize,
    sink: &mut Sink<'_>,
    quiet: bool,
) -> Result<(Vec<EpisodeEntry>, Vec<CheckpointEntry>)> {
    let c = &args.common;
    let setup = Setup::new(task, 0, max_steps, None);
    let device = nn::device::selected()?;
    let dirs = checkpoint_dirs(dir)?;
    let expect = expectations(task);
    let seeds: Vec<u64> = harness::seed::range(c.seed_start, c.episodes)?.collect();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(c.jobs.max(1))
        .build()
        .map_err(|e| SimError::Refused(format!("starting threads: {e}")))?;
    let pb = runner::progress::bar(dirs.len() as u64 * c.episodes, "collect", quiet);
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
                let (s, attr) =
                    sink.append(t, &name).with_context(|| format!("policy {name}, seed {}", t.seed))?;
                score += s;
                episodes.push(attr);
            }
            pb.inc(batch.len() as u64);
        }
        let mean = score / seeds.len().max(1) as f64;
        tracing::info!("{name}: {} episodes, mean score {mean:.3}", seeds.len());
        checkpoints.push(CheckpointEntry {
            name,
            path: d.clone(),
            episodes: seeds.len() as u64,
            mean_score: mean,
        });
    }
    pb.finish_and_clear();
    Ok((episodes, checkpoints))
}
