//! `simulate --policy DIR --replay-imagined WORLD_MODEL`: every episode three ways
//! from the same initial state — the policy in MuJoCo, the policy in the world model
//! (as `rank` imagines it, read by the same judge), and the imagined episode's own
//! actions replayed in MuJoCo.
//!
//! Why: when the world model imagines a policy succeeding more often than MuJoCo
//! sees it, either the imagined frames made the policy act better (its imagined
//! actions then succeed in MuJoCo too) or the imagined dynamics forgave actions that
//! fail for real (they then fail there). The counts per checkpoint tell the two apart.

use std::path::Path;
use std::sync::Arc;

use crate::error::{Context, Result, refuse};
use crate::{Invocation, say};
use engine::{Setup, Start, Timing, Trajectory, replay_in_sim, sim_branch, wm_branch};
use harness::policy::Policy;
use harness::replay::attrs::Source;
use harness::results::{EpisodeRow, PairedSuccess};
use harness::rows::append_rows;
use policies::dir::{checkpoint_dirs, checkpoint_name};
use serde::Serialize;
use world_model::model::WorldModel;

use crate::args::SimulateArgs;
use crate::collect::load_task;
use crate::record::Sink;
use policies::kinds::{expectations, load_any};
use runner::command::write_json;
use runner::defaults;
use runner::inputs::{load_judge, load_world_model};
use runner::output::Staged;

/// One checkpoint's three success rates and how the imagined successes fare.
#[derive(Debug, Serialize)]
struct Replayed {
    name: String,
    episodes: usize,
    /// The policy in MuJoCo.
    mujoco: f64,
    /// The policy in the world model.
    imagined: f64,
    /// The imagined episodes' actions in MuJoCo.
    imagined_actions_in_mujoco: f64,
    /// Imagined successes whose actions also succeed in MuJoCo.
    imagined_success_holds: usize,
    /// Imagined successes whose actions fail in MuJoCo.
    imagined_success_fails: usize,
}

/// A judge shared by the worker threads.
type SharedJudge = Arc<dyn harness::judge::Judge>;

/// The judge of imagined frames: `--judge`, or the task's shipped one for a task without a
/// judge of its own (none for a task that judges its own frames), with its folder.
///
/// # Errors
/// A task without a judge of its own and none to load, or a judge that does not load.
fn judge_of(
    args: &SimulateArgs,
    task: &dyn harness::task::Task,
    device: &burn::tensor::Device,
) -> Result<(Option<std::path::PathBuf>, Option<SharedJudge>)> {
    let (judge_dir, own) = defaults::judge(args.judge.as_deref(), task, Path::new("checkpoints"));
    if judge_dir.is_none() && !own {
        refuse!(
            "--judge: the {} task has no hand-written judge of imagined frames and checkpoints/{}/judge is \
             not a folder here (run from the repository root, or pass --judge DIR)",
            task.name(),
            task.name()
        );
    }
    let judge = match &judge_dir {
        Some(d) => Some(Arc::new(load_judge(d, task, device)?) as Arc<dyn harness::judge::Judge>),
        None => None,
    };
    Ok((judge_dir, judge))
}

/// Writes the `--record` dataset's attributes (how the replays were made: the policies, the
/// world model `wm_dir` with its noise scale, the judge and the master seed) and moves it
/// into place; returns its path.
fn finish_record(
    sink: Sink<'_>,
    args: &SimulateArgs,
    (wm_dir, judge_dir, noise_scale, seed): (&Path, Option<&Path>, f32, u64),
    max_steps: usize,
    episodes: Vec<harness::replay::attrs::EpisodeEntry>,
) -> Result<std::path::PathBuf> {
    let source = Source {
        policy: Some(args.policy.clone()),
        replay_imagined: Some(wm_dir.to_path_buf()),
        judge: judge_dir.map(Path::to_path_buf),
        noise_scale: Some(noise_scale),
        seed: Some(seed),
        what: Some(
            "each imagined episode's executed actions, stepped in MuJoCo from the same initial state".into(),
        ),
        ..Source::default()
    };
    sink.finish(args.common.seed_start, source, max_steps, episodes)
}

/// Runs the three branches for every checkpoint under `--policy`.
pub fn run(args: &SimulateArgs, wm_dir: &Path, inv: &Invocation, say: &mut dyn FnMut(&str)) -> Result<bool> {
    let c = &args.common;
    let task = load_task(&c.scenario)?;
    let max_steps = c.max_steps.map_or(task.max_steps(), |m| m as usize);
    let device = nn::device::selected()?;
    let wm = load_world_model(wm_dir, None, args.noise_scale, &device)?;
    let (judge_dir, judge) = judge_of(args, task.as_ref(), &device)?;
    let setup = Setup::new(task.as_ref(), args.seed.unwrap_or(0), max_steps, judge.as_ref());
    let dirs = checkpoint_dirs(Path::new(&args.policy))?;
    let inputs = args.inputs().maybe("--judge", judge_dir.as_deref());
    let out = Staged::new(&args.out, c.force, &inputs)?;
    let expect = expectations(task.as_ref());
    let seeds: Vec<u64> = harness::seed::range(c.seed_start, c.episodes)?.collect();
    let pb = runner::progress::bar((dirs.len() as u64) * c.episodes, "replay", inv.quiet);
    let (jsonl, replay_jsonl) = (out.file("episodes.jsonl"), out.file("replay.jsonl"));
    let mut sink = match &args.record {
        Some(path) => {
            let inputs = inputs.clone().add("--out", &args.out);
            Some((Sink::create(task.as_ref(), path, c.force, &inputs)?, Vec::new()))
        }
        None => None,
    };
    let mut policies = Vec::new();
    for d in &dirs {
        let name = checkpoint_name(d);
        let policy =
            load_any(d, &expect, &device, task.as_ref()).with_context(|| format!("policy {name}"))?;
        policies.push((name, policy));
    }
    // One unit per checkpoint and batch of up to 50 seeds (rank's default batch), run on
    // `--jobs` workers and handed on in order: a checkpoint's rows are the same for any
    // worker count.
    let batches: Vec<&[u64]> = seeds.chunks(50).collect();
    let units: Vec<(usize, &[u64])> =
        (0..policies.len()).flat_map(|p| batches.iter().map(move |b| (p, *b))).collect();
    let record = sink.is_some();
    let work = |&(p, batch): &(usize, &[u64])| {
        let (name, policy) = &policies[p];
        three_ways(policy.as_ref(), batch, &setup, &wm, record).with_context(|| format!("policy {name}"))
    };
    // The units' frames are rendered on the workers' threads: what each holds for the task
    // goes when it is done (`Task::release_thread`).
    let release = || task.release_thread();
    let mut summary = Vec::new();
    let (mut real, mut imagined, mut replayed) = (Vec::new(), Vec::new(), Vec::new());
    engine::schedule::run_ordered(&units, c.jobs, &work, &release, &mut |i,
                                                                         unit: Result<Unit>|
     -> Result<()> {
        let unit = unit?;
        let name = &policies[units[i].0].0;
        for ((row, t), imagined_row) in unit.replayed.into_iter().zip(&unit.imagined) {
            if let (Some((sink, attrs)), Some(t)) = (sink.as_mut(), t) {
                let label = format!("{name}/imagined-actions");
                let (_, mut attr) =
                    sink.append(&t, &label).with_context(|| format!("recording {label}, seed {}", t.seed))?;
                attr.imagined_success = Some(imagined_row.success);
                attrs.push(attr);
            }
            replayed.push(row);
        }
        real.extend(unit.real);
        imagined.extend(unit.imagined);
        pb.inc(units[i].1.len() as u64);
        if (i + 1) % batches.len() == 0 {
            // The checkpoint's last batch.
            append_rows(&jsonl, &real)?;
            append_rows(&jsonl, &imagined)?;
            append_rows(&replay_jsonl, &replayed)?;
            let r = tally(name, &real, &imagined, &replayed);
            say!(
                say,
                "{name:<16} MuJoCo {:.2}  imagined {:.2}  imagined actions in MuJoCo {:.2}  (imagined successes: {} hold in MuJoCo, {} fail)",
                r.mujoco,
                r.imagined,
                r.imagined_actions_in_mujoco,
                r.imagined_success_holds,
                r.imagined_success_fails
            );
            summary.push(r);
            (real, imagined, replayed) = (Vec::new(), Vec::new(), Vec::new());
        }
        Ok(())
    })?;
    pb.finish_and_clear();
    write_json(
        &out.file("replay.json"),
        &serde_json::json!({"scenario": c.scenario, "policies_dir": args.policy, "world_model": wm_dir,
            "noise_scale": wm.noise_scale(), "judge": judge_dir, "seed_start": c.seed_start, "episodes": c.episodes,
            "max_steps": max_steps, "seed": setup.master_seed, "policies": summary}),
    )?;
    if let Some((sink, episodes)) = sink {
        let (n, what) = (episodes.len(), (wm_dir, judge_dir.as_deref(), wm.noise_scale(), setup.master_seed));
        let path = finish_record(sink, args, what, max_steps, episodes)?;
        say!(say, "{} dataset: {n} replayed episodes -> {}", c.scenario, path.display());
    }
    let o = out.commit()?;
    say!(say, "-> {}", o.display());
    Ok(true)
}

/// One batch of a checkpoint's seeds, run three ways: rows in seed order, the replays
/// with their episodes when recording.
struct Unit {
    real: Vec<EpisodeRow>,
    imagined: Vec<EpisodeRow>,
    replayed: Vec<(EpisodeRow, Option<Trajectory>)>,
}

/// The policy in the world model (keeping its executed actions), in MuJoCo, and its
/// imagined actions replayed in MuJoCo, on the seeds of `batch`, on this thread.
fn three_ways(
    policy: &dyn Policy,
    batch: &[u64],
    setup: &Setup,
    wm: &WorldModel,
    record: bool,
) -> Result<Unit> {
    let mut timing = Timing::default();
    let mut start = Start::new(policy.name(), batch, setup)?;
    start.trajectories = true;
    let wm_out = wm_branch(policy, &start, setup, wm, &mut timing).context("the world-model branch")?;
    start.trajectories = false;
    let real = sim_branch(policy, start, setup, &mut timing).context("the MuJoCo branch")?.rows;
    let horizons = (policy.obs_horizon(), policy.action_horizon());
    let replayed = wm_out
        .episodes
        .iter()
        .map(|e| {
            replay_in_sim(policy.name(), horizons, e.seed, e.actions.clone(), (setup, record), &mut timing)
        })
        .collect::<Result<Vec<_>, _>>()
        .context("replaying the imagined actions")?;
    Ok(Unit { real, imagined: wm_out.rows, replayed })
}

/// The rates of one checkpoint's rows (each list in seed order, one row per seed).
fn tally(name: &str, real: &[EpisodeRow], imagined: &[EpisodeRow], replayed: &[EpisodeRow]) -> Replayed {
    let rate =
        |rows: &[EpisodeRow]| rows.iter().filter(|r| r.success).count() as f64 / rows.len().max(1) as f64;
    // Each seed's replayed actions (in MuJoCo) against its imagined episode.
    let c = PairedSuccess::count(replayed.iter().zip(imagined).map(|(r, i)| (r.success, i.success)));
    Replayed {
        name: name.to_string(),
        episodes: real.len(),
        mujoco: rate(real),
        imagined: rate(imagined),
        imagined_actions_in_mujoco: rate(replayed),
        imagined_success_holds: c.both,
        imagined_success_fails: c.imagined_only,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use harness::results::Branch;

    #[test]
    fn tally_counts_imagined_successes_by_their_replay() {
        // Seeds 1–4, success (MuJoCo, imagined, replayed): (F, T, T), (F, T, F), (T, T, F),
        // (F, F, F). Rates 1/4, 3/4, 1/4; of the 3 imagined successes, 1 holds and 2 fail.
        let row = |seed, b, ok: bool| {
            let x = f64::from(u8::from(ok));
            EpisodeRow::new("p", seed, b, x, x, x, 0.5, 10) // success: x > 0.5
        };
        let rows = |b, oks: [bool; 4]| -> Vec<EpisodeRow> {
            oks.iter().zip(1..).map(|(&ok, i)| row(i, b, ok)).collect()
        };
        let real = rows(Branch::Sim, [false, false, true, false]);
        let imag = rows(Branch::WorldModel, [true, true, true, false]);
        let rep = rows(Branch::Sim, [true, false, false, false]);
        let t = tally("p", &real, &imag, &rep);
        assert_eq!((t.mujoco, t.imagined, t.imagined_actions_in_mujoco), (0.25, 0.75, 0.25));
        assert_eq!((t.imagined_success_holds, t.imagined_success_fails, t.episodes), (1, 2, 4));
    }
}
